"""the clusters' intersection test.

Two spaces *intersect* when they overlap by more than 1e-9 m (coal's signed
distance below -1e-9 m; touching does not count). Two upright cylinders or disks
(axis along world z) are answered in closed form: they overlap by min(r1 + r2 - d,
overlap of the z ranges), the exact penetration depth of two parallel vertical
cylinders. Every other pair goes to coal. :class:`SpaceSet` keeps one coal
geometry and transform per space and brings them up to date only when a pair that
needs coal asks (Shrinking changes many spaces that only meet upright cylinders);
every query clears its result first. :meth:`SpaceSet.intersecting_pairs` tests
only the pairs whose bounding boxes overlap.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .shapes import Shape, is_upright

INTERSECT_TOL = 1e-9
# Flips a coal cone (apex at +halfLength) onto ours (apex at the origin, axis +z).
_FLIP_X = np.diag([1.0, -1.0, -1.0])


def _coal():
    """coal, imported on first use: parsing scenes and reading the bake's schema (the
    JAX half) import this package but never need it."""
    import coal  # deferred: 165 ms to import

    return coal


def _coal_geometry(shape: Shape):
    coal = _coal()
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


def _coal_translation(shape: Shape, axis: tuple[float, float, float]) -> np.ndarray:
    x, y, z = shape.center
    if shape.kind == "cone":  # coal's cone is centred half-way along its axis
        h = shape.dims[0] / 2
        return np.array((x + axis[0] * h, y + axis[1] * h, z + axis[2] * h))
    return np.array((x, y, z), dtype=np.float64)


def _set_transform(tf, shape: Shape) -> None:
    rot = shape.rotation
    tf.setRotation(rot @ _FLIP_X if shape.kind == "cone" else rot)
    tf.setTranslation(_coal_translation(shape, tuple(rot[:, 2].tolist())))


def upright_overlap(a: Shape, b: Shape) -> float:
    """Penetration depth of two upright cylinders (negative: apart by at least that)."""
    d = math.hypot(a.center[0] - b.center[0], a.center[1] - b.center[1])
    top = min(a.center[2] + a.dims[1] / 2, b.center[2] + b.dims[1] / 2)
    bottom = max(a.center[2] - a.dims[1] / 2, b.center[2] - b.dims[1] / 2)
    return min(a.dims[0] + b.dims[0] - d, top - bottom)


class SpaceSet:
    """The intersection test over a list of shapes, updatable in place."""

    def __init__(self, shapes: Sequence[Shape]):
        self.shapes = list(shapes)
        self.upright = [is_upright(s) for s in self.shapes]
        self.geoms: list = [None] * len(self.shapes)
        self.tfs: list = [None] * len(self.shapes)
        self._stale = [True] * len(self.shapes)
        self._quat: list = [None] * len(self.shapes)
        self._axis = [tuple(s.rotation[:, 2].tolist()) for s in self.shapes]
        boxes = [s.aabb() for s in self.shapes]
        self._lo = np.array([b[0] for b in boxes]).reshape(-1, 3)
        self._hi = np.array([b[1] for b in boxes]).reshape(-1, 3)
        coal = _coal()
        self._distance = coal.distance
        self._req = coal.DistanceRequest()
        self._req.enable_signed_distance = True
        self._res = coal.DistanceResult()

    def update(self, i: int, shape: Shape) -> None:
        """Space i is now ``shape`` (same kind; Shrinking only ever makes it smaller, so
        the bounding boxes of :meth:`candidate_pairs` stay valid as upper bounds)."""
        assert shape.kind == self.shapes[i].kind
        self.shapes[i] = shape
        self._stale[i] = True

    def _coal(self, i: int):
        if self._stale[i]:
            s = self.shapes[i]
            if self.geoms[i] is None:
                self.geoms[i], self.tfs[i] = _coal_geometry(s), _coal().Transform3s()
                _set_transform(self.tfs[i], s)
                self._quat[i] = s.quat
            else:
                _set_geometry(self.geoms[i], s)
                if s.quat == self._quat[i]:  # Shrinking: the rotation stays
                    self.tfs[i].setTranslation(_coal_translation(s, self._axis[i]))
                else:
                    _set_transform(self.tfs[i], s)
                    self._quat[i] = s.quat
            self._stale[i] = False
        return self.geoms[i], self.tfs[i]

    def candidate_pairs(self) -> list[tuple[int, int]]:
        """Pairs (i < j) whose bounding boxes (of the shapes given at construction)
        overlap, in order: one vectorised test instead of n^2 small ones."""
        ok = np.all((self._lo[:, None, :] <= self._hi[None, :, :])
                    & (self._lo[None, :, :] <= self._hi[:, None, :]), axis=-1)
        i, j = np.nonzero(np.triu(ok, 1))
        return list(zip(i.tolist(), j.tolist(), strict=True))

    def signed_distance(self, i: int, j: int) -> float:
        """coal's signed distance (the test's reference, for every pair kind)."""
        gi, ti = self._coal(i)
        gj, tj = self._coal(j)
        self._res.clear()
        return float(self._distance(gi, ti, gj, tj, self._req, self._res))

    def intersects(self, i: int, j: int, tol: float = INTERSECT_TOL) -> bool:
        if self.upright[i] and self.upright[j]:
            return upright_overlap(self.shapes[i], self.shapes[j]) > tol
        return self.signed_distance(i, j) < -tol

    def intersecting_pairs(self) -> list[tuple[int, int]]:
        return [(i, j) for i, j in self.candidate_pairs() if self.intersects(i, j)]
