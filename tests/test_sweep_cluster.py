"""``shacc sweep`` on Dask: the chunk plan, padded shapes, bad scene files, and the
client's memory on a cluster started apart. (A cluster started apart against the
embedded one, and workers killed mid-task: tests/test_sweep.py, beside its reference
sweep.)"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from test_sweep import CONFIG, write

from geometry_precompute import InputError, bake, precompute, random_scene
from sweeps.config import load_config, parse_config
from sweeps.distributed import evaluation_worker
from sweeps.distributed.plan import bucket, plan, shapes


def test_buckets():
    sizes = [bucket(n) for n in range(1, 20_000)]
    assert all(b >= n for n, b in enumerate(sizes, 1))
    assert all(b <= max(8, 1.25 * n) for n, b in enumerate(sizes, 1))
    assert sizes == sorted(sizes) and bucket(10_000) == 10_240 and bucket(1000) == 1024
    assert len(set(sizes)) < 60  # a few programs for every chunk size up to 20 000


def test_precompute_batches_cover_the_chunk_in_order():
    """Every scene of a chunk in exactly one precompute task, in order; at most 64 a
    task, at most two tasks per worker thread (unless that cap needs more), and at least
    one per thread where the chunk has the scenes."""
    from sweeps.distributed.plan import precompute_batches

    for n, workers in [(1000, 16), (1000, 30), (1000, 4), (3, 2), (7, 1), (64, 64)]:
        parts = precompute_batches(range(100, 100 + n), workers)
        assert [i for p in parts for i in p] == list(range(100, 100 + n))
        assert max(map(len, parts)) <= 64
        assert len(parts) <= 2 * workers or max(map(len, parts)) == 64
        assert len(parts) >= min(n, workers)


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

    import programs

    import shacc_jax
    from geometry_precompute.baking import concatenate

    results = [precompute(s, s.settings(overrides={"start_grid": [2, 3]}))
               for s in (random_scene(7, "uniform", 3, 4), random_scene(8, "gaussian", 3, 4))]
    own = programs.evaluate(*shacc_jax.inputs(bake(results)))
    padded = concatenate([bake(results[:1], 6, max_objects=7),
                          bake(results[1:], 6, max_objects=7)], pad_to=4)
    g, p, layout = shacc_jax.inputs(padded)
    assert layout.meta_formula == "yaw" and layout.n_objects == 7 and g.task_mask.shape == (4, 6)
    wide = programs.evaluate(g, p, dataclasses.replace(layout, meta_formula="both"))
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


def _env() -> dict:
    return {**os.environ, "JAX_PLATFORMS": "cpu", "PYTHONUNBUFFERED": "1"}


def _summary(res: subprocess.CompletedProcess) -> dict:
    assert res.returncode == 0, res.stderr[-3000:]
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_client_memory_does_not_grow_with_the_number_of_chunks(started_cluster, tmp_path):
    """The client holds a bounded number of chunks (here at most four in flight: one
    evaluation worker, a lookahead of two scenes): its peak of Python memory is the same
    for 3 chunks as for 12, while the 12 chunks' results are several times what that
    peak could hide."""
    script = """
import json, sys, tracemalloc
from pathlib import Path
from sweeps.config import load_config
from sweeps.distributed.runner import run_sweep
cfg, out = load_config(sys.argv[1]), Path(sys.argv[2])
tracemalloc.start()
run_sweep(cfg, out, out.parent / "cache", progress=False, scheduler=sys.argv[3],
          lookahead=2)
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


def test_an_early_warm_up_serves_the_task_of_its_job_only(tmp_path):
    """A warm-up begun early (in a thread, as a local evaluation worker begins one with
    its process) serves the warm-up task of the same job; a task of another job runs its
    own; an early warm-up that failed is run again by the task, which raises the
    error."""
    from dataclasses import replace

    from sweeps.distributed.evaluation_worker import EarlyWarmUp, warm_up
    from sweeps.distributed.runner import warm_up_job

    cfg = load_config(write(tmp_path, CONFIG))
    job, ref = warm_up_job(cfg, plan(cfg), None)
    got = warm_up(job, ref, early=EarlyWarmUp(job, ref).start())
    assert got["early"] is True and got["seconds"] > 0
    assert got["compiled"] + got["loaded"] >= 1
    other = warm_up(replace(job, modes=("baseline",)), ref, early=EarlyWarmUp(job, ref).start())
    assert other["early"] is False
    bad = (ref[0], "bogus", *ref[2:])  # random_scene refuses this sampling kind
    with pytest.raises(ValueError, match="sampling kind"):
        warm_up(job, bad, early=EarlyWarmUp(job, bad).start())
    assert warm_up(job, ref)["early"] is False  # outside a worker: no early warm-up


def test_local_workers_are_forked_from_one_server_and_set_up_by_the_plugin(tmp_path):
    """The local cluster's workers are forked from one fork server, which imported the
    task modules before any task ran; none of them has JAX before its first task, and
    the server is not this process. Each is set up by the plugin: SIGINT ignored, the
    precompute worker at nice 5, and the evaluation worker's warm-up, passed to the
    cluster, begun with its process and taken by the warm-up task of its job (JAX comes
    with it)."""
    import signal

    from sweeps.distributed.cluster import connect
    from sweeps.distributed.runner import warm_up_job

    def probe():
        return (os.getppid(), "geometry_precompute.batch" in sys.modules,
                signal.getsignal(signal.SIGINT) == signal.SIG_IGN, os.nice(0))

    cfg = load_config(write(tmp_path, CONFIG))
    job, ref = warm_up_job(cfg, plan(cfg), None)
    with connect(workers=1, warm_up=(job, ref)) as pool:
        found = pool.client.run(probe)
        without_jax = pool.client.run(lambda: "jax" not in sys.modules,
                                      workers=[*set(found) - set(pool.evaluators)])
        warmed = pool.client.submit(evaluation_worker.warm_up, job, ref,
                                    resources=pool.evaluate, pure=False).result()
    parents = {p for p, *_ in found.values()}
    assert len(found) == 2 and len(parents) == 1 and os.getpid() not in parents
    server = open(f"/proc/{parents.pop()}/cmdline", "rb").read()
    assert b"multiprocessing.forkserver" in server
    assert all(imported and ignored for _, imported, ignored, _ in found.values())
    nice = {w in pool.evaluators: n for w, (*_, n) in found.items()}
    assert nice[False] == os.nice(0) + 5 and nice[True] == os.nice(0)
    assert list(without_jax.values()) == [True]
    assert warmed["early"] is True and warmed["compiled"] + warmed["loaded"] >= 1


def test_local_dashboard_is_built_when_first_opened():
    """The local cluster's dashboard is built when a page of it is first asked for, not
    with the scheduler: its printed address then answers with bokeh's status page, as
    do its other pages; distributed's own routes answer before that."""
    import urllib.request

    from sweeps.distributed.cluster import connect

    def bokeh_apps(pool) -> int:
        return pool.client.run_on_scheduler(lambda dask_scheduler: sum(
            "Bokeh" in type(a).__name__ for a in dask_scheduler.http_application.applications))

    with connect(workers=1) as pool:
        root = pool.dashboard.rsplit("/", 1)[0]
        assert pool.dashboard.endswith("/status") and bokeh_apps(pool) == 0
        assert urllib.request.urlopen(root + "/health", timeout=30).read() == b"ok"
        assert bokeh_apps(pool) == 0
        page = urllib.request.urlopen(pool.dashboard, timeout=60)
        assert page.url == pool.dashboard and b"bokeh" in page.read().lower()
        assert bokeh_apps(pool) == 1
        assert b"bokeh" in urllib.request.urlopen(root + "/workers", timeout=30).read().lower()


def test_no_fork_server_means_spawned_workers(monkeypatch):
    """Where the fork server cannot start, the local cluster spawns its workers."""
    import multiprocessing.forkserver

    import dask

    from sweeps.distributed.cluster import start_fork_server

    def refuse():
        raise OSError("no unix sockets here")

    monkeypatch.setattr(multiprocessing.forkserver, "ensure_running", refuse)
    with dask.config.set({"distributed.worker.multiprocessing-method": "forkserver"}):
        assert start_fork_server() is False
        assert dask.config.get("distributed.worker.multiprocessing-method") == "spawn"


def test_a_chunk_evaluates_the_same_however_its_precompute_was_split(tmp_path):
    """``join_chunk`` (a CPU worker's task in a sweep) joins a chunk's precompute batches
    in the chunk's order, padded to the chunk's shape; its evaluation, trimmed back to
    the chunk's scenes, does not depend on how the scenes were split into batches."""
    from geometry_precompute.batch import precompute_batch
    from sweeps.distributed.evaluation_worker import ChunkJob, evaluate_chunk, join_chunk

    cfg = parse_config({"name": "j", "chunk": 9, "source": {
        "kind": "random", "count": 9, "tasks": [3, 4], "seed": 1}}, "<test>", str(tmp_path))
    chunk, shp = plan(cfg)[0], shapes(cfg)
    assert shp.scenes == 10  # one scene of padding
    job = ChunkJob(chunk, ({},), cfg.modes, shp, ())

    def joined(*parts):
        return join_chunk(job, *(precompute_batch(
            [cfg.random_ref(i) for i in part], [{}], str(tmp_path / "c"), shp.tasks,
            shp.objects) for part in parts))

    split = joined([0, 1, 2], [3], [4, 5, 6, 7, 8])
    whole = joined(range(9))  # from the cache the split run filled
    assert split.bakes[0].n_scenes == shp.scenes
    assert split.labels["name"] == [random_scene(*cfg.random_ref(i)).name for i in range(9)]
    assert split.counts == {"precomputed": 9, "cache_hits": 0, "cache_warning": None,
                            "scene_warnings": ()}
    assert whole.counts == {"precomputed": 0, "cache_hits": 9, "cache_warning": None,
                            "scene_warnings": ()}
    a, b = evaluate_chunk(job, split), evaluate_chunk(job, whole)
    assert a.labels == b.labels
    for x, y in zip(a.rollouts, b.rollouts, strict=True):
        assert x.keys() == y.keys()
        for k in x:
            assert x[k].shape[0] == 9, k
            np.testing.assert_array_equal(x[k], y[k], err_msg=k)


def test_the_worker_watch_never_holds_the_command_when_the_scheduler_is_gone(monkeypatch):
    """A look at the workers sent just as the scheduler died waits out the client's
    connection timeout (60 s) before it fails: the sweep, which says in one line that
    the scheduler is lost, leaves the watch at once instead of waiting for it."""
    import threading
    import time
    from types import SimpleNamespace

    from sweeps.distributed import cluster

    monkeypatch.setattr(cluster, "NO_WORKER_CHECK", 0.01)
    asked, release = threading.Event(), threading.Event()

    def scheduler_info(n_workers):
        asked.set()
        release.wait(30)  # a query to a scheduler that no longer answers
        raise OSError("timed out")

    client = SimpleNamespace(status="running", scheduler_info=scheduler_info)
    pool = SimpleNamespace(client=client, precompute={"precompute": 1},
                           evaluate={"evaluate": 1})
    try:
        t = time.monotonic()
        with cluster.watch_workers(pool, "tcp://nowhere:1", print):
            assert asked.wait(10)
        assert time.monotonic() - t < 5
        # Once the client knows the scheduler is gone, the watch asks nothing more.
        release.set()
        asked.clear()
        client.status = "connecting"
        with cluster.watch_workers(pool, "tcp://nowhere:1", print):
            time.sleep(0.2)
        assert not asked.is_set()
    finally:
        release.set()
