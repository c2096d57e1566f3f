"""Exact signed distances, closest points and ray intervals of the four shapes
(reference/model), for one point and one shape; batching is vmap's job.

Kinds: 0 cylinder, 1 disk (a cylinder to the maths), 2 cone, 3 box, with the
dims of ``geometry_precompute.shapes``. The per-kind formulas are all
evaluated and the right one selected with ``where`` (STYLE: one vectorised
block rather than a switch); every formula is NaN-free for any positive dims,
so the unselected branches never poison a gradient.

Cylinders and cones are bodies of revolution: their distance is the 2-D
distance in the meridian half-plane (rho, z) to the rectangle or triangle of
their cross-section, and their closest point maps back along the point's
azimuth. On the axis (rho = 0) the closest point of an outside point is itself
on the axis, so the azimuth never matters.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from geometry_precompute.schema import BOX, CONE, CYLINDER, DISK  # noqa: F401

from . import quaternion as quat


def _safe_norm(v: Array) -> Array:
    """|v| with a zero (not NaN) gradient at v = 0 (the double-where trick)."""
    sq = quat.dot(v, v)
    nz = sq > 0
    return jnp.where(nz, jnp.sqrt(jnp.where(nz, sq, 1.0)), 0.0)


def _cone_angle(alpha: Array) -> Array:
    # Keeps the cone branch finite when it is evaluated on another kind's dims.
    return jnp.clip(alpha, 1e-3, 1.5)


def _cylinder_local(p: Array, r: Array, h: Array) -> tuple[Array, Array]:
    rho = _safe_norm(p[:2])
    dr = rho - r
    dz = jnp.abs(p[2]) - h / 2
    out = _safe_norm(jnp.stack([jnp.maximum(dr, 0.0), jnp.maximum(dz, 0.0)]))
    sdf = out + jnp.minimum(jnp.maximum(dr, dz), 0.0)
    scale = jnp.where(rho > r, r / jnp.where(rho > 0, rho, 1.0), 1.0)
    proj = jnp.stack([p[0] * scale, p[1] * scale, jnp.clip(p[2], -h / 2, h / 2)])
    return sdf, proj


def _cone_local(p: Array, length: Array, trig: Array) -> tuple[Array, Array]:
    tan_a, cos_a, sin_a = trig[0], trig[1], trig[2]
    radius = length * tan_a
    rho = _safe_norm(p[:2])
    z = p[2]
    # Lateral segment (0, 0) -> (radius, length) of the meridian triangle.
    seg2 = radius * radius + length * length
    t = jnp.clip((rho * radius + z * length) / seg2, 0.0, 1.0)
    lat = jnp.stack([t * radius, t * length])
    # Base segment (0, length) -> (radius, length).
    base = jnp.stack([jnp.clip(rho, 0.0, radius), length])
    q2 = jnp.stack([rho, z])
    d_lat = _safe_norm(q2 - lat)
    d_base = _safe_norm(q2 - base)
    inside = (z <= length) & (rho * cos_a <= z * sin_a)
    dist = jnp.minimum(d_lat, d_base)
    sdf = jnp.where(inside, -dist, dist)
    near = jnp.where(d_lat <= d_base, lat, base)
    dir_xy = jnp.where(rho > 0, p[:2] / jnp.where(rho > 0, rho, 1.0), jnp.zeros(2, p.dtype))
    proj_out = jnp.concatenate([dir_xy * near[0], near[1:]])
    return sdf, jnp.where(inside, p, proj_out)


def _box_local(p: Array, e: Array) -> tuple[Array, Array]:
    q = jnp.abs(p) - e
    sdf = _safe_norm(jnp.maximum(q, 0.0)) + jnp.minimum(jnp.max(q), 0.0)
    return sdf, jnp.clip(p, -e, e)


class Prepared(NamedTuple):
    """A posed shape with what every query needs computed once: the rotation matrix
    and, for cones, tan, cos and sin of the half angle (three transcendentals that a
    query would otherwise repeat for every point)."""

    kind: Int[Array, ""]
    center: Float[Array, "3"]
    rot: Float[Array, "3 3"]
    dims: Float[Array, "3"]
    trig: Float[Array, "3"]


def prepare(kind, center, q, dims) -> Prepared:
    alpha = _cone_angle(dims[1])
    trig = jnp.stack([jnp.tan(alpha), jnp.cos(alpha), jnp.sin(alpha)])
    return Prepared(kind, center, quat.to_matrix(q), dims, trig)


def sdf_and_project_local(kind: Int[Array, ""], dims: Float[Array, "3"], trig: Array,
                          p: Float[Array, "3"]) -> tuple[Array, Array]:
    s_cyl, p_cyl = _cylinder_local(p, dims[0], dims[1])
    s_cone, p_cone = _cone_local(p, dims[0], trig)
    s_box, p_box = _box_local(p, dims)
    is_cone = kind == CONE
    is_box = kind == BOX
    sdf = jnp.where(is_box, s_box, jnp.where(is_cone, s_cone, s_cyl))
    proj = jnp.where(is_box, p_box, jnp.where(is_cone, p_cone, p_cyl))
    return sdf, proj


def _sqrt0(x: Array) -> Array:
    """sqrt(x) for x >= 0 with a zero (not NaN) gradient at 0."""
    pos = x > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def prepared_sdf(s: Prepared, p: Float[Array, "3"]) -> Float[Array, ""]:
    """The exact signed distance, written on scalar components (no stacked 2- or
    3-vectors): under vmap over tasks and points every intermediate is then a plain
    (points, tasks) array, and on shapes laid out components first (rot (3, 3,
    *batch), ...) any batch shape broadcasts (``rot[i, j]``, ``p[i]`` are whole
    arrays). The vectorised form of :func:`sdf_and_project_local` ran 8 times slower
    on CPU (71 against 8.5 ns per distance, 10 tasks x 1 M points);
    tests/test_shapes_jax.py checks both agree."""
    rot, c, dims = s.rot, s.center, s.dims
    dx, dy, dz = p[0] - c[0], p[1] - c[1], p[2] - c[2]
    # Local coordinates R^T (p - c).
    lx = rot[0, 0] * dx + rot[1, 0] * dy + rot[2, 0] * dz
    ly = rot[0, 1] * dx + rot[1, 1] * dy + rot[2, 1] * dz
    lz = rot[0, 2] * dx + rot[1, 2] * dy + rot[2, 2] * dz
    rho = _sqrt0(lx * lx + ly * ly)
    # Cylinder and disk: the rectangle [0, r] x [-h/2, h/2] of the meridian plane.
    dr, dh = rho - dims[0], jnp.abs(lz) - dims[1] / 2
    er, eh = jnp.maximum(dr, 0.0), jnp.maximum(dh, 0.0)
    s_cyl = _sqrt0(er * er + eh * eh) + jnp.minimum(jnp.maximum(dr, dh), 0.0)
    # Cone: the triangle (0, 0), (R, L), (0, L); its boundary is the lateral segment
    # from the apex and the base segment.
    length, tan_a, cos_a, sin_a = dims[0], s.trig[0], s.trig[1], s.trig[2]
    radius = length * tan_a
    t = jnp.clip((rho * radius + lz * length) / (radius * radius + length * length), 0.0, 1.0)
    ax, az = rho - t * radius, lz - t * length
    bx, bz = rho - jnp.clip(rho, 0.0, radius), lz - length
    dist = _sqrt0(jnp.minimum(ax * ax + az * az, bx * bx + bz * bz))
    inside = (lz <= length) & (rho * cos_a <= lz * sin_a)
    s_cone = jnp.where(inside, -dist, dist)
    # Box: half extents dims.
    qx, qy, qz = jnp.abs(lx) - dims[0], jnp.abs(ly) - dims[1], jnp.abs(lz) - dims[2]
    ox, oy, oz = jnp.maximum(qx, 0.0), jnp.maximum(qy, 0.0), jnp.maximum(qz, 0.0)
    s_box = (_sqrt0(ox * ox + oy * oy + oz * oz)
             + jnp.minimum(jnp.maximum(jnp.maximum(qx, qy), qz), 0.0))
    return jnp.where(s.kind == BOX, s_box, jnp.where(s.kind == CONE, s_cone, s_cyl))


def prepared_contains(s: Prepared, p: Float[Array, "3"]) -> Bool[Array, ""]:
    """Whether ``p`` lies in the (closed) shape: the sign of :func:`prepared_sdf`
    without the distance, a few comparisons (the optimized mode's estimate of C tests
    512 points against every space of every candidate; written with the distances, its
    program took minutes to compile on a GPU)."""
    rot, c, dims = s.rot, s.center, s.dims
    dx, dy, dz = p[0] - c[0], p[1] - c[1], p[2] - c[2]
    lx = rot[0, 0] * dx + rot[1, 0] * dy + rot[2, 0] * dz
    ly = rot[0, 1] * dx + rot[1, 1] * dy + rot[2, 1] * dz
    lz = rot[0, 2] * dx + rot[1, 2] * dy + rot[2, 2] * dz
    rho2 = lx * lx + ly * ly
    cyl = (rho2 <= dims[0] * dims[0]) & (jnp.abs(lz) <= dims[1] / 2)
    r_cone = lz * s.trig[0]
    cone = (lz >= 0.0) & (lz <= dims[0]) & (rho2 <= r_cone * r_cone)
    box = (jnp.abs(lx) <= dims[0]) & (jnp.abs(ly) <= dims[1]) & (jnp.abs(lz) <= dims[2])
    return jnp.where(s.kind == BOX, box, jnp.where(s.kind == CONE, cone, cyl))


def prepared_project(s: Prepared, p: Float[Array, "3"]) -> Float[Array, "3"]:
    """The closest point of the shape to ``p`` (``p`` itself inside): the perfect
    user's aim, whose recorded answers this form keeps bit for bit
    (tests/test_reference_answers.py); the stepped users' move uses
    :func:`project_components`."""
    local = sdf_and_project_local(s.kind, s.dims, s.trig, quat.matvec(s.rot.T, p - s.center))[1]
    return s.center + quat.matvec(s.rot, local)


def project_components(kind: Array, c: Array, rot: Any, dims: Array, trig: Array,
                       p: tuple[Array, Array, Array]) -> tuple[Array, Array, Array]:
    """:func:`prepared_project` on scalar components, like :func:`prepared_sdf`, of the
    fields of a ``Prepared`` (equal to it up to float rounding): the point and the
    closest point as three arrays each;
    ``rot`` may be rows of separate entries (``rot[i][j]``). Vmapped over lanes every
    intermediate is a plain row of the batch; the stacked form
    (:func:`sdf_and_project_local`) became 3-vector products and reductions over a
    minor axis of three, and a stacked result makes XLA's CPU backend compute the
    whole projection once per component. tests/test_shapes_jax.py checks both
    agree."""
    dx, dy, dz = p[0] - c[0], p[1] - c[1], p[2] - c[2]
    lx = rot[0][0] * dx + rot[1][0] * dy + rot[2][0] * dz
    ly = rot[0][1] * dx + rot[1][1] * dy + rot[2][1] * dz
    lz = rot[0][2] * dx + rot[1][2] * dy + rot[2][2] * dz
    rho = _sqrt0(lx * lx + ly * ly)
    on_axis = rho > 0
    safe_rho = jnp.where(on_axis, rho, 1.0)
    # Cylinder and disk: onto the rectangle [0, r] x [-h/2, h/2] of the meridian plane.
    r, half = dims[0], dims[1] / 2
    scale = jnp.where(rho > r, r / safe_rho, 1.0)
    cyl = (lx * scale, ly * scale, jnp.clip(lz, -half, half))
    # Cone: the nearer of the lateral segment from the apex and the base segment.
    length, tan_a, cos_a, sin_a = dims[0], trig[0], trig[1], trig[2]
    radius = length * tan_a
    t = jnp.clip((rho * radius + lz * length) / (radius * radius + length * length), 0.0, 1.0)
    lat_r, lat_z = t * radius, t * length
    base_r = jnp.clip(rho, 0.0, radius)
    d_lat = _sqrt0((rho - lat_r) * (rho - lat_r) + (lz - lat_z) * (lz - lat_z))
    d_base = _sqrt0((rho - base_r) * (rho - base_r) + (lz - length) * (lz - length))
    lateral = d_lat <= d_base
    near_r = jnp.where(lateral, lat_r, base_r)
    near_z = jnp.where(lateral, lat_z, length)
    inside = (lz <= length) & (rho * cos_a <= lz * sin_a)
    ux, uy = jnp.where(on_axis, lx / safe_rho, 0.0), jnp.where(on_axis, ly / safe_rho, 0.0)
    cone = (jnp.where(inside, lx, ux * near_r), jnp.where(inside, ly, uy * near_r),
            jnp.where(inside, lz, near_z))
    box = (jnp.clip(lx, -dims[0], dims[0]), jnp.clip(ly, -dims[1], dims[1]),
           jnp.clip(lz, -dims[2], dims[2]))
    is_box, is_cone = kind == BOX, kind == CONE
    x, y, z = (jnp.where(is_box, b, jnp.where(is_cone, k, a))
               for a, k, b in zip(cyl, cone, box, strict=True))
    return (c[0] + rot[0][0] * x + rot[0][1] * y + rot[0][2] * z,
            c[1] + rot[1][0] * x + rot[1][1] * y + rot[1][2] * z,
            c[2] + rot[2][0] * x + rot[2][1] * y + rot[2][2] * z)


def sdf(kind, center, q, dims, p: Float[Array, "3"]) -> Float[Array, ""]:
    """Exact Euclidean signed distance (negative inside) of a posed shape."""
    return prepared_sdf(prepare(kind, center, q, dims), p)


def project(kind, center, q, dims, p: Float[Array, "3"]) -> Float[Array, "3"]:
    """Closest point of the (solid) shape to ``p``; ``p`` itself when inside."""
    return prepared_project(prepare(kind, center, q, dims), p)


# --------------------------------------------------------------------------------------
# Ray intervals: a superset of {t : sdf(o + t d) <= tau} for a unit direction d.
#
# The shape inflated by tau (a Minkowski sum with a ball) is contained in the shape
# with every face moved out by tau (for the cone: apex moved back by tau / sin(alpha)
# along the axis, base moved out by tau). Those sharp shapes are intersections of
# slabs and quadrics, whose ray intervals are closed-form. ``slack`` widens them a
# little more so that rounding in the quadratics never loses a point (the Automaton
# verifies every candidate with the exact SDF, so a superset is all that is needed).
# --------------------------------------------------------------------------------------


def slab_interval(o: Array, d: Array, lo, hi) -> tuple[Array, Array]:
    """The t with lo <= o + t d <= hi, as (from, to), elementwise; empty (from > to)
    when d is parallel to the slab (|d| < 1e-12) and o lies outside it, everything when
    inside. The ray intervals of the shapes and the gripper's path cull use it."""
    big = jnp.asarray(jnp.inf, o.dtype)
    par = jnp.abs(d) < 1e-12
    ds = jnp.where(par, 1.0, d)
    t1, t2 = (lo - o) / ds, (hi - o) / ds
    inside = (o >= lo) & (o <= hi)
    a = jnp.where(par, jnp.where(inside, -big, big), jnp.minimum(t1, t2))
    b = jnp.where(par, jnp.where(inside, big, -big), jnp.maximum(t1, t2))
    return a, b


def _quadratic_ge0(A: Array, B: Array, C: Array) -> tuple[Array, Array, Array, Array]:
    """{t : A t^2 + 2 B t + C >= 0} as the union of (-inf, r1] and [r2, inf) when A > 0,
    or the interval [r1, r2] when A < 0; returned as (lo1, hi1, lo2, hi2) of two
    intervals (the second empty where unused)."""
    inf = jnp.asarray(jnp.inf, A.dtype)
    disc = B * B - A * C
    sq = jnp.sqrt(jnp.maximum(disc, 0.0))
    # Stable roots: q = -(B + sign(B) sqrt(disc)), roots q / A and C / q.
    qv = -(B + jnp.where(B >= 0, 1.0, -1.0) * sq)
    qs = jnp.where(qv == 0, 1.0, qv)
    As = jnp.where(A == 0, 1.0, A)
    r_a = jnp.where(qv == 0, 0.0, qv / As)
    r_b = jnp.where(qv == 0, 0.0, C / qs)
    r1, r2 = jnp.minimum(r_a, r_b), jnp.maximum(r_a, r_b)
    lin = jnp.abs(A) < 1e-9
    # Linear case 2 B t + C >= 0.
    Bs = jnp.where(B == 0, 1.0, B)
    root = -C / (2 * Bs)
    lin_lo = jnp.where(B == 0, jnp.where(C >= 0, -inf, inf), jnp.where(B > 0, root, -inf))
    lin_hi = jnp.where(B == 0, jnp.where(C >= 0, inf, -inf), jnp.where(B > 0, inf, root))
    pos = A > 0
    has_roots = disc >= 0
    lo1 = jnp.where(lin, lin_lo, jnp.where(pos, -inf, jnp.where(has_roots, r1, inf)))
    hi1 = jnp.where(lin, lin_hi, jnp.where(pos, jnp.where(has_roots, r1, inf),
                                           jnp.where(has_roots, r2, -inf)))
    lo2 = jnp.where(lin | ~pos, inf, jnp.where(has_roots, r2, inf))
    hi2 = jnp.where(lin | ~pos, -inf, inf)
    return lo1, hi1, lo2, hi2


def _cap(a1, b1, a2, b2):
    return jnp.maximum(a1, a2), jnp.minimum(b1, b2)


def _hull_of_two(a1, b1, a2, b2):
    """Convex hull of two intervals, either possibly empty (lo > hi)."""
    e1, e2 = a1 > b1, a2 > b2
    lo = jnp.where(e1, a2, jnp.where(e2, a1, jnp.minimum(a1, a2)))
    hi = jnp.where(e1, b2, jnp.where(e2, b1, jnp.maximum(b1, b2)))
    return lo, hi


def _ray_cylinder(o, d, r, h, grow):
    R = r + grow
    A = d[0] ** 2 + d[1] ** 2
    B = o[0] * d[0] + o[1] * d[1]
    C = o[0] ** 2 + o[1] ** 2 - R * R
    # Inside the infinite cylinder: -(A t^2 + 2 B t + C) >= 0.
    lo1, hi1, lo2, hi2 = _quadratic_ge0(-A, -B, -C)
    a, b = _hull_of_two(lo1, hi1, lo2, hi2)
    za, zb = slab_interval(o[2], d[2], -h / 2 - grow, h / 2 + grow)
    return _cap(a, b, za, zb)


def _ray_cone(o, d, length, trig, grow):
    z0 = -grow / trig[2]
    oz = o[2] - z0
    k2 = trig[0] ** 2
    A = k2 * d[2] ** 2 - d[0] ** 2 - d[1] ** 2
    B = k2 * oz * d[2] - o[0] * d[0] - o[1] * d[1]
    C = k2 * oz * oz - o[0] ** 2 - o[1] ** 2
    lo1, hi1, lo2, hi2 = _quadratic_ge0(A, B, C)
    # Keep the upper nappe (z >= z0) and the base slab; hull of what is left.
    za, zb = slab_interval(o[2], d[2], z0, length + grow)
    a1, b1 = _cap(lo1, hi1, za, zb)
    a2, b2 = _cap(lo2, hi2, za, zb)
    return _hull_of_two(a1, b1, a2, b2)


def _ray_box(o, d, e, grow):
    a, b = slab_interval(o, d, -e - grow, e + grow)
    return jnp.max(a), jnp.min(b)


def ray_interval(kind, center, q, dims, origin: Float[Array, "3"], direction: Float[Array, "3"],
                 grow: Float[Array, ""]) -> tuple[Array, Array]:
    """(lo, hi) containing every t with sdf(origin + t direction) <= ``grow``-ish: the
    exact tau-sublevel set lies inside it whenever ``grow`` >= tau + rounding slack.
    Empty when lo > hi."""
    return prepared_ray_interval(prepare(kind, center, q, dims), origin, direction, grow)


def prepared_ray_interval(s: Prepared, origin: Float[Array, "3"], direction: Float[Array, "3"],
                          grow: Float[Array, ""]) -> tuple[Array, Array]:
    kind, dims = s.kind, s.dims
    o = quat.matvec(s.rot.T, origin - s.center)
    d = quat.matvec(s.rot.T, direction)
    # Re-centre the ray at its point closest to the local origin: the quadratics'
    # coefficients then scale with the ray's distance from the shape, not from the
    # start, and their cancellation error shrinks accordingly (a float32 ray through
    # a cone's apex 0.8 m away lost its whole interval without this).
    t0 = -quat.dot(o, d)
    o = o + t0 * d
    a_c, b_c = _ray_cylinder(o, d, dims[0], dims[1], grow)
    a_k, b_k = _ray_cone(o, d, dims[0], s.trig, grow)
    a_b, b_b = _ray_box(o, d, dims, grow)
    is_cone, is_box = kind == CONE, kind == BOX
    lo = jnp.where(is_box, a_b, jnp.where(is_cone, a_k, a_c))
    hi = jnp.where(is_box, b_b, jnp.where(is_cone, b_k, b_c))
    return lo + t0, hi + t0


def volume(kind, dims: Float[Array, "3"]) -> Float[Array, ""]:
    cyl = jnp.pi * dims[0] ** 2 * dims[1]
    cone = jnp.pi / 3.0 * (dims[0] * jnp.tan(_cone_angle(dims[1]))) ** 2 * dims[0]
    box = 8.0 * dims[0] * dims[1] * dims[2]
    return jnp.where(kind == BOX, box, jnp.where(kind == CONE, cone, cyl))


def prepare_all(kind, center, q, dims) -> Prepared:
    """:func:`prepare` over a leading task axis."""
    return jax.vmap(prepare)(kind, center, q, dims)


all_sdf = jax.vmap(prepared_sdf, in_axes=(0, None))
all_contains = jax.vmap(prepared_contains, in_axes=(0, None))
all_ray_intervals = jax.vmap(prepared_ray_interval, in_axes=(0, None, None, None))
