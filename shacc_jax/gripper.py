"""The gripper as three capsules posed by the EE pose (p, R): two fingers parallel to
the approach axis (EE z), at EE y = +-opening/2, from the palm (z = -finger_length) to
the tool centre point p (z = 0), and a palm across them along EE y. Its dimensions
are per-scene settings (``gripper.*``), so a sweep varies them without recompiling."""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

from . import quaternion as quat


def gripper_reach(dims: Float[Array, "4"]) -> Array:
    """Radius of a sphere about p that contains the whole gripper."""
    length, r_f, opening, r_p = dims[0], dims[1], dims[2], dims[3]
    return jnp.sqrt(length ** 2 + (0.5 * opening) ** 2) + jnp.maximum(r_f, r_p)


def capsule_axes(p, q, dims):
    """The gripper's three capsules at poses (p, q) (..., 3), (..., 4): the one
    definition, which every check, the path cull and the pictures use. Each capsule
    is (start, extent, radius): its axis is the segment start + t extent, t in [0, 1],
    in world coordinates, start and extent (x, y, z) tuples. The fingers run from the
    palm (EE z = -finger_length) to the tool centre point, at EE y = +-opening/2; the
    palm runs across them along EE y. Written elementwise (``dims`` (..., 4):
    [finger_length, finger_radius, opening, palm_radius], broadcasts), so that the
    fused pair check computes it without (..., 3) intermediates.

    >>> import jax.numpy as jnp
    >>> (s, e, r), _, (ps, pe, pr) = capsule_axes(jnp.zeros(3), jnp.array([1., 0, 0, 0]),
    ...                                          jnp.array([0.1, 0.01, 0.08, 0.02]))
    >>> [round(float(v), 3) for v in (*s, *e, r)]
    [0.0, 0.04, -0.1, 0.0, 0.0, 0.1, 0.01]
    >>> [round(float(v), 3) for v in (*ps, *pe, pr)]
    [0.0, -0.04, -0.1, 0.0, 0.08, 0.0, 0.02]
    """
    w, x, y, z = (q[..., i] for i in range(4))
    ey = (2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x))  # R[:, 1]
    ez = (2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y))  # R[:, 2]
    length, r_f, opening, r_p = (dims[..., i] for i in range(4))
    palm = tuple(p[..., i] - length * ez[i] for i in range(3))  # the palm's centre
    half = 0.5 * opening
    return [(tuple(palm[i] + half * ey[i] for i in range(3)),
             tuple(length * ez[i] for i in range(3)), r_f),
            (tuple(palm[i] - half * ey[i] for i in range(3)),
             tuple(length * ez[i] for i in range(3)), r_f),
            (tuple(palm[i] - half * ey[i] for i in range(3)),
             tuple(opening * ey[i] for i in range(3)), r_p)]


def capsule_segments(p: Float[Array, "3"], q: Float[Array, "4"],
                     dims: Float[Array, "4"]) -> tuple[Array, Array, Array]:
    """:func:`capsule_axes` of one pose as arrays: starts (3, 3), extents (3, 3) and
    radii (3,), one row per capsule (the fingers, then the palm)."""
    axes = capsule_axes(p, q, dims)
    return (jnp.stack([jnp.stack(start) for start, _, _ in axes]),
            jnp.stack([jnp.stack(extent) for _, extent, _ in axes]),
            jnp.stack([radius for _, _, radius in axes]))


def gripper_geoms(p: Float[Array, "3"], q: Float[Array, "4"],
                  dims: Float[Array, "4"]) -> tuple[Array, Array, Array]:
    """:func:`capsule_axes` in MuJoCo's layout (the pictures, and the tests against
    MuJoCo): centres (3, 3), rotation matrices (3, 3, 3) whose z is each axis, and
    capsule sizes (3, 2) [radius, half length]."""
    starts, extents, radii = capsule_segments(p, q, dims)
    R = quat.to_matrix(q)
    x, y, z = R[:, 0], R[:, 1], R[:, 2]
    palm = jnp.stack([x, -z, y], axis=1)  # local z along the EE's y axis
    half = jnp.stack([0.5 * dims[0], 0.5 * dims[0], 0.5 * dims[2]])
    return (starts + 0.5 * extents, jnp.stack([R, R, palm]),
            jnp.stack([radii, half], axis=1))
