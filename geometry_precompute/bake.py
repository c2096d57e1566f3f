"""The bake: precomputed scenes as fixed-shape NumPy arrays (SPEC section 15).

This is the only bridge between the CPU half and the JAX half: ``shacc_jax``
reads these arrays by name and nothing else. S scenes are padded to T tasks
(``max_tasks``, default the largest task count); padded rows have
``task_mask = False``, harmless finite geometry, and can never activate or
weigh in an average on the JAX side.

Fields (float64 here; the JAX side casts to its working precision):

==================  ==========  ===============================================
field               shape       meaning
==================  ==========  ===============================================
task_mask           (S, T)      True for a real task
kind                (S, T)      shape kind: 0 cylinder, 1 disk, 2 cone, 3 box
center_init         (S, T, 3)   initial space's centre (cone: apex), world
quat_init           (S, T, 4)   initial space's rotation (w, x, y, z)
dims_init           (S, T, 3)   initial dims (cylinder/disk r, h, 0; cone L,
                                alpha, 0; box half extents)
center_opt ...      ...         the same for the shrunk (optimised) space
cluster             (S, T)      meta-skill cluster label (0, 1, ... in task
                                order) for tasks in clusters of >= 2, else -1
orient_kind         (S, T)      0 fixed, 1 point-to-axis
orient_quat         (S, T, 4)   fixed orientation; for point-to-axis the
                                orientation used on the axis itself
orient_axis         (S, T, 2)   (x, y) of the vertical axis (point-to-axis)
starts              (S, N, 7)   start poses [x, y, z, qw, qx, qy, qz]
obj_mask            (S, O)      True for a real object (O: most objects)
obj_kind            (S, O)      0 cylinder, 1 box
obj_center          (S, O, 3)   the object body's centre, world
obj_quat            (S, O, 4)   its rotation (w, x, y, z)
obj_size            (S, O, 3)   MuJoCo geom size: cylinder [r, half height, 0],
                                box half extents
dt, v_max,          (S,)        rollout settings, one value per scene, so a
omega_max,                      sweep can vary them without recompiling
activation_tol,
max_steps,
ambiguity_nearest,
collision,                      True for collision = "mjx"
gripper_finger_length,          the ``gripper.*`` settings
gripper_finger_radius,
gripper_opening,
gripper_palm_radius
==================  ==========  ===============================================

The ``optimized`` mode's search (SPEC section 17) builds spaces for any parameter
vector on the accelerator. Every template's space is affine in its shrinkable
parameters q (P = 2 slots: the most any template has), so the bake carries that map:

==================  ==========  ===============================================
q_mask              (S, T, P)   True for a real parameter of a real task
q_min, q_init,      (S, T, P)   its bounds and Shrinking's value (0 where masked)
q_shrunk
center_dq           (S, T, 3, P)  d centre / d q: centre(q) = center_init +
                                center_dq (q - q_init)
dims_dq             (S, T, 3, P)  d dims / d q, the same way
opt_starts          (S, No, 7)  the search's own start poses (``optimize_starts``,
                                ``optimize_seed``; padded to the batch's largest)
opt_start_mask      (S, No)     True for a real search start
optimize_seed,      (S,)        the search's settings; population and
optimize_population,            generations must agree across a batch (they
optimize_generations            are static sizes of its program)
==================  ==========  ===============================================

Metadata for people (names, task ids, C values) rides along in ``meta`` and
is never passed to JAX.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from .errors import InputError
from .precompute import PrecomputeResult
from .shapes import KIND_CODES
from .starts import optimize_start_poses, start_poses
from .templates import TaskSpace, object_body

ARRAY_FIELDS = ("task_mask", "kind", "center_init", "quat_init", "dims_init", "center_opt",
                "quat_opt", "dims_opt", "cluster", "orient_kind", "orient_quat", "orient_axis",
                "starts", "obj_mask", "obj_kind", "obj_center", "obj_quat", "obj_size")
PARAM_FIELDS = ("dt", "v_max", "omega_max", "activation_tol", "max_steps", "ambiguity_nearest",
                "collision", "gripper_finger_length", "gripper_finger_radius", "gripper_opening",
                "gripper_palm_radius")
SEARCH_FIELDS = ("q_mask", "q_min", "q_init", "q_shrunk", "center_dq", "dims_dq", "opt_starts",
                 "opt_start_mask", "optimize_seed", "optimize_population",
                 "optimize_generations")
MAX_PARAMS = 2  # shrinkable parameters of one template, at most (handle_grasp: L, alpha)
GRIPPER_FIELDS = ("gripper_finger_length", "gripper_finger_radius", "gripper_opening",
                  "gripper_palm_radius")
_PAD_DIMS = (0.01, 0.01, 0.01)


@dataclass(frozen=True)
class BakedScenes:
    task_mask: np.ndarray
    kind: np.ndarray
    center_init: np.ndarray
    quat_init: np.ndarray
    dims_init: np.ndarray
    center_opt: np.ndarray
    quat_opt: np.ndarray
    dims_opt: np.ndarray
    cluster: np.ndarray
    orient_kind: np.ndarray
    orient_quat: np.ndarray
    orient_axis: np.ndarray
    starts: np.ndarray
    obj_mask: np.ndarray
    obj_kind: np.ndarray
    obj_center: np.ndarray
    obj_quat: np.ndarray
    obj_size: np.ndarray
    dt: np.ndarray
    v_max: np.ndarray
    omega_max: np.ndarray
    activation_tol: np.ndarray
    max_steps: np.ndarray
    ambiguity_nearest: np.ndarray
    collision: np.ndarray
    gripper_finger_length: np.ndarray
    gripper_finger_radius: np.ndarray
    gripper_opening: np.ndarray
    gripper_palm_radius: np.ndarray
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
    meta: dict = field(default_factory=dict, compare=False)

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
        return {k: getattr(self, k) for k in ARRAY_FIELDS + PARAM_FIELDS + SEARCH_FIELDS}


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
           "opt_start_mask": np.zeros((S, No), bool)}
    for k in ("q_min", "q_init", "q_shrunk"):
        out[k] = np.zeros((S, T, MAX_PARAMS))
    for k in ("optimize_seed", "optimize_population", "optimize_generations"):
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


def bake(results: Sequence[PrecomputeResult], max_tasks: int | None = None,
         starts: np.ndarray | None = None) -> BakedScenes:
    """Bake precomputed scenes; ``starts`` (N, 7) or (S, N, 7) overrides the
    settings' start grid (quaternions are validated and normalised)."""
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
    }
    for which in ("init", "opt"):
        out[f"center_{which}"] = np.zeros((S, T, 3))
        out[f"quat_{which}"] = np.tile([1.0, 0.0, 0.0, 0.0], (S, T, 1))
        out[f"dims_{which}"] = np.tile(_PAD_DIMS, (S, T, 1))
    params = {k: np.zeros(S) for k in PARAM_FIELDS}
    params["max_steps"] = np.zeros(S, np.int32)
    params["ambiguity_nearest"] = np.zeros(S, bool)
    params["collision"] = np.zeros(S, bool)
    O = max(1, max(len(r.scene.objects) for r in results))
    out["obj_mask"] = np.zeros((S, O), bool)
    out["obj_kind"] = np.zeros((S, O), np.int32)
    out["obj_center"] = np.zeros((S, O, 3))
    out["obj_quat"] = np.tile([1.0, 0.0, 0.0, 0.0], (S, O, 1))
    out["obj_size"] = np.tile(_PAD_DIMS, (S, O, 1))
    for si, r in enumerate(results):
        s = r.settings
        for oi, obj in enumerate(r.scene.objects):
            body = object_body(obj)
            out["obj_mask"][si, oi] = True
            out["obj_center"][si, oi] = body.center
            out["obj_quat"][si, oi] = body.quat
            if body.kind == "box":
                out["obj_kind"][si, oi] = 1
                out["obj_size"][si, oi] = body.dims
            else:
                out["obj_size"][si, oi] = (body.dims[0], body.dims[1] / 2, 0.0)
        params["collision"][si] = s["collision"] == "mjx"
        for k in GRIPPER_FIELDS:
            params[k][si] = s[k.replace("gripper_", "gripper.")]
        for ti, space in enumerate(r.spaces):
            out["task_mask"][si, ti] = True
            out["kind"][si, ti] = KIND_CODES[r.shapes_init[ti].kind]
            for which, shape in (("init", r.shapes_init[ti]), ("opt", r.shapes_opt[ti])):
                out[f"center_{which}"][si, ti] = shape.center
                out[f"quat_{which}"][si, ti] = shape.quat
                out[f"dims_{which}"][si, ti] = shape.dims
            o = space.orientation
            out["orient_kind"][si, ti] = 1 if o.kind == "point_to_axis" else 0
            out["orient_quat"][si, ti] = o.quat
            out["orient_axis"][si, ti] = o.axis_xy
        for label, members in enumerate(r.meta_clusters()):
            out["cluster"][si, members] = label
        for k in ("dt", "v_max", "omega_max"):
            params[k][si] = s[k]
        params["activation_tol"][si] = s["activation_tol"]
        params["max_steps"][si] = s["max_steps"]
        params["ambiguity_nearest"][si] = s["ambiguity"] == "nearest"
    meta = {
        "names": [r.scene.name for r in results],
        "task_ids": [r.task_ids for r in results],
        "C_init": np.array([r.C_init for r in results]),
        "C_final": np.array([r.C_final for r in results]),
    }
    return BakedScenes(starts=starts_arr, meta=meta, **out, **params,
                       **_search_fields(results, T))
