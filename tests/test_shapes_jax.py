"""JAX SDFs and projections against trimesh's mesh distances, and their properties."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import trimesh
from jax_layouts import components_first
from scipy.spatial.transform import Rotation

from geometry_precompute.frames import quat_from_matrix
from geometry_precompute.meshes import shape_trimesh
from geometry_precompute.shapes import KIND_CODES, Shape
from shacc_jax import shapes

ROT = tuple(quat_from_matrix(Rotation.from_euler("xyz", [0.4, -0.3, 1.1]).as_matrix()))
CASES = [
    Shape("cylinder", (0.1, -0.2, 0.3), ROT, (0.2, 0.15, 0.0)),
    Shape("disk", (0.0, 0.1, 0.2), ROT, (0.15, 0.04, 0.0)),
    Shape("cone", (0.05, 0.0, 0.1), ROT, (0.3, 0.5236, 0.0)),
    Shape("cone", (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (0.2, 1.2, 0.0)),  # wide cone
    Shape("box", (0.0, 0.3, 0.1), ROT, (0.1, 0.05, 0.2)),
]
IDS = ["cylinder", "disk", "cone", "wide-cone", "box"]


def args(s: Shape):
    return (jnp.int32(KIND_CODES[s.kind]), jnp.asarray(s.center, jnp.float32),
            jnp.asarray(s.quat, jnp.float32), jnp.asarray(s.dims, jnp.float32))


def points_around(s: Shape, n: int, seed: int = 0) -> np.ndarray:
    lo, hi = s.aabb()
    pad = 0.5 * (hi - lo)
    return np.random.default_rng(seed).uniform(lo - pad, hi + pad, size=(n, 3))


sdf_batch = jax.jit(jax.vmap(shapes.sdf, in_axes=(None, None, None, None, 0)))
proj_batch = jax.jit(jax.vmap(shapes.project, in_axes=(None, None, None, None, 0)))
grad_batch = jax.jit(jax.vmap(jax.grad(shapes.sdf, argnums=4), in_axes=(None, None, None, None, 0)))
jac_batch = jax.jit(jax.vmap(jax.jacfwd(shapes.project, argnums=4),
                             in_axes=(None, None, None, None, 0)))


@pytest.mark.parametrize("s", CASES, ids=IDS)
def test_sdf_matches_trimesh(s):
    pts = points_around(s, 3000)
    mesh = shape_trimesh(s, 512)
    expected = -trimesh.proximity.signed_distance(mesh, pts)  # trimesh: positive inside
    got = np.asarray(sdf_batch(*args(s), jnp.asarray(pts, jnp.float32)))
    # The 512-gon deviates from the circle by ~r * 2e-5; float32 adds ~1e-7.
    np.testing.assert_allclose(got, expected, atol=2e-5 + 1e-4 * max(s.dims))


@pytest.mark.parametrize("s", CASES, ids=IDS)
@pytest.mark.parametrize("n", [1, 7, 500])
def test_projection_properties(s, n):
    pts = jnp.asarray(points_around(s, n, seed=n), jnp.float32)
    a = args(s)
    d = np.asarray(sdf_batch(*a, pts))
    q = proj_batch(*a, pts)
    dq = np.asarray(sdf_batch(*a, q))
    gap = np.linalg.norm(np.asarray(pts - q), axis=1)
    out = d > 0
    np.testing.assert_allclose(gap[out], d[out], atol=2e-6)     # |p - proj(p)| = sdf(p)
    np.testing.assert_allclose(dq[out], 0.0, atol=2e-6)          # proj(p) on the surface
    np.testing.assert_allclose(np.asarray(q)[~out], np.asarray(pts)[~out], atol=1e-7)


@pytest.mark.parametrize("s", CASES, ids=IDS)
def test_unit_gradient(s):
    pts = jnp.asarray(points_around(s, 400, seed=3), jnp.float32)
    g = np.asarray(grad_batch(*args(s), pts))
    assert np.all(np.isfinite(g))
    np.testing.assert_allclose(np.linalg.norm(g, axis=1), 1.0, atol=1e-4)


def _special_points(s: Shape) -> np.ndarray:
    """Axis, apex, rims and centre, in world coordinates."""
    a, b, c = s.dims
    if s.kind in ("cylinder", "disk"):
        local = [(0, 0, 0), (0, 0, b / 2), (0, 0, b), (0, 0, -b), (a, 0, b / 2), (0, a, 0)]
    elif s.kind == "cone":
        r = a * np.tan(b)
        local = [(0, 0, 0), (0, 0, -0.1), (0, 0, a), (0, 0, a + 0.1), (r, 0, a), (0, 0, a / 2)]
    else:
        local = [(0, 0, 0), (a, b, c), (a, 0, 0), (2 * a, 2 * b, 2 * c)]
    return np.asarray(s.center) + np.asarray(local, float) @ s.rotation.T


@pytest.mark.parametrize("s", CASES, ids=IDS)
def test_no_nan_at_axis_apex_and_rims(s):
    pts = jnp.asarray(_special_points(s), jnp.float32)
    a = args(s)
    for out in (sdf_batch(*a, pts), proj_batch(*a, pts), grad_batch(*a, pts), jac_batch(*a, pts)):
        assert np.all(np.isfinite(np.asarray(out)))


@pytest.mark.parametrize("s", CASES, ids=IDS)
def test_rigid_motion_invariance(s):
    rng = np.random.default_rng(5)
    R = Rotation.random(rng=rng)
    t = rng.normal(size=3)
    moved = Shape(s.kind, tuple(R.apply(s.center) + t),
                  tuple(quat_from_matrix((R * Rotation.from_matrix(s.rotation)).as_matrix())),
                  s.dims)
    pts = points_around(s, 300, seed=9)
    d0 = np.asarray(sdf_batch(*args(s), jnp.asarray(pts, jnp.float32)))
    d1 = np.asarray(sdf_batch(*args(moved), jnp.asarray(R.apply(pts) + t, jnp.float32)))
    np.testing.assert_allclose(d1, d0, atol=2e-6)


@pytest.mark.parametrize("s", CASES, ids=IDS)
def test_ray_interval_contains_sublevel_set(s):
    """Every point of a ray with sdf <= tau lies inside the closed-form interval."""
    rng = np.random.default_rng(11)
    a = args(s)
    tau = 1e-4
    grow = jnp.float32(tau + 128 * np.finfo(np.float32).eps)
    ts = np.linspace(0.0, 2.0, 4001)
    lo_hi = jax.jit(shapes.ray_interval)
    for _ in range(60):
        o = np.asarray(s.center) + rng.normal(scale=0.4, size=3)
        target = np.asarray(s.center) + rng.normal(scale=0.1, size=3)
        d = (target - o) / np.linalg.norm(target - o)
        lo, hi = (float(v) for v in lo_hi(*a, jnp.asarray(o, jnp.float32),
                                           jnp.asarray(d, jnp.float32), grow))
        pts = jnp.asarray(o[None] + ts[:, None] * d[None], jnp.float32)
        inside = np.asarray(sdf_batch(*a, pts)) <= tau
        assert np.all((ts[inside] >= lo - 1e-6) & (ts[inside] <= hi + 1e-6))


def test_volumes_match_cpu():
    for s in CASES:
        assert float(shapes.volume(*args(s)[::3])) == pytest.approx(s.volume(), rel=1e-5)


def test_component_form_matches_vectorised_form_and_layouts():
    """prepared_sdf (scalar components) equals the vectorised per-kind formulas of
    sdf_and_project_local, per point and vmapped, and on the components_first layout
    with tasks x lanes x samples broadcasting (the layout of the meta-target pass)."""
    columns = zip(*(args(s) for s in CASES), strict=True)
    prepared = shapes.prepare_all(*(jnp.stack(a) for a in columns))
    pts = jnp.asarray(np.concatenate([points_around(s, 200, seed=i) for i, s in
                                      enumerate(CASES)]), jnp.float32)

    def vectorised(sp, p):
        local = jnp.sum(sp.rot.T * (p - sp.center)[None, :], axis=1)
        return shapes.sdf_and_project_local(sp.kind, sp.dims, sp.trig, local)[0]

    per_point = jax.jit(jax.vmap(lambda p: shapes.all_sdf(prepared, p)))(pts)  # (P, T)
    reference = jax.jit(jax.vmap(lambda p: jax.vmap(vectorised, (0, None))(prepared, p)))(pts)
    np.testing.assert_allclose(per_point, reference, atol=2e-6)
    # components_first: tasks (T, 1, 1) against points (3, 1, 2, P/2) (components, a
    # tasks axis of one, two rows of points: ranks spelled out, as the meta pass does).
    c = components_first(prepared)
    c = jax.tree.map(lambda a: a[..., None, None], c)
    grid = pts.T.reshape(3, 1, 2, -1)
    laid_out = shapes.prepared_sdf(c, grid)  # (T, 2, P/2)
    np.testing.assert_allclose(laid_out.reshape(len(CASES), -1), per_point.T, atol=1e-6)


def test_projection_on_components_matches_vectorised_form():
    """project_components (scalar components, the stepped users' move) equals
    prepared_project (the vectorised per-kind closest points of sdf_and_project_local
    mapped back to the world) to float rounding, for points inside, outside and on the
    axis of every kind; and its rotation may be given as rows of entries (the move's,
    made from a quaternion) with the same result."""
    columns = zip(*(args(s) for s in CASES), strict=True)
    prepared = shapes.prepare_all(*(jnp.stack(a) for a in columns))
    pts = np.concatenate([points_around(s, 200, seed=i) for i, s in enumerate(CASES)])
    # Points on each shape's axis (rho = 0), where the azimuth is undefined.
    axis = np.asarray(prepared.center)[:, None, :] + np.linspace(-0.2, 0.2, 9)[None, :, None] \
        * np.asarray(prepared.rot)[:, None, :, 2]
    pts = jnp.asarray(np.concatenate([pts, axis.reshape(-1, 3)]), jnp.float32)

    def components(sp, p, rows=False):
        r = tuple(tuple(sp.rot[i, j] for j in range(3)) for i in range(3)) if rows else sp.rot
        return jnp.stack(shapes.project_components(sp.kind, sp.center, r, sp.dims, sp.trig,
                                                   (p[0], p[1], p[2])))

    def each(fn):
        return jax.jit(jax.vmap(lambda p: jax.vmap(fn, (0, None))(prepared, p)))(pts)

    got = each(components)  # (P, T, 3)
    np.testing.assert_allclose(got, each(shapes.prepared_project), atol=2e-6)
    assert np.isfinite(np.asarray(got)).all()
    np.testing.assert_array_equal(each(lambda sp, p: components(sp, p, rows=True)), got)
