"""Orientation spaces (SPEC sections 2 and 3): the EE orientation a task wants
at an EE position p, as a quaternion.

- fixed (kind 0): always ``quat``;
- point-to-axis (kind 1): frame_from_approach((ax - px, ay - py, 0)), pointing
  at the vertical axis through ``axis``; on the axis itself (horizontal
  distance below 1e-9 m), ``quat`` (the object's yaw direction).
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

from . import quaternion as quat

FIXED, POINT_TO_AXIS = 0, 1
ON_AXIS = 1e-9


def frame_from_approach(a: Float[Array, "3"]) -> Float[Array, "3 3"]:
    """SPEC section 2: z = a/|a|; u = world z, or world x where |z . world z| > 0.99;
    x = normalize(u x z); y = z x x. Columns are the EE axes."""
    z = a / jnp.linalg.norm(a)
    u = jnp.where(jnp.abs(z[2]) > 0.99, jnp.array([1.0, 0.0, 0.0], a.dtype),
                  jnp.array([0.0, 0.0, 1.0], a.dtype))
    x = jnp.cross(u, z)
    x = x / jnp.linalg.norm(x)
    y = jnp.cross(z, x)
    return jnp.stack([x, y, z], axis=1)


def task_orientation(kind, q_fixed: Float[Array, "4"], axis: Float[Array, "2"],
                     p: Float[Array, "3"]) -> Float[Array, "4"]:
    v = jnp.stack([axis[0] - p[0], axis[1] - p[1], jnp.zeros((), p.dtype)])
    on_axis = jnp.sum(v[:2] ** 2) <= ON_AXIS**2
    v = jnp.where(on_axis, jnp.array([1.0, 0.0, 0.0], p.dtype), v)
    q_pta = quat.from_matrix(frame_from_approach(v))
    return jnp.where((kind == POINT_TO_AXIS) & ~on_axis, q_pta, q_fixed)
