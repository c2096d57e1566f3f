"""The sweep runner (reference/outputs): a streaming pipeline on Dask distributed.

The chunk plan (``plan``) comes from the config alone. For every chunk not yet
written, the client submits its precompute tasks (``geometry_precompute.batch.precompute_batch``, on
the CPU workers, each scene built and precomputed where it runs, cached per host)
an evaluation task that depends on them (``evaluation_worker.evaluate_chunk``, on an
evaluation worker) and a task that makes its tables (``evaluation_worker.encode_chunk``,
on a CPU worker), keeping a bounded number of chunks in flight: while one chunk is
evaluated, later scenes are being precomputed, and memory on the client and on each
worker stays bounded by the chunk size and the cluster, whatever the sweep's size.
Each chunk's Parquet parts (one per table, ``tables.TABLES``) come back as bytes; the
client alone writes ``OUT``.

A chunk's parts are written atomically, the scenes part last, and a chunk counts
as done when its scenes part exists: a run killed at any moment (SIGKILL included)
leaves whole chunks only (and perhaps a temporary file, which the rerun deletes),
and the rerun does the rest. A worker lost mid-task is replaced and its task rerun
by Dask; the tables are those of an uninterrupted run. A rerun of a finished sweep
does nothing.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import sys
import time
import uuid
from collections import Counter
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from geometry_precompute import DEFAULTS, HostError, InputError
from geometry_precompute.fileio import read_bytes_limited
from geometry_precompute.population import POPULATED, is_table
from sweeps.analysis import tables
from sweeps.config import SweepConfig
from sweeps.distributed.cluster import (
    ClusterLost,
    check_scheduler,
    connect,
    default_precompute_workers,
    local_gpus,
    lost_scheduler,
    watch_workers,
)
from sweeps.distributed.plan import Chunk, bucket, plan, point_groups, precompute_batches, shapes
from sweeps.output import check_output_dir, provenance, write_atomic, write_json

__all__ = ["run_sweep"]

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


# Scenes per precompute thread that may be precomputed ahead of the evaluation.
LOOKAHEAD = 1024

# What a sweep writes into its output folder; a folder holding anything else is refused.
TABLES = tables.TABLES
# ``report.html`` is what ``shacc report`` writes into the folder by default.
SWEEP_FILES = ("config.json", *TABLES, ".*.tmp", ".lock", "report.html")


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
    settings = [DEFAULTS.with_overrides(p) for p in cfg.points]
    if cfg.source["kind"] == "files":  # a scene file's own [settings] may set these
        first = cfg.scenes()[0]
        settings = [first.settings(DEFAULTS, p) for p in cfg.points]
    grids = [s["start_grid"] for s in settings]
    rollouts = sum(int(np.prod(g)) for g in grids) * tasks_total * len(cfg.modes)
    # Precompute runs once per scene and distinct precompute-stage settings (the cache
    # serves the rest; a warm cache makes this part smaller than estimated).
    stages = {json.dumps(DEFAULTS.with_overrides(p).by_stage("precompute"), sort_keys=True,
                         default=str) for p in cfg.points}
    from shacc_jax.runplan import bytes_per_rollout  # deferred: 1.3 s to import

    n_workers = workers or default_precompute_workers()
    gpus = local_gpus()
    platform = "gpu" if gpus else "cpu"
    chunk = max(1, min(cfg.chunk, n))
    # One program per start grid and group size (the chunks are padded to one shape);
    # none when the persistent cache holds them.
    programs = len({(tuple(g), len(grp)) for grp in point_groups(cfg)
                    for g in (grids[i] for i in grp)})
    n_chunks = len(point_groups(cfg)) * -(-n // chunk)
    est = {
        "precompute": len(stages) * tasks_total * PRECOMPUTE_S_PER_TASK / n_workers
        + WORKER_START_S,
        "compile": programs * COMPILE_S,
        "rollouts": rollouts / RATES[platform],
        "tables_and_writes": rollouts * TABLE_S_PER_ROLLOUT + n_chunks * CHUNK_OVERHEAD_S,
    }
    collision = any(s["collision"] != "off" for s in settings)
    per_chunk = bytes_per_rollout(collision, platform) * \
        int(max(np.prod(g) for g in grids)) * max_tasks * \
        len(cfg.modes) * bucket(chunk) * max(len(g) for g in point_groups(cfg))
    return {"points": len(cfg.points), "scenes": n, "scene_evaluations": len(cfg.points) * n,
            "rollouts": int(rollouts), "chunks": n_chunks, "chunk_scenes": chunk,
            "estimated_memory_per_chunk_MB": per_chunk / 2**20,
            "evaluation_workers": [f"gpu {g}" for g in gpus] or ["cpu"],
            "precompute_workers": n_workers,
            "estimated_seconds": {k: round(v, 2) for k, v in est.items()},
            "estimated_total_seconds": round(sum(est.values()), 1),
            "rate_assumed_per_s": RATES[platform]}


def run_sweep(cfg: SweepConfig, out: Path, cache: Path | None = None,
              workers: int | None = None, progress: bool = True,
              scheduler: str | None = None, lookahead: int = LOOKAHEAD) -> dict:
    """Run (or resume) a sweep into ``out``. ``cache``: the precompute cache folder, the
    same path on every worker host (default: each host's ``~/.cache/shacc/precompute``);
    ``workers``: precompute processes of the local cluster (default: three quarters
    of the cores, ``cluster.default_precompute_workers``);
    ``scheduler``: an existing Dask cluster's address (default: the config's
    ``scheduler``, else a local cluster); ``lookahead``: scenes per precompute thread
    that may be precomputed ahead of the evaluation. Returns a summary (points, scenes,
    rollouts, timings). The dataset's tables and columns: docs/reference/outputs.md.

    From a script, call it under ``if __name__ == "__main__":`` (the local cluster
    starts worker processes that import the main module); notebooks need nothing.

    Example::

        from sweeps.config import load_config
        run_sweep(load_config("sweeps/configs/laptop.toml"), Path("out/laptop"))
        scenes = pandas.read_parquet("out/laptop/scenes")
    """
    # Everything that can refuse the sweep is checked before a file or folder is made.
    scheduler = scheduler or cfg.scheduler
    if scheduler is not None:

        check_scheduler(scheduler)
    check_output_dir(out, "--out", SWEEP_FILES)
    if cache is not None:
        check_output_dir(cache, "--cache", ("*",))
    h = cfg.hash()  # scene files are loaded and checked here
    _check_folder_kinds(out)
    _check_marker(out, cfg, h, write=False)
    try:
        if cache is not None:
            cache.mkdir(parents=True, exist_ok=True)
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise HostError.of(e, out, "make the folder") from None
    with folder_lock(out):
        return _run_locked(cfg, out, cache, workers, progress, scheduler, lookahead, h)


def _check_folder_kinds(out: Path) -> None:
    """What a sweep writes into ``out`` is of the kind it writes: ``.lock`` and
    ``config.json`` files, a folder per table."""
    kinds = {".lock": False, "config.json": False, **dict.fromkeys(TABLES, True)}
    for name, folder in kinds.items():
        p = out / name
        if (p.exists() or p.is_symlink()) and p.is_dir() != folder:
            raise InputError(p, "--out", f"is {'a file' if folder else 'a folder'} where this "
                             f"sweep keeps {'a folder' if folder else 'a file'}; remove it or "
                             "use a new --out")


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


def _check_marker(out: Path, cfg: SweepConfig, h: str, write: bool = True) -> None:
    """``out/config.json`` names this sweep, or is missing (then written, ``write``)."""
    marker = out / "config.json"
    if marker.exists():
        try:
            previous = json.loads(read_bytes_limited(marker, "a sweep's config.json"))
            if not isinstance(previous, dict):
                raise ValueError("not an object")
        except (ValueError, UnicodeDecodeError, RecursionError) as e:
            raise InputError(marker, "<file>", f"is damaged ({e}); remove the folder or use "
                             "a new --out") from None
        if previous.get("hash") != h:
            raise InputError(out, "config", f"this folder holds another sweep (hash "
                             f"{previous.get('hash')}, this config {h}); use a new --out")
    elif write:
        write_json(marker, {"hash": h, "config": cfg.resolved(), "provenance": provenance()})


def _setting_names(cfg: SweepConfig) -> tuple[str, ...]:
    """Every setting any point sets, in order of first appearance."""
    return tuple(dict.fromkeys(k for p in cfg.points for k in p))


def _populations(cfg: SweepConfig) -> tuple[str, ...]:
    """The user settings some point gives a population (reference/outputs: their set.*
    columns are text, and the rollouts table carries every rollout's drawn values)."""

    return tuple(k for k in POPULATED if any(is_table(p.get(k)) for p in cfg.points))


def _rollouts_per_scene(cfg: SweepConfig, files) -> list[float]:
    """Per sweep point, the rollouts of one scene (a random source: of its mean task
    count), for the progress bar's total."""
    if files is not None:
        tasks = float(np.mean([len(s.tasks) for s in files]))
        grids = [files[0].settings(DEFAULTS, p)["start_grid"] for p in cfg.points]
    else:
        tasks = sum(cfg.source["tasks"]) / 2
        grids = [DEFAULTS.with_overrides(p)["start_grid"] for p in cfg.points]
    return [tasks * int(np.prod(g)) * len(cfg.modes) for g in grids]


def _run_locked(cfg: SweepConfig, out: Path, cache: Path | None, workers: int | None,
                progress: bool, scheduler: str | None, lookahead: int, h: str) -> dict:
    t0 = time.perf_counter()
    _check_marker(out, cfg, h)  # again, under the lock
    chunks = plan(cfg)
    for name in TABLES:
        (out / name).mkdir(exist_ok=True)
    # A run killed in the middle of a write leaves its temporary file (output.write_atomic);
    # only this sweep writes into OUT, so any there now is such a leftover.
    for folder in (out, *(out / name for name in TABLES)):
        for stale in folder.glob(".*.tmp"):
            stale.unlink(missing_ok=True)
    todo = [c for c in chunks if not tables.part_path(out, "scenes", c.index).exists()]
    summary = {"hash": h, "chunks": len(chunks), "done_before": len(chunks) - len(todo)}
    if not todo:
        summary["status"] = "nothing to do: the sweep is complete"
        return summary
    files = cfg.scenes() if cfg.source["kind"] == "files" else None

    # When each phase ended, in seconds since the start (the client's wall clock).
    phases = {"config": time.perf_counter() - t0}
    # A local cluster's evaluation workers start the warm-up with their processes.
    first = warm_up_job(cfg, todo, files)
    with connect(scheduler, workers, warm_up=first) as pool:
        phases["cluster"] = time.perf_counter() - t0
        if progress and pool.dashboard:
            print(f"Dask dashboard: {pool.dashboard}", file=sys.stderr)
        # A cluster started apart can lose every worker of a kind: say so, and wait.
        watch = watch_workers(pool, scheduler, lambda line: tqdm.write(line, file=sys.stderr)) \
            if scheduler else contextlib.nullcontext()
        try:
            with watch:
                counts = _stream(cfg, out, todo, files, pool, cache, progress, lookahead,
                                 first)
        except Exception as e:
            if not lost_scheduler(pool.client, e):
                raise
            written = sum(tables.part_path(out, "scenes", c.index).exists() for c in chunks)
            where = f"at {scheduler}" if scheduler else "of the local cluster"
            why = " ".join(f"{type(e).__name__}: {e}".split())  # on one line
            raise ClusterLost(f"lost the Dask scheduler {where} ({why}); "
                              f"{written} of {len(chunks)} chunks are written in {out}: run "
                              "the same command again to go on from there") from None
        phases["stream"] = time.perf_counter() - t0
        summary.update(counts)
        summary.update({"precompute_workers": pool.precompute_threads,
                        "evaluation_workers": pool.evaluate_workers,
                        "scheduler": scheduler or "local"})
    phases["closed"] = time.perf_counter() - t0
    summary["status"] = "complete"
    summary["phases"] = {k: round(v, 3) for k, v in phases.items()}
    summary["seconds"] = round(time.perf_counter() - t0, 3)
    return summary


def job_maker(cfg: SweepConfig) -> Callable[[Chunk], Any]:
    """The ``evaluation_worker.ChunkJob`` of each chunk of the sweep: what decides its
    evaluation program (the sweep's shapes, modes, settings and populations, and the
    calls of that program), worked out once. The warm-up and every chunk take their jobs
    from here, so the program warmed up is the one the chunks run."""
    from sweeps.distributed.evaluation_worker import ChunkJob  # deferred: 15 ms to import

    shp, names, populations = shapes(cfg), _setting_names(cfg), _populations(cfg)
    calls = program_calls(cfg)

    def job(c: Chunk):
        return ChunkJob(c, tuple(cfg.points[i] for i in c.points), cfg.modes, shp, names,
                        populations, calls[len(c.points)])
    return job


def warm_up_job(cfg: SweepConfig, todo: list[Chunk], files) -> tuple:
    """(job, scene) of ``evaluation_worker.warm_up``: the first chunk's job and its first
    scene (a Scene, or ``random_scene``'s arguments)."""
    c = todo[0]
    return job_maker(cfg)(c), files[c.scenes[0]] if files is not None else \
        cfg.random_ref(c.scenes[0])


def program_calls(cfg: SweepConfig) -> dict[int, int]:
    """Chunks of the whole sweep per number of points in a chunk: the calls of one
    evaluation program, since every chunk is padded to the sweep's shapes. Their work
    together decides the program's compiler options (a sweep of many small chunks is
    not compiled as one small batch would be), from the config alone, so a resumed run
    builds or loads the same programs."""
    return dict(Counter(len(c.points) for c in plan(cfg)))


def _stream(cfg: SweepConfig, out: Path, todo: list[Chunk], files, pool, cache: Path | None,
            progress: bool, lookahead: int, first: tuple) -> dict:
    """Submit the chunks of ``todo`` with a bounded number in flight, and write each as its
    evaluation comes back. Returns the counts and busy times for the summary."""
    from distributed import as_completed  # deferred: 672 ms to import

    from geometry_precompute.batch import precompute_batch  # deferred: 10 ms to import
    from sweeps.distributed import evaluation_worker  # deferred: 15 ms to import

    # deferred: importing it takes 15 ms
    from sweeps.distributed.evaluation_worker import (
        encode_chunk,
        evaluate_chunk,
        join_chunk,
    )

    client = pool.client
    run = uuid.uuid4().hex[:8]  # task keys of this run, apart from any earlier run's
    shp = shapes(cfg)
    chunk_job = job_maker(cfg)
    cache_arg = None if cache is None else str(cache)
    per_scene = _rollouts_per_scene(cfg, files)
    # In flight (submitted, not yet written): four chunks per evaluation worker, and the
    # precompute may run up to ``lookahead`` scenes per precompute thread ahead of the
    # evaluation (while the first program compiles, say: a precomputed scene waiting is
    # its bake, under a kilobyte). Bounded by the chunk size and the cluster, never by the
    # sweep's size.
    cap = max(4 * len(todo[0].scenes) * pool.evaluate_workers,
              lookahead * pool.precompute_threads)
    told: set[str] = set()  # the scenes' warnings said so far
    busy = dict.fromkeys(("precompute", "warm_up", "join", "evaluate", "tables", "write"),
                         0.0)
    totals: dict[str, Any] = {"rollouts_this_run": 0, "precomputed": 0, "precompute_cache_hits": 0,
              "compilations": 0, "programs_loaded": 0, "warmed_up_with_the_process": 0}
    bar_opts = {"disable": None if progress else True, "file": sys.stderr, "smoothing": 0.1}
    scenes_bar = tqdm(total=sum(len(c.scenes) for c in todo), unit="scene",
                      desc="precompute", **bar_opts)
    rollouts_bar = tqdm(total=int(sum(len(c.scenes) * sum(per_scene[i] for i in c.points)
                                      for c in todo)),
                        unit="rollout", unit_scale=True, desc="evaluate", **bar_opts)
    waiting = iter(todo)
    flying: dict[str, tuple[Chunk, list]] = {}  # encode key -> chunk, all its tasks
    batch_size: dict[str, int] = {}
    done = as_completed()

    def submit(c: Chunk) -> None:
        points = [cfg.points[i] for i in c.points]
        batches = []
        for b, part in enumerate(precompute_batches(c.scenes, pool.precompute_threads)):
            refs = [files[i] for i in part] if files is not None else \
                [cfg.random_ref(i) for i in part]
            f = client.submit(precompute_batch, refs, points, cache_arg, shp.tasks, shp.objects,
                              key=f"precompute-{run}-{c.index}-{b}", priority=-c.index,
                              resources=pool.precompute, pure=False)
            batch_size[f.key] = len(part)
            batches.append(f)
            done.add(f)
        job = chunk_job(c)
        # Joined on a CPU worker: the evaluation worker then only evaluates.
        joined = client.submit(join_chunk, job, *batches, key=f"join-{run}-{c.index}",
                               priority=-c.index, resources=pool.precompute, pure=False)
        ev = client.submit(evaluate_chunk, job, joined, key=f"evaluate-{run}-{c.index}",
                           priority=-c.index, resources=pool.evaluate, pure=False)
        enc = client.submit(encode_chunk, job, ev, key=f"encode-{run}-{c.index}",
                            priority=1_000_000 - c.index, resources=pool.precompute,
                            pure=False)
        flying[enc.key] = (c, [*batches, joined, ev, enc])
        done.add(enc)

    def fill() -> None:
        while True:
            in_flight = sum(len(c.scenes) for c, _ in flying.values())
            if flying and in_flight >= cap:
                return
            c = next(waiting, None)
            if c is None:
                return
            submit(c)

    def warm_up() -> None:
        """Each evaluation worker compiles (or loads) the first chunk's program while the
        scenes are being precomputed (a local cluster's workers began it with their
        processes: the task then waits for that warm-up to end)."""
        job, ref = first
        # One per evaluation worker: each takes one, holding its single evaluate slot.
        # (Not pinned with workers=[...]: distributed 2026.8's scheduler fails with a
        # KeyError when a pinned task with resources is moved off a dead worker.)
        for k in range(pool.evaluate_workers):
            f = client.submit(evaluation_worker.warm_up, job, ref, key=f"warm-up-{run}-{k}",
                              resources=pool.evaluate, priority=1, pure=False)
            warming.add(f.key)
            done.add(f)

    warming: set[str] = set()
    started = time.perf_counter()
    try:
        warm_up()
        fill()
        for fut in done:
            if fut.key in warming:
                w = fut.result()
                busy["warm_up"] += w["seconds"]
                totals["compilations"] += w["compiled"]
                totals["programs_loaded"] += w["loaded"]
                totals["warmed_up_with_the_process"] += w["early"]
                warming.discard(fut.key)
                continue
            if fut.key in batch_size:  # a precompute task: count it, leave its result
                if fut.status == "error":
                    fut.result()  # raises the scene's error here, before more evaluation
                scenes_bar.update(batch_size.pop(fut.key))
                continue
            c, _ = flying.pop(fut.key)
            res = fut.result()
            t = time.perf_counter()
            # The scenes part last: it marks the chunk done (module docstring).
            for name in (*(t for t in TABLES if t != "scenes"), "scenes"):
                write_atomic(tables.part_path(out, name, c.index), res.parts[name])
            busy["write"] += time.perf_counter() - t
            for k, v in res.seconds.items():
                busy[k] += v
            totals["rollouts_this_run"] += res.n_rollouts
            totals["precomputed"] += res.precomputed
            totals["precompute_cache_hits"] += res.cache_hits
            for line in res.scene_warnings:  # each once, as ``evaluate`` says them
                if line not in told:
                    told.add(line)
                    tqdm.write(f"warning: {line}", file=sys.stderr)
            if res.cache_warning and "cache_warning" not in totals:
                totals["cache_warning"] = res.cache_warning
                tqdm.write(f"warning: {res.cache_warning}; the sweep goes on without storing "
                           "precomputed scenes", file=sys.stderr)
            totals["compilations"] += res.compiled
            totals["programs_loaded"] += res.loaded
            rollouts_bar.update(res.n_rollouts)
            totals.setdefault("first_chunk_written", round(time.perf_counter() - started, 3))
            del fut, res
            fill()
    except BaseException:
        client.cancel([f for _, fs in flying.values() for f in fs])
        raise
    finally:
        scenes_bar.close()
        rollouts_bar.close()
    totals["stage_seconds"] = {k: round(v, 3) for k, v in busy.items()}
    return totals
