"""``shacc sweep``: validation, results, the precompute cache, resuming after SIGKILL,
and sharding over two (forced) CPU devices."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pytest
from conftest import StartedCluster, process_group_members

from geometry_precompute import InputError, bake, precompute, random_scene
from sweeps.config import load_config, parse_config
from sweeps.distributed.runner import dry_run, run_sweep

CONFIG = """
name = "tiny"
chunk = 1
[source]
kind = "random"
count = 3
tasks = [3, 3]
sampling = "both"
seed = 5
[axes]
v_max = [0.15, 0.3]
start_grid = [[2, 2]]
"""


def assert_same_tables(out: Path, ref: Path) -> None:
    """Both datasets of two sweeps hold the same rows in the same order, no row missing
    or duplicated."""
    keys = {"scenes": ["point", "scene_index"],
            "rollouts": ["point", "scene_index", "mode", "start", "task"]}
    for name, key in keys.items():
        got, want = pd.read_parquet(out / name), pd.read_parquet(ref / name)
        assert not got.duplicated(key).any()
        pd.testing.assert_frame_equal(got, want)


def write(tmp_path: Path, text: str, name: str = "sweep.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize("text,field,rule", [
    (CONFIG.replace("v_max =", "warp_speed ="), "axes.warp_speed", "unknown setting"),
    (CONFIG.replace("[0.15, 0.3]", "[0.15, -1.0]"), "axes.v_max", "(0, 100]"),
    (CONFIG + '[[points]]\nbogus = 1\n', "points[0].bogus", "unknown setting"),
    (CONFIG.replace('name = "tiny"', 'name = "tiny"\nspeed = 1'), "speed", "unknown field"),
    (CONFIG.replace('kind = "random"', 'kind = "lottery"'), "source.kind", "random or files"),
    (CONFIG.replace("count = 3", "count = 0"), "source.count", "in [1, "),
])
def test_bad_configs_rejected_before_work(tmp_path, text, field, rule):
    with pytest.raises(InputError) as e:
        load_config(write(tmp_path, text))
    assert e.value.field == field and rule in e.value.rule and "sweep.toml" in str(e.value)


def test_points_grid_and_explicit(tmp_path):
    cfg = load_config(write(tmp_path, CONFIG + "[[points]]\nv_max = 0.5\n"))
    assert cfg.points == [{"v_max": 0.15, "start_grid": [2, 2]},
                          {"v_max": 0.3, "start_grid": [2, 2]}, {"v_max": 0.5}]


def test_files_source(tmp_path):
    from geometry_precompute import shipped_scene_paths

    folder = tmp_path / "scenes"
    folder.mkdir()
    for p in shipped_scene_paths()[:2]:
        (folder / p.name).write_text(p.read_text())
    cfg = parse_config({"source": {"kind": "files", "path": "scenes"}}, "cfg.toml", tmp_path)
    assert len(cfg.scenes()) == 2 and cfg.points == [{}]
    with pytest.raises(InputError, match="folder"):
        parse_config({"source": {"kind": "files", "path": "nope"}}, "cfg.toml", tmp_path)


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("sweep")
    cfg = load_config(write(tmp, CONFIG))
    out, cache = tmp / "out", tmp / "cache"
    summary = run_sweep(cfg, out, cache, workers=1, progress=False)
    return cfg, out, cache, summary


def test_tables_and_values(finished):
    cfg, out, _, summary = finished
    assert summary["status"] == "complete" and summary["precomputed"] == 3
    # The local cluster's evaluation worker began its warm-up with its process.
    assert summary["warmed_up_with_the_process"] == 1
    # The two points differ only in v_max (a rollout setting): one group, evaluated with a
    # points axis, so 3 chunks of one scene each, not 6.
    assert summary["chunks"] == 3
    scenes = pd.read_parquet(out / "scenes")
    rollouts = pd.read_parquet(out / "rollouts")
    assert sorted(p.name for p in (out / "rollouts").iterdir()) == \
        [f"part-00000{k}.parquet" for k in range(3)]
    assert len(scenes) == 2 * 3 and len(rollouts) == 2 * 3 * 3 * 4 * 3
    assert {"point", "scene", "C_init", "C_final", "d", "h", "shacc.success",
            "shacc.delta_R_mean", "baseline.n_wrong"} <= set(scenes.columns)
    assert list(rollouts.columns) == ["point", "scene_index", "mode", "start", "task", "outcome",
                                      "activated", "steps", "delta_R", "time", "path_length",
                                      "assist_none", "assist_scene", "assist_correct",
                                      "assist_wrong"]
    assert json.loads((out / "config.json").read_text())["hash"] == cfg.hash()
    # A row against a direct evaluation of the same scene and settings.
    import programs

    import shacc_jax

    scene = random_scene(5 + 1, "gaussian", 3, 3)
    r = precompute(scene, scene.settings(overrides={"v_max": 0.3, "start_grid": [2, 2]}))
    ev = programs.evaluate(*shacc_jax.inputs(bake([r])))
    row = scenes[(scenes.point == 1) & (scenes.scene_index == 1)].iloc[0]
    for m, mode in enumerate(shacc_jax.MODES):
        assert row[f"{mode}.success"] == pytest.approx(float(ev.metrics.u_scene[0, m]))
    sub = rollouts[(rollouts.point == 1) & (rollouts.scene_index == 1) &
                   (rollouts["mode"] == "shacc")].sort_values(["start", "task"])
    np.testing.assert_array_equal(sub.steps.to_numpy(),
                                  np.asarray(ev.rollouts.step[0, 2]).ravel())


def test_the_dataset_reads_the_same_typed_everywhere(finished):
    """The four tables read alike with pyarrow.dataset, pandas, polars and DuckDB: typed
    swept settings (a float, a list), task and start identities that join the rollouts,
    and every column described in the parts' own metadata."""
    import duckdb
    import polars as pl
    import pyarrow.dataset as ds
    import pyarrow.parquet as pq

    from sweeps.analysis.tables import COLUMNS, TABLES

    _, out, _, _ = finished
    con = duckdb.connect()

    def sql(query):
        return con.execute(query).fetchall()

    for name in TABLES:
        arrow = ds.dataset(out / name).to_table()
        frame = pd.read_parquet(out / name)
        polar = pl.read_parquet(str(out / name / "*.parquet"))
        rel = con.sql(f"select * from read_parquet('{out / name}/*.parquet')")
        duck = rel.to_arrow_table() if hasattr(rel, "to_arrow_table") else rel.arrow()
        assert arrow.column_names == list(frame.columns) == polar.columns == duck.column_names
        assert arrow.num_rows == len(frame) == polar.height == duck.num_rows
        meta = pq.read_schema(next((out / name).glob("*.parquet"))).metadata
        described = json.loads(meta[b"shacc.columns"])
        assert described.keys() == COLUMNS[name].keys()
        assert json.loads(meta[b"shacc.provenance"])["backend"] == "cpu"
        for col in arrow.column_names:  # every column is described (NAME, MODE, KIND)
            rest = col.split(".", 1)[-1]
            pattern = col if col in described else "set.NAME" if col.startswith("set.") else \
                "assist_KIND" if col.startswith("assist_") else \
                "MODE." + ("n_OUTCOME" if rest.startswith("n_") else "assist_KIND"
                           if rest.startswith("assist_") else rest)
            assert pattern in described, col
    scenes = ds.dataset(out / "scenes").to_table()
    assert scenes.schema.field("set.v_max").type == pa.float64()
    assert scenes.schema.field("set.start_grid").type == pa.list_(pa.int64())
    assert pl.read_parquet(str(out / "scenes" / "*.parquet"))["set.v_max"].dtype == pl.Float64
    assert sql(f"select typeof(\"set.start_grid\") from read_parquet("
               f"'{out}/scenes/*.parquet') limit 1")[0][0] == "BIGINT[]"
    # The rollouts join their task and start rows by the documented keys.
    joined = sql(f"""
        select count(*), count(t.task_id), count(s.x), count(distinct t.template)
        from read_parquet('{out}/rollouts/*.parquet') r
        join read_parquet('{out}/tasks/*.parquet') t using (point, scene_index, task)
        join read_parquet('{out}/starts/*.parquet') s using (point, scene_index, start)
    """)[0]
    n_rollouts = len(pd.read_parquet(out / "rollouts"))
    assert joined[:3] == (n_rollouts, n_rollouts, n_rollouts) and joined[3] >= 1
    tasks = pd.read_parquet(out / "tasks")
    assert set(tasks.template) <= {"side_grasp", "handle_grasp"}
    assert all(len(n) == len(q) for n, q in zip(tasks.param_names, tasks.q_init, strict=True))


def test_rerun_is_a_no_op(finished):
    cfg, out, cache, _ = finished
    before = (out / "scenes" / "part-000001.parquet").stat().st_mtime_ns
    # What a run killed in the middle of a write leaves: write_atomic's temporary files.
    stale = [out / "scenes" / ".part-000001.parquet.k1ll3d.tmp",
             out / ".config.json.k1ll3d.tmp"]
    for p in stale:
        p.write_bytes(b"half a file")
    again = run_sweep(cfg, out, cache, workers=1, progress=False)
    assert again["status"].startswith("nothing to do")
    assert (out / "scenes" / "part-000001.parquet").stat().st_mtime_ns == before
    assert not any(p.exists() for p in stale)


def test_the_same_sweep_again_reads_its_batch_files(finished, tmp_path):
    """A later sweep of the same config reads each precompute task's bakes from its
    batch file, without the scenes' own entries, and writes the same tables."""
    cfg, out, cache, _ = finished
    assert list(cache.glob("batch-*.npz"))
    aside = tmp_path / "entries"
    aside.mkdir()
    for p in cache.glob("*.json"):  # the scenes' entries, out of the way
        p.rename(aside / p.name)
    try:
        s = run_sweep(cfg, tmp_path / "again", cache, workers=1, progress=False)
    finally:
        for p in aside.iterdir():
            p.rename(cache / p.name)
    assert s["precomputed"] == 0 and s["precompute_cache_hits"] == 3
    for table in ("scenes", "rollouts"):
        pd.testing.assert_frame_equal(pd.read_parquet(out / table),
                                      pd.read_parquet(tmp_path / "again" / table))


def test_rollout_setting_reuses_the_cache(finished, tmp_path):
    _, _, cache, _ = finished
    cfg = load_config(write(tmp_path, CONFIG.replace("v_max = [0.15, 0.3]",
                                                     "omega_max = [1.0]")))
    s = run_sweep(cfg, tmp_path / "out2", cache, workers=1, progress=False)
    assert s["precomputed"] == 0 and s["precompute_cache_hits"] == 3
    with pytest.raises(InputError, match="another sweep"):
        run_sweep(cfg, finished[1], cache, workers=1, progress=False)


def test_dry_run_counts(finished):
    info = dry_run(finished[0])
    assert info["points"] == 2 and info["scenes"] == 3 and info["rollouts"] == 216
    assert info["chunks"] == 3


def test_points_group_by_everything_but_rollout_settings(tmp_path):
    from sweeps.distributed.plan import point_groups

    cfg = load_config(write(tmp_path, CONFIG + "[[points]]\nshrink_step = 0.9\n"
                            "[[points]]\ngripper.opening = 0.12\n"))
    # v_max 0.15, v_max 0.3, shrink_step 0.9 (new geometry), the default with a wider grip
    assert point_groups(cfg) == [(0, 1), (2,), (3,)]
    with_search = load_config(write(tmp_path, CONFIG.replace(
        'name = "tiny"', 'name = "tiny"\nmodes = ["shrinking", "optimized"]')))
    assert point_groups(with_search) == [(0,), (1,)]


def _sweep_cmd(config: Path, out: Path, cache: Path) -> list[str]:
    return [sys.executable, "-m", "sweeps", "sweep", str(config), "--out", str(out),
            "--cache", str(cache), "--workers", "1", "--quiet"]


def test_killed_workers_and_client_lose_and_duplicate_nothing(tmp_path, finished):
    """One sweep of 12 chunks, interrupted twice. First its evaluation worker is killed
    while it compiles (the compilation cache is off, so that takes seconds), and a
    precompute worker with it: the nannies start new ones and Dask reruns the lost
    tasks. Then, after its first chunk, the command itself is killed with SIGKILL: it
    leaves whole chunks and no process. The rerun finishes it: every row once, and the
    rows of the reference sweep's three scenes (the same seeds) equal."""
    _, ref_out, _, _ = finished
    config = write(tmp_path, CONFIG.replace("count = 3", "count = 12"))
    out, cache = tmp_path / "killed", tmp_path / "cache"
    env = {**_env(), "SHACC_COMPILE_CACHE": "off"}
    cmd = [*_sweep_cmd(config, out, cache)[:-3], "--workers", "2", "--quiet"]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL,
                            start_new_session=True)  # its own group: to find its workers
    deadline = time.time() + 300
    while not list(cache.glob("*.json")) and proc.poll() is None and time.time() < deadline:
        time.sleep(0.05)
    time.sleep(0.3)
    evaluators = _session_processes(proc.pid, "jaxlib")
    precomputers = [p for p in _session_processes(proc.pid, "libcoal")
                    if p not in evaluators]
    assert evaluators and precomputers, "workers not found"
    assert not list((out / "scenes").glob("part-*")), "the first chunk was already written"
    for pid in (evaluators[0], precomputers[0]):
        os.kill(pid, signal.SIGKILL)
    # The evaluations queue on one worker; the first part is written while most of the
    # others are still to come.
    first = out / "scenes" / "part-000000.parquet"
    while not first.exists() and proc.poll() is None and time.time() < deadline:
        time.sleep(0.005)
    assert first.exists(), "the sweep wrote no chunk after losing its workers"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    deadline = time.time() + 10  # the workers see their nanny's pipe close and exit
    while process_group_members(proc.pid) and time.time() < deadline:
        time.sleep(0.1)
    assert process_group_members(proc.pid) == [], "worker processes outlived the sweep"
    done = sorted(p.name for p in (out / "scenes").glob("part-*.parquet"))
    assert 1 <= len(done) < 12
    res = subprocess.run(_sweep_cmd(config, out, cache), env=_env(), capture_output=True,
                         text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    assert summary["done_before"] == len(done) and summary["status"] == "complete"
    _assert_twelve_scenes(out, ref_out)


def _assert_twelve_scenes(out: Path, ref_out: Path) -> None:
    """``out`` holds a 12-scene sweep of CONFIG's seeds: every row once, and the rows of
    its first three scenes equal the 3-scene reference sweep's."""
    keys = {"scenes": ["point", "scene_index"],
            "rollouts": ["point", "scene_index", "mode", "start", "task"]}
    for name, key in keys.items():
        got, want = pd.read_parquet(out / name), pd.read_parquet(ref_out / name)
        assert not got.duplicated(key).any() and len(got) == 4 * len(want)
        first_rows = got[got.scene_index < 3].sort_values(key).reset_index(drop=True)
        pd.testing.assert_frame_equal(first_rows,
                                      want.sort_values(key).reset_index(drop=True))
    assert not list(out.rglob("*.tmp"))


def test_lost_scheduler_ends_the_sweep_in_one_line_and_the_rerun_goes_on(tmp_path, finished):
    """The scheduler killed: a 12-chunk sweep on a cluster started apart
    loses its scheduler (SIGKILL) after its first chunk. The command ends at once, with
    one line (exit 1; how many chunks are written; no traceback) and whole parts. Run
    again on another cluster, it goes on from there: every row once, and the reference
    sweep's rows equal."""
    _, ref_out, _, _ = finished
    config = write(tmp_path, CONFIG.replace("count = 3", "count = 12"))
    out, cache = tmp_path / "lost", tmp_path / "cache"
    for name in ("first", "second"):
        (tmp_path / name).mkdir()
    first = StartedCluster(tmp_path / "first")
    try:
        proc = subprocess.Popen([*_sweep_cmd(config, out, cache), "--scheduler", first.address],
                                env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True)
        deadline = time.time() + 300
        while not list((out / "scenes").glob("part-*.parquet")) and proc.poll() is None \
                and time.time() < deadline:
            time.sleep(0.005)
        assert list((out / "scenes").glob("part-*.parquet")), "the sweep wrote no chunk"
        first.scheduler.kill()
        _, stderr = proc.communicate(timeout=60)
    finally:
        first.stop()
    done = sorted((out / "scenes").glob("part-*.parquet"))
    assert 1 <= len(done) < 12, "the sweep ended before its scheduler was killed"
    assert proc.returncode == 1 and "Traceback" not in stderr, stderr[-3000:]
    last = stderr.strip().splitlines()[-1]
    assert last.startswith(f"error: lost the Dask scheduler at {first.address}"), last
    assert f"{len(done)} of 12 chunks are written" in last and "run the same command" in last, \
        (last, [p.name for p in done])
    second = StartedCluster(tmp_path / "second")
    try:
        summary = _summary(subprocess.run(
            [*_sweep_cmd(config, out, cache), "--scheduler", second.address], env=_env(),
            capture_output=True, text=True, timeout=600))
    finally:
        second.stop()
    assert summary["done_before"] == len(done) and summary["status"] == "complete"
    _assert_twelve_scenes(out, ref_out)


def test_evaluation_spread_over_two_cpu_devices(shipped_bake):
    """run() splits the scenes over both CPU devices of the test process (conftest sets
    two): the same bits as on one device, also with a points axis (each point as its own
    call) and with only some fields copied back."""
    from dataclasses import replace

    import jax

    import shacc_jax

    assert len(jax.local_devices()) == 2
    assert len(shacc_jax.plan(shipped_bake).devices) == 1  # a CPU's devices share its cores
    # Stepped users leave cores idle from one device: the plan of a large batch takes
    # every CPU device; a small one stays on one (a second device's program would cost
    # more than it saves).
    noisy = replace(shipped_bake, user_noise=np.full_like(shipped_bake.user_noise, 0.1))
    stepped = shacc_jax.plan(noisy)
    assert stepped.layout.stepped_users and len(stepped.devices) == 1
    rollouts = int(np.prod(noisy.task_mask.shape)) * noisy.starts.shape[1] * 3
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(shacc_jax.runplan, "CPU_SPLIT_ROLLOUTS", rollouts)
        assert len(shacc_jax.plan(noisy).devices) == 2
        mp.setattr(shacc_jax.runplan, "CPU_SPLIT_ROLLOUTS", rollouts + 1)
        assert len(shacc_jax.plan(noisy).devices) == 1
    two = shacc_jax.plan(shipped_bake, devices=jax.local_devices())
    assert len(two.devices) == 2 and two.padded_scenes == 12
    both = shacc_jax.execute(two, shipped_bake)
    one = shacc_jax.execute(shacc_jax.plan(shipped_bake, devices=jax.local_devices()[:1]),
                            shipped_bake)
    for x, y in zip(jax.tree.leaves(one), jax.tree.leaves(both), strict=True):
        np.testing.assert_array_equal(x, y)
    slow = replace(shipped_bake, v_max=shipped_bake.v_max * 0.5)
    keep = ("outcome", "step")
    points = shacc_jax.run(shipped_bake, points=[shipped_bake, slow], fields=keep).evaluation
    alone = shacc_jax.run(slow, fields=keep).evaluation
    np.testing.assert_array_equal(points.rollouts.outcome[1], alone.rollouts.outcome)
    np.testing.assert_array_equal(points.rollouts.step[0], both.rollouts.step)
    assert (points.rollouts.step[1] != points.rollouts.step[0]).any()  # v_max mattered
    assert points.rollouts.delta_R is None and points.rollouts.orientation is None
    with pytest.raises(ValueError, match="differ from the bake in center_init"):
        shacc_jax.run(shipped_bake, points=[replace(shipped_bake,
                                                    center_init=shipped_bake.center_init + 1)])


def test_task_counts_without_building_match_the_built_scenes(tmp_path):
    """The dry run counts a random scene's tasks from its seed alone: the generator's
    first draw. Kept equal to the scenes the generator builds."""
    cfg = parse_config({"name": "n", "source": {"kind": "random", "count": 12,
                                                "tasks": [3, 9], "seed": 40}},
                       "<test>", tmp_path)
    assert cfg.task_counts() == [len(s.tasks) for s in cfg.scenes()]


def test_sweep_with_the_optimized_mode(tmp_path):
    """modes = [..., "optimized"] and an axis over a search setting: each point's row
    equals a direct evaluation of the same scene and settings."""
    from sweeps.pipeline import evaluate_results

    text = CONFIG.replace('name = "tiny"', 'name = "tiny"\nmodes = ["shrinking", "optimized"]')
    text = text.replace("count = 3", "count = 2").replace("v_max = [0.15, 0.3]",
                                                          "optimize_population = [4, 8]")
    text += "[settings]\noptimize_generations = 3\noptimize_starts = 8\n"
    cfg = load_config(write(tmp_path, text))
    out = tmp_path / "out"
    summary = run_sweep(cfg, out, tmp_path / "cache", workers=1, progress=False)
    assert summary["status"] == "complete"
    scenes = pd.read_parquet(out / "scenes")
    rollouts = pd.read_parquet(out / "rollouts")
    assert set(rollouts["mode"]) == {"shrinking", "optimized"}
    row = scenes[(scenes.point == 1) & (scenes.scene_index == 1)].iloc[0]
    scene = random_scene(5 + 1, "gaussian", 3, 3)
    r = precompute(scene, scene.settings(overrides={
        "optimize_population": 8, "optimize_generations": 3, "optimize_starts": 8,
        "start_grid": [2, 2]}))
    ev = evaluate_results([r], ("shrinking", "optimized"))
    for m, mode in enumerate(("shrinking", "optimized")):
        assert row[f"{mode}.success"] == pytest.approx(float(ev.evaluation.metrics.u_scene[0, m]))


def _env() -> dict:
    return {**os.environ, "JAX_PLATFORMS": "cpu", "PYTHONUNBUFFERED": "1"}


def _summary(res: subprocess.CompletedProcess) -> dict:
    assert res.returncode == 0, res.stderr[-3000:]
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_started_cluster_gives_the_embedded_tables(started_cluster, tmp_path, finished):
    """``--scheduler``: a scheduler and two workers started apart on 127.0.0.1 (the
    protocol between hosts; one takes the precompute, one the evaluation) write the
    tables of the embedded local cluster."""
    config = write(tmp_path, CONFIG)
    apart = tmp_path / "apart"
    cmd = [*_sweep_cmd(config, apart, tmp_path / "cache"), "--scheduler", started_cluster]
    s = _summary(subprocess.run(cmd, env=_env(), capture_output=True, text=True, timeout=600))
    assert s["scheduler"] == started_cluster and s["status"] == "complete"
    assert s["precompute_workers"] == 1 and s["evaluation_workers"] == 1
    assert s["precomputed"] == 3 and s["compilations"] + s["programs_loaded"] > 0
    assert s["warmed_up_with_the_process"] == 0  # a cluster started apart: the task's
    assert_same_tables(apart, finished[1])


def test_missing_kind_of_worker_is_said_and_the_sweep_goes_on_when_one_joins(
        tmp_path, finished, monkeypatch, capsys):
    """A cluster started apart loses its only evaluation worker (and its nanny) as the
    sweep starts: the command says, in one line, that no worker has the 'evaluate'
    resource, waits, and finishes when a new one joins; the tables are whole."""
    from sweeps.distributed import cluster

    monkeypatch.setattr(cluster, "NO_WORKER_PATIENCE", 1.0)
    monkeypatch.setattr(cluster, "NO_WORKER_CHECK", 0.2)
    _, ref_out, _, _ = finished
    cfg = load_config(write(tmp_path, CONFIG.replace("count = 3", "count = 12")))
    out, cache = tmp_path / "out", tmp_path / "cache"
    started = StartedCluster(tmp_path)
    started.wait_for_workers(2)  # both kinds known to the sweep when it starts
    said: list[str] = []

    def lose_and_replace() -> None:
        deadline = time.time() + 300
        while not list(cache.glob("*.json")) and time.time() < deadline:
            time.sleep(0.005)  # the sweep has started: its first scene is precomputed
        started.kill(started.workers["evaluate"])
        while not said and time.time() < deadline:  # the line, then a new worker
            time.sleep(0.1)
            said.extend(line for line in capsys.readouterr().err.splitlines()
                        if line.startswith("waiting: "))
        started.add_worker("evaluate")

    helper = threading.Thread(target=lose_and_replace)
    helper.start()
    try:
        summary = run_sweep(cfg, out, cache, progress=False, scheduler=started.address)
    finally:
        helper.join()
        started.stop()
    said.extend(line for line in capsys.readouterr().err.splitlines()
                if line.startswith("waiting: "))
    assert len(said) == 1, said  # once per absence
    assert f"at {started.address} has the 'evaluate' resource" in said[0]
    assert f"dask worker {started.address} --resources evaluate=1" in said[0]
    assert summary["status"] == "complete" and summary["done_before"] == 0
    _assert_twelve_scenes(out, ref_out)


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


def test_sweep_over_collision_and_gripper_sizes(tmp_path):
    """An axis over ``collision`` and one over the gripper's opening: all four points
    share one geometry (rollout settings only), so one group and one evaluation per
    chunk; without checks nothing collides, with them both grips collide and the
    opening changes how often."""
    from sweeps.distributed.plan import point_groups

    text = CONFIG.replace("v_max = [0.15, 0.3]\nstart_grid = [[2, 2]]",
                          'collision = ["off", "on"]\ngripper.opening = [0.04, 0.14]\n'
                          "start_grid = [[4, 3]]")
    cfg = load_config(write(tmp_path, text))
    assert point_groups(cfg) == [(0, 1, 2, 3)]
    run_sweep(cfg, tmp_path / "out", tmp_path / "cache", workers=1, progress=False)
    rows = pd.read_parquet(tmp_path / "out" / "rollouts")
    hits = rows.assign(hit=rows["outcome"] == "collision").groupby("point")["hit"].sum()
    by = {(p["collision"], p["gripper.opening"]): int(hits[i])
          for i, p in enumerate(cfg.points)}
    assert by[("off", 0.04)] == 0 and by[("off", 0.14)] == 0
    assert by[("on", 0.04)] > 0 and by[("on", 0.14)] > 0
    assert by[("on", 0.04)] != by[("on", 0.14)]


def test_modes_come_back_in_the_order_asked(shipped_bake):
    """``run`` returns the modes in the order asked, each mode's rollouts and metrics the
    same bits whatever the order or company it was evaluated in."""
    import shacc_jax

    modes = shacc_jax.MODES
    ev = shacc_jax.run(shipped_bake, modes).evaluation
    backwards = shacc_jax.run(shipped_bake, modes[::-1]).evaluation
    for got, want in zip([*backwards.rollouts, *backwards.metrics],
                         [*ev.rollouts, *ev.metrics], strict=True):
        np.testing.assert_array_equal(got, want[:, ::-1])
    alone = shacc_jax.run(shipped_bake, ("shacc",)).evaluation
    np.testing.assert_array_equal(alone.rollouts.outcome[:, 0], ev.rollouts.outcome[:, 2])
    np.testing.assert_array_equal(alone.metrics.u_scene[:, 0], ev.metrics.u_scene[:, 2])


def test_random_source_presets(tmp_path):
    """A random source names the generator's preset (compact by default, whose cache keys
    and scenes stay those of earlier sweeps); the paper preset spreads the objects
    wider, so its uniform scenes are less cluttered."""
    base = {"source": {"kind": "random", "count": 12, "tasks": [5, 10], "sampling": "uniform"}}
    compact = parse_config(base, "c.toml", tmp_path)
    paper = parse_config({"source": {**base["source"], "preset": "paper"}}, "p.toml", tmp_path)
    assert compact.random_ref(3) == (3, "uniform", 5, 10)
    assert paper.random_ref(3) == (3, "uniform", 5, 10, "paper") and paper.hash() != compact.hash()
    with pytest.raises(InputError, match=r"source\.preset"):
        parse_config({"source": {**base["source"], "preset": "wide"}}, "w.toml", tmp_path)
    c = [precompute(random_scene(*compact.random_ref(i))).C_init for i in range(12)]
    p = [precompute(random_scene(*paper.random_ref(i))).C_init for i in range(12)]
    assert np.mean(p) < 0.6 * np.mean(c)


def test_compare_two_sweep_folders(finished):
    """A sweep compared with itself: a row per point, mode and metric, every difference
    zero (the same scenes and points, read from the typed tables)."""
    from sweeps.analysis.compare import METRICS, compare

    _, out, _, _ = finished
    result = compare(out, out, n_boot=200)
    assert {r["point"] for r in result["rows"]} == {0, 1}
    assert len(result["rows"]) == 2 * 3 * len(METRICS)
    assert all(r["diff"] in (0.0, None) and r["n_scenes"] <= 3 for r in result["rows"])
