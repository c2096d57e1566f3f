"""Skill templates: from a task to its position space and orientation space.

A task names a template (:mod:`geometry_precompute.template_files`: the built-in file
or the scene's own template files); :func:`resolve_task` evaluates the template's
bounds and fixed dimensions for the task's object and settings, the task's own
``[tasks.bounds]`` / ``[tasks.fixed]`` taking precedence. A :class:`TaskSpace` knows
its shrinkable parameters (names, min, init) and builds its
:class:`~geometry_precompute.shapes.Shape` for any parameter vector, so Shrinking never
needs to know which template it works on.

The object's frame: origin at the centre of the object's base (``SceneObject.base``),
x along its yaw, z up. A point (lx, ly, lz) of that frame is, in the world,
``(x + (c lx - s ly), y + (s lx + c ly), z + lz)`` with c, s the cosine and sine of
the yaw: the order of operations the four built-in templates were written in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from .errors import InputError
from .frames import IDENTITY, quat_of_approach, quat_of_rotation, yaw_matrix
from .scene import Scene, SceneObject, Task, large_sizes, ratio_slip
from .settings import Settings
from .shapes import Shape
from .template_files import SHAPE_DIMS, Template, namespace, object_measures


@dataclass(frozen=True)
class OrientationSpace:
    """``fixed``: always ``quat``. ``point_to_axis``: frame_from_approach towards the
    vertical line through ``axis_xy``; on that line itself, ``quat`` (the object's yaw
    direction)."""

    kind: str
    quat: tuple[float, float, float, float]
    axis_xy: tuple[float, float] = (0.0, 0.0)


@dataclass(frozen=True)
class TaskSpace:
    task: Task
    obj: SceneObject
    template: str
    param_names: tuple[str, ...]
    q_min: np.ndarray
    q_init: np.ndarray
    fixed: dict[str, float]
    orientation: OrientationSpace
    pose_quat: tuple[float, float, float, float]  # the space's rotation; fixed by the template
    spec: Template | None = None  # the template's definition (None only for hand-made spaces)
    values: dict[str, float] | None = None  # the object's measures and settings it reads
    aim: tuple[float, float, float] | None = None

    @property
    def aim_point(self) -> tuple[float, float, float]:
        """Where a user aiming at the object steers (``user_aim = "object"``): the
        template's ``aim``, or its centre where it has none. The built-in templates':
        the side grasp's point on the object's axis at half the space's height, the
        handle grasp point g, the top centre of the object, the centre of the drawer's
        face."""
        assert self.aim is not None
        return self.aim

    def shape(self, q: np.ndarray | None = None) -> Shape:
        q = self.q_init if q is None else np.asarray(q, dtype=np.float64)
        return self.shape_of(tuple(float(v) for v in q))

    def shape_of(self, q: tuple[float, ...]) -> Shape:
        """:meth:`shape` for a tuple of floats (Shrinking's inner loop)."""
        assert self.spec is not None
        lx, ly, lz, d0, d1, d2 = self._local(*q)
        center = self._fixed_center or to_world(self.obj, (lx, ly, lz))
        return Shape(self.spec.shape, center, self.pose_quat, (d0, d1, d2))

    def __getstate__(self) -> dict:
        """Pickled without the compiled function of the parameters (a lambda, which
        pickle refuses; it is compiled again where it is next needed)."""
        state = dict(self.__dict__)
        state.pop("_local", None)
        return state

    @cached_property
    def _local(self) -> Any:
        """The template's function of the parameters: centre (object frame), dims."""
        assert self.spec is not None
        return eval(self.spec.shape_code, namespace({**(self.values or {}), **self.fixed}))

    @cached_property
    def _fixed_center(self) -> tuple[float, float, float] | None:
        """The shape's centre where the parameters do not move it (all but the drawer's)."""
        assert self.spec is not None
        if self.spec.center_moves:
            return None
        return to_world(self.obj, self._local(*(float(v) for v in self.q_init))[:3])


def _yaw_cs(obj: SceneObject) -> tuple[float, float]:
    return float(np.cos(obj.yaw)), float(np.sin(obj.yaw))


def to_world(obj: SceneObject, local) -> tuple[float, float, float]:
    """A point of the object's frame in the world (the module's docstring)."""
    lx, ly, lz = local
    x, y, z = obj.base
    c, s = _yaw_cs(obj)
    return (x + (c * lx - s * ly), y + (s * lx + c * ly), z + lz)


def direction_to_world(obj: SceneObject, d) -> tuple[float, float, float]:
    """A direction of the object's frame in the world."""
    dx, dy, dz = d
    c, s = _yaw_cs(obj)
    return (c * dx - s * dy, s * dx + c * dy, dz)


def _pose_quat(t: Template, obj: SceneObject) -> tuple[float, float, float, float]:
    if t.rotation == "world":
        return IDENTITY
    if t.rotation == "object":
        return quat_of_rotation(yaw_matrix(obj.yaw))
    return quat_of_approach(direction_to_world(obj, t.rotation))


def _orientation(t: Template, obj: SceneObject) -> OrientationSpace:
    if t.orientation == "point_to_axis":
        return OrientationSpace("point_to_axis", quat_of_approach(
            direction_to_world(obj, (1.0, 0.0, 0.0))), (obj.position[0], obj.position[1]))
    return OrientationSpace("fixed", quat_of_approach(direction_to_world(obj, t.orientation)))


def _values(t: Template, obj: SceneObject, s: Settings) -> dict[str, float]:
    """The object's measures and the settings the template's expressions read."""
    out: dict[str, float] = object_measures(obj)
    for n in t.settings_read:
        out[n] = float(s[n[len("settings__"):].replace("__", ".")])
    return out


def _check_space(scene: Scene, task: Task, t: Template, space: TaskSpace) -> None:
    """The template's space for this object at both bounds: finite, with positive
    dimensions and a cone's half angle below pi/2 (affine in the parameters, so then
    everywhere between)."""
    names = SHAPE_DIMS[t.shape]
    for q, which in ((space.q_init, "init"), (space.q_min, "min")):
        try:
            local = space._local(*(float(v) for v in q))
        except (ArithmeticError, ValueError) as e:
            raise InputError(scene.source, f"tasks[{task.id}].template",
                             f"{t.name}'s space cannot be evaluated for this object "
                             f"({e})") from None
        dims = local[3:3 + len(names)]
        if not all(math.isfinite(v) for v in local):
            raise InputError(scene.source, f"tasks[{task.id}].template",
                             f"{t.name} gives a space that is not finite for this "
                             f"{space.obj.kind} (at its parameters' {which})")
        for name, v in zip(names, dims, strict=True):
            if not v > 0:
                raise InputError(scene.source, f"tasks[{task.id}].template",
                                 f"{t.name} gives a {t.shape} {name} of {v:.4g} for this "
                                 f"{space.obj.kind} (at its parameters' {which}); it must "
                                 "be > 0")
        if t.shape == "cone" and not dims[1] < math.pi / 2:
            raise InputError(scene.source, f"tasks[{task.id}].template",
                             "a cone's half angle must be below pi/2, got "
                             f"{dims[1]:.4g} (at its parameters' {which})")


def _run(code, ns: dict, scene: Scene, task: Task, fld: str) -> Any:
    """A template's compiled expression evaluated (code checked by
    :mod:`~geometry_precompute.template_files`: arithmetic and a few functions only);
    arithmetic that fails for this object is an InputError naming the task."""
    try:
        return eval(code, ns)
    except (ArithmeticError, ValueError) as e:
        raise InputError(scene.source, f"tasks[{task.id}].template",
                         f"{task.template}'s {fld} cannot be evaluated for this object "
                         f"({e})") from None


def _unit_hint(obj, lo: float, hi: float) -> str:
    """Where a template does not fit its object because the scene was written in
    centimetres or millimetres: the words that say so (empty otherwise). The object's
    own sizes above a metre say it; so does a bound 30 to 3 000 times the other, the
    factor a unit slip makes."""
    big = large_sizes(obj)
    if big:
        name, v = next(iter(big.items()))
        return (f"; the object's {name} is {v:g} m: if the scene is in centimetres, that is "
                f"{v / 100:g} m (scenes are written in metres)")
    return ratio_slip(lo, hi)


def resolve_task(scene: Scene, task: Task, settings: Settings) -> TaskSpace:
    obj = scene.object(task.object)
    t = scene.templates[task.template]
    values = _values(t, obj, settings)
    ns = namespace(values)
    bounds = {p.name: (_run(p.min.tree_code, ns, scene, task, f"params.{p.name}.min"),
                       _run(p.init.tree_code, ns, scene, task, f"params.{p.name}.init"))
              for p in t.params}
    fixed = {n: _run(e.tree_code, ns, scene, task, f"fixed.{n}") for n, e in t.fixed}
    bounds.update(task.bounds)
    fixed.update(task.fixed)
    names = t.param_names
    for p in t.params:
        lo, hi = bounds[p.name]
        where = f"tasks[{task.id}].bounds.{p.name}"
        if not lo <= hi:
            raise InputError(scene.source, where,
                             f"min {lo:.4g} > init {hi:.4g} for this {obj.kind} (the template "
                             "does not fit its object; set [tasks.bounds] or the settings)"
                             + _unit_hint(obj, lo, hi))
        if p.unit == "rad" and not (0 < lo and hi < math.pi / 2):
            raise InputError(scene.source, where, f"an angle's bounds must lie in (0, pi/2), "
                             f"got [{lo:.4g}, {hi:.4g}]")
    for n, v in fixed.items():
        if not (math.isfinite(v) and v >= 0):
            raise InputError(scene.source, f"tasks[{task.id}].fixed.{n}",
                             f"{t.name} gives {v:.4g} for this {obj.kind}; a fixed "
                             "dimension must be finite and >= 0")
    q_min = np.array([bounds[n][0] for n in names])
    q_init = np.array([bounds[n][1] for n in names])
    aim = to_world(obj, _run(t.aim_code, namespace({**values, **fixed}), scene, task, "aim"))
    space = TaskSpace(task, obj, task.template, names, q_min, q_init, fixed,
                      _orientation(t, obj), _pose_quat(t, obj), t, values, aim)
    _check_space(scene, task, t, space)
    return space


def resolve_tasks(scene: Scene, settings: Settings) -> list[TaskSpace]:
    return [resolve_task(scene, t, settings) for t in scene.tasks]
