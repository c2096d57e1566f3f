"""Sweep configurations (reference/outputs): a scene source, the modes, and axes
over any setting of the settings (reference/settings), validated in full before any work starts.

    name = "speed"
    modes = ["baseline", "shrinking", "shacc"]   # optional, default all three
    chunk = 32                                   # optional: scenes per saved chunk
    scheduler = "tcp://10.0.0.5:8786"            # optional: an existing Dask cluster

    [source]                                     # the random generator ...
    kind = "random"
    count = 200
    tasks = [5, 10]
    sampling = "both"                            # "uniform" | "gaussian" | "both"
    seed = 0
    preset = "compact"                           # or "paper": the generator's table area
    # [source.generator]: which objects, sizes, mesh folders and templates (optional;
    # docs/reference/experiments.md)
    # ... or scene files:  kind = "files"; path = "scenes/" (relative to this file)

    [settings]                                   # optional: fixed for every point
    start_grid = [8, 8]

    [axes]                                       # grid product of the listed values
    v_max = [0.1, 0.15, 0.2]
    shrink_step = [0.05, 0.1]
    side_grasp.radius_init = [0.15, 0.2]         # dotted names bare or quoted

    [[points]]                                   # and/or explicit points
    v_max = 0.3

Points are the axes' grid product (in the order written, the last axis fastest)
followed by the explicit points; with neither, the one point of the defaults. The
``[settings]`` table is added to every point (a point's own value wins).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from geometry_precompute import DEFAULTS, InputError, load_scene, random_scene, schema
from geometry_precompute.bodies import check_bodies_apart
from geometry_precompute.errors import SceneWarning, shown, unknown_field
from geometry_precompute.fileio import read_toml
from geometry_precompute.generate import MAX_TASKS, PRESETS, check_generator
from geometry_precompute.loading import scene_files
from geometry_precompute.scene import Scene, parse_scene, scene_to_dict
from geometry_precompute.settings import INT32_MAX, flatten_settings
from geometry_precompute.templates import resolve_tasks

_TOP = {"name", "modes", "chunk", "source", "settings", "axes", "points", "scheduler"}
_RANDOM = {"kind", "count", "tasks", "sampling", "seed", "preset", "generator"}
MAX_COUNT = 100_000_000  # random scenes in one sweep
MAX_POINTS = 100_000     # sweep points (the point list is built, checked and stored)
MAX_CHUNK = 1_000_000    # scenes per chunk
_FILES = {"kind", "path"}


@dataclass(frozen=True)
class SweepConfig:
    name: str
    modes: tuple[str, ...]
    chunk: int
    source: dict
    points: list[dict]
    base_dir: Path
    scheduler: str | None = None  # where it runs; not part of the results (nor the hash)

    def scenes(self) -> list[Scene]:
        src = self.source
        if src["kind"] == "files":
            folder = self.base_dir / src["path"]
            return [load_scene(p) for p in scene_files(folder)]
        return [random_scene(*self.random_ref(i)) for i in range(src["count"])]

    def random_ref(self, i: int) -> tuple:
        """``random_scene``'s arguments for scene ``i`` of a random source: scenes are
        built where they are precomputed, from these few numbers. The generator preset
        is named only when it is not ``compact`` (the default), so that the precompute
        cache keys of earlier sweeps stay valid."""
        src = self.source
        kinds = {"uniform": ["uniform"], "gaussian": ["gaussian"],
                 "both": ["uniform", "gaussian"]}[src["sampling"]]
        preset = src.get("preset", "compact")
        ref = (src["seed"] + i, kinds[i % len(kinds)], *src["tasks"])
        if "generator" in src:
            return (*ref, preset, src["generator"])
        return ref if preset == "compact" else (*ref, preset)

    def n_scenes(self) -> int:
        src = self.source
        return src["count"] if src["kind"] == "random" else \
            len(scene_files(self.base_dir / src["path"]))

    def max_tasks(self) -> int:
        """The most tasks (and objects) a scene of the source can have: a random
        source's upper bound, or the largest scene file's count."""
        if self.source["kind"] == "random":
            return self.source["tasks"][1]
        return max(max(len(s.tasks), len(s.objects)) for s in self.scenes())

    def task_counts(self) -> list[int]:
        """Task count of every scene, in order. Random scenes are not built: their task
        count is the generator's first draw from its seed (``random_scene``)."""
        src = self.source
        if src["kind"] == "files":
            return [len(s.tasks) for s in self.scenes()]
        lo, hi = src["tasks"]
        return [int(np.random.default_rng(src["seed"] + i).integers(lo, hi + 1))
                for i in range(src["count"])]

    def resolved(self) -> dict:
        """Everything that decides the results, as plain data (and so the hash)."""
        scenes = [_portable_scene(s) for s in self.scenes()] if self.source["kind"] == "files" \
            else None
        return {"name": self.name, "modes": list(self.modes), "chunk": self.chunk,
                "source": _portable(self.source), "scene_files": scenes,
                "points": self.points, "defaults": DEFAULTS.to_dict(),
                "shacc_version": installed_version()}

    def hash(self) -> str:
        blob = json.dumps(self.resolved(), sort_keys=True, default=str).encode()
        return hashlib.sha256(blob).hexdigest()[:16]


def _portable(source: dict) -> dict:
    """The source as the hash sees it: a generator's mesh files by name and content (a
    CRC-32 of each), not by where they lie on this machine."""
    if "generator" not in source:
        return source
    objects = []
    for e in source["generator"]["objects"]:
        if "files" in e:
            e = {**e, "files": [Path(f).name for f in e["files"]]}
        objects.append(e)
    gen = {**source["generator"], "objects": objects}
    if "template_files" in gen:  # by name: template_digest holds their content
        gen["template_files"] = [Path(f).name for f in gen["template_files"]]
    return {**source, "generator": gen}


def _portable_scene(scene) -> dict:
    """A scene file as the hash sees it: its mesh and template files by name and content
    (a CRC-32 of each mesh, a digest of the templates' definitions), not by where they
    lie on this machine."""
    d = scene_to_dict(scene)
    for o, od in zip(scene.objects, d["objects"], strict=True):
        if o.mesh is not None:
            od["mesh"] = [Path(o.mesh.path).name, o.mesh.digest]
    if "templates" in d:
        d["templates"] = [Path(f).name for f in d["templates"]]
        d["template_digest"] = scene.templates.digest()
    return d


def installed_version() -> str:
    """This installation's shacc version (recorded with a sweep's config; the workers of
    a cluster must have the same)."""
    import importlib.metadata as md  # deferred: 37 ms to import

    try:
        return md.version("shacc")
    except md.PackageNotFoundError:
        return "unknown"


def _int(v: Any, src: str, fld: str, lo: int = 0, hi: int = INT32_MAX) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
        raise InputError(src, fld, f"must be an integer in [{lo}, {hi}], got {shown(v)}")
    return v


def _check_point(point: Any, src: str, where: str) -> dict:
    """A table of setting = value, its dotted names flat, every name and value valid."""
    if not isinstance(point, Mapping):
        raise InputError(src, where, "must be a table of setting = value")
    point = flatten_settings(point, src, where + ".")
    DEFAULTS.with_overrides(point, src, where + ".")  # validates each name and value
    return point


def parse_config(data: Mapping, source: str, base_dir: Path) -> SweepConfig:
    src = str(source)
    for key in data:
        if key not in _TOP:
            raise InputError(src, key, unknown_field(_TOP, key))
    name = data.get("name", Path(src).stem)
    if not isinstance(name, str) or not name:
        raise InputError(src, "name", "must be a non-empty string")
    modes = data.get("modes", list(schema.MODES))
    if not isinstance(modes, list) or not modes \
            or any(m not in schema.ALL_MODES for m in modes) or len(set(modes)) != len(modes):
        raise InputError(src, "modes", f"must be distinct names from {list(schema.ALL_MODES)}")
    chunk = _int(data.get("chunk", 32), src, "chunk", 1, MAX_CHUNK)
    raw = data.get("source")
    if not isinstance(raw, Mapping) or "kind" not in raw:
        raise InputError(src, "source.kind", "missing: \"random\" or \"files\"")
    if not isinstance(raw["kind"], str):
        raise InputError(src, "source.kind", f"must be random or files, got {shown(raw['kind'])}")
    if raw["kind"] == "random":
        for key in raw:
            if key not in _RANDOM:
                raise InputError(src, f"source.{key}", f"unknown field for random scenes "
                                 f"(allowed: {sorted(_RANDOM)})")
        tasks = raw.get("tasks", [5, 10])
        if not (isinstance(tasks, list) and len(tasks) == 2
                and all(isinstance(t, int) and not isinstance(t, bool) for t in tasks)
                and 1 <= tasks[0] <= tasks[1] <= MAX_TASKS):
            raise InputError(src, "source.tasks", f"must be [min, max] with 1 <= min <= max "
                             f"<= {MAX_TASKS} (the most objects the generator places)")
        sampling = raw.get("sampling", "both")
        if not isinstance(sampling, str) or sampling not in ("uniform", "gaussian", "both"):
            raise InputError(src, "source.sampling", "must be uniform, gaussian or both")
        count = _int(raw.get("count"), src, "source.count", 1, MAX_COUNT)
        # Scene i is seeded seed + i: every seed stays a 32-bit integer.
        seed = _int(raw.get("seed", 0), src, "source.seed", 0, INT32_MAX - count + 1)

        preset = raw.get("preset", "compact")
        if not isinstance(preset, str) or preset not in PRESETS:
            raise InputError(src, "source.preset", f"must be one of {', '.join(PRESETS)}, got "
                             f"{shown(preset)}")
        source_out = {"kind": "random", "count": count,
                      "tasks": list(tasks), "sampling": sampling, "seed": seed}
        if preset != "compact":  # the hash of a compact sweep stays what it was
            source_out["preset"] = preset
        if "generator" in raw:

            source_out["generator"] = check_generator(raw["generator"], src,
                                                      "source.generator", base_dir)
    elif raw["kind"] == "files":
        for key in raw:
            if key not in _FILES:
                raise InputError(src, f"source.{key}", "unknown field for scene files "
                                 f"(allowed: {sorted(_FILES)})")
        path = raw.get("path")
        if not isinstance(path, str) or not (base_dir / path).is_dir():
            raise InputError(src, "source.path", f"must name a folder of scene files, got "
                             f"{shown(path)}")
        if not scene_files(base_dir / path):
            raise InputError(src, "source.path", f"no *.toml scene files in {shown(path)}")
        source_out = {"kind": "files", "path": path}
    else:
        raise InputError(src, "source.kind", f"must be random or files, got {shown(raw['kind'])}")

    fixed = _check_point(data.get("settings", {}), src, "settings")
    axes = data.get("axes", {})
    if not isinstance(axes, Mapping):
        raise InputError(src, "axes", "must be a table of setting = [values]")
    axes = flatten_settings(axes, src, "axes.")
    for k, values in axes.items():
        if not isinstance(values, list) or not values:
            raise InputError(src, f"axes.{k}", "must be a non-empty list of values")
    explicit = data.get("points", [])
    if not isinstance(explicit, list):
        raise InputError(src, "points", "must be an array of tables ([[points]])")
    # Counted before anything is built: the grid product of a few long axes is large.
    n_points = (math.prod(len(v) for v in axes.values()) if axes else 0) + len(explicit)
    if n_points > MAX_POINTS:
        raise InputError(src, "axes", f"the axes and [[points]] give {n_points} points, more "
                         f"than {MAX_POINTS} a sweep may have; split it into several sweeps")
    for k, values in axes.items():
        for v in values:
            _check_point({k: v}, src, "axes")
    points = [dict(zip(axes, combo, strict=True)) for combo in
              itertools.product(*axes.values())] if axes else []
    points += [_check_point(p, src, f"points[{i}]") for i, p in enumerate(explicit)]
    if not points:
        points = [{}]
    # The fixed settings hold for every point; a point's own value of one wins.
    points = [{**fixed, **p} for p in points]
    scheduler = data.get("scheduler")
    if scheduler is not None and (not isinstance(scheduler, str) or not scheduler.strip()):
        raise InputError(src, "scheduler", "must be a Dask scheduler address such as "
                         f"\"tcp://10.0.0.5:8786\", got {shown(scheduler)}")
    cfg = SweepConfig(name, tuple(modes), chunk, source_out, points, base_dir, scheduler)
    _check_templates_fit(cfg, src)
    if source_out["kind"] == "files":
        # Scene files are loaded (and validated) before any work starts, and each point
        # against each scene's own [settings]. Random scenes have no [settings] of their
        # own, so the points' checks above cover them without building any.
        scenes = cfg.scenes()

        for scene in scenes:  # the rest of reference/errors: here, not mid-sweep
            check_bodies_apart(scene)
        for i, p in enumerate(points):
            grids = {tuple(s.settings(DEFAULTS, p)["start_grid"]): s.source for s in scenes}
            if len(grids) > 1:
                raise InputError(src, "source.path", f"the scenes ask for different start "
                                 f"grids {sorted(grids)} (point {i}); a point's scenes are "
                                 "evaluated as one batch: set start_grid in the config's "
                                 "[settings] or make the scenes agree")
    return cfg


def _probe_scene(generator: dict | None = None) -> Scene:
    """The object kinds and templates the random generator uses, at their default
    sizes (a configured generator's: every kind at its largest, every mesh file, every
    template), far apart: a point's template settings are checked on it."""

    if generator is not None:
        objects: list[dict] = []
        tasks: list[dict] = []
        for i, e in enumerate(generator["objects"]):
            sizes = ([{"radius": e["radius"][1], "height": e["height"][1]}]
                     if e["kind"] in ("mug", "cup") else
                     [{"half_extents": [r[1] for r in e["half_extents"]]}]
                     if e["kind"] == "box" else
                     [{"mesh": f, **p} for f, p in zip(e["files"], e["placements"],
                                                        strict=True)])
            for k, size in enumerate(sizes):
                oid = f"{e['kind']}{i}-{k}"
                objects.append({"id": oid, "kind": e["kind"],
                                "position": [float(len(objects) % 10), float(len(objects) // 10),
                                             0.0], **size})
                tasks += [{"id": f"{t}-{oid}", "object": oid, "template": t}
                          for t in e["templates"]]
        probe = {"name": "probe", "objects": objects, "tasks": tasks}
        if generator.get("template_files"):
            probe["templates"] = generator["template_files"]
        with warnings.catch_warnings():  # the meshes' warnings were said by check_generator
            warnings.simplefilter("ignore", SceneWarning)
            return parse_scene(probe, "<generator>")
    return parse_scene({"name": "probe", "objects": [
        {"id": "mug", "kind": "mug", "position": [0.0, 0.0, 0.0]},
        {"id": "cup", "kind": "cup", "position": [0.0, 5.0, 0.0]}], "tasks": [
        {"id": "side", "object": "mug", "template": "side_grasp"},
        {"id": "handle", "object": "cup", "template": "handle_grasp"}]}, "<generator>")


def _check_templates_fit(cfg: SweepConfig, src: str) -> None:
    """Every point's template settings fit every scene of the source (bounds min <=
    init), here rather than in the first task of a running sweep. Only the
    precompute-stage settings matter, so each distinct set of them is checked once."""

    scenes = cfg.scenes() if cfg.source["kind"] == "files" else \
        [_probe_scene(cfg.source.get("generator"))]
    seen: set[str] = set()
    for k, point in enumerate(cfg.points):
        stage = json.dumps(DEFAULTS.with_overrides(point).by_stage("precompute"),
                           sort_keys=True, default=str)
        if stage in seen:
            continue
        seen.add(stage)
        for scene in scenes:
            try:
                resolve_tasks(scene, scene.settings(DEFAULTS, point))
            except InputError as e:
                where = "the random generator's objects" if scene.source == \
                    "<generator>" else e.source
                raise InputError(src, f"point {k}", f"{e.field} of {where}: {e.rule} "
                                 f"(the point sets {shown(point)})") from None


def load_config(path: str | Path) -> SweepConfig:
    path = Path(path)
    return parse_config(read_toml(path, "a sweep config TOML file"), str(path), path.parent)
