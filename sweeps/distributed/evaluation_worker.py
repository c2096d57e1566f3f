"""A sweep chunk's way from its precomputed scenes to the bytes of its two Parquet parts.

On a CPU worker, :func:`join_chunk` joins the bakes the precompute tasks made (at the
sweep's padded shapes, ``plan.Shapes``); on a worker that holds the accelerator (or the
CPU evaluation worker), :func:`warm_up` compiles the chunks' program early and
:func:`evaluate_chunk` evaluates every point of the chunk's group in one call; on a
CPU worker again, :func:`encode_chunk` builds the Arrow tables and encodes them, so
that only bytes travel back to the machine that writes the output.
The compiled programs persist on disk (``compile_cache``); the compilations each chunk
caused are counted with JAX's monitoring events and reported.
"""

from __future__ import annotations

import functools
import os
import platform
import socket
import threading
import time
import warnings
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import numpy as np
import pyarrow as pa

from geometry_precompute import precompute, random_scene
from geometry_precompute.baking import concatenate
from geometry_precompute.batch import bake_batch, point_settings
from geometry_precompute.errors import SceneWarning
from geometry_precompute.outcomes import scene_metrics
from geometry_precompute.population import POPULATED
from geometry_precompute.scene import Scene
from sweeps import compile_cache
from sweeps.analysis import tables
from sweeps.distributed.kinds import PLUGIN
from sweeps.distributed.plan import Chunk, Shapes


@dataclass(frozen=True)
class ChunkJob:
    chunk: Chunk
    points: tuple[dict, ...]       # the overrides of chunk.points, in that order
    modes: tuple[str, ...]
    shapes: Shapes
    setting_names: tuple[str, ...]  # the scenes table's set.* columns
    populations: tuple[str, ...] = ()  # settings some point gives a population: their
    #                                    set.* columns are text, the rollouts carry draws
    calls: int = 1                 # the sweep's chunks that run this chunk's program


@dataclass(frozen=True)
class ChunkResult:
    index: int
    parts: dict                    # table name -> the Parquet file of the chunk's rows
    n_scenes: int
    n_rollouts: int
    precomputed: int               # scenes precomputed (not read from a cache)
    cache_hits: int
    cache_warning: str | None      # why the precompute cache could not be written
    seconds: dict = field(default_factory=dict)  # busy time: precompute (its tasks, bake
    #                                              included), join, evaluate, tables
    compiled: int = 0              # programs XLA built for this chunk
    loaded: int = 0                # programs read from the persistent cache instead
    worker: str = ""
    scene_warnings: tuple[str, ...] = ()  # the precompute's, "scene NAME: MESSAGE"


# The rollout fields the tables hold, and the dtypes they travel in; only these are copied
# from the accelerator (17 of a 1 000-scene chunk's 57 MB).
COMPACT = {"outcome": "int8", "activated": "int16", "step": "int32", "delta_R": "float32",
           "path_length": "float32", "assist": "int32"}

_LOCK = threading.Lock()
_COUNTS = {"programs": 0, "loaded": 0}
_READY = False


def _setup() -> None:
    """Once per worker process: the persistent compilation cache, and counters of
    compilations and cache loads (JAX's monitoring events)."""
    global _READY
    with _LOCK:
        if _READY:
            return
        from shacc_jax import configure_runtime  # deferred: 1.8 s to import

        configure_runtime()  # before this worker starts JAX (shacc_jax/runtime.py)
        from jax import monitoring  # deferred: 1.8 s to import


        compile_cache.enable()

        def on_duration(event: str, duration_secs: float, **_: str | int) -> None:
            # Timed around every backend compilation, persistent-cache loads included.
            if event == "/jax/core/compile/backend_compile_duration":
                _COUNTS["programs"] += 1

        def on_event(event: str, **_: str | int) -> None:
            if event == "/jax/compilation_cache/cache_hits":
                _COUNTS["loaded"] += 1

        monitoring.register_event_duration_secs_listener(on_duration)
        monitoring.register_event_listener(on_event)
        _READY = True


class EarlyWarmUp:
    """A :func:`warm_up` begun in a thread of this process as it starts (the local
    cluster's evaluation workers begin one: ``worker_setup.WorkerSetup``), so that JAX's
    start, the accelerator's and the program's load or compilation overlap the start of
    the other workers instead of beginning when the sweep's first task arrives. The
    warm-up task of the same job waits for it and reports its result.

    >>> EarlyWarmUp.__name__
    'EarlyWarmUp'
    """

    def __init__(self, job: ChunkJob, ref) -> None:
        self.job, self.ref = job, ref
        self._outcome: dict = {}
        self._thread = threading.Thread(target=self._run, name="shacc-warm-up", daemon=True)

    def start(self) -> EarlyWarmUp:
        self._thread.start()
        return self

    def _run(self) -> None:
        try:
            self._outcome["result"] = _warm_up(self.job, self.ref)
        except BaseException as e:  # the task reruns the warm-up and raises it there
            self._outcome["error"] = e

    def result_for(self, job: ChunkJob) -> dict | None:
        """Wait for it to end (also for another job: two warm-ups at once only
        compete); its result if it warmed up ``job`` and succeeded, else None."""
        self._thread.join()
        return self._outcome.get("result") if job == self.job else None


def early_warm_up() -> EarlyWarmUp | None:
    """The warm-up this worker began as it started (``worker_setup.WorkerSetup``), handed
    out once; None outside a worker, on a worker without one, or once taken."""
    from distributed import get_worker  # deferred: 1.1 s to import

    try:
        worker = get_worker()
    except ValueError:  # not in a worker's task
        return None
    plugin: Any = worker.plugins.get(PLUGIN)
    early = getattr(plugin, "early", None)
    if not isinstance(early, EarlyWarmUp):
        return None
    plugin.early = None
    return early


def warm_up(job: ChunkJob, ref, early: EarlyWarmUp | None = None) -> dict:
    """Compile (or load) the program of ``job``'s chunks while their scenes are still
    being precomputed: one scene (``ref``: a Scene or ``random_scene``'s arguments) is
    precomputed here, outside any cache, and evaluated, padded to the chunk's shapes.
    ``early``: a warm-up begun before (default: the one this worker began as it
    started, :func:`early_warm_up`). Returns the seconds it took, the
    programs it compiled and loaded, and whether the early warm-up served it."""
    if early is None:
        early = early_warm_up()
    if early is not None and (done := early.result_for(job)) is not None:
        return {**done, "early": True}
    return {**_warm_up(job, ref), "early": False}


# When the steps of this process's last warm-up ended, on the wall clock (read by
# benchmarks/bench_timeline.py): begun, imports (JAX among them), device (the backend up),
# baked (the scene precomputed and baked), ended (the program loaded or compiled, and run).
WARM_UP_MARKS: dict[str, float] = {}


@functools.cache
def _provenance() -> dict:
    """What evaluated a chunk: software versions and the device, recorded in its parts."""
    import importlib.metadata as md  # deferred: 53 ms to import

    import jax  # deferred: 1.8 s to import
    import jaxlib  # deferred: 10 ms to import

    try:
        shacc = md.version("shacc")
    except md.PackageNotFoundError:
        shacc = "unknown"
    dev = jax.devices()[0]
    return {"shacc": shacc, "jax": jax.__version__, "jaxlib": jaxlib.__version__,
            "numpy": np.__version__, "python": platform.python_version(),
            "backend": jax.default_backend(), "device": getattr(dev, "device_kind", str(dev)),
            "host": socket.gethostname()}


def _warm_up(job: ChunkJob, ref) -> dict:
    WARM_UP_MARKS.clear()
    WARM_UP_MARKS["begun"] = time.time()
    import jax  # deferred: 1.8 s to import


    WARM_UP_MARKS["imports"] = time.time()
    _setup()
    jax.devices()
    WARM_UP_MARKS["device"] = time.time()
    before = dict(_COUNTS)
    t0 = time.perf_counter()
    settings = point_settings(list(job.points))
    with warnings.catch_warnings():  # the scene's precompute task says its warnings
        warnings.simplefilter("ignore", SceneWarning)
        scene = ref if isinstance(ref, Scene) else random_scene(*ref)
        batch = bake_batch([(precompute(scene, settings(scene, 0)), False)], list(job.points),
                           job.shapes.tasks, job.shapes.objects, 0.0, settings)
    WARM_UP_MARKS["baked"] = time.time()
    _evaluate([concatenate([b], pad_to=job.shapes.scenes) for b in batch.bakes], job.modes,
              calls=job.calls)
    WARM_UP_MARKS["ended"] = time.time()
    loaded = _COUNTS["loaded"] - before["loaded"]
    return {"seconds": time.perf_counter() - t0, "loaded": loaded,
            "compiled": _COUNTS["programs"] - before["programs"] - loaded}


@dataclass(frozen=True)
class ChunkArrays:
    """A chunk's evaluation, trimmed to its scenes and to compact dtypes, on its way from
    the evaluation worker to the CPU worker that makes its tables."""

    rollouts: list        # per point: outcome, activated, step, delta_R (S, M, N, T)
    params: list          # per point: q_min, q_init, q_shrunk, q_optimized, starts
    labels: dict          # per scene: name, n_tasks, C_init, ...; per task: ids, templates
    counts: dict          # precomputed, cache_hits
    provenance: dict      # the evaluation worker's software and device
    seconds: dict
    compiled: int
    loaded: int
    worker: str


@dataclass(frozen=True)
class JoinedChunk:
    """A chunk's precompute tasks' results as one input of its evaluation."""

    bakes: list           # per point: the chunk's scenes as one bake, padded to its shape
    labels: dict          # per scene: name, n_tasks, C_init, C_final, d, h
    counts: dict          # precomputed, cache_hits
    seconds: dict         # busy time: precompute (its tasks), join


def join_chunk(job: ChunkJob, *batches) -> JoinedChunk:
    """``batches``: the chunk's precompute tasks' results, in order
    (``geometry_precompute.batch.Batch``: each point's bake of its scenes), joined into
    one bake per point. A CPU worker's task in a sweep, so that the accelerator's
    worker, which evaluates the chunks one after another, spends its time on the
    evaluations only."""
    t0 = time.perf_counter()
    bakes = [concatenate([b.bakes[k] for b in batches], pad_to=job.shapes.scenes)
             for k in range(len(job.points))]
    labels = {k: [x for b in batches for x in b.scenes[k]] for k in batches[0].scenes}
    return JoinedChunk(bakes, labels,
                       {"precomputed": sum(b.precomputed for b in batches),
                        "cache_hits": sum(b.cache_hits for b in batches),
                        "cache_warning": next((b.cache_warning for b in batches
                                               if b.cache_warning), None),
                        "scene_warnings": tuple(w for b in batches for w in b.scene_warnings)},
                       {"precompute": sum(b.seconds for b in batches),
                        "join": time.perf_counter() - t0})


def _evaluate(bakes: list, modes, populations: bool = False, calls: int = 1) -> list[tuple]:
    """Per point of a chunk: (its Evaluation, its search or None), from one
    ``shacc_jax.run`` with a points axis. Only the COMPACT fields come back, and no
    per-scene metrics: encode_chunk computes them on a CPU worker, off this worker's
    path (8 ms a 1 000-scene chunk). ``calls``: the sweep's chunks that run the same
    program, for its compiler options."""
    import jax  # deferred: 1.8 s to import

    import shacc_jax  # deferred: 1.8 s to import

    fields = tuple(COMPACT) + (("user",) if populations else ())
    if len(bakes) == 1:  # no points axis to add and take off again
        one = shacc_jax.run(bakes[0], modes, fields=fields, metrics=False, calls=calls)
        assert not isinstance(one.search, list)
        return [(one.evaluation, one.search)]
    out = shacc_jax.run(bakes[0], modes, points=bakes, fields=fields, metrics=False,
                        calls=calls)
    searches = out.search if isinstance(out.search, list) else [None] * len(bakes)
    return [(jax.tree.map(lambda a, i=i: a[i], out.evaluation), found)
            for i, found in enumerate(searches)]


def _drawn(user: np.ndarray, b, S: int) -> np.ndarray:
    """The user settings each rollout drew, (S, M, N, T, len(POPULATED)) float32: the evaluation's
    where its points had a population, else each scene's plain values (a sweep whose
    other points have a population keeps one set of columns)."""
    if user.shape[-1] == len(POPULATED):
        return user.astype(np.float32)
    plain = np.stack([np.asarray(getattr(b, k))[:S] for k in POPULATED], -1)
    return np.broadcast_to(plain[:, None, None, None, :].astype(np.float32),
                           (*user.shape[:-1], len(POPULATED)))


def evaluate_chunk(job: ChunkJob, joined: JoinedChunk) -> ChunkArrays:
    """A chunk's evaluation from its :func:`join_chunk`. Only the accelerator's part
    runs here; :func:`encode_chunk` makes the tables on a CPU worker."""
    _setup()
    before = dict(_COUNTS)
    t1 = time.perf_counter()
    evs = _evaluate(joined.bakes, job.modes, bool(job.populations), job.calls)
    S = len(job.chunk.scenes)
    # Plain dicts of NumPy arrays: no JAX type travels to the CPU workers.
    rollouts = [{k: getattr(ev.rollouts, k)[:S].astype(t) for k, t in COMPACT.items()}
                for ev, _ in evs]
    if job.populations:
        for ro, b, (ev, _) in zip(rollouts, joined.bakes, evs, strict=True):
            ro["user"] = _drawn(ev.rollouts.user[:S], b, S)
    params = [{"q_min": b.q_min[:S], "q_init": b.q_init[:S], "q_shrunk": b.q_shrunk[:S],
               "q_optimized": None if found is None else np.asarray(found.q)[:S],
               "starts": b.starts[:S], "dt": b.dt[:S]}
              for b, (_, found) in zip(joined.bakes, evs, strict=True)]
    t2 = time.perf_counter()
    programs = _COUNTS["programs"] - before["programs"]
    loaded = _COUNTS["loaded"] - before["loaded"]
    return ChunkArrays(rollouts, params, joined.labels, joined.counts, _provenance(),
                       {**joined.seconds, "evaluate": t2 - t1},
                       programs - loaded, loaded, f"{socket.gethostname()}:{os.getpid()}")


def encode_chunk(job: ChunkJob, arrays: ChunkArrays) -> ChunkResult:
    """A chunk's two Parquet parts from its evaluation (a CPU worker's task: the tables
    of many chunks are made in parallel, not one after another on the accelerator's
    worker)."""

    t0 = time.perf_counter()
    parts: dict[str, list] = {name: [] for name in tables.TABLES}
    S = len(job.chunk.scenes)
    n_tasks = np.asarray(arrays.labels["n_tasks"])
    task_mask = np.arange(job.shapes.tasks)[None, :] < n_tasks[:, None]
    for i, p, ro, pa_ in zip(job.chunk.points, job.points, arrays.rollouts, arrays.params,
                             strict=True):
        u, mean, counts, _, time_mean, path_mean, fraction = scene_metrics(
            ro["outcome"], ro["delta_R"], task_mask[:S], ro["step"], ro["path_length"],
            ro["assist"], pa_["dt"])
        me = SimpleNamespace(u_scene=u, delta_R_mean=mean, outcome_counts=counts,
                             time_mean=time_mean, path_length_mean=path_mean,
                             assist_fraction=fraction)
        parts["scenes"].append(tables.scenes_table(i, p, job.setting_names, job.modes,
                                                   job.chunk.scenes, arrays.labels, me,
                                                   job.populations))
        parts["tasks"].append(tables.tasks_table(i, job.modes, job.chunk.scenes, arrays.labels,
                                                 pa_, ro["outcome"]))
        parts["starts"].append(tables.starts_table(i, job.chunk.scenes, pa_["starts"]))
        parts["rollouts"].append(tables.rollouts_table(i, job.modes, job.chunk.scenes,
                                                       SimpleNamespace(**ro), pa_["dt"]))
    joined = {name: pa.concat_tables(ts) for name, ts in parts.items()}
    encoded = {name: tables.parquet_bytes(t, name, arrays.provenance)
               for name, t in joined.items()}
    return ChunkResult(job.chunk.index, encoded, joined["scenes"].num_rows,
                       joined["rollouts"].num_rows,
                       arrays.counts["precomputed"], arrays.counts["cache_hits"],
                       arrays.counts["cache_warning"],
                       {**arrays.seconds, "tables": time.perf_counter() - t0},
                       arrays.compiled, arrays.loaded, arrays.worker,
                       arrays.counts.get("scene_warnings", ()))
