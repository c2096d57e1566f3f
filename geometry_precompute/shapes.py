"""The four position-space shapes (reference/model), on the CPU.

A :class:`Shape` is a kind, a pose (centre c and quaternion q, mapping the
local frame to the world) and three dimensions whose meaning depends on the
kind:

========  ===================  ===============================================
kind      dims                 local shape
========  ===================  ===============================================
cylinder  (r, h, 0)            |z| <= h/2, x^2 + y^2 <= r^2
disk      (r, h, 0)            the same; h is a fixed small thickness
cone      (L, alpha, 0)        apex at the origin: 0 <= z <= L, rho <= z tan a
box       (ex, ey, ez)         |x| <= ex, |y| <= ey, |z| <= ez (half extents)
========  ===================  ===============================================

The integer codes (:data:`KIND_CODES`) are the schema's, the ones baked for the JAX half.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .schema import KIND_CODES, KINDS  # noqa: F401  (the codes the bake writes)


@dataclass(frozen=True)
class Shape:
    kind: str
    center: tuple[float, float, float]
    quat: tuple[float, float, float, float]
    dims: tuple[float, float, float]

    @cached_property
    def rotation(self) -> np.ndarray:
        return rotation_matrix(self.quat)

    def volume(self) -> float:
        """Exact volume (reference/model)."""
        a, b, c = self.dims
        if self.kind in ("cylinder", "disk"):
            return float(np.pi * a * a * b)
        if self.kind == "cone":
            radius = a * np.tan(b)
            return float(np.pi / 3.0 * radius * radius * a)
        return float(8.0 * a * b * c)

    def _local_box(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """(centre, half extents) of the shape's box in its local frame."""
        a, b, c = self.dims
        if self.kind in ("cylinder", "disk"):
            return (0.0, 0.0, 0.0), (a, a, b / 2)
        if self.kind == "cone":
            radius = a * math.tan(b)
            return (0.0, 0.0, a / 2), (radius, radius, a / 2)
        return (0.0, 0.0, 0.0), (a, b, c)

    def aabb(self) -> tuple[np.ndarray, np.ndarray]:
        """A world axis-aligned box that contains the shape (its local box, rotated).
        Written in floats: the precompute asks for one per space and scene."""
        mid, half = self._local_box()
        lo, hi = [], []
        for row, x in zip(self._rows, self.center, strict=True):
            cx = x + row[0] * mid[0] + row[1] * mid[1] + row[2] * mid[2]
            ex = abs(row[0]) * half[0] + abs(row[1]) * half[1] + abs(row[2]) * half[2]
            lo.append(cx - ex)
            hi.append(cx + ex)
        return np.array(lo), np.array(hi)

    @cached_property
    def _rows(self) -> list[list[float]]:
        return self.rotation.tolist()


# A space counts as upright (axis along world z) or level (axis horizontal) within this.
AXIS_TOL = 1e-12


def is_upright(s: Shape) -> bool:
    """A cylinder or disk whose axis is world z (side and top grasps)."""
    return s.kind in ("cylinder", "disk") and abs(s.rotation[2, 2] - 1.0) <= AXIS_TOL


def is_level(s: Shape) -> bool:
    """A cone whose axis is horizontal (handle grasps)."""
    return s.kind == "cone" and abs(s.rotation[2, 2]) <= AXIS_TOL


def rotation_matrix(q) -> np.ndarray:
    """3x3 matrix of a unit quaternion (w, x, y, z): the textbook formula, written out
    because scipy's Rotation costs ~30 us per call and Shrinking builds many shapes."""
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def aabbs_overlap(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray],
                  pad: float = 0.0) -> bool:
    return bool(np.all(a[0] <= b[1] + pad) and np.all(b[0] <= a[1] + pad))
