"""The bake's schema: every array that crosses from the CPU half to the JAX half,
its shape and meaning, the integer codes inside them, and the static layout of a
batch. Defined once here; the bake (``baking.py``) fills these fields and the JAX
half (``shacc_jax.types``) builds its pytrees from the same lists. Plain Python:
importing it imports neither JAX nor the mesh libraries.

A batch is three things (STYLE patterns 3 and 4; gymnax keeps its ``EnvParams``
apart from the state for the same reason):

- **Geometry** (:data:`GEOMETRY`): the scenes' arrays, leading axis S. Fixed by the
  precompute: spaces, clusters, orientation spaces, start poses, objects.
- **Params** (:data:`PARAMS`): every rollout setting, one value per scene (S,), as
  each setting's declaration says (``settings.SPECS``: a setting is declared once, its
  bake encoding with it). A leading axis of sweep points, (P, S), evaluates P settings
  over one geometry in one call. Leaves, so new values never recompile.
- **Layout** (:class:`Layout`): hashable and static, computed once in NumPy by the
  bake (``BakedScenes.layout``, :func:`batch_layout`): padded sizes, the modes, which
  meta-target formula the scenes need, whether the program checks collisions and has
  box slots, and the lane scheduler's block sizes. It decides the compiled program, so
  a chunk's mix of scenes changes it only through fields one can read.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import NamedTuple

from .population import ARGS, MAX_VALUES, POPULATED

# Modes and outcomes (reference/model, statistics).
MODES = ("baseline", "shrinking", "shacc")
# The fourth mode: shacc's rules on the spaces the search found; it needs the search
# first (shacc_jax.optimize), so ``shacc_jax.evaluate`` computes MODES only.
OPTIMIZED = "optimized"
# Assistance that infers intent (reference/model, "Intent inference"), computed only when
# asked for: policy blending on the initial spaces, hindsight optimization on them, and
# hindsight optimization with Shrinking's spaces and the meta skill. Always stepped.
INTENT_MODES = ("blend", "ho", "shacc_ho")
# The paper's four, what reproduce and optimize evaluate.
PAPER_MODES = (*MODES, OPTIMIZED)
ALL_MODES = (*PAPER_MODES, *INTENT_MODES)
OUTCOMES = ("success", "wrong", "ambiguous", "timeout", "collision")
SUCCESS, WRONG, AMBIGUOUS, TIMEOUT, COLLISION = range(5)
# The kinds of assistance a step is taken under (the pilot study's, reference/model): no
# orientation target, the meta skill's cluster average, towards the intended task,
# towards another task.
ASSISTANCE = ("none", "scene", "correct", "wrong")
INVALID = -1  # the rollout's intended task is a padded (masked) task

# Shape kinds, for task spaces and for objects alike (objects are cylinders or boxes).
KINDS = ("cylinder", "disk", "cone", "box")
CYLINDER, DISK, CONE, BOX = range(4)
KIND_CODES = {name: i for i, name in enumerate(KINDS)}
# An object's body may also be a mesh's convex hull (obj_hull), with its bounding upright
# cylinder in obj_size: everything that bounds a body treats it as that cylinder.
MESH = 4
# Orientation-space kinds (reference/scenes, templates).
ORIENT_KINDS = ("fixed", "point_to_axis")
FIXED, POINT_TO_AXIS = range(2)

META_FORMULAS = ("yaw", "general", "both")
MAX_PARAMS = 2  # shrinkable parameters of one template, at most (handle_grasp: L, alpha)


class Field(NamedTuple):
    name: str
    shape: tuple  # axis names (S scenes, T tasks, N starts, O objects, ...) or sizes
    dtype: str    # "bool", "int" or "float"
    doc: str


def names(fields) -> tuple[str, ...]:
    return tuple(f.name for f in fields)


def _stepped(field: str) -> bool:
    """Whether the setting whose field this is needs the stepped users' program above
    zero (``settings.Param.stepped``)."""
    from .settings import SPECS  # the schema alone stays light (PARAMS, below)

    return any(s.param is not None and s.param.field == field and s.param.stepped
               for s in SPECS.values())


GEOMETRY = (
    Field("task_mask", ("S", "T"), "bool", "True for a real task"),
    Field("kind", ("S", "T"), "int", "shape kind (KINDS): cylinder, disk, cone"),
    Field("center_init", ("S", "T", 3), "float", "initial space's centre (cone: apex)"),
    Field("quat_init", ("S", "T", 4), "float", "initial space's rotation (w, x, y, z)"),
    Field("dims_init", ("S", "T", 3), "float",
          "cylinder/disk (r, h, 0); cone (L, alpha, 0); box half extents"),
    Field("center_opt", ("S", "T", 3), "float", "the shrunk (optimised) space's centre"),
    Field("quat_opt", ("S", "T", 4), "float", "its rotation"),
    Field("dims_opt", ("S", "T", 3), "float", "its dims"),
    Field("cluster", ("S", "T"), "int",
          "meta-skill cluster label (0, 1, ... in task order) in clusters of >= 2, else -1"),
    Field("yaw_meta", ("S",), "bool", "every cluster member's orientation space is a "
          "horizontal approach frame (the meta target's closed form serves the scene)"),
    Field("orient_kind", ("S", "T"), "int", "orientation kind (ORIENT_KINDS)"),
    Field("orient_quat", ("S", "T", 4), "float",
          "fixed orientation; for point-to-axis the one on the axis itself"),
    Field("orient_axis", ("S", "T", 2), "float", "(x, y) of the vertical axis (point-to-axis)"),
    Field("aim_point", ("S", "T", 3), "float", "where a user aiming at the object steers "
          "(user_aim = object; per template, reference/scenes)"),
    Field("starts", ("S", "N", 7), "float", "start poses [x, y, z, qw, qx, qy, qz]"),
    Field("start_index", ("S", "N"), "int", "each start's index in the scene's whole start "
          "grid (a piece of the grid keeps it): keys the simulated users' random numbers"),
    Field("obj_mask", ("S", "O"), "bool", "True for a real object (checked for collisions)"),
    Field("obj_kind", ("S", "O"), "int", "object body kind (KINDS): cylinder or box; MESH "
          "(4) for a mesh's convex hull"),
    Field("obj_center", ("S", "O", 3), "float", "the object body's centre (a mesh: its "
          "bounding upright cylinder's)"),
    Field("obj_quat", ("S", "O", 4), "float", "its rotation (w, x, y, z)"),
    Field("obj_size", ("S", "O", 3), "float",
          "MuJoCo geom size: cylinder (r, half height, 0), box half extents; a mesh: its "
          "bounding upright cylinder's (r, half height, 0)"),
    Field("obj_hull", ("S", "O", "F", 3, 3), "float", "a mesh object's convex hull: its "
          "triangles' corners in the object's frame (about obj_center), counter-clockwise "
          "seen from outside; padded by repeating a triangle. F is 0 where no scene of the "
          "batch checks collisions with a mesh"),
    Field("obj_hull_plane", ("S", "O", "F", 4), "float", "each hull triangle's outward "
          "unit normal and offset b: the hull is n . x <= b"),
    Field("scene_key", ("S",), "int", "the scene's own number (a digest of its content, "
          "in [0, 2^31)): keys the simulated users' random numbers, whatever the batch"),
)

def _declared_params() -> tuple[Field, ...]:
    """Every rollout setting's field, in the order the settings are declared
    (``settings.SPECS``: each declares its own encoding, ``settings.Param``), then the
    populations' three fields, which encode a distribution for the POPULATED ones."""
    from .settings import SPECS  # the schema alone stays light (PARAMS, below)

    fields = [Field(s.param.field, ("S",), s.param.dtype,
                    s.doc + (f", {s.unit}" if s.unit else "")
                    + ("" if s.param.field == s.name.replace(".", "_")
                       else f" (the setting {s.name})"))
              for s in SPECS.values() if s.param is not None]
    return (*fields,
            Field("user_dist", ("S", len(POPULATED)), "int", "per populated user setting "
                  "(POPULATED) its "
                  "distribution: 0 the plain value, 1 uniform, 2 truncated normal, 3 a "
                  "list of values"),
            Field("user_dist_args", ("S", len(POPULATED), ARGS), "float", "uniform: (low, "
                  "high, low, high); normal: (mean, sd, low, high) with the range it is "
                  "truncated to; values: (count, 0, 0, 0)"),
            Field("user_dist_values", ("S", len(POPULATED), MAX_VALUES), "float", "the "
                  "values of a list (zero after count)"))


# Derived from the settings' declarations when first read (module __getattr__ below), so
# that importing the schema alone (the command line does, for the modes) stays light:
# every rollout setting's field and the populations' (PARAMS); the fields that need the
# stepped users' program above zero (USER: a setting's Param.stepped, and a population;
# all zero and user_aim_object False is the perfect user's closed form); the collision
# gripper's dimensions, in the order Params.gripper stacks them (GRIPPER).
PARAMS: tuple[Field, ...]
USER: tuple[str, ...]
GRIPPER: tuple[str, ...]


def __getattr__(name: str):
    if name not in ("PARAMS", "USER", "GRIPPER"):
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    params = _declared_params()
    derived = {"PARAMS": params,
               "USER": (*(f for f in names(params[:-3]) if _stepped(f)), "user_dist"),
               "GRIPPER": tuple(f for f in names(params) if f.startswith("gripper_"))}
    globals().update(derived)
    return derived[name]

SEARCH = (
    Field("q_mask", ("S", "T", "P"), "bool", "True for a real parameter of a real task"),
    Field("q_min", ("S", "T", "P"), "float", "lower bound (0 where masked)"),
    Field("q_init", ("S", "T", "P"), "float", "initial value (upper bound)"),
    Field("q_shrunk", ("S", "T", "P"), "float", "Shrinking's value"),
    Field("center_dq", ("S", "T", 3, "P"), "float",
          "d centre / d q: centre(q) = center_init + center_dq (q - q_init)"),
    Field("dims_dq", ("S", "T", 3, "P"), "float", "d dims / d q, the same way"),
    Field("opt_starts", ("S", "No", 7), "float", "the search's own start poses"),
    Field("opt_start_mask", ("S", "No"), "bool", "True for a real search start"),
    Field("optimize_seed", ("S",), "int", "the search's seed"),
    Field("optimize_population", ("S",), "int", "CMA-ES population (one value per batch)"),
    Field("optimize_generations", ("S",), "int", "generations (one value per batch)"),
    Field("start_plane", ("S", 5), "float",
          "the start plane: x, y from, y to, z from, z to (validation starts are drawn on it)"),
    Field("optimize_validation_starts", ("S",), "int", "validation starts of the scene"),
    Field("optimize_validation_seed", ("S",), "int", "their seed"),
    Field("optimize_candidates", ("S",), "int",
          "the search's best distinct candidates validated (one value per batch)"),
    Field("optimize_validate", ("S",), "bool",
          "optimize_selection = validation (else the search's best on its own starts)"),
)



def per_task(fields) -> frozenset[str]:
    """Fields whose second axis is the tasks (cut together when a batch is cut to
    fewer tasks)."""
    return frozenset(f.name for f in fields if f.shape[1:2] == ("T",))


def lanes_per_block_default(backend: str, collision_checks: bool = False,
                            stepped_users: bool = False) -> int:
    """Lanes per block of the lane scheduler: large on accelerators (each block is one
    sequence of kernel launches), small on CPU (less spread within a block). With
    collision checks a block holds lanes x samples x capsules x objects pairs, and an
    accelerator's takes half as many lanes (measured on an H100, a quarter, half and
    all of them: 0.63, 0.59, 0.72 s for 10 000 scenes; benchmarks/RESULTS.md); a CPU's
    keeps all of them (fewer, fuller rounds of the exact search). Stepped users
    (``shacc_jax.stepping``): the number of slots the stepping loop keeps busy (measured,
    54 000 rollouts on 2 CPU cores: 8192 slots 1.94 s, 4096 2.12 s; 10.8 M on an H100:
    2^19 slots 1.62 s, 2^18 1.81 s, 2^20 1.73 s).

    >>> lanes_per_block_default("gpu"), lanes_per_block_default("gpu", True)
    (131072, 65536)
    >>> lanes_per_block_default("cpu", True), lanes_per_block_default("cpu", stepped_users=True)
    (256, 8192)
    """
    accelerator = backend in ("gpu", "cuda", "rocm", "tpu")
    if stepped_users:
        return 1 << 19 if accelerator else 1 << 13
    if accelerator:
        return 1 << 16 if collision_checks else 1 << 17
    return 1 << 8


@dataclass(frozen=True)
class Layout:
    """The static side of a batch: everything that decides the compiled program.

    ``n_tasks``, ``n_starts``, ``n_objects``: padded sizes (T, N, O). ``modes``: which
    of MODES and INTENT_MODES, in output order. ``meta_formula``: "yaw" when every scene's cluster
    members have horizontal approach frames (Geometry.yaw_meta), "general" when no
    scene's have, "both" otherwise (each kind of lane gets its own pass).
    ``collision_checks``: whether the program checks gripper collisions (some scene's
    ``collision`` param is on; scenes with it off are not checked). ``stepped_users``:
    whether some scene's simulated user is not the perfect one (a :data:`USER` param
    above zero): the program then steps every rollout (``shacc_jax.stepping``) instead of
    the perfect user's closed form. ``populations``: whether some scene's user settings
    are a population (``user_dist`` above zero): each rollout then draws its own, and the
    rollouts carry the drawn values (``Rollouts.user``). ``switching``: whether some
    scene's user may change its mind (``user_switch`` above zero, or drawn): only then
    does the stepped program find, each step, the closest point of the task first
    headed for. ``joystick``: whether some scene's user has the two-mode joystick
    (``user_input`` modes): only then do the lanes carry a mode and a pause.
    ``swept_checks``: whether some scene checks
    activation along each step's segment (``activation_check`` swept): only then does
    the stepped program trace that check. ``intent_yaw``: whether every real task of
    every scene has a horizontal approach frame (side, handle and drawer grasps): the
    intent modes' posterior-weighted average orientation then takes the meta skill's
    closed form instead of the Markley average's eigenvector (the same rotation; set only
    where the modes include an intent mode). ``box_objects``:
    whether the collision model needs box slots. ``lanes_per_block`` (None: the
    backend's default for the program, :func:`lanes_per_block_default`, which the run
    plan writes in) and ``samples_per_block``: the lane scheduler's block of lanes x
    samples (``shacc_jax.lanes``). ``stepping`` (None: the mode's and the backend's,
    ``shacc_jax.stepping.FULL_CHECK_SHARE`` and ``STEPPING``): the stepped program's
    (share, steps) for every mode, a 1 / share of the slots checked in full per step and
    that many steps per loop iteration; the answers are the same for every value.
    """

    n_tasks: int
    n_starts: int
    n_objects: int
    modes: tuple[str, ...] = MODES
    meta_formula: str = "general"
    collision_checks: bool = False
    box_objects: bool = False
    stepped_users: bool = False
    populations: bool = False
    switching: bool = False
    joystick: bool = False
    swept_checks: bool = False
    intent_yaw: bool = False
    lanes_per_block: int | None = None
    samples_per_block: int = 16
    stepping: tuple[int, int] | None = None

    def __post_init__(self):
        modes = tuple(self.modes)
        object.__setattr__(self, "modes", modes)
        allowed = (*MODES, *INTENT_MODES)
        bad = [m for m in modes if m not in allowed]
        if bad or not modes or len(set(modes)) != len(modes):
            raise ValueError(f"Layout.modes must be distinct names from {allowed}, got "
                             f"{modes}")
        if self.meta_formula not in META_FORMULAS:
            raise ValueError(f"Layout.meta_formula must be one of {META_FORMULAS}, got "
                             f"{self.meta_formula!r}")
        for name in ("n_tasks", "n_starts", "n_objects", "samples_per_block"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"Layout.{name} must be >= 1, got {getattr(self, name)}")
        if self.stepping is not None:
            stepping = tuple(int(v) for v in self.stepping)
            if len(stepping) != 2 or min(stepping) < 1:
                raise ValueError(f"Layout.stepping must be None or (share >= 1, steps >= 1), "
                                 f"got {self.stepping}")
            object.__setattr__(self, "stepping", stepping)
        if self.lanes_per_block is not None and int(self.lanes_per_block) < 1:
            raise ValueError(f"Layout.lanes_per_block must be >= 1 or None, got "
                             f"{self.lanes_per_block}")


def is_horizontal_approach(q) -> bool:
    """Whether orientation ``q`` is a horizontal approach frame: q = (cos psi/2, 0, 0,
    sin psi/2) * q_forward, i.e. the x and y parts of q * conj(q_forward) vanish to 64
    machine epsilons (float64). The JAX half's ``orientation.fixed_direction`` applies
    the same test in its working precision; the layout's decision is this one."""
    w, x, y, z = (float(v) for v in q)
    fw, fx, fy, fz = 0.5, -0.5, -0.5, -0.5  # conj(q_forward), q_forward = (1, 1, 1, 1) / 2
    rx = w * fx + x * fw + y * fz - z * fy
    ry = w * fy - x * fz + y * fw + z * fx
    rw = w * fw - x * fx - y * fy - z * fz
    rz = w * fz + x * fy - y * fx + z * fw
    return bool(abs(rx) + abs(ry) <= 64 * sys.float_info.epsilon and rw * rw + rz * rz > 0.5)


def _every_task_yaw(arrays) -> bool:
    """Whether every real task of the bake has a horizontal approach frame."""
    import numpy as np

    mask, quats = np.asarray(arrays.task_mask), np.asarray(arrays.orient_quat)
    return all(is_horizontal_approach(q) for q in quats[mask])


def batch_layout(arrays, modes=MODES, lanes_per_block: int | None = None,
                 samples_per_block: int = 16) -> Layout:
    """:class:`Layout` of any object with the schema's
    GEOMETRY and PARAMS fields (NumPy arrays; PARAMS may carry a leading axis of sweep
    points)."""
    import numpy as np  # here: the rest of the schema is plain Python

    yaw = np.asarray(arrays.yaw_meta)
    collide = bool(np.asarray(arrays.collision).any())
    boxes = collide and bool((np.asarray(arrays.obj_mask)
                              & (np.asarray(arrays.obj_kind) == BOX)).any())
    stepped = any(bool((np.asarray(getattr(arrays, k)) > 0).any())
                  for k in __getattr__("USER"))
    return Layout(
        n_tasks=arrays.task_mask.shape[-1], n_starts=arrays.starts.shape[-2],
        n_objects=arrays.obj_mask.shape[-1], modes=tuple(modes),
        meta_formula="yaw" if yaw.all() else "general" if not yaw.any() else "both",
        collision_checks=collide, box_objects=boxes, stepped_users=stepped,
        intent_yaw=any(m in INTENT_MODES for m in modes) and _every_task_yaw(arrays),
        populations=bool((np.asarray(arrays.user_dist) > 0).any()),
        joystick=bool(np.asarray(arrays.user_input_modes).any()),
        switching=bool((np.asarray(arrays.user_switch) > 0).any()
                       or (np.asarray(arrays.user_dist)[..., POPULATED.index("user_switch")]
                           > 0).any()),
        swept_checks=bool(np.asarray(arrays.activation_swept).any()),
        lanes_per_block=lanes_per_block,
        samples_per_block=samples_per_block)
