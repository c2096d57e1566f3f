"""Shapes, meshes and clutteredness against exact volumes and Monte Carlo."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from geometry_precompute.clutteredness import clutteredness
from geometry_precompute.frames import frame_from_approach, quat_from_matrix
from geometry_precompute.meshes import shape_manifold, shape_trimesh
from geometry_precompute.settings import DEFAULTS
from geometry_precompute.shapes import Shape

SECTIONS = DEFAULTS["mesh_sections"]
IDENT = (1.0, 0.0, 0.0, 0.0)


def inside(shape: Shape, pts: np.ndarray) -> np.ndarray:
    """Exact point-in-shape test (an independent, obvious reference)."""
    local = (pts - np.asarray(shape.center)) @ shape.rotation
    a, b, c = shape.dims
    rho = np.hypot(local[:, 0], local[:, 1])
    z = local[:, 2]
    if shape.kind in ("cylinder", "disk"):
        return (rho <= a) & (np.abs(z) <= b / 2)
    if shape.kind == "cone":
        return (z >= 0) & (z <= a) & (rho <= z * np.tan(b))
    return np.all(np.abs(local) <= np.array([a, b, c]), axis=1)


def mc_intersection(s1: Shape, s2: Shape, n: int = 400_000, seed: int = 0) -> tuple[float, float]:
    """Monte-Carlo V(s1 ∩ s2) over s1's bounding box: (estimate, standard error)."""
    lo, hi = s1.aabb()
    pts = np.random.default_rng(seed).uniform(lo, hi, size=(n, 3))
    hit = inside(s1, pts) & inside(s2, pts)
    box = float(np.prod(hi - lo))
    p = hit.mean()
    return box * p, box * math.sqrt(p * (1 - p) / n)


shape_strategy = st.one_of(
    st.builds(lambda r, h: Shape("cylinder", (0, 0, 0), IDENT, (r, h, 0)),
              st.floats(0.02, 0.3), st.floats(0.02, 0.4)),
    st.builds(lambda r, h: Shape("disk", (0, 0, 0), IDENT, (r, h, 0)),
              st.floats(0.02, 0.3), st.floats(0.01, 0.05)),
    st.builds(lambda L, a: Shape("cone", (0, 0, 0), IDENT, (L, a, 0)),
              st.floats(0.05, 0.4), st.floats(0.1, 1.2)),
    st.builds(lambda x, y, z: Shape("box", (0, 0, 0), IDENT, (x, y, z)),
              st.floats(0.01, 0.3), st.floats(0.01, 0.3), st.floats(0.01, 0.3)),
)


@given(shape_strategy)
def test_mesh_volume_matches_exact(shape):
    mesh_v = shape_manifold(shape, SECTIONS).volume()
    assert mesh_v == pytest.approx(shape.volume(), rel=0.01)
    tm = shape_trimesh(shape, SECTIONS)
    assert tm.is_watertight and tm.volume == pytest.approx(mesh_v, rel=1e-9)


def test_exact_volumes():
    assert Shape("cylinder", (0, 0, 0), IDENT, (0.2, 0.15, 0)).volume() == pytest.approx(
        math.pi * 0.04 * 0.15)
    cone = Shape("cone", (0, 0, 0), IDENT, (0.3, math.radians(30), 0))
    assert cone.volume() == pytest.approx(math.pi / 3 * (0.3 * math.tan(math.radians(30))) ** 2
                                          * 0.3)
    assert Shape("box", (0, 0, 0), IDENT, (0.1, 0.2, 0.3)).volume() == pytest.approx(0.048)


@pytest.mark.parametrize("d", [0.02, 0.1, 0.2, 0.3, 0.38])
def test_parallel_cylinders_lens(d):
    r, h = 0.2, 0.15
    a = Shape("cylinder", (0, 0, 0), IDENT, (r, h, 0))
    b = Shape("cylinder", (d, 0, 0), IDENT, (r, h, 0))
    lens = 2 * r * r * math.acos(d / (2 * r)) - d / 2 * math.sqrt(4 * r * r - d * d)
    v = (shape_manifold(a, SECTIONS) ^ shape_manifold(b, SECTIONS)).volume()
    assert v == pytest.approx(lens * h, rel=0.01)
    # C of the pair: the one intersection over both volumes.
    assert clutteredness([a, b], SECTIONS) == pytest.approx(lens * h / (2 * a.volume()), rel=0.01)


HALF_ANGLE = math.radians(30)


def _cone(apex, direction, length=0.3, alpha=HALF_ANGLE):
    q = tuple(quat_from_matrix(frame_from_approach(direction)))
    return Shape("cone", tuple(apex), q, (length, alpha, 0.0))


@pytest.mark.parametrize("case", ["cone-cylinder", "cone-cone", "cone-box", "tilted"])
def test_intersections_against_monte_carlo(case):
    if case == "cone-cylinder":
        s1 = _cone((0.0, -0.2, 0.05), (0.0, 1.0, 0.0))
        s2 = Shape("cylinder", (0.0, 0.05, 0.075), IDENT, (0.2, 0.15, 0.0))
    elif case == "cone-cone":
        s1 = _cone((0.0, -0.15, 0.05), (0.0, 1.0, 0.0))
        s2 = _cone((0.0, 0.15, 0.05), (0.3, -1.0, 0.0))
    elif case == "cone-box":
        s1 = _cone((-0.1, 0.0, 0.05), (1.0, 0.2, 0.1))
        s2 = Shape("box", (0.1, 0.0, 0.05), IDENT, (0.1, 0.08, 0.05))
    else:
        q = tuple(quat_from_matrix(Rotation.from_euler("xyz", [0.3, -0.5, 0.7]).as_matrix()))
        s1 = Shape("cylinder", (0.0, 0.0, 0.0), q, (0.15, 0.3, 0.0))
        s2 = Shape("box", (0.05, 0.1, 0.0), IDENT, (0.1, 0.1, 0.1))
    v = (shape_manifold(s1, SECTIONS) ^ shape_manifold(s2, SECTIONS)).volume()
    est, se = mc_intersection(s1, s2)
    assert est > 20 * se  # a real overlap, not a sliver
    assert abs(v - est) <= 4 * se + 0.01 * est


def test_clutteredness_zero_cases():
    one = [Shape("cylinder", (0, 0, 0), IDENT, (0.2, 0.15, 0))]
    assert clutteredness(one) == 0.0
    apart = [Shape("cylinder", (x, 0, 0), IDENT, (0.2, 0.15, 0)) for x in (0.0, 0.5, 1.0)]
    assert clutteredness(apart) == 0.0


def test_pair_counted_once():
    s = Shape("cylinder", (0, 0, 0), IDENT, (0.2, 0.15, 0))
    # Two identical spaces: V / 2V; three: three pairs of V over 3V.
    assert clutteredness([s, s]) == pytest.approx(0.5, rel=1e-6)
    assert clutteredness([s, s, s]) == pytest.approx(1.0, rel=1e-6)


@given(st.floats(-3.0, 3.0), st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1))
def test_clutteredness_invariant_under_rigid_motion(angle, tx, ty, tz):
    shapes = [Shape("cylinder", (0.0, 0.0, 0.075), IDENT, (0.2, 0.15, 0.0)),
              Shape("cylinder", (0.0, 0.25, 0.075), IDENT, (0.2, 0.15, 0.0)),
              _cone((0.1, -0.1, 0.05), (0.0, 1.0, 0.2))]
    rot = Rotation.from_rotvec(np.array([0.3, 0.5, 0.8]) / np.linalg.norm([0.3, 0.5, 0.8])
                               * angle)
    moved = []
    for s in shapes:
        c = rot.apply(s.center) + np.array([tx, ty, tz])
        q = quat_from_matrix((rot * Rotation.from_matrix(s.rotation)).as_matrix())
        moved.append(Shape(s.kind, tuple(c), tuple(q), s.dims))
    # A tilt takes the cylinders off the fast paths, so both sides use the booleans.
    assert clutteredness(moved, method="boolean") == pytest.approx(
        clutteredness(shapes, method="boolean"), rel=1e-6, abs=1e-9)


def test_aabb_contains_mesh():
    q = tuple(quat_from_matrix(Rotation.from_euler("xyz", [0.3, -0.5, 0.7]).as_matrix()))
    for s in [Shape("cylinder", (0.1, 0.2, 0.3), q, (0.15, 0.3, 0.0)), _cone((0, 0, 0), (1, 1, 1)),
              Shape("box", (0, 0, 0), q, (0.1, 0.2, 0.3))]:
        lo, hi = s.aabb()
        v = shape_trimesh(s, 64).vertices
        assert np.all(v >= lo - 1e-3) and np.all(v <= hi + 1e-3)
