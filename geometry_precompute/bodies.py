"""Object bodies as shapes, and the bad-input rules' rule that they do not interpenetrate.

The rule needs coal's distances, so it is checked where the geometry is built
(``precompute`` calls :func:`check_bodies_apart`), not when a scene file is read:
reading a scene never loads the collision library.
"""

from __future__ import annotations

import numpy as np

from .errors import InputError
from .frames import IDENTITY, quat_of_rotation, yaw_matrix
from .intersect import SpaceSet
from .mesh_objects import placed, solid
from .meshes import shape_trimesh
from .scene import INTERPENETRATION_TOL, Scene, SceneObject
from .shapes import Shape, aabbs_overlap


def object_body(obj: SceneObject) -> Shape:
    """The object's body as a shape (cylinder or box), for collision checks; for a mesh
    object its bounding upright cylinder (its solid is :func:`object_solid`)."""
    if obj.mesh is not None:
        x, y, z = obj.base
        h = obj.body_height
        return Shape("cylinder", (x, y, z + h / 2), IDENTITY, (obj.body_radius, h, 0.0))
    x, y, z = obj.position
    if obj.kind == "box":
        ex, ey, ez = obj.box_half_extents
        return Shape("box", (x, y, z + ez), quat_of_rotation(yaw_matrix(obj.yaw)), (ex, ey, ez))
    r, h = obj.body_radius, obj.body_height
    return Shape("cylinder", (x, y, z + h / 2), IDENTITY, (r, h, 0.0))


def object_solid(obj: SceneObject, sections: int = 32):
    """The object's solid as a trimesh in the world frame: a mesh object's mesh (or its
    convex hull, ``mesh_objects``), a primitive's shape meshed with ``sections``."""
    if obj.mesh is not None:

        return solid(obj.mesh, obj.position, obj.yaw)

    return shape_trimesh(object_body(obj), sections)


def inside_object(obj: SceneObject, p) -> bool:
    """Whether point ``p`` lies inside the object (its mesh for a mesh object)."""
    if obj.mesh is not None:
        return bool(object_solid(obj).contains(np.asarray(p, float)[None, :])[0])
    return inside(object_body(obj), p)


def inside(body: Shape, p) -> bool:
    """Whether point ``p`` lies inside a body shape (cylinder or box)."""
    local = body.rotation.T @ (np.asarray(p) - np.asarray(body.center))
    a, b, c = body.dims
    if body.kind == "box":
        return bool(np.all(np.abs(local) <= np.array([a, b, c])))
    return bool(local[0] ** 2 + local[1] ** 2 <= a * a and abs(local[2]) <= b / 2)


# Two objects of which one is a mesh interpenetrate where their solids share more than
# this volume (manifold3d's exact boolean of the meshes), m^3: a cube of 0.1 mm.
MESH_OVERLAP_TOL = 1e-12


def check_bodies_apart(scene: Scene) -> None:
    """Objects must not interpenetrate (reference/errors): primitives where coal's signed
    distance is below -1e-6 m; a pair with a mesh object where their bounding bodies
    meet (a mesh's bounding upright cylinder) and their solids share more than
    MESH_OVERLAP_TOL (manifold3d's exact boolean)."""

    bodies = SpaceSet([object_body(o) for o in scene.objects])
    solids: dict[int, object] = {}
    for i, j in bodies.candidate_pairs():
        if scene.objects[i].mesh is not None or scene.objects[j].mesh is not None:
            if not bodies.intersects(i, j, 0.0):  # the bounding bodies are apart
                continue
            if not aabbs_overlap(_solid_box(scene.objects[i]), _solid_box(scene.objects[j])):
                continue
            common = float((_manifold(scene.objects, i, solids)
                            ^ _manifold(scene.objects, j, solids)).volume())
            if common > MESH_OVERLAP_TOL:
                raise InputError(scene.source, f"objects[{scene.objects[j].id}].position",
                                 f"interpenetrates object {scene.objects[i].id!r} (their "
                                 f"solids share {common:.3g} m^3)")
            continue
        if bodies.intersects(i, j, INTERPENETRATION_TOL):
            d = bodies.signed_distance(i, j)
            raise InputError(scene.source, f"objects[{scene.objects[j].id}].position",
                             f"interpenetrates object {scene.objects[i].id!r} "
                             f"(signed distance {d:.4g} m < -1e-6 m)")


def _solid_box(obj: SceneObject) -> tuple[np.ndarray, np.ndarray]:
    """A world axis-aligned box around the object's solid."""
    if obj.mesh is None:
        return object_body(obj).aabb()

    v = placed(obj.mesh, obj.position, obj.yaw)
    return v.min(axis=0), v.max(axis=0)


def _manifold(objects, i: int, made: dict):
    """Object i's solid as a manifold3d Manifold (made once per check, kept in ``made``)."""
    if i not in made:
        import manifold3d  # deferred: 18 ms to import

        m = object_solid(objects[i], 64)
        made[i] = manifold3d.Manifold(manifold3d.Mesh(
            vert_properties=np.asarray(m.vertices, np.float32),
            tri_verts=np.asarray(m.faces, np.uint32)))
    return made[i]
