"""Gripper-object collisions (SPEC sections 9, 12b), exact, on the accelerator.

The gripper is three capsules posed by the EE pose (p, R): two fingers parallel to
the approach axis (EE z), at EE y = +-opening/2, from the palm (z = -finger_length)
to the tool centre point p (z = 0), and a palm across them along EE y. Its
dimensions are per-scene settings (``gripper.*``), so a sweep varies them without
recompiling. The objects are the scene's cylinders and boxes, posed and sized as in
the exported MJCF.

A capsule penetrates a convex body by more than eps exactly when its axis segment
comes within (radius - eps) of the body, so the check is a segment-to-solid distance:
the distance to a cylinder or box is convex along the segment and a golden-section
search finds its minimum to 1e-7 m. Every (capsule, object) pair of a pose is one
array operation. This replaced MJX's collision pipeline, whose capsule-cylinder
routine (a few gradient steps on the SDFs) reported distances up to 8 mm too large
near contact and cost 250-330x a rollout (benchmarks/RESULTS.md). CPU MuJoCo's
``mj_geomDistance`` on the same geoms is the reference in the tests.

The table is not an obstacle: start poses a few centimetres above it in random
orientations would otherwise collide before moving (docs/DECISIONS.md).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from geometry_precompute.schema import BOX

from . import automaton as am
from . import quaternion as quat

PENETRATION_EPS = 1e-4  # m: a penetration deeper than this is a collision


def gripper_geoms(p: Float[Array, "3"], q: Float[Array, "4"],
                  dims: Float[Array, "4"]) -> tuple[Array, Array, Array]:
    """Centres (3, 3), rotation matrices (3, 3, 3) and MuJoCo capsule sizes (3, 2)
    [radius, half length] of the fingers and the palm. ``dims`` is
    [finger_length, finger_radius, opening, palm_radius]."""
    length, r_f, opening, r_p = dims[0], dims[1], dims[2], dims[3]
    R = quat.to_matrix(q)
    x, y, z = R[:, 0], R[:, 1], R[:, 2]
    centres = jnp.stack([p + 0.5 * opening * y - 0.5 * length * z,
                         p - 0.5 * opening * y - 0.5 * length * z,
                         p - length * z])
    palm = jnp.stack([x, -z, y], axis=1)  # local z along the EE's y axis
    mats = jnp.stack([R, R, palm])
    sizes = jnp.stack([jnp.stack([r_f, 0.5 * length]), jnp.stack([r_f, 0.5 * length]),
                       jnp.stack([r_p, 0.5 * opening])])
    return centres, mats, sizes


def gripper_reach(dims: Float[Array, "4"]) -> Array:
    """Radius of a sphere about p that contains the whole gripper."""
    length, r_f, opening, r_p = dims[0], dims[1], dims[2], dims[3]
    return jnp.sqrt(length ** 2 + (0.5 * opening) ** 2) + jnp.maximum(r_f, r_p)


# Golden-section iterations of the segment distance: the bracket ends at 0.618^30 of the
# segment (1e-7 m for a 0.1 m palm), far below PENETRATION_EPS.
GOLDEN_ITERATIONS = 30
_INV_PHI = 0.6180339887498949


def scene_objects(obj_kind, obj_center, obj_quat, obj_size, obj_mask):
    """One scene's objects for :func:`deepest`: kinds (O,), centres (O, 3), rotation
    matrices (O, 3, 3), sizes (O, 3) (a cylinder's [radius, half height, -], a box's
    half extents) and the mask (O,)."""
    return obj_kind, obj_center, jax.vmap(quat.to_matrix)(obj_quat), obj_size, obj_mask


def _point_distance(x, kind, size):
    """Euclidean distance from points x (..., 3), in an object's frame, to the solid
    cylinder or box (0 inside)."""
    radial = jnp.sqrt(x[..., 0] ** 2 + x[..., 1] ** 2)
    dr = jnp.maximum(radial - size[..., 0], 0.0)
    dz = jnp.maximum(jnp.abs(x[..., 2]) - size[..., 1], 0.0)
    out = jnp.maximum(jnp.abs(x) - size, 0.0)
    return jnp.where(kind == BOX, jnp.sqrt(jnp.sum(out * out, axis=-1)),
                     jnp.sqrt(dr * dr + dz * dz))


def segment_distance(a, d, kind, size):
    """Distance from segments a + t d, t in [0, 1] (..., 3, object frame), to solid
    cylinders or boxes: golden-section search over t. The distance to a convex body is
    convex along a segment, so the search brackets the minimum; the result is within
    |d| 0.618^GOLDEN_ITERATIONS above the exact distance, never below it."""
    def f(t):
        return _point_distance(a + t[..., None] * d, kind, size)

    zero = jnp.zeros(a.shape[:-1], a.dtype)
    one = jnp.ones_like(zero)
    lo, hi = zero, one
    x1, x2 = hi - _INV_PHI, lo + _INV_PHI
    f1, f2 = f(x1), f(x2)

    def shrink(_, state):
        lo, hi, x1, x2, f1, f2 = state
        left = f1 <= f2  # the minimum lies in [lo, x2]
        lo, hi = jnp.where(left, lo, x1), jnp.where(left, x2, hi)
        new = jnp.where(left, hi - _INV_PHI * (hi - lo), lo + _INV_PHI * (hi - lo))
        f_new = f(new)
        x1, x2 = jnp.where(left, new, x2), jnp.where(left, x1, new)
        f1, f2 = jnp.where(left, f_new, f2), jnp.where(left, f1, f_new)
        return lo, hi, x1, x2, f1, f2

    *_, f1, f2 = jax.lax.fori_loop(0, GOLDEN_ITERATIONS, shrink, (lo, hi, x1, x2, f1, f2))
    return jnp.minimum(jnp.minimum(f1, f2), jnp.minimum(f(zero), f(one)))


def deepest(objects, p: Float[Array, "3"], q: Float[Array, "4"],
            dims: Float[Array, "4"]) -> Array:
    """Smallest (capsule axis to object distance - capsule radius) over the gripper's
    capsules and the scene's objects (``scene_objects``' output), at the EE pose (p, q).
    Where a capsule and an object are apart this is their distance, as CPU MuJoCo's
    ``mj_geomDistance`` reports it; where they overlap it is at most minus the depth
    of the overlap's smallest separating move short of the capsule radius, and it is
    below -eps exactly when MuJoCo's penetration depth exceeds eps (a capsule overlaps
    a convex body by more than eps iff its axis comes within radius - eps of it)."""
    kind, centre, mat, size, mask = objects
    g_pos, g_mat, g_size = gripper_geoms(p, q, dims)
    axis = g_mat[:, :, 2] * g_size[:, 1:2]  # (3, 3): half the capsule's axis
    a = g_pos - axis
    # Into each object's frame: (capsules, objects, 3).
    a_loc = jnp.einsum("oji,coj->coi", mat, a[:, None, :] - centre[None, :, :])
    d_loc = jnp.einsum("oji,cj->coi", mat, 2.0 * axis)
    dist = segment_distance(a_loc, d_loc, kind[None, :], size[None, :, :])
    gap = dist - g_size[:, 0:1]
    return jnp.min(jnp.where(mask[None, :], gap, jnp.inf))


def penetrates(objects, p, q, dims) -> Bool[Array, ""]:
    return deepest(objects, p, q, dims) < -PENETRATION_EPS


def window_start(obj_kind, obj_center, obj_size, obj_mask, gripper: Float[Array, "4"],
                 path: am.Path, max_steps: Array) -> Array:
    """First sample at which the gripper's bounding sphere (about p) reaches an object's
    bounding sphere; inf if none. A penetration needs that, so the samples before it
    are skipped without loss. One scene's objects, one path."""
    size = obj_size
    r_obj = jnp.where(obj_kind == BOX, jnp.linalg.norm(size, axis=-1),
                      jnp.hypot(size[:, 0], size[:, 1]))
    reach = gripper_reach(gripper) + r_obj + 1e-3
    rel = obj_center - path.p0
    b = rel @ path.u
    disc = b * b - (jnp.sum(rel * rel, axis=-1) - reach * reach)
    root = jnp.sqrt(jnp.maximum(disc, 0.0))
    inf = jnp.asarray(jnp.inf, b.dtype)
    ok = obj_mask & (disc >= 0)
    lo, hi = jnp.where(ok, b - root, inf), jnp.where(ok, b + root, -inf)
    return jnp.min(am.first_sample(lo, hi, jnp.zeros((), b.dtype), path, max_steps))
