"""``shacc sweep`` on Dask: the chunk plan, padded shapes, a cluster started apart
(``dask scheduler`` / ``dask worker`` on 127.0.0.1, the protocol between hosts),
workers killed mid-task, bad scenes, and the client's memory."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import process_group_members
from test_sweep import CONFIG, assert_same_tables, write

from geometry_precompute import InputError, bake, precompute, random_scene
from sweeps.config import load_config, parse_config
from sweeps.plan import bucket, plan, shapes


def test_buckets():
    sizes = [bucket(n) for n in range(1, 20_000)]
    assert all(b >= n for n, b in enumerate(sizes, 1))
    assert all(b <= max(8, 1.25 * n) for n, b in enumerate(sizes, 1))
    assert sizes == sorted(sizes) and bucket(10_000) == 10_240 and bucket(1000) == 1024
    assert len(set(sizes)) < 60  # a few programs for every chunk size up to 20 000


def test_plan_depends_on_the_config_alone(tmp_path, monkeypatch):
    cfg = load_config(write(tmp_path, CONFIG.replace("chunk = 1", "chunk = 2")
                            + "[[points]]\nshrink_step = 0.2\n"))
    first = (plan(cfg), shapes(cfg))
    # Another machine: less memory, other devices, another core count.
    monkeypatch.setenv("SHACC_MEMORY_BUDGET", "1K")
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "0,1,2")
    monkeypatch.setattr(os, "cpu_count", lambda: 128)
    assert (plan(cfg), shapes(cfg)) == first
    chunks, shp = first
    # v_max points share geometry: one group; the shrink_step point is its own.
    assert [(c.points, list(c.scenes)) for c in chunks] == [
        ((0, 1), [0, 1]), ((0, 1), [2]), ((2,), [0, 1]), ((2,), [2])]
    assert (shp.scenes, shp.tasks, shp.objects) == (2, 3, 3)


def test_padded_shapes_change_no_result():
    """A chunk evaluated at the sweep's shapes (more scenes, tasks and objects), and with
    both meta formulas (the layout of a chunk that mixes scenes of both), gives the
    rollouts of its own smallest batch."""
    import dataclasses

    import shacc_jax
    from geometry_precompute.bake import concatenate

    results = [precompute(s, s.settings(overrides={"start_grid": [2, 3]}))
               for s in (random_scene(7, "uniform", 3, 4), random_scene(8, "gaussian", 3, 4))]
    own = shacc_jax.evaluate(*shacc_jax.inputs(bake(results)))
    padded = concatenate([bake(results[:1], 6, max_objects=7),
                          bake(results[1:], 6, max_objects=7)], pad_to=4)
    g, p, layout = shacc_jax.inputs(padded)
    assert layout.meta_formula == "yaw" and layout.n_objects == 7 and g.task_mask.shape == (4, 6)
    wide = shacc_jax.evaluate(g, p, dataclasses.replace(layout, meta_formula="both"))
    T = own.rollouts.outcome.shape[-1]
    for a, b in zip(own.rollouts, wide.rollouts, strict=True):
        a, b = np.asarray(a), np.asarray(b)[:2, :, :, :T]
        if a.dtype.kind == "f":  # float32: another batch shape may round differently
            np.testing.assert_allclose(b, a, atol=1e-4)
        else:
            np.testing.assert_array_equal(b, a)
    np.testing.assert_allclose(np.asarray(wide.metrics.u_scene)[:2],
                               np.asarray(own.metrics.u_scene))


def test_bad_scene_in_the_middle_of_a_folder_stops_before_work(tmp_path):
    """A scene file whose objects interpenetrate (read fine, caught by the bodies check),
    second of three: the config is refused, naming it, before any work."""
    import tomllib

    import tomli_w

    from geometry_precompute import shipped_scene_paths

    folder = tmp_path / "scenes"
    folder.mkdir()
    for i, p in enumerate(shipped_scene_paths()[:3]):
        data = tomllib.loads(p.read_text())
        if i == 1:  # the second object onto the first
            x, y, z = data["objects"][0]["position"]
            data["objects"][1]["position"] = [x + 0.01, y, z]
        (folder / f"{i}_{p.name}").write_text(tomli_w.dumps(data))
    with pytest.raises(InputError) as e:
        parse_config({"source": {"kind": "files", "path": "scenes"}}, "cfg.toml", tmp_path)
    assert "1_" in e.value.source and "interpenetrates" in e.value.rule


def _sweep(config: Path, out: Path, cache: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "sweeps.cli", "sweep", str(config), "--out", str(out),
            "--cache", str(cache), "--quiet", *extra]


def _env() -> dict:
    return {**os.environ, "JAX_PLATFORMS": "cpu", "PYTHONUNBUFFERED": "1"}


def _summary(res: subprocess.CompletedProcess) -> dict:
    assert res.returncode == 0, res.stderr[-3000:]
    return json.loads(res.stdout.strip().splitlines()[-1])


@pytest.fixture
def started_cluster(tmp_path):
    """A scheduler and two workers started apart, as on other hosts: one takes the
    precompute, one the evaluation. All stopped afterwards."""
    sched_file = tmp_path / "scheduler.json"
    dask = [sys.executable, "-m", "dask"]
    procs = [subprocess.Popen([*dask, "scheduler", "--host", "127.0.0.1", "--port", "0",
                               "--no-dashboard", "--scheduler-file", str(sched_file)],
                              env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              start_new_session=True)]
    try:
        deadline = time.time() + 60
        while not sched_file.exists() and time.time() < deadline:
            time.sleep(0.1)
        address = json.loads(sched_file.read_text())["address"]
        for resource in ("precompute=1", "evaluate=1"):
            procs.append(subprocess.Popen(
                [*dask, "worker", address, "--host", "127.0.0.1", "--nthreads", "1",
                 "--nworkers", "1", "--resources", resource, "--no-dashboard"],
                env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                start_new_session=True))
        yield address
    finally:
        for p in procs:
            with_group = [p.pid, *process_group_members(p.pid)]
            for pid in with_group:
                try:
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
            p.wait()


def test_started_cluster_gives_the_embedded_tables(started_cluster, tmp_path):
    from test_sweep import CONFIG as TEXT

    config = write(tmp_path, TEXT)
    embedded, apart = tmp_path / "embedded", tmp_path / "apart"
    s1 = _summary(subprocess.run(_sweep(config, embedded, tmp_path / "c1", "--workers", "2"),
                                 env=_env(), capture_output=True, text=True, timeout=600))
    s2 = _summary(subprocess.run(_sweep(config, apart, tmp_path / "c2", "--scheduler",
                                        started_cluster),
                                 env=_env(), capture_output=True, text=True, timeout=600))
    assert s1["scheduler"] == "local" and s2["scheduler"] == started_cluster
    assert s2["precompute_workers"] == 1 and s2["evaluation_workers"] == 1
    assert s2["precomputed"] == 3 and s1["status"] == s2["status"] == "complete"
    assert_same_tables(apart, embedded)


def _session_processes(sid: int, holding: str) -> list[int]:
    """Processes of session ``sid`` that have a library whose path holds ``holding``
    mapped (the evaluation worker maps jaxlib; a precompute worker coal)."""
    found = []
    for pid in process_group_members(sid):
        if pid == sid:
            continue
        try:
            if holding in Path(f"/proc/{pid}/maps").read_text():
                found.append(pid)
        except OSError:
            pass
    return found


def test_workers_killed_mid_task_lose_and_duplicate_nothing(tmp_path):
    """The evaluation worker is killed while it compiles the first chunk (the
    compilation cache is off, so that takes seconds) and a precompute worker with it;
    the nannies start new ones, Dask reruns the lost tasks, and the tables equal an
    uninterrupted run's."""
    text = CONFIG.replace("count = 3", "count = 4")
    config = write(tmp_path, text)
    ref = tmp_path / "ref"
    _summary(subprocess.run(_sweep(config, ref, tmp_path / "c0", "--workers", "2"),
                            env=_env(), capture_output=True, text=True, timeout=600))
    out, cache = tmp_path / "killed", tmp_path / "cache"
    env = {**_env(), "SHACC_COMPILE_CACHE": "off"}
    proc = subprocess.Popen(_sweep(config, out, cache, "--workers", "2"), env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    deadline = time.time() + 300
    while not list(cache.glob("*.pkl")) and proc.poll() is None and time.time() < deadline:
        time.sleep(0.05)
    time.sleep(0.5)  # the first chunk's evaluation has begun: it compiles for seconds
    evaluators = _session_processes(proc.pid, "jaxlib")
    precomputers = [p for p in _session_processes(proc.pid, "libcoal")
                    if p not in evaluators]
    assert evaluators and precomputers, "workers not found"
    assert not list((out / "scenes").glob("part-*")), "the first chunk was already written"
    for pid in (evaluators[0], precomputers[0]):
        os.kill(pid, signal.SIGKILL)
    stdout, stderr = proc.communicate(timeout=600)
    assert proc.returncode == 0, stderr[-3000:]
    summary = json.loads(stdout.strip().splitlines()[-1])
    assert summary["status"] == "complete" and summary["done_before"] == 0
    assert_same_tables(out, ref)
    assert process_group_members(proc.pid) == []


def test_client_memory_does_not_grow_with_the_number_of_chunks(started_cluster, tmp_path):
    """The client holds a bounded number of chunks: its peak of Python memory is the
    same for 3 chunks as for 12, while the 12 chunks' results are several times what
    that peak could hide."""
    script = """
import json, sys, tracemalloc
from pathlib import Path
from sweeps.config import load_config
from sweeps.runner import run_sweep
cfg, out = load_config(sys.argv[1]), Path(sys.argv[2])
tracemalloc.start()
run_sweep(cfg, out, out.parent / "cache", progress=False, scheduler=sys.argv[3])
size = sum(p.stat().st_size for p in out.rglob("part-*.parquet"))
print(json.dumps({"peak": tracemalloc.get_traced_memory()[1], "written": size}))
"""
    peaks = {}
    for n in (3, 12):
        text = CONFIG.replace("count = 3", f"count = {2 * n}").replace("chunk = 1", "chunk = 2")
        text = text.replace("tasks = [3, 3]", "tasks = [10, 10]").replace("[[2, 2]]", "[[16, 16]]")
        config = write(tmp_path, text, f"sweep{n}.toml")
        res = subprocess.run([sys.executable, "-c", script, str(config), str(tmp_path / f"o{n}"),
                              started_cluster],
                             env=_env(), capture_output=True, text=True, timeout=600)
        peaks[n] = _summary(res)
    grown = peaks[12]["peak"] - peaks[3]["peak"]
    extra = peaks[12]["written"] - peaks[3]["written"]
    assert extra > 800_000  # what holding every chunk would add, at least
    assert grown < 0.25 * extra, (peaks, grown, extra)
