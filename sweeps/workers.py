"""The precompute's worker processes (CPU only, no JAX), and the functions they run.

The task functions live here, in a module that imports nothing from JAX: a spawned
worker imports the module of the function it is sent, so a task defined beside the
evaluation would load JAX into every worker (a test holds this).

Started with spawn (forking a process in which JAX runs threads can deadlock). They
ignore SIGINT: Ctrl-C reaches the whole process group, and the command, not each
worker, decides what an interruption means (one line, exit 130, the pool shut down).
And they die with the command: on Linux each asks the kernel for SIGKILL when its
parent ends (``PR_SET_PDEATHSIG``), so a command killed with SIGKILL leaves no worker
behind (before, they waited on their task queue for ever, about 400 MB each).
"""

from __future__ import annotations

import contextlib
import ctypes
import hashlib
import json
import multiprocessing
import os
import pickle
import signal
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path

from geometry_precompute import DEFAULTS, bake, load_scene, precompute, random_scene
from geometry_precompute.generate import GENERATOR_VERSION
from geometry_precompute.precompute import PRECOMPUTE_VERSION, PrecomputeResult
from geometry_precompute.scene import Scene, scene_to_dict

from .output import write_atomic

_PR_SET_PDEATHSIG = 1  # linux/prctl.h


def _worker_setup(parent: int) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        if os.getppid() != parent:  # the parent ended before the request was made
            os._exit(1)


@contextlib.contextmanager
def precompute_pool(workers: int | None):
    """A process pool that, on any exception (Ctrl-C included), drops its queued tasks
    and waits only for the running ones, so no worker outlives the command."""
    pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_worker_setup, initargs=(os.getpid(),))
    try:
        yield pool
    except BaseException:
        pool.shutdown(wait=True, cancel_futures=True)
        raise
    pool.shutdown(wait=True)


def cache_key(scene: Scene, settings) -> str:
    """The precompute cache's key: the scene, its precompute-stage settings and the
    precompute's version (a rollout setting never triggers a new precompute)."""
    blob = json.dumps({"scene": scene_to_dict(scene), "settings": settings.by_stage("precompute"),
                       "version": PRECOMPUTE_VERSION}, sort_keys=True, default=str).encode()
    return hashlib.sha256(blob).hexdigest()


def precompute_cached(args) -> tuple[PrecomputeResult, bool]:
    """(result, whether it came from the cache) of (scene, overrides, cache folder)."""
    scene, overrides, cache = args
    return _cached(scene, scene.settings(DEFAULTS, overrides), Path(cache))


def random_key(ref: tuple, settings) -> str:
    """The cache key of a random scene: ``random_scene``'s arguments, the generator's
    version, the precompute-stage settings and the precompute's version. A warm sweep
    of random scenes then reads its results without building the scenes (1.7 ms a
    scene, about what reading a result costs)."""
    blob = json.dumps({"random": list(ref), "generator": GENERATOR_VERSION,
                       "settings": settings.by_stage("precompute"),
                       "version": PRECOMPUTE_VERSION}, sort_keys=True, default=str).encode()
    return hashlib.sha256(blob).hexdigest()


def _cached(scene: Scene | tuple, settings, cache: Path) -> tuple[PrecomputeResult, bool]:
    """(result, from the cache) of a Scene, or of ``random_scene``'s arguments (the
    scene is built only when its result is not cached)."""
    random = not isinstance(scene, Scene)
    key = random_key(scene, settings) if random else cache_key(scene, settings)
    path = cache / f"{key}.pkl"
    if path.exists():
        try:
            with path.open("rb") as f:
                r = pickle.load(f)
            return replace(r, settings=settings), True
        except (OSError, pickle.UnpicklingError, EOFError):
            pass  # a damaged entry is recomputed and rewritten
    r = precompute(random_scene(*scene) if random else scene, settings)
    write_atomic(path, pickle.dumps(r))
    return r, False


def default_cache() -> Path:
    """The precompute cache of this host: ``$XDG_CACHE_HOME/shacc/precompute``
    (``~/.cache/shacc/precompute`` when it is unset)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "shacc" / "precompute"


@dataclass(frozen=True)
class Batch:
    """What a sweep's precompute task returns: its scenes baked, once per sweep point of
    the chunk's group, and the per-scene numbers of the scenes table."""

    bakes: list          # BakedScenes per point, at the sweep's task and object counts
    scenes: dict         # name, n_tasks, C_init, C_final, d, h: one entry per scene
    precomputed: int     # scenes computed here (the others came from the cache)
    cache_hits: int
    seconds: float


def precompute_batch(refs, points: list[dict], cache: str | None, tasks: int,
                     objects: int) -> Batch:
    """A sweep's precompute task (a Dask task on a CPU worker). ``refs``: Scenes or
    ``random_scene``'s arguments (the scene is built here); ``points``: the overrides of
    the group's sweep points (they differ only in rollout settings, so the first one's
    precompute serves all); ``cache``: the cache folder on this worker's host (None:
    the host's default, :func:`default_cache`). The scenes are precomputed (or read
    from the cache) and baked here, spreading the bake over every CPU of the cluster;
    only arrays travel on."""
    t0 = time.perf_counter()
    folder = Path(cache) if cache else default_cache()
    folder.mkdir(parents=True, exist_ok=True)
    settings = point_settings(points)
    got = [_cached(ref, settings(ref if isinstance(ref, Scene) else None, 0), folder)
           for ref in refs]
    return bake_batch(got, points, tasks, objects, time.perf_counter() - t0, settings)


def point_settings(points: list[dict]):
    """``settings(scene, k)``: the Settings of sweep point k for a scene, made once per
    distinct scene [settings] table (every random scene shares one; None stands for a
    scene without one)."""
    known: dict[tuple[str, int], object] = {}

    def settings(scene: Scene | None, k: int):
        own = scene.settings_overrides if scene is not None else {}
        key = (json.dumps(own, sort_keys=True, default=str), k)
        if key not in known:
            known[key] = (scene or Scene("", (), ())).settings(DEFAULTS, points[k])
        return known[key]

    return settings


def bake_batch(got: list[tuple[PrecomputeResult, bool]], points: list[dict], tasks: int,
               objects: int, seconds: float, settings=None) -> Batch:
    """A :class:`Batch` of precomputed scenes ((result, cache hit) pairs): each point's
    bake at the sweep's sizes (``settings``: :func:`point_settings` of ``points``)."""
    t0 = time.perf_counter()
    settings = settings or point_settings(points)
    bakes = [bake([replace(r, settings=settings(r.scene, k)) for r, _ in got], tasks,
                  max_objects=objects) for k in range(len(points))]
    results = [r for r, _ in got]
    hits = sum(hit for _, hit in got)
    return Batch(bakes, {"name": [r.scene.name for r in results],
                         "n_tasks": [len(r.spaces) for r in results],
                         **{k: [getattr(r, k) for r in results]
                            for k in ("C_init", "C_final", "d", "h")}},
                 len(got) - hits, hits, seconds + time.perf_counter() - t0)


def precompute_scene(item) -> PrecomputeResult:
    """``reproduce``'s task: ("manual", path, overrides) or ("random", (seed, kind),
    overrides)."""
    kind, ref, overrides = item
    scene = load_scene(ref) if kind == "manual" else random_scene(ref[0], ref[1], 5, 10)
    return precompute(scene, scene.settings(DEFAULTS, overrides))
