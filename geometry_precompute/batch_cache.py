"""A sweep's baked batches kept as arrays, beside the precompute cache.

A warm sweep read every scene's precompute entry (JSON), rebuilt its task spaces and
baked it again: about 2.4 ms a 10-task scene on the 2-core CPU, 42 worker-seconds of a
warm 10 000-scene sweep on a 16-worker host, for arrays that came out the same bits
each time. A precompute task (``batch.precompute_batch``) now also keeps what it
returns: the bake of each sweep point and the scenes' table columns, in one
``batch-KEY.npz`` file of the cache folder (NumPy arrays, read without pickle) with
its labels as JSON inside. The next sweep with the same task reads that file and
bakes nothing.

The key is everything that decides the arrays: each scene's own precompute key (its
content or its generator arguments, with the precompute settings), the points'
settings, the batch's task and object counts, and the source of this package (any
change to the code gives new keys; the scenes' entries, keyed by the precompute's
version only, stay valid). A batch is the scenes one task was given, which depends on
the sweep's chunk and its count of precompute workers: a sweep with another count reads
the scenes' entries instead, as before.

A file's name holds the code's version. Reading an entry marks it used; the first entry
a process stores removes the entries of other versions that nothing has used for a day
(``fileio.prune_stale``), so the folder does not grow with every code change, and two
versions of the code used side by side keep each other's entries.

An entry is used only if it is whole and written for its key (``fileio.seal``), holds
every field of the bake once per point with the batch's scene count, and nothing but
plain numbers and booleans; anything else is a miss, and the batch is made and
written again.
"""

from __future__ import annotations

import hashlib
import io
import json
import zipfile
from pathlib import Path

import numpy as np

from .baking import GEOMETRY_FIELDS, PARAM_FIELDS, SEARCH_FIELDS, BakedScenes
from .cache import random_key, scene_key
from .errors import HostError
from .fileio import mark_used, prune_stale, seal, source_digest, unseal, write_atomic
from .scene import Scene

FORMAT = "shacc-batch-cache"
VERSION = 1
_FIELDS = GEOMETRY_FIELDS + PARAM_FIELDS + SEARCH_FIELDS
_SOURCE: str | None = None


def _source() -> str:
    """A digest of this package's code and data files (templates, settings)."""
    global _SOURCE
    if _SOURCE is None:
        here = Path(__file__).parent
        _SOURCE = source_digest(sorted([*here.glob("*.py"), *here.glob("*.toml")]))
    return _SOURCE


def batch_key(refs, points: list[dict], tasks: int, objects: int, settings) -> str:
    """The key of a precompute task's batch. ``settings``: ``batch.point_settings`` of
    ``points``."""
    scenes = [scene_key(r, settings(r, 0)) if isinstance(r, Scene)
              else random_key(r, settings(None, 0)) for r in refs]
    blob = {"format": FORMAT, "version": VERSION, "source": _source(), "scenes": scenes,
            "points": points, "tasks": tasks, "objects": objects}
    return hashlib.sha256(json.dumps(blob, sort_keys=True, default=repr).encode()).hexdigest()


def path_of(folder: Path, key: str) -> Path:
    """The entry's file: its name holds the code's version (the source digest's first
    16 digits), by which :func:`store` prunes other versions' entries."""
    return folder / f"batch-{_source()[:16]}-{key}.npz"


def store(folder: Path, key: str, bakes: list[BakedScenes], scenes: dict,
          scene_warnings: tuple[str, ...]) -> None:
    """Write a batch's entry (raises OSError or HostError where the folder cannot take
    it)."""
    arrays = {f"{k}.{name}": a for k, b in enumerate(bakes) for name, a in b.arrays().items()}
    labels = [{"names": b.labels["names"], "task_ids": b.labels["task_ids"],
               "C_init": np.asarray(b.labels["C_init"]).tolist(),
               "C_final": np.asarray(b.labels["C_final"]).tolist()} for b in bakes]
    meta = {"format": FORMAT, "version": VERSION, "key": key, "labels": labels,
            "scenes": scenes, "scene_warnings": list(scene_warnings)}
    arrays["meta"] = np.frombuffer(json.dumps(meta).encode(), np.uint8)
    # What np.savez_compressed writes (np.load reads it), at zlib's fastest level: 6.6
    # against 11.8 ms for 63 random 10-task scenes on the 2-core CPU, 7 % larger.
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as zf:
        for name, a in arrays.items():
            with zf.open(f"{name}.npy", "w", force_zip64=True) as f:
                np.lib.format.write_array(f, np.asanyarray(a), allow_pickle=False)
    folder.mkdir(parents=True, exist_ok=True)
    write_atomic(path_of(folder, key), seal(key, buffer.getvalue()))
    # Any code change makes new keys: other versions' entries unused for a day go.
    prune_stale(folder, "batch-*.npz", _source()[:16])


def read(folder: Path, key: str, n_scenes: int, n_points: int
         ) -> tuple[list[BakedScenes], dict, tuple[str, ...]] | None:
    """(the bakes, one per point; the scenes' columns; the scenes' warnings) of the entry
    for ``key``, or None where there is no valid one."""
    path = path_of(folder, key)
    try:
        payload = unseal(key, path.read_bytes())
    except OSError:
        return None
    if payload is None:
        return None
    try:
        with np.load(io.BytesIO(payload), allow_pickle=False) as npz:
            data = {name: npz[name] for name in npz.files}
        meta = json.loads(data.pop("meta").tobytes())
        if not isinstance(meta, dict) or meta.get("format") != FORMAT \
                or meta.get("version") != VERSION or meta.get("key") != key:
            return None
        labels, scenes = meta["labels"], meta["scenes"]
        warnings = meta["scene_warnings"]
        expected = {f"{k}.{name}" for k in range(n_points) for name in _FIELDS}
        if set(data) != expected or not isinstance(labels, list) or len(labels) != n_points \
                or not isinstance(scenes, dict) or not isinstance(warnings, list) \
                or not all(isinstance(w, str) for w in warnings):
            return None
        if any(a.dtype.kind not in "biuf" or a.ndim == 0 or len(a) != n_scenes
               for a in data.values()):
            return None
        bakes = []
        for k, lab in enumerate(labels):
            if not isinstance(lab, dict) or any(len(lab[f]) != n_scenes for f in
                                                ("names", "task_ids", "C_init", "C_final")):
                return None
            bakes.append(BakedScenes(
                **{name: data[f"{k}.{name}"] for name in _FIELDS},
                labels={"names": lab["names"], "task_ids": lab["task_ids"],
                        "C_init": np.asarray(lab["C_init"], float),
                        "C_final": np.asarray(lab["C_final"], float)}))
    except (OSError, ValueError, KeyError, TypeError, EOFError):  # not an entry of ours
        return None
    mark_used(path)  # a valid entry: in use (one that is not may be pruned)
    return bakes, scenes, tuple(warnings)


def store_quietly(folder: Path, key: str, bakes: list[BakedScenes], scenes: dict,
                  scene_warnings: tuple[str, ...]) -> str | None:
    """:func:`store`; the reason it could not, or None."""
    try:
        store(folder, key, bakes, scenes, scene_warnings)
    except OSError as e:  # a HostError is one, and HostError.of keeps it
        return str(HostError.of(e, folder, "store precomputed scenes"))
    return None
