"""Which samples of a rollout's straight path can bring the gripper near an object,
in closed form: the path's samples whose gripper (every capsule within
``gripper_reach`` of p) can meet an object's bounding shape. Only those are checked
(``collision``); the rest cannot collide, whatever R is."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from geometry_precompute.schema import BOX

from . import automaton as am
from . import quaternion as quat
from .gripper import capsule_segments, gripper_reach
from .shapes import slab_interval

# Slack of the path cull (m): far above float32 rounding of metre-scale coordinates.
CULL_MARGIN = 1e-3


_TINY = 1e-12


def _dot(u, v):
    """u . v over the last axis (3), written out: a reduction ends an XLA GPU fusion and
    writes its inputs to memory, where these products and sums fuse with what follows."""
    return u[..., 0] * v[..., 0] + u[..., 1] * v[..., 1] + u[..., 2] * v[..., 2]


def _line_sphere(u, c, rho):
    """The t with |t u - c| <= rho (u a unit vector or zero)."""
    inf = jnp.asarray(jnp.inf, rho.dtype)
    b = _dot(u, c)
    uu = _dot(u, u)
    disc = b * b - uu * (_dot(c, c) - rho * rho)
    root = jnp.sqrt(jnp.maximum(disc, 0.0))
    moving = uu > _TINY
    safe = jnp.where(moving, uu, 1.0)
    still = _dot(c, c) <= rho * rho  # u = 0: all t or none
    lo = jnp.where(moving, jnp.where(disc >= 0, (b - root) / safe, inf),
                   jnp.where(still, -inf, inf))
    hi = jnp.where(moving, jnp.where(disc >= 0, (b + root) / safe, -inf),
                   jnp.where(still, inf, -inf))
    return lo, hi


def _line_capsule(u, a, e, rho):
    """The t with dist(t u, segment [a, a + e]) <= rho: the capsule's two end spheres
    and its body (an infinite cylinder cut by the slab of the segment). The union is
    convex, so its t form one interval."""
    inf = jnp.asarray(jnp.inf, rho.dtype)
    lo_a, hi_a = _line_sphere(u, a, rho)
    lo_b, hi_b = _line_sphere(u, a + e, rho)
    length = jnp.sqrt(_dot(e, e))
    axis = e / jnp.maximum(length, _TINY)[..., None]
    ua, aa = _dot(u, axis), _dot(a, axis)
    up, ap = u - ua[..., None] * axis, a - aa[..., None] * axis
    A = _dot(up, up)
    B = _dot(up, ap)
    disc = B * B - A * (_dot(ap, ap) - rho * rho)
    ok = (A > _TINY) & (disc >= 0)  # near-parallel lines: the end spheres cover them
    safe = jnp.where(ok, A, 1.0)
    root = jnp.sqrt(jnp.maximum(disc, 0.0))
    s_lo, s_hi = slab_interval(-aa, ua, 0.0, length)
    lo_c = jnp.maximum(jnp.where(ok, (B - root) / safe, inf), s_lo)
    hi_c = jnp.minimum(jnp.where(ok, (B + root) / safe, -inf), s_hi)
    body = lo_c <= hi_c
    lo = jnp.minimum(jnp.minimum(lo_a, lo_b), jnp.where(body, lo_c, inf))
    hi = jnp.maximum(jnp.maximum(hi_a, hi_b), jnp.where(body, hi_c, -inf))
    return lo, hi


def line_rounded_parallelogram(u, c0, e1, e2, rho):
    """The t with dist(t u, {c0 + x e1 + y e2 : x, y in [0, 1]}) <= rho: the four edge
    capsules and the slab of thickness 2 rho over the parallelogram's face. Convex, so
    one interval (from, to), empty when from > to. (The path cull's set of steps at
    which a capsule axis, moved along u, comes within rho of another.)

    >>> import jax.numpy as jnp
    >>> lo, hi = line_rounded_parallelogram(jnp.array([1., 0, 0]), jnp.array([1., 0, 0]),
    ...     jnp.array([0., 1, 0]), jnp.array([0., 0, 1]), jnp.asarray(0.5))
    >>> round(float(lo), 3), round(float(hi), 3)
    (0.5, 1.5)
    """
    inf = jnp.asarray(jnp.inf, rho.dtype)
    lo, hi = inf, -inf
    for a, e in ((c0, e1), (c0 + e2, e1), (c0, e2), (c0 + e1, e2)):
        l, h = _line_capsule(u, a, e, rho)
        lo, hi = jnp.minimum(lo, l), jnp.maximum(hi, h)
    n = jnp.cross(e1, e2)
    area = jnp.sqrt(_dot(n, n))
    flat = area > 1e-6  # a thinner face lies within 1e-6 m of its edges
    safe = jnp.where(flat, area, 1.0)[..., None]
    n = n / safe
    m1, m2 = jnp.cross(e2, n) / safe, jnp.cross(n, e1) / safe  # dual basis of the face
    f_lo, f_hi = slab_interval(-_dot(c0, n), _dot(u, n), -rho, rho)
    for m in (m1, m2):
        l, h = slab_interval(-_dot(c0, m), _dot(u, m), 0.0, 1.0)
        f_lo, f_hi = jnp.maximum(f_lo, l), jnp.minimum(f_hi, h)
    face = flat & (f_lo <= f_hi)
    return (jnp.minimum(lo, jnp.where(face, f_lo, inf)),
            jnp.maximum(hi, jnp.where(face, f_hi, -inf)))


class Bounds(NamedTuple):
    """One scene's objects as the path cull sees them (O,): each bounding capsule's axis
    (start and extent) and radius, and each bounding sphere (about the centre)."""

    start: Array
    extent: Array
    radius: Array
    sphere: Array


def object_bounds(obj_kind, obj_center, obj_quat, obj_size) -> Bounds:
    """A cylinder's bounding capsule is its own axis with its radius; a box's runs along
    its longest half extent. Computed once per scene, used by every path."""
    mats = jax.vmap(quat.to_matrix)(obj_quat)
    longest = jnp.argmax(obj_size, axis=-1)
    box_axis = jnp.take_along_axis(mats, longest[:, None, None], axis=2)[:, :, 0]
    box_half = jnp.max(obj_size, axis=-1)
    box_radius = jnp.sqrt(jnp.maximum(quat.ordered_sum(obj_size ** 2, -1) - box_half ** 2, 0.0))
    is_box = obj_kind == BOX
    half = jnp.where(is_box[:, None], box_axis * box_half[:, None],
                     mats[:, :, 2] * obj_size[:, 1:2])
    radius = jnp.where(is_box, box_radius, obj_size[:, 0])
    sphere = jnp.where(is_box, quat.norm(obj_size, -1),
                       jnp.hypot(obj_size[:, 0], obj_size[:, 1]))
    return Bounds(obj_center - half, 2.0 * half, radius, sphere)


def path_window(bounds: Bounds, obj_center, obj_mask, gripper: Float[Array, "4"],
                r0: Float[Array, "4"], path: am.Path, turn_from: Array,
                max_steps: Array) -> tuple[Array, Array]:
    """Per object (O,): the first and last sample of one path at which the gripper can
    touch it; empty when first > last. One scene's objects (``object_bounds``), one path.

    Before ``turn_from`` (the first sample at which the meta skill may rotate; inf
    without one) the gripper keeps the start orientation ``r0`` and moves along the
    straight path, so each capsule's axis sweeps a parallelogram and it can reach an
    object only where its axis comes within (capsule radius + the object's bounding
    capsule radius) of the object's bounding axis: one interval of t per (capsule,
    object) pair, in closed form. From ``turn_from`` on the orientation is not known
    beforehand, and the gripper's bounding sphere about p against the object's
    bounding sphere decides. Both are necessary for a penetration, so no sample that
    can collide is left out."""
    dtype = path.length.dtype
    inf = jnp.asarray(jnp.inf, dtype)
    start, extent, radius, sphere = bounds
    g_start, g_extent, g_radius = capsule_segments(path.p0, r0, gripper)
    # Pairs (capsules, objects): t u within rho of the parallelogram of axis offsets.
    c0 = start[None, :, :] - g_start[:, None, :]
    rho = g_radius[:, None] + radius[None, :] + CULL_MARGIN
    lo, hi = line_rounded_parallelogram(jnp.broadcast_to(path.u, c0.shape), c0,
                                        jnp.broadcast_to(extent, c0.shape),
                                        jnp.broadcast_to(-g_extent[:, None, :], c0.shape),
                                        rho)
    lo, hi = jnp.where(obj_mask[None, :], lo, inf), jnp.where(obj_mask[None, :], hi, -inf)
    zero = jnp.zeros((), dtype)
    first = jnp.min(am.first_sample(lo, hi, zero, path, max_steps), axis=0)
    last = jnp.minimum(jnp.max(am.last_sample(lo, hi, path, max_steps), axis=0),
                       turn_from - 1.0)
    first = jnp.where(first <= last, first, inf)
    last = jnp.where(jnp.isfinite(first), last, -inf)
    # From turn_from on: bounding spheres.
    reach = gripper_reach(gripper) + sphere + CULL_MARGIN
    offsets = obj_center - path.p0[None]
    s_lo, s_hi = _line_sphere(jnp.broadcast_to(path.u, offsets.shape), offsets, reach)
    s_lo, s_hi = jnp.where(obj_mask, s_lo, inf), jnp.where(obj_mask, s_hi, -inf)
    kmin = jnp.where(jnp.isfinite(turn_from), turn_from, inf)
    s_first = am.first_sample(s_lo, s_hi, jnp.minimum(kmin, max_steps.astype(dtype) + 1.0), path,
                              max_steps)
    s_first = jnp.where(jnp.isfinite(kmin), s_first, inf)
    s_last = jnp.where(jnp.isfinite(s_first), am.last_sample(s_lo, s_hi, path, max_steps),
                       -inf)
    return jnp.minimum(first, s_first), jnp.maximum(last, s_last)
