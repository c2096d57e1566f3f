"""Skill templates: from a task to its position space and orientation space.

the scene format's table, with every default read from the settings and the
task's own ``[tasks.bounds]`` / ``[tasks.fixed]`` taking precedence. A
:class:`TaskSpace` knows its shrinkable parameters (names, min, init) and
builds its :class:`~geometry_precompute.shapes.Shape` for any parameter
vector, so Shrinking never needs to know which template it works on.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from geometry_precompute.errors import InputError
from geometry_precompute.frames import IDENTITY, quat_of_approach, quat_of_rotation, yaw_matrix
from geometry_precompute.scene import TEMPLATE_PARAMS, Scene, SceneObject, Task
from geometry_precompute.settings import Settings
from geometry_precompute.shapes import Shape


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

    @property
    def aim_point(self) -> tuple[float, float, float]:
        """Where a user aiming at the object steers (:func:`aim_point`)."""
        return aim_point(self.template, self.obj, self.fixed)

    def shape(self, q: np.ndarray | None = None) -> Shape:
        q = self.q_init if q is None else np.asarray(q, dtype=np.float64)
        return self.shape_of(tuple(float(v) for v in q))

    def shape_of(self, q: tuple[float, ...]) -> Shape:
        """:meth:`shape` for a tuple of floats (Shrinking's inner loop)."""
        return _build_shape(self.template, self.obj, q, self.fixed, self.pose_quat,
                            self._fixed_center)

    @cached_property
    def _fixed_center(self) -> tuple[float, float, float] | None:
        """The shape's centre where the parameters do not move it (all but the drawer)."""
        if self.template == "drawer_pull":
            return None
        return _build_shape(self.template, self.obj, self.q_init, self.fixed,
                            self.pose_quat).center


def aim_point(template: str, obj: SceneObject, fixed: dict) -> tuple[float, float, float]:
    """Where a user who aims at the object steers for this template (``user_aim =
    "object"``): the side grasp's point on the object's axis at half the space's height,
    the handle grasp point g, the top centre of the object, the centre of the drawer's
    face."""
    x, y, z = obj.base  # the position, but for a mesh whose lowest point is off its origin
    if template == "side_grasp":
        return (x, y, z + fixed["height"] / 2)
    if template == "handle_grasp":
        g, _ = handle_point(obj, fixed["handle_offset"])
        return (float(g[0]), float(g[1]), float(g[2]))
    if template == "top_grasp":
        return (x, y, z + obj.body_height)
    ex, _, ez = obj.box_half_extents
    return (x - np.cos(obj.yaw) * ex, y - np.sin(obj.yaw) * ex, z + ez)


def handle_point(obj: SceneObject, offset: float) -> tuple[np.ndarray, np.ndarray]:
    """The cup handle's grasp point g and direction u (reference/scenes)."""
    u = np.array([np.cos(obj.yaw), np.sin(obj.yaw), 0.0])
    g = np.asarray(obj.position) + (obj.body_radius + offset) * u \
        + np.array([0, 0, obj.body_height / 2])
    return g, u


def _pose_quat(template: str, obj: SceneObject) -> tuple[float, float, float, float]:
    if template == "handle_grasp":
        return quat_of_approach((np.cos(obj.yaw), np.sin(obj.yaw), 0.0))
    if template == "drawer_pull":
        return quat_of_rotation(yaw_matrix(obj.yaw))
    return IDENTITY


def _build_shape(template: str, obj: SceneObject, q, fixed: dict, pose_quat: tuple,
                 center: tuple | None = None) -> Shape:
    """The template's shape for parameters q; ``center``, when given, is its centre
    (which q does not move, but for the drawer)."""
    x, y, z = obj.base  # the position, but for a mesh whose lowest point is off its origin
    if template == "side_grasp":
        h = fixed["height"]
        return Shape("cylinder", center or (x, y, z + h / 2), pose_quat, (float(q[0]), h, 0.0))
    if template == "handle_grasp":
        if center is None:
            center = tuple(handle_point(obj, fixed["handle_offset"])[0])
        return Shape("cone", center, pose_quat, (float(q[0]), float(q[1]), 0.0))
    if template == "top_grasp":
        center = center or (x, y, z + obj.body_height + fixed["offset"])
        return Shape("disk", center, pose_quat, (float(q[0]), fixed["thickness"], 0.0))
    # drawer_pull: the local -x face stays put, the far face moves with the depth.
    ex, _, ez = obj.box_half_extents
    depth = float(q[0])
    c, s = np.cos(obj.yaw), np.sin(obj.yaw)
    lx = -ex - depth / 2
    center = (obj.position[0] + c * lx, obj.position[1] + s * lx, obj.position[2] + ez)
    return Shape("box", center, pose_quat, (depth / 2, fixed["width"] / 2, fixed["height"] / 2))


def _template_values(template: str, obj: SceneObject, s: Settings) -> tuple[dict, dict]:
    """(bounds {name: (min, init)}, fixed {name: value}) from the settings."""
    if template == "side_grasp":
        return ({"radius": (obj.body_radius + s["side_grasp.radius_margin"],
                            s["side_grasp.radius_init"])},
                {"height": obj.body_height + s["side_grasp.height_margin"]})
    if template == "handle_grasp":
        return ({"length": (s["handle_grasp.length_min"], s["handle_grasp.length_init"]),
                 "half_angle": (s["handle_grasp.half_angle_min"],
                                s["handle_grasp.half_angle_init"])},
                {"handle_offset": s["handle_grasp.handle_offset"]})
    if template == "top_grasp":
        return ({"radius": (obj.body_radius + s["top_grasp.radius_margin"],
                            s["top_grasp.radius_init"])},
                {"thickness": s["top_grasp.thickness"], "offset": s["top_grasp.offset"]})
    _, ey, ez = obj.box_half_extents
    return ({"depth": (s["drawer_pull.depth_min"], s["drawer_pull.depth_init"])},
            {"width": 2 * ey, "height": 2 * ez})


def _orientation(template: str, obj: SceneObject, s: Settings) -> OrientationSpace:
    if template == "side_grasp":
        yaw_dir = (np.cos(obj.yaw), np.sin(obj.yaw), 0.0)
        return OrientationSpace("point_to_axis", quat_of_approach(yaw_dir),
                                (obj.position[0], obj.position[1]))
    if template == "handle_grasp":
        _, u = handle_point(obj, s["handle_grasp.handle_offset"])
        return OrientationSpace("fixed", quat_of_approach(-u))
    if template == "top_grasp":
        return OrientationSpace("fixed", quat_of_approach((0.0, 0.0, -1.0)))
    return OrientationSpace("fixed", quat_of_approach(yaw_matrix(obj.yaw)[:, 0]))


def resolve_task(scene: Scene, task: Task, settings: Settings) -> TaskSpace:
    obj = scene.object(task.object)
    bounds, fixed = _template_values(task.template, obj, settings)
    bounds.update(task.bounds)
    fixed.update(task.fixed)
    names = TEMPLATE_PARAMS[task.template]
    for name in names:
        lo, hi = bounds[name]
        if not lo <= hi:
            raise InputError(scene.source, f"tasks[{task.id}].bounds.{name}",
                             f"min {lo:.4g} > init {hi:.4g} for this {obj.kind} (the template "
                             "does not fit its object; set [tasks.bounds] or the settings)")
        if name == "half_angle" and not hi < np.pi / 2:
            raise InputError(scene.source, f"tasks[{task.id}].bounds.{name}",
                             "a cone's half angle must be below pi/2")
    q_min = np.array([bounds[n][0] for n in names])
    q_init = np.array([bounds[n][1] for n in names])
    return TaskSpace(task, obj, task.template, names, q_min, q_init, fixed,
                     _orientation(task.template, obj, settings), _pose_quat(task.template, obj))


def resolve_tasks(scene: Scene, settings: Settings) -> list[TaskSpace]:
    return [resolve_task(scene, t, settings) for t in scene.tasks]
