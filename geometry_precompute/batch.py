"""Precompute, then bake: a batch of scenes made ready for the JAX half, once per
sweep point (CPU only, no JAX).

The local cluster's precompute workers run these functions as tasks
(``sweeps.distributed.cluster``): :func:`precompute_batch` for ``shacc sweep``,
:func:`precompute_scene` for ``shacc reproduce``. A worker imports the module of the
task it is sent, so this module imports nothing from JAX (a test holds this).
"""

from __future__ import annotations

import json
import re
import time
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

from . import batch_cache
from .baking import bake
from .cache import cached, default_folder
from .errors import SceneWarning
from .generate import random_scene
from .loading import load_scene
from .precomputing import PrecomputeResult, precompute
from .scene import Scene
from .settings import DEFAULTS

GENERATED = re.compile(r"^<generator>: objects\[\d+\]\.\w*: ")


@dataclass(frozen=True)
class Batch:
    """What a sweep's precompute task returns: its scenes baked, once per sweep point of
    the chunk's group, and the per-scene numbers of the scenes table."""

    bakes: list          # BakedScenes per point, at the sweep's task and object counts
    scenes: dict         # name, n_tasks, C_init, C_final, d, h: one entry per scene
    precomputed: int     # scenes computed here (the others came from the cache)
    cache_hits: int
    seconds: float
    cache_warning: str | None = None  # why results could not be stored, if they could not
    # The scenes' warnings (an open mesh, one floating), "scene NAME: MESSAGE", each once.
    scene_warnings: tuple[str, ...] = ()


def precompute_batch(refs, points: list[dict], cache: str | None, tasks: int,
                     objects: int) -> Batch:
    """A sweep's precompute task (a Dask task on a CPU worker). ``refs``: Scenes or
    ``random_scene``'s arguments (the scene is built here); ``points``: the overrides of
    the group's sweep points (they differ only in rollout settings, so the first one's
    precompute serves all); ``cache``: the cache folder on this worker's host (None:
    the host's default, ``cache.default_folder``). The scenes are precomputed (or read
    from the cache) and baked here, spreading the bake over every CPU of the cluster;
    only arrays travel on."""
    t0 = time.perf_counter()
    folder = Path(cache) if cache else default_folder()
    settings = point_settings(points)
    key = batch_cache.batch_key(refs, points, tasks, objects, settings)
    kept = batch_cache.read(folder, key, len(refs), len(points))
    if kept is not None:  # this very task ran before: its arrays, nothing baked
        bakes, scenes, said_before = kept
        return Batch(bakes, scenes, 0, len(refs), time.perf_counter() - t0,
                     scene_warnings=said_before)
    got, warning = [], None
    said: dict[str, None] = {}
    for ref in refs:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", SceneWarning)
            r, hit, why = cached(ref, settings(ref if isinstance(ref, Scene) else None, 0),
                                 folder)
        for w in caught:  # told by the client, one line each, not by this worker's stderr
            if issubclass(w.category, SceneWarning):
                # A generated scene's object index says nothing: one line per cause.
                cause = GENERATED.sub("", str(w.message))
                said.setdefault(f"scene {r.scene.name}: {cause}", None)
            else:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        got.append((r, hit))
        warning = warning or why
    batch = bake_batch(got, points, tasks, objects, time.perf_counter() - t0, settings)
    if warning is None:  # where scenes could not be stored, neither can the batch
        warning = batch_cache.store_quietly(folder, key, batch.bakes, batch.scenes, tuple(said))
    return replace(batch, cache_warning=warning, scene_warnings=tuple(said))


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
    # The points share one geometry: mesh hulls in all where any point checks collisions.
    hulls = any(settings(r.scene, k)["collision"] != "off" for r, _ in got
                for k in range(len(points)))
    bakes = [bake([replace(r, settings=settings(r.scene, k)) for r, _ in got], tasks,
                  max_objects=objects, mesh_hulls=hulls) for k in range(len(points))]
    results = [r for r, _ in got]
    hits = sum(hit for _, hit in got)
    return Batch(bakes, scene_labels(results), len(got) - hits, hits,
                 seconds + time.perf_counter() - t0)


def scene_labels(results: list[PrecomputeResult]) -> dict[str, list]:
    """What the tables say of each scene and its tasks beside the arrays: per scene its
    name, task count, C_init, C_final, d, h, and per task its id, object, object kind,
    template and parameter names."""
    def per_task(get):
        return [[get(r, t, sp) for t, sp in zip(r.scene.tasks, r.spaces, strict=True)]
                for r in results]

    return {"name": [r.scene.name for r in results],
            "n_tasks": [len(r.spaces) for r in results],
            **{k: [getattr(r, k) for r in results] for k in ("C_init", "C_final", "d", "h")},
            "task_ids": per_task(lambda r, t, sp: t.id),
            "object_ids": per_task(lambda r, t, sp: t.object),
            "object_kinds": per_task(lambda r, t, sp: r.scene.object(t.object).kind),
            "templates": per_task(lambda r, t, sp: t.template),
            "param_names": per_task(lambda r, t, sp: list(sp.param_names))}


def precompute_scene(item) -> PrecomputeResult:
    """``reproduce``'s task: ("manual", path, overrides) or ("random", (seed, kind),
    overrides)."""
    kind, ref, overrides = item
    scene = load_scene(ref) if kind == "manual" else random_scene(ref[0], ref[1], 5, 10,
                                                                  *ref[2:])
    return precompute(scene, scene.settings(DEFAULTS, overrides))
