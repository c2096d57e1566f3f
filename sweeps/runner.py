"""The sweep runner (SPEC section 12): precompute on CPU in worker processes with a
disk cache, evaluate on the accelerator in chunks spread over the local devices,
write Parquet, and resume after any interruption.

Work is a list of chunks, each of one group of sweep points and up to ``chunk``
scenes, in a fixed order. Points that differ only in rollout settings (the schema's
Params: speeds, tolerances, collisions, gripper sizes) share their geometry, so they
form one group and are evaluated in one call, with a points axis on Params (the
optimized mode's search depends on them: with it, each point is its own group). A
finished chunk is two Parquet files in ``OUT/parts/``, each written to a temporary
name and renamed, the per-rollout part first: a chunk counts as done when its
per-scene part exists, so a run killed at any moment (SIGKILL included) leaves only
whole chunks (and perhaps a temporary file, which the rerun deletes), and the rerun
redoes the unfinished ones. When every chunk is done, the parts are joined into
``OUT/scenes.parquet`` and ``OUT/rollouts.parquet`` (also atomically); a rerun of a
finished sweep does nothing.

The precompute cache (``--cache``, default ``~/.cache/shacc/precompute``) stores one
pickle per (scene, precompute-stage settings) hash, so a rollout setting never
triggers a new precompute and overlapping sweeps share results.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import jax
import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
from tqdm import tqdm

from geometry_precompute import DEFAULTS, SPECS, InputError, bake
from geometry_precompute.scene import Scene
from shacc_jax.types import OPTIMIZED, OUTCOMES

from . import memory
from .config import SweepConfig
from .output import check_output_dir, write_atomic, write_json
from .pipeline import evaluate_points
from .workers import precompute_cached, precompute_pool

# For --dry-run's time estimate, all measured (benchmarks/RESULTS.md): rollouts per
# second (random 10-task scenes: 2 CPU cores 1.4e5, one H100 9.2e7); precompute per task
# and core (31 ms for a 10-task scene on one core); starting the spawned workers; one
# compilation of the evaluation (5-7 s on the 2-core CPU, about 7 s on an H100); pyarrow
# tables and Parquet writes per rollout and per chunk. The laptop sweep: estimated 13.5 s,
# measured 19 s.
RATES = {"cpu": 1.4e5, "gpu": 9.2e7}
PRECOMPUTE_S_PER_TASK = 3.1e-3
WORKER_START_S = 1.5
COMPILE_S = 7.0
TABLE_S_PER_ROLLOUT = 7e-7
CHUNK_OVERHEAD_S = 0.05
DRY_RUN_EXACT = 100_000


# What a sweep writes into its output folder; a folder holding anything else is refused.
SWEEP_FILES = ("config.json", "parts", "scenes.parquet", "rollouts.parquet", ".*.tmp", ".lock")


def default_cache() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "shacc" / "precompute"


@dataclass(frozen=True)
class Chunk:
    index: int
    points: tuple[int, ...]
    scenes: tuple[int, ...]


def point_groups(cfg: SweepConfig) -> list[tuple[int, ...]]:
    """The sweep's points grouped by everything but their rollout settings (in the order
    of each group's first point); one point per group when the optimized mode runs."""
    groups: dict[str, list[int]] = {}
    for i, point in enumerate(cfg.points):
        shared = {k: v for k, v in point.items() if SPECS[k].stage != "rollout"}
        key = json.dumps(shared, sort_keys=True, default=str) if OPTIMIZED not in cfg.modes \
            else str(i)
        groups.setdefault(key, []).append(i)
    return [tuple(g) for g in groups.values()]


def plan(cfg: SweepConfig, n_scenes: int, chunk: int) -> list[Chunk]:
    out = []
    for points in point_groups(cfg):
        for start in range(0, n_scenes, chunk):
            out.append(Chunk(len(out), points,
                             tuple(range(start, min(start + chunk, n_scenes)))))
    return out


def _chunk_size(cfg: SweepConfig, scenes: list[Scene], n_starts: int) -> int:
    """Scenes per chunk: the config's, lowered if the memory budget is short (a chunk of
    one scene that still does not fit is evaluated in pieces of its start grid)."""
    per_scene = _bytes_per_scene(cfg, scenes, n_starts) * len(jax.local_devices()) * \
        max(len(g) for g in point_groups(cfg))
    return max(1, min(cfg.chunk, memory.budget() // per_scene))


def _bytes_per_scene(cfg: SweepConfig, scenes: list[Scene], n_starts: int) -> int:
    return memory.BYTES_PER_ROLLOUT * n_starts * max(len(s.tasks) for s in scenes) * len(cfg.modes)


def _max_starts(cfg: SweepConfig, scenes: list[Scene]) -> int:
    """The largest start grid over the sweep's points."""
    return max(int(np.prod(scenes[0].settings(DEFAULTS, p)["start_grid"])) for p in cfg.points)


def _tables(cfg: SweepConfig, chunk: Chunk, point_index: int, results, ev
            ) -> tuple[pd.DataFrame, ...]:
    """The per-scene and per-rollout rows of one point of a chunk (``ev``: that point's
    evaluation)."""
    point = cfg.points[point_index]
    ro, me = ev.rollouts, ev.metrics
    rows = []
    for i, (si, r) in enumerate(zip(chunk.scenes, results, strict=True)):
        row = {"point": point_index, **{f"set.{k}": str(v) for k, v in point.items()},
               "scene_index": si, "scene": r.scene.name, "n_tasks": len(r.spaces),
               "C_init": r.C_init, "C_final": r.C_final, "d": r.d, "h": r.h}
        for m, mode in enumerate(cfg.modes):
            dr = me.delta_R_mean[i, m]
            row[f"{mode}.success"] = float(me.u_scene[i, m])
            row[f"{mode}.delta_R_mean"] = float(dr) if np.isfinite(dr) else np.nan
            for o, name in enumerate(OUTCOMES):
                row[f"{mode}.n_{name}"] = int(me.outcome_counts[i, m, o])
        rows.append(row)
    scenes_df = pd.DataFrame(rows)
    S, M, N, T = ro.outcome.shape
    s_i, m_i, n_i, t_i = np.meshgrid(np.arange(S), np.arange(M), np.arange(N), np.arange(T),
                                     indexing="ij")
    valid = ro.outcome >= 0
    outcome_names = np.array(OUTCOMES)
    rollouts_df = pd.DataFrame({
        "point": np.full(valid.sum(), point_index, np.int32),
        "scene_index": np.asarray(chunk.scenes)[s_i[valid]].astype(np.int32),
        "mode": pd.Categorical(np.array(cfg.modes)[m_i[valid]], categories=list(cfg.modes)),
        "start": n_i[valid].astype(np.int32),
        "task": t_i[valid].astype(np.int16),
        "outcome": pd.Categorical(outcome_names[ro.outcome[valid]], categories=list(OUTCOMES)),
        "activated": ro.activated[valid].astype(np.int16),
        "steps": ro.step[valid].astype(np.int32),
        "delta_R": ro.delta_R[valid].astype(np.float32),
    })
    return scenes_df, rollouts_df


def _write_parquet(path: Path, table: pa.Table) -> None:
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink)
    write_atomic(path, sink.getvalue().to_pybytes())


def dry_run(cfg: SweepConfig, workers: int | None = None) -> dict:
    """Sizes and a time estimate, without building the scenes (a random source's task
    counts come from the generator's seeds; beyond ``DRY_RUN_EXACT`` scenes, from a
    sample of them)."""
    n = cfg.source["count"] if cfg.source["kind"] == "random" else None
    if n is not None and n > DRY_RUN_EXACT:
        sample = replace(cfg, source={**cfg.source, "count": DRY_RUN_EXACT}).task_counts()
        tasks_total, max_tasks = float(np.mean(sample)) * n, cfg.source["tasks"][1]
    else:
        counts = cfg.task_counts()
        n, tasks_total, max_tasks = len(counts), float(sum(counts)), max(counts)
    grids = [DEFAULTS.with_overrides(p)["start_grid"] for p in cfg.points]
    if cfg.source["kind"] == "files":  # a scene file's own [settings] may set the grid
        first = cfg.scenes()[0]
        grids = [first.settings(DEFAULTS, p)["start_grid"] for p in cfg.points]
    rollouts = sum(int(np.prod(g)) for g in grids) * tasks_total * len(cfg.modes)
    # Precompute runs once per scene and distinct precompute-stage settings (the cache
    # serves the rest; a warm cache makes this part smaller than estimated).
    stages = {json.dumps(DEFAULTS.with_overrides(p).by_stage("precompute"), sort_keys=True,
                         default=str) for p in cfg.points}
    n_workers = workers or os.cpu_count() or 1
    platform = "gpu" if jax.default_backend() in ("gpu", "cuda", "rocm") else "cpu"
    chunk = max(1, min(cfg.chunk, n))
    shapes = len({tuple(g) for g in grids}) * (1 if n % chunk == 0 else 2)
    n_chunks = len(point_groups(cfg)) * -(-n // chunk)
    est = {
        "precompute": len(stages) * tasks_total * PRECOMPUTE_S_PER_TASK / n_workers
        + WORKER_START_S,
        "compile": shapes * COMPILE_S,
        "rollouts": rollouts / RATES[platform],
        "tables_and_writes": rollouts * TABLE_S_PER_ROLLOUT + n_chunks * CHUNK_OVERHEAD_S,
    }
    per_chunk = memory.BYTES_PER_ROLLOUT * int(max(np.prod(g) for g in grids)) * max_tasks * \
        len(cfg.modes) * chunk * max(len(g) for g in point_groups(cfg))
    return {"points": len(cfg.points), "scenes": n, "scene_evaluations": len(cfg.points) * n,
            "rollouts": int(rollouts), "chunks": n_chunks, "chunk_scenes": chunk,
            "estimated_memory_per_chunk_MB": per_chunk / 2**20,
            "devices": [str(d) for d in jax.local_devices()], "precompute_workers": n_workers,
            "estimated_seconds": {k: round(v, 2) for k, v in est.items()},
            "estimated_total_seconds": round(sum(est.values()), 1),
            "rate_assumed_per_s": RATES[platform]}


def run_sweep(cfg: SweepConfig, out: Path, cache: Path | None = None,
              workers: int | None = None, progress: bool = True) -> dict:
    cache = Path(cache or default_cache())
    check_output_dir(out, "--out", SWEEP_FILES)
    check_output_dir(cache, "--cache", ("*",))
    out.mkdir(parents=True, exist_ok=True)
    cache.mkdir(parents=True, exist_ok=True)
    with folder_lock(out):
        return _run_locked(cfg, out, cache, workers, progress)


@contextlib.contextmanager
def folder_lock(out: Path):
    """One sweep at a time in ``out``: an exclusive lock on ``out/.lock``, held for the
    run and released by the kernel whenever the process ends (SIGKILL included), so a
    stale lock cannot outlive its sweep. A second run into the folder is refused."""
    fd = os.open(out / ".lock", os.O_RDWR | os.O_CREAT, 0o666)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
            raise InputError(out, "--out", f"another shacc sweep (pid {holder}) is writing "
                             "into this folder; wait for it to end or use another --out") \
                from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, str(os.getpid()).encode(), 0)
        yield
    finally:
        os.close(fd)


def _run_locked(cfg: SweepConfig, out: Path, cache: Path, workers: int | None,
                progress: bool) -> dict:
    h = cfg.hash()
    marker = out / "config.json"
    if marker.exists():
        try:
            previous = json.loads(marker.read_text())
            if not isinstance(previous, dict):
                raise ValueError("not an object")
        except (ValueError, UnicodeDecodeError) as e:
            raise InputError(marker, "<file>", f"is damaged ({e}); remove the folder or use "
                             "a new --out") from None
        if previous.get("hash") != h:
            raise InputError(out, "config", f"this folder holds another sweep (hash "
                             f"{previous.get('hash')}, this config {h}); use a new --out")
    else:
        write_json(marker, {"hash": h, "config": cfg.resolved()})
    final_s, final_r = out / "scenes.parquet", out / "rollouts.parquet"
    scenes = cfg.scenes()
    chunk_n = _chunk_size(cfg, scenes, _max_starts(cfg, scenes))
    chunks = plan(cfg, len(scenes), chunk_n)
    max_tasks = max(len(s.tasks) for s in scenes)
    parts = out / "parts"
    parts.mkdir(exist_ok=True)
    # A run killed in the middle of a write leaves its temporary file (output.write_atomic);
    # only this sweep writes into OUT, so any there now is such a leftover.
    for stale in [*out.glob(".*.tmp"), *parts.glob(".*.tmp")]:
        stale.unlink(missing_ok=True)
    todo = [c for c in chunks if not (parts / f"scenes-{c.index:06d}.parquet").exists()]
    summary = {"hash": h, "chunks": len(chunks), "done_before": len(chunks) - len(todo)}
    if not todo and final_s.exists() and final_r.exists():
        summary["status"] = "nothing to do: the sweep is complete"
        return summary
    t0 = time.perf_counter()
    n_rollouts = hits_total = computed = 0
    # Where the time goes, summed over chunks (reported in the summary).
    stage = dict.fromkeys(("precompute", "bake", "evaluate", "tables", "write"), 0.0)

    def lap(name: str, since: float) -> float:
        now = time.perf_counter()
        stage[name] += now - since
        return now

    bar = tqdm(total=len(chunks), initial=len(chunks) - len(todo), unit="chunk",
               disable=None if progress else True, file=sys.stderr, desc=cfg.name)
    n_workers = workers or os.cpu_count() or 1
    with precompute_pool(n_workers) as pool:
        for c in todo:
            t = time.perf_counter()
            # A group's points share everything the precompute reads, so each scene is
            # precomputed (or read from the cache) once, for the group's first point; the
            # other points take that result with their own settings.
            first = cfg.points[c.points[0]]
            args = [(scenes[k], first, str(cache)) for k in c.scenes]
            got = list(pool.map(precompute_cached, args, chunksize=max(1, len(args) // 64)))
            hits = sum(hit for _, hit in got)
            hits_total += hits
            computed += len(got) - hits
            per_point = [[replace(r, settings=r.scene.settings(DEFAULTS, cfg.points[i]))
                          for r, _ in got] for i in c.points]
            t = lap("precompute", t)
            # One task count for every chunk, so chunks of a group share one compilation.
            bakes = [bake(results, max_tasks) for results in per_point]
            t = lap("bake", t)
            evs = evaluate_points(bakes, cfg.modes)
            t = lap("evaluate", t)
            tables = [_tables(cfg, c, i, results, ev)
                      for i, results, ev in zip(c.points, per_point, evs, strict=True)]
            scenes_df = pd.concat([a for a, _ in tables], ignore_index=True)
            rollouts_df = pd.concat([b for _, b in tables], ignore_index=True)
            t = lap("tables", t)
            for name, df in (("rollouts", rollouts_df), ("scenes", scenes_df)):  # this order
                _write_parquet(parts / f"{name}-{c.index:06d}.parquet",
                               pa.Table.from_pandas(df, preserve_index=False))
            lap("write", t)
            n_rollouts += len(rollouts_df)
            rate = n_rollouts / (time.perf_counter() - t0)
            bar.set_postfix(rollouts=n_rollouts, rate=f"{rate:.3g}/s", cache_hits=hits)
            bar.update(1)
    bar.close()
    for name, final in (("scenes", final_s), ("rollouts", final_r)):
        files = [parts / f"{name}-{c.index:06d}.parquet" for c in chunks]
        _write_parquet(final, pa.concat_tables([pq.read_table(f) for f in files],
                                               promote_options="default"))
    summary.update({"status": "complete", "rollouts_this_run": n_rollouts,
                    "precompute_cache_hits": hits_total, "precomputed": computed,
                    "seconds": time.perf_counter() - t0,
                    "stage_seconds": {k: round(v, 3) for k, v in stage.items()},
                    "precompute_workers": n_workers})
    return summary


def cmd_sweep(args) -> int:
    from .config import load_config

    cfg = load_config(args.config)
    if args.dry_run:
        info = dry_run(cfg, args.workers)
        for k, v in info.items():
            print(f"{k}: {v:.4g}" if isinstance(v, float) else f"{k}: {v}")
        return 0
    if not args.out:
        raise InputError("<arguments>", "--out", "required unless --dry-run")
    summary = run_sweep(cfg, Path(args.out), Path(args.cache) if args.cache else None,
                        args.workers, progress=not args.quiet)
    print(json.dumps(summary))
    return 0
