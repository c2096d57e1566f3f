"""Object bodies as shapes, and the bad-input rules' rule that they do not interpenetrate.

The rule needs coal's distances, so it is checked where the geometry is built
(``precompute`` calls :func:`check_bodies_apart`), not when a scene file is read:
reading a scene never loads the collision library.
"""

from __future__ import annotations

import numpy as np

from .errors import InputError
from .frames import IDENTITY, quat_of_rotation, yaw_matrix
from .scene import INTERPENETRATION_TOL, Scene, SceneObject
from .shapes import Shape


def object_body(obj: SceneObject) -> Shape:
    """The object's body as a shape (cylinder or box), for collision checks."""
    x, y, z = obj.position
    if obj.kind == "box":
        ex, ey, ez = obj.box_half_extents
        return Shape("box", (x, y, z + ez), quat_of_rotation(yaw_matrix(obj.yaw)), (ex, ey, ez))
    r, h = obj.body_radius, obj.body_height
    return Shape("cylinder", (x, y, z + h / 2), IDENTITY, (r, h, 0.0))


def inside(body: Shape, p) -> bool:
    """Whether point ``p`` lies inside a body shape (cylinder or box)."""
    local = body.rotation.T @ (np.asarray(p) - np.asarray(body.center))
    a, b, c = body.dims
    if body.kind == "box":
        return bool(np.all(np.abs(local) <= np.array([a, b, c])))
    return bool(local[0] ** 2 + local[1] ** 2 <= a * a and abs(local[2]) <= b / 2)


def check_bodies_apart(scene: Scene) -> None:
    """Objects must not interpenetrate (coal distance below -1e-6 m; reference/errors)."""
    from .intersect import SpaceSet

    bodies = SpaceSet([object_body(o) for o in scene.objects])
    for i, j in bodies.candidate_pairs():
        if bodies.intersects(i, j, INTERPENETRATION_TOL):
            d = bodies.signed_distance(i, j)
            raise InputError(scene.source, f"objects[{scene.objects[j].id}].position",
                             f"interpenetrates object {scene.objects[i].id!r} "
                             f"(signed distance {d:.4g} m < -1e-6 m)")
