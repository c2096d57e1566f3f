"""Triangle meshes of the shapes (reference/model), built with manifold3d.

Round cross-sections are regular polygons of ``sections`` sides whose radius
is scaled so that the polygon's *area* equals the circle's: a polygon
inscribed in the circle would lose (1 - N sin(2 pi / N) / (2 pi)) of the
volume (0.16 % at N = 64, 0.6 % at N = 32); the area-preserving polygon makes
every mesh volume exact up to rounding, and pairwise intersection volumes
stay within 1 % of the exact ones (tests/test_geometry.py).
"""

from __future__ import annotations

import math

import numpy as np

from .shapes import Shape


def area_preserving_scale(sections: int) -> float:
    return math.sqrt(2.0 * math.pi / (sections * math.sin(2.0 * math.pi / sections)))


def _pose_matrix(shape: Shape) -> np.ndarray:
    m = np.zeros((3, 4))
    m[:, :3] = shape.rotation
    m[:, 3] = shape.center
    return m


def shape_manifold(shape: Shape, sections: int):
    """The shape as a ``manifold3d.Manifold`` (imported here, on first use: importing
    the package, as the JAX half does for the bake's schema, must not load it)."""
    import manifold3d as m3  # deferred: 13 ms to import

    a, b, c = shape.dims
    k = area_preserving_scale(sections)
    if shape.kind in ("cylinder", "disk"):
        local = m3.Manifold.cylinder(b, a * k, a * k, sections, True)
    elif shape.kind == "cone":
        local = m3.Manifold.cylinder(a, 0.0, a * math.tan(b) * k, sections, False)
    else:
        local = m3.Manifold.cube((2 * a, 2 * b, 2 * c), True)
    return local.transform(_pose_matrix(shape))


def manifold_to_trimesh(m):
    """The manifold as a ``trimesh.Trimesh`` (trimesh is imported here, on first use:
    the precompute itself needs only manifold3d)."""
    import trimesh  # deferred: 1.4 s to import

    mesh = m.to_mesh64()
    return trimesh.Trimesh(np.asarray(mesh.vert_properties)[:, :3],
                           np.asarray(mesh.tri_verts), process=False)


def shape_trimesh(shape: Shape, sections: int):
    return manifold_to_trimesh(shape_manifold(shape, sections))
