"""The bake: precomputed scenes as fixed-shape NumPy arrays (reference/index).

This is the only bridge between the CPU half and the JAX half: ``shacc_jax``
reads these arrays by name and nothing else. S scenes are padded to T tasks
(``max_tasks``, default the largest task count); padded rows have
``task_mask = False``, harmless finite geometry, and can never activate or
weigh in an average on the JAX side.

The fields, their shapes and meanings, and the integer codes in them are the
schema's (``schema.py``: GEOMETRY, PARAMS, SEARCH); floats are float64 here, the
JAX side casts them to its working precision. ``BakedScenes.layout`` computes the
batch's static :class:`~geometry_precompute.schema.Layout` in NumPy.

The ``optimized`` mode's search (reference/model) builds spaces for any parameter
vector on the accelerator. Every template's space is affine in its shrinkable
parameters q (P = 2 slots: the most any template has), so the bake carries that
map (``center_dq``, ``dims_dq``) and checks it at each template's midpoint.

Labels for people (names, task ids, C values) ride along in ``labels`` and are never
passed to JAX.
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import population, schema
from .bodies import object_body
from .errors import InputError
from .frames import yaw_matrix
from .mesh_objects import hull
from .population import POPULATED, Population
from .precomputing import PrecomputeResult
from .schema import KIND_CODES, MAX_PARAMS, batch_layout, is_horizontal_approach
from .settings import SPECS, population_range
from .starts import optimize_start_poses, start_plane, start_poses
from .templates import TaskSpace

GEOMETRY_FIELDS = schema.names(schema.GEOMETRY)
PARAM_FIELDS = schema.names(schema.PARAMS)
# The settings the rollouts read, each with its bake encoding (settings.Param).
ROLLOUT_PARAMS = tuple((s.name, s.param) for s in SPECS.values() if s.param is not None)
SEARCH_FIELDS = schema.names(schema.SEARCH)
_PAD_DIMS = (0.01, 0.01, 0.01)


@dataclass(frozen=True)
class BakedScenes:
    """A bake: one NumPy array per schema field (``schema.GEOMETRY``, ``PARAMS``,
    ``SEARCH``, in that order; a test keeps the two lists equal), leading axis S, and
    ``labels`` for people (names, task ids, C values), never passed to JAX."""

    task_mask: np.ndarray
    kind: np.ndarray
    center_init: np.ndarray
    quat_init: np.ndarray
    dims_init: np.ndarray
    center_opt: np.ndarray
    quat_opt: np.ndarray
    dims_opt: np.ndarray
    cluster: np.ndarray
    yaw_meta: np.ndarray
    orient_kind: np.ndarray
    orient_quat: np.ndarray
    orient_axis: np.ndarray
    aim_point: np.ndarray
    starts: np.ndarray
    start_index: np.ndarray
    obj_mask: np.ndarray
    obj_kind: np.ndarray
    obj_center: np.ndarray
    obj_quat: np.ndarray
    obj_size: np.ndarray
    obj_hull: np.ndarray
    obj_hull_plane: np.ndarray
    scene_key: np.ndarray
    dt: np.ndarray
    v_max: np.ndarray
    omega_max: np.ndarray
    max_steps: np.ndarray
    activation_tol: np.ndarray
    ambiguity_nearest: np.ndarray
    user_seed: np.ndarray
    collision: np.ndarray
    user_noise: np.ndarray
    user_noise_tau: np.ndarray
    user_tremor: np.ndarray
    user_tremor_hz: np.ndarray
    user_input_modes: np.ndarray
    user_mode_switch_s: np.ndarray
    user_switch: np.ndarray
    user_switch_at: np.ndarray
    user_aim_object: np.ndarray
    activation_swept: np.ndarray
    intent_beta: np.ndarray
    blend_threshold: np.ndarray
    ho_gain: np.ndarray
    gripper_finger_length: np.ndarray
    gripper_finger_radius: np.ndarray
    gripper_opening: np.ndarray
    gripper_palm_radius: np.ndarray
    user_dist: np.ndarray
    user_dist_args: np.ndarray
    user_dist_values: np.ndarray
    q_mask: np.ndarray
    q_min: np.ndarray
    q_init: np.ndarray
    q_shrunk: np.ndarray
    center_dq: np.ndarray
    dims_dq: np.ndarray
    opt_starts: np.ndarray
    opt_start_mask: np.ndarray
    optimize_seed: np.ndarray
    optimize_population: np.ndarray
    optimize_generations: np.ndarray
    start_plane: np.ndarray
    optimize_validation_starts: np.ndarray
    optimize_validation_seed: np.ndarray
    optimize_candidates: np.ndarray
    optimize_validate: np.ndarray
    labels: dict = field(default_factory=dict, compare=False)

    @property
    def n_scenes(self) -> int:
        return self.task_mask.shape[0]

    @property
    def n_tasks(self) -> int:
        return self.task_mask.shape[1]

    @property
    def n_starts(self) -> int:
        return self.starts.shape[1]

    def arrays(self) -> dict[str, np.ndarray]:
        """Every schema field by name (for ``np.savez``; ``BakedScenes(**arrays)`` reads
        them back)."""
        return {k: getattr(self, k) for k in GEOMETRY_FIELDS + PARAM_FIELDS + SEARCH_FIELDS}

    def layout(self, modes=schema.MODES, lanes_per_block: int | None = None,
               samples_per_block: int = 16) -> schema.Layout:
        """The batch's static layout, read off the arrays once, in NumPy."""
        return batch_layout(self, modes, lanes_per_block, samples_per_block)


def concatenate(bakes: Sequence[BakedScenes], pad_to: int | None = None) -> BakedScenes:
    """Bakes of one shape (tasks, objects, starts) as one, scenes in order; ``pad_to``:
    that many scenes, the last repeated (a padded scene's results are dropped by who
    asked for it)."""
    F = max(b.obj_hull.shape[2] for b in bakes)
    arrays = {k: np.concatenate([_hull_rows(getattr(b, k), F) if k in _HULL_FIELDS
                                 else getattr(b, k) for b in bakes])
              for k in GEOMETRY_FIELDS + PARAM_FIELDS + SEARCH_FIELDS}
    S = len(arrays["task_mask"])
    if pad_to is not None and pad_to > S:
        arrays = {k: np.concatenate([a, np.repeat(a[-1:], pad_to - S, axis=0)])
                  for k, a in arrays.items()}
    labels: dict[str, Any] = {k: [x for b in bakes for x in b.labels[k]]
                              for k in ("names", "task_ids")}
    labels.update({k: np.concatenate([b.labels[k] for b in bakes])
                   for k in ("C_init", "C_final")})
    return BakedScenes(**arrays, labels=labels)


_HULL_FIELDS = ("obj_hull", "obj_hull_plane")


def _hull_rows(a: np.ndarray, F: int) -> np.ndarray:
    """A bake's hull array (S, O, F0, ...) with F rows per object, its triangles repeated
    (each object's F0 rows are its hull's triangles, repeated already)."""
    if a.shape[2] == F:
        return a
    if a.shape[2] == 0:
        return np.zeros((*a.shape[:2], F, *a.shape[3:]))
    return a[:, :, np.arange(F) % a.shape[2]]


def hull_rows(n: int) -> int:
    """The padded hull size F of a batch whose largest hull has n triangles: four sizes
    per octave from 16 (at most 25 % more), so that a sweep's chunks mostly share one
    program.

    >>> [hull_rows(n) for n in (0, 4, 17, 284, 478, 968)]
    [0, 16, 20, 320, 512, 1024]
    """
    if n <= 0:
        return 0
    size = 16
    while size < n:
        octave = 1 << (size.bit_length() - 1)
        size += octave // 4
    return size


def _affine_map(space: TaskSpace, source) -> tuple[np.ndarray, np.ndarray]:
    """(d centre / d q, d dims / d q), each (3, P), of a template's space, read off the
    shapes at the bounds; checked at the midpoint, so a template whose space is not
    affine in its parameters cannot be baked silently wrong."""
    # In floats (the same IEEE operations as NumPy's, without its per-call cost).
    q0 = tuple(float(v) for v in space.q_init)
    qm = tuple(float(v) for v in space.q_min)
    base = space.shape_of(q0)
    dc = [[0.0] * MAX_PARAMS for _ in range(3)]
    dd = [[0.0] * MAX_PARAMS for _ in range(3)]
    for k in range(len(q0)):
        step = qm[k] - q0[k]
        if step == 0.0:  # a fixed parameter: the search cannot move it
            continue
        moved = space.shape_of((*q0[:k], qm[k], *q0[k + 1:]))
        for a in range(3):
            dc[a][k] = (moved.center[a] - base.center[a]) / step
            dd[a][k] = (moved.dims[a] - base.dims[a]) / step
    mid = tuple((lo + hi) / 2.0 for lo, hi in zip(qm, q0, strict=True))
    shape = space.shape_of(mid)
    dq = [m - i for m, i in zip(mid, q0, strict=True)]
    errs = [abs(got[a] - (ref[a] + sum(d[a][k] * dq[k] for k in range(len(dq)))))
            for got, ref, d in ((shape.center, base.center, dc), (shape.dims, base.dims, dd))
            for a in range(3)]
    if not all(e <= 1e-9 for e in errs):  # also when NaN
        raise InputError(source, f"tasks[{space.task.id}].template",
                         f"{space.template}'s space is not affine in its parameters; the "
                         "optimized mode cannot bake it")
    return np.array(dc), np.array(dd)


def _search_fields(results: Sequence[PrecomputeResult], T: int) -> dict[str, np.ndarray]:
    S = len(results)
    opt = [optimize_start_poses(r.scene, r.settings) for r in results]
    No = max(len(o) for o in opt)
    out = {"q_mask": np.zeros((S, T, MAX_PARAMS), bool),
           "center_dq": np.zeros((S, T, 3, MAX_PARAMS)),
           "dims_dq": np.zeros((S, T, 3, MAX_PARAMS)),
           "opt_starts": np.tile([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], (S, No, 1)),
           "opt_start_mask": np.zeros((S, No), bool),
           "start_plane": np.array([[x, *ys, *zs] for x, ys, zs in
                                    (start_plane(r.scene, r.settings) for r in results)]),
           "optimize_validate": np.array([r.settings["optimize_selection"] == "validation"
                                          for r in results])}
    for k in ("q_min", "q_init", "q_shrunk"):
        out[k] = np.zeros((S, T, MAX_PARAMS))
    for k in ("optimize_seed", "optimize_population", "optimize_generations",
              "optimize_validation_starts", "optimize_validation_seed", "optimize_candidates"):
        out[k] = np.array([r.settings[k] for r in results], np.int64)
    for si, r in enumerate(results):
        out["opt_starts"][si, :len(opt[si])] = opt[si]
        out["opt_start_mask"][si, :len(opt[si])] = True
        for ti, (space, q) in enumerate(zip(r.spaces, r.q_opt, strict=True)):
            n = len(space.param_names)
            out["q_mask"][si, ti, :n] = True
            out["q_min"][si, ti, :n] = space.q_min
            out["q_init"][si, ti, :n] = space.q_init
            out["q_shrunk"][si, ti, :n] = q
            out["center_dq"][si, ti], out["dims_dq"][si, ti] = _affine_map(space, r.scene.source)
    return out


def _check_quaternions(q: np.ndarray, source: str, fld: str) -> None:
    norms = np.linalg.norm(q, axis=-1)
    if not np.all(np.isfinite(q)):
        raise InputError(source, fld, "must be finite (no NaN or inf)")
    if np.any(norms < 1e-9):
        raise InputError(source, fld, "a zero quaternion is not a rotation")


def _placed_hull(obj, center) -> tuple[np.ndarray, np.ndarray]:
    """A mesh object's hull (``mesh_objects.hull``) turned by its yaw and placed about
    ``center``: triangles (F, 3, 3) and planes (F, 4), the offsets computed in float64
    where they are placed."""

    tri, normals = hull(obj.mesh)
    turn = yaw_matrix(obj.yaw)
    offset = np.asarray(obj.position, float) - np.asarray(center, float)
    tri = tri @ turn.T + offset
    normals = normals @ turn.T
    return tri, np.concatenate([normals, np.einsum("fi,fi->f", normals, tri[:, 0])[:, None]],
                               axis=1)


def scene_key(scene) -> int:
    """The scene's own number, in [0, 2^31): a CRC-32 of its name, objects and tasks.
    It keys the simulated users' random numbers (``shacc_jax.streams``), so that a
    rollout draws the same numbers whatever batch, piece or device it runs in.

    >>> from geometry_precompute import load_scene, shipped_scene_paths
    >>> a = load_scene(shipped_scene_paths()[0])
    >>> scene_key(a) == scene_key(load_scene(shipped_scene_paths()[0])) != scene_key(
    ...     load_scene(shipped_scene_paths()[1]))
    True
    """
    text = repr((scene.name, scene.objects, scene.tasks))
    return zlib.crc32(text.encode()) & 0x7FFFFFFF


def bake(results: Sequence[PrecomputeResult], max_tasks: int | None = None,
         starts: np.ndarray | None = None, max_objects: int | None = None,
         mesh_hulls: bool | None = None) -> BakedScenes:
    """Bake precomputed scenes into fixed-shape arrays, the one input of the JAX half.

    :param results: S precomputed scenes (:func:`precompute`).
    :param max_tasks: pad the task axis T to at least this (default: the most tasks).
    :param starts: (N, 7) or (S, N, 7) start poses ``[x, y, z, qw, qx, qy, qz]`` (m,
        unit quaternion w first) instead of the settings' grid (quaternions are
        validated and normalised).
    :param max_objects: pad the object axis to at least this.
    :param mesh_hulls: whether mesh objects get their collision slot and hull (None: in
        the scenes whose ``collision`` is on). A sweep's points that differ only in
        rollout settings share one geometry, so their bakes pass True where any of them
        checks collisions.
    :returns: a :class:`BakedScenes` (``geometry_precompute/schema.py`` lists every
        array and its shape); ``shacc_jax.inputs`` splits it into Geometry, Params and
        Layout. A sweep's chunks share their padded shapes, so they share one program.

    Example::

        baked = bake([precompute(load_scene(p)) for p in shipped_scene_paths()])
        baked.starts.shape      # (12, 36, 7)
    """
    if not results:
        raise InputError("<bake>", "results", "needs at least one precomputed scene")
    n_max = max(len(r.spaces) for r in results)
    T = n_max if max_tasks is None else int(max_tasks)
    if T < n_max:
        raise InputError("<bake>", "max_tasks", f"{T} is fewer than the largest scene's "
                         f"{n_max} tasks")
    S = len(results)
    if starts is None:
        per_scene = [start_poses(r.scene, r.settings) for r in results]
        counts = {len(p) for p in per_scene}
        if len(counts) != 1:
            odd = next(r for r, p in zip(results, per_scene, strict=True)
                       if len(p) != len(per_scene[0]))
            raise InputError(odd.scene.source, "start_grid", "every scene of one batch needs "
                             f"the same number of start poses, got {sorted(counts)}: "
                             "evaluate them apart or give --set start_grid=[NY,NZ]")
        starts_arr = np.stack(per_scene)
    else:
        starts_arr = np.asarray(starts, dtype=np.float64)
        if starts_arr.ndim == 2:
            starts_arr = np.broadcast_to(starts_arr, (S, *starts_arr.shape)).copy()
        if starts_arr.ndim != 3 or starts_arr.shape[0] != S or starts_arr.shape[2] != 7:
            raise InputError("<bake>", "starts", "must have shape (N, 7) or (S, N, 7), got "
                             f"{starts_arr.shape}")
        _check_quaternions(starts_arr[..., 3:], "<bake>", "starts[..., 3:7]")
        starts_arr[..., 3:] /= np.linalg.norm(starts_arr[..., 3:], axis=-1, keepdims=True)

    out = {
        "task_mask": np.zeros((S, T), bool),
        "kind": np.zeros((S, T), np.int32),
        "cluster": np.full((S, T), -1, np.int32),
        "orient_kind": np.zeros((S, T), np.int32),
        "orient_quat": np.tile([1.0, 0.0, 0.0, 0.0], (S, T, 1)),
        "orient_axis": np.zeros((S, T, 2)),
        "aim_point": np.zeros((S, T, 3)),
        "yaw_meta": np.zeros(S, bool),
    }
    for which in ("init", "opt"):
        out[f"center_{which}"] = np.zeros((S, T, 3))
        out[f"quat_{which}"] = np.tile([1.0, 0.0, 0.0, 0.0], (S, T, 1))
        out[f"dims_{which}"] = np.tile(_PAD_DIMS, (S, T, 1))
    # Every rollout setting's field, as its declaration says (settings.SPECS: Param).
    dtypes = {"float": np.float64, "int": np.int32, "bool": bool}
    params = {f.name: np.zeros(S, dtypes[f.dtype]) for f in schema.PARAMS[:-3]}
    params["user_dist"] = np.zeros((S, len(POPULATED)), np.int32)
    params["user_dist_args"] = np.zeros((S, len(POPULATED), population.ARGS))
    params["user_dist_values"] = np.zeros((S, len(POPULATED), population.MAX_VALUES))
    out["scene_key"] = np.array([scene_key(r.scene) for r in results], np.int32)
    out["start_index"] = np.broadcast_to(np.arange(starts_arr.shape[1], dtype=np.int32),
                                         starts_arr.shape[:2]).copy()
    O = max(1, max(len(r.scene.objects) for r in results), max_objects or 0)
    out["obj_mask"] = np.zeros((S, O), bool)
    out["obj_kind"] = np.zeros((S, O), np.int32)
    out["obj_center"] = np.zeros((S, O, 3))
    out["obj_quat"] = np.tile([1.0, 0.0, 0.0, 0.0], (S, O, 1))
    out["obj_size"] = np.tile(_PAD_DIMS, (S, O, 1))
    hulls: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
    for si, r in enumerate(results):
        s = r.settings
        for oi, obj in enumerate(r.scene.objects):
            body = object_body(obj)
            if obj.mesh is not None and not (s["collision"] != "off" if mesh_hulls is None
                                             else mesh_hulls):
                continue  # not collided with: no slot (nor a hull to carry)
            out["obj_mask"][si, oi] = True
            out["obj_center"][si, oi] = body.center
            out["obj_quat"][si, oi] = body.quat
            out["obj_kind"][si, oi] = KIND_CODES[body.kind]
            if body.kind == "box":
                out["obj_size"][si, oi] = body.dims
            else:
                out["obj_size"][si, oi] = (body.dims[0], body.dims[1] / 2, 0.0)
            if obj.mesh is not None:  # its hull, checked exactly; bounded by that cylinder
                out["obj_kind"][si, oi] = schema.MESH
                hulls[si, oi] = _placed_hull(obj, body.center)
    F = hull_rows(max((len(t) for t, _ in hulls.values()), default=0))
    out["obj_hull"] = np.zeros((S, O, F, 3, 3))
    out["obj_hull_plane"] = np.zeros((S, O, F, 4))
    for (si, oi), (tri, plane) in hulls.items():
        pad = np.arange(F) % len(tri)  # repeating its triangles changes no distance
        out["obj_hull"][si, oi] = tri[pad]
        out["obj_hull_plane"][si, oi] = plane[pad]
    for si, r in enumerate(results):
        s = r.settings
        for ti, space in enumerate(r.spaces):
            out["task_mask"][si, ti] = True
            out["kind"][si, ti] = KIND_CODES[r.shapes_init[ti].kind]
            for which, shape in (("init", r.shapes_init[ti]), ("opt", r.shapes_opt[ti])):
                out[f"center_{which}"][si, ti] = shape.center
                out[f"quat_{which}"][si, ti] = shape.quat
                out[f"dims_{which}"][si, ti] = shape.dims
            o = space.orientation
            out["orient_kind"][si, ti] = schema.ORIENT_KINDS.index(o.kind)
            out["orient_quat"][si, ti] = o.quat
            out["orient_axis"][si, ti] = o.axis_xy
            out["aim_point"][si, ti] = space.aim_point
        for label, members in enumerate(r.meta_clusters()):
            out["cluster"][si, members] = label
        out["yaw_meta"][si] = all(is_horizontal_approach(out["orient_quat"][si, t])
                                  for members in r.meta_clusters() for t in members)
        for name, param in ROLLOUT_PARAMS:
            value = s[name]
            # A population's own leaf is unused: each rollout draws its value.
            params[param.field][si] = 0.0 if isinstance(value, Population) \
                else param.encode(value)
        for i, k in enumerate(POPULATED):
            params["user_dist"][si, i], params["user_dist_args"][si, i], \
                params["user_dist_values"][si, i] = population.encode(s[k],
                                                                      *population_range(k))
    labels = {
        "names": [r.scene.name for r in results],
        "task_ids": [r.task_ids for r in results],
        "C_init": np.array([r.C_init for r in results]),
        "C_final": np.array([r.C_final for r in results]),
    }
    return BakedScenes(starts=starts_arr, labels=labels, **out, **params,
                       **_search_fields(results, T))
