"""SPEC section 6's intersection test, through coal.

Two spaces *intersect* when coal's signed distance between them is below
-1e-9 m (touching does not count). :class:`SpaceSet` keeps one coal geometry
and one transform per space and updates them in place when a space's
parameters change, so Shrinking allocates nothing per iteration; every query
clears its result first. Pairs whose bounding boxes are disjoint are answered
without a call to coal.
"""

from __future__ import annotations

from collections.abc import Sequence

import coal
import numpy as np

from .errors import InputError
from .scene import INTERPENETRATION_TOL, Scene
from .shapes import Shape, aabbs_overlap

INTERSECT_TOL = 1e-9
# Flips a coal cone (apex at +halfLength) onto ours (apex at the origin, axis +z).
_FLIP_X = np.diag([1.0, -1.0, -1.0])


def _coal_geometry(shape: Shape):
    a, b, c = shape.dims
    if shape.kind in ("cylinder", "disk"):
        return coal.Cylinder(a, b)
    if shape.kind == "cone":
        return coal.Cone(a * np.tan(b), a)
    return coal.Box(2 * a, 2 * b, 2 * c)


def _set_geometry(geom, shape: Shape) -> None:
    a, b, c = shape.dims
    if shape.kind in ("cylinder", "disk"):
        geom.radius, geom.halfLength = a, b / 2
    elif shape.kind == "cone":
        geom.radius, geom.halfLength = a * np.tan(b), a / 2
    else:
        geom.halfSide = np.array([a, b, c])
    geom.computeLocalAABB()


def _set_transform(tf: coal.Transform3s, shape: Shape) -> None:
    rot = shape.rotation
    center = np.asarray(shape.center, dtype=np.float64)
    if shape.kind == "cone":
        center = center + rot[:, 2] * (shape.dims[0] / 2)
        rot = rot @ _FLIP_X
    tf.setRotation(rot)
    tf.setTranslation(center)


class SpaceSet:
    """Coal geometries of a list of shapes, updatable in place."""

    def __init__(self, shapes: Sequence[Shape]):
        self.shapes = list(shapes)
        self.geoms = [_coal_geometry(s) for s in self.shapes]
        self.tfs = [coal.Transform3s() for _ in self.shapes]
        for tf, s in zip(self.tfs, self.shapes, strict=True):
            _set_transform(tf, s)
        self.boxes = [s.aabb() for s in self.shapes]
        self._lo = np.array([b[0] for b in self.boxes]).reshape(-1, 3)
        self._hi = np.array([b[1] for b in self.boxes]).reshape(-1, 3)
        self._req = coal.DistanceRequest()
        self._req.enable_signed_distance = True
        self._res = coal.DistanceResult()

    def update(self, i: int, shape: Shape) -> None:
        assert shape.kind == self.shapes[i].kind
        self.shapes[i] = shape
        _set_geometry(self.geoms[i], shape)
        _set_transform(self.tfs[i], shape)
        self.boxes[i] = shape.aabb()
        self._lo[i], self._hi[i] = self.boxes[i]

    def candidate_pairs(self) -> list[tuple[int, int]]:
        """Pairs (i < j) whose bounding boxes overlap, in order: one vectorised test
        instead of n^2 small ones."""
        ok = np.all((self._lo[:, None, :] <= self._hi[None, :, :])
                    & (self._lo[None, :, :] <= self._hi[:, None, :]), axis=-1)
        i, j = np.nonzero(np.triu(ok, 1))
        return list(zip(i.tolist(), j.tolist(), strict=True))

    def signed_distance(self, i: int, j: int) -> float:
        self._res.clear()
        return float(coal.distance(self.geoms[i], self.tfs[i], self.geoms[j], self.tfs[j],
                                   self._req, self._res))

    def intersects(self, i: int, j: int, tol: float = INTERSECT_TOL) -> bool:
        if not aabbs_overlap(self.boxes[i], self.boxes[j]):
            return False
        return self.signed_distance(i, j) < -tol


def check_bodies_apart(scene: Scene) -> None:
    """SPEC section 13: objects must not interpenetrate (coal distance below -1e-6 m)."""
    from .templates import object_body

    bodies = SpaceSet([object_body(o) for o in scene.objects])
    n = len(scene.objects)
    for i in range(n):
        for j in range(i + 1, n):
            if bodies.intersects(i, j, INTERPENETRATION_TOL):
                d = bodies.signed_distance(i, j)
                raise InputError(scene.source, f"objects[{scene.objects[j].id}].position",
                                 f"interpenetrates object {scene.objects[i].id!r} "
                                 f"(signed distance {d:.4g} m < -1e-6 m)")
