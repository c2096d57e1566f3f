"""The precompute cache: one JSON file per scene and precompute settings, checked on
every read.

A sweep precomputes each scene once per host and reads it back on every later sweep.
The entries hold data only (JSON: the scene, its Shrinking parameters, C, clusters,
d, h), never code: the cache folder may be shared by a cluster's hosts, and a pickle
read there would run whatever its writer put in it. Everything else of a
:class:`~geometry_precompute.precomputing.PrecomputeResult` (the task spaces, their
shapes) is rebuilt from the scene and the settings, which is what the precompute
itself does before its geometry, and costs a fraction of it.

An entry is used only if it is whole and what its name says: the format and version
match, it names its own key, its scene parses (and, for a scene file, hashes to the
key), every number is finite and every Shrinking parameter lies within its task's
bounds, the clusters are a partition of the tasks. Anything else (a truncated file, a
foreign or damaged entry, an entry of another version) is computed again and
rewritten. A folder that cannot be written is used to read what it holds; the
precompute then goes on without storing (:func:`cached` returns the reason, for one
warning line).
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from .errors import HostError, InputError
from .fileio import cache_home, write_atomic
from .generate import GENERATOR_VERSION, random_scene
from .precomputing import PRECOMPUTE_VERSION, PrecomputeResult, precompute
from .scene import Scene, parse_scene, scene_to_dict
from .settings import Settings
from .templates import resolve_tasks

FORMAT = "shacc-precompute-cache"
VERSION = 1  # of this file format; PRECOMPUTE_VERSION is in every key


def default_folder() -> Path:
    """This host's precompute cache: ``$XDG_CACHE_HOME/shacc/precompute``."""
    return cache_home() / "precompute"


def _digest(blob: dict) -> str:
    return hashlib.sha256(json.dumps(blob, sort_keys=True, default=str).encode()).hexdigest()


def scene_key(scene: Scene, settings: Settings) -> str:
    """The key of a scene: its content (with its template files' definitions), its
    precompute-stage settings and the precompute's version (a rollout setting never asks
    for a new precompute)."""
    return _digest({"scene": scene_to_dict(scene), "settings": settings.by_stage("precompute"),
                    "templates": scene.templates.digest(), "version": PRECOMPUTE_VERSION})


def random_key(ref: tuple, settings: Settings) -> str:
    """The key of a random scene: ``random_scene``'s arguments, the generator's version,
    the precompute-stage settings and the precompute's version. A warm sweep of random
    scenes then reads its results without building the scenes."""
    return _digest({"random": list(ref), "generator": GENERATOR_VERSION,
                    "settings": settings.by_stage("precompute"), "version": PRECOMPUTE_VERSION})


def _entry(key: str, r: PrecomputeResult) -> bytes:
    return json.dumps({
        "format": FORMAT, "version": VERSION, "key": key,
        "scene": scene_to_dict(r.scene), "source": r.scene.source,
        "q_opt": [[float(v) for v in q] for q in r.q_opt],
        "C_init": r.C_init, "C_final": r.C_final, "clusters": r.clusters,
        "iterations": r.iterations, "still_intersecting": [list(p) for p in r.still_intersecting],
        "d": r.d, "h": r.h, "seconds": r.seconds,
    }).encode()


def _finite(x, lo: float = -math.inf) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x) and x >= lo


def _read(data: bytes, key: str, settings: Settings, content_key: bool, source: str | None
          ) -> PrecomputeResult | None:
    """The result an entry holds, or None where it is not a valid entry for ``key``."""
    try:
        e = json.loads(data)
    except (ValueError, RecursionError):
        return None
    if not isinstance(e, dict) or e.get("format") != FORMAT or e.get("version") != VERSION \
            or e.get("key") != key:
        return None
    try:
        source = e["source"] if source is None else source  # a random scene's own
        if not isinstance(source, str):
            return None
        scene = replace(parse_scene(e["scene"], source), source=source)
        if content_key and scene_key(scene, settings) != key:
            return None
        spaces = resolve_tasks(scene, settings)
        n = len(spaces)
        q_raw, clusters, still = e["q_opt"], e["clusters"], e["still_intersecting"]
        if not (isinstance(q_raw, list) and len(q_raw) == n and isinstance(clusters, list)
                and isinstance(still, list)):
            return None
        q_opt = []
        for sp, q in zip(spaces, q_raw, strict=True):
            if not (isinstance(q, list) and len(q) == len(sp.param_names)
                    and all(_finite(v) and lo - 1e-9 <= v <= hi + 1e-9
                            for v, lo, hi in zip(q, sp.q_min.tolist(), sp.q_init.tolist(),
                                                 strict=True))):
                return None  # a Shrinking parameter outside its bounds
            q_opt.append(np.array(q, dtype=np.float64))
        members = [i for c in clusters if isinstance(c, list) for i in c]
        if sorted(members) != list(range(n)) or any(not isinstance(c, list) or not c
                                                    for c in clusters):
            return None
        pairs = [tuple(p) for p in still]
        if any(len(p) != 2 or not all(isinstance(i, int) and 0 <= i < n for i in p)
               for p in pairs):
            return None
        iterations = e["iterations"]
        if not (isinstance(iterations, int) and not isinstance(iterations, bool)
                and 0 <= iterations <= settings["shrink_max_iter"]):
            return None
        numbers = [e["C_init"], e["C_final"], e["d"], e["h"]]
        seconds = e["seconds"]
        if not all(_finite(v, 0.0) for v in numbers) or not isinstance(seconds, dict) \
                or not all(isinstance(k, str) and _finite(v) for k, v in seconds.items()):
            return None
    except (KeyError, TypeError, ValueError, InputError):
        return None
    shapes_init = [sp.shape() for sp in spaces]
    shapes_opt = [sp.shape(q) for sp, q in zip(spaces, q_opt, strict=True)]
    return PrecomputeResult(scene, settings, spaces, shapes_init, shapes_opt, q_opt,
                            float(e["C_init"]), float(e["C_final"]), clusters, iterations,
                            pairs, float(e["d"]), float(e["h"]), dict(seconds))


def cached(scene: Scene | tuple, settings: Settings, folder: Path | None
           ) -> tuple[PrecomputeResult, bool, str | None]:
    """(result, whether it came from the cache, why it could not be stored or None) of
    a Scene, or of ``random_scene``'s arguments (the scene is built only when its result
    is not cached). ``folder`` None: no cache."""
    def build() -> Scene:
        return scene if isinstance(scene, Scene) else random_scene(*scene)

    if folder is None:
        return precompute(build(), settings), False, None
    is_scene = isinstance(scene, Scene)
    key = scene_key(scene, settings) if isinstance(scene, Scene) else random_key(scene, settings)
    path = folder / f"{key}.json"
    source = scene.source if isinstance(scene, Scene) else None
    try:
        data = path.read_bytes()
    except OSError:
        data = None
    if data is not None:
        found = _read(data, key, settings, is_scene, source)
        if found is not None:
            return found, True, None
    r = precompute(build(), settings)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        write_atomic(path, _entry(key, r))
    except OSError as e:  # a HostError is one, and HostError.of keeps it
        return r, False, str(HostError.of(e, folder, "store precomputed scenes"))
    return r, False, None
