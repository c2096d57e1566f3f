"""Orientation spaces (reference/conventions, scenes): the EE orientation a task wants
at an EE position p, as a quaternion.

- fixed (kind 0): always ``quat``;
- point-to-axis (kind 1): frame_from_approach((ax - px, ay - py, 0)), pointing
  at the vertical axis through ``axis``; on the axis itself (horizontal
  distance below 1e-9 m), ``quat`` (the object's yaw direction).
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

from geometry_precompute.schema import POINT_TO_AXIS

from . import quaternion as quat

ON_AXIS = 1e-9


def frame_from_approach(a: Float[Array, "3"]) -> Float[Array, "3 3"]:
    """reference/conventions: z = a/|a|; u = world z, or world x where |z . world z| > 0.99;
    x = normalize(u x z); y = z x x. Columns are the EE axes."""
    z = a / quat.norm(a)
    u = jnp.where(jnp.abs(z[2]) > 0.99, jnp.array([1.0, 0.0, 0.0], a.dtype),
                  jnp.array([0.0, 0.0, 1.0], a.dtype))
    x = jnp.cross(u, z)
    x = x / quat.norm(x)
    y = jnp.cross(z, x)
    return jnp.stack([x, y, z], axis=1)


# frame_from_approach((1, 0, 0)) = [[0, 0, 1], [1, 0, 0], [0, 1, 0]] as a quaternion.
_FORWARD = (0.5, 0.5, 0.5, 0.5)


def horizontal_approach_quat(c: Array, s: Array) -> Float[Array, "4"]:
    """frame_from_approach((c, s, 0)) for a unit (c, s), in closed form: for a
    horizontal approach the frame is the forward frame turned by the yaw psi =
    atan2(s, c) about world z, q = (cos psi/2, 0, 0, sin psi/2) * q_forward. The
    half-angle comes from the normalised half vector (1 + c, s), so no atan2 or
    matrix conversion is needed (tested against frame_from_approach)."""
    hc, hs = 1.0 + c, s
    n = jnp.sqrt(hc * hc + hs * hs)
    back = n < 1e-6  # psi = pi: the half vector vanishes
    ch = jnp.where(back, 0.0, hc / jnp.where(back, 1.0, n))
    sh = jnp.where(back, 1.0, hs / jnp.where(back, 1.0, n))
    yaw = jnp.stack([ch, jnp.zeros_like(ch), jnp.zeros_like(ch), sh])
    return quat.multiply(yaw, jnp.asarray(_FORWARD, c.dtype))


def fixed_direction(q_fixed: Float[Array, "4"]) -> tuple[Float[Array, "2"], Array]:
    """((cos psi, sin psi), True) when ``q_fixed`` is a horizontal approach frame, i.e.
    q = (cos psi/2, 0, 0, sin psi/2) * q_forward up to rounding (side, handle and
    drawer grasps); False otherwise (a top grasp looks down). The test: the x and y
    parts of q * conj(q_forward) vanish to 64 machine epsilons."""
    y = quat.multiply(q_fixed, quat.conjugate(jnp.asarray(_FORWARD, q_fixed.dtype)))
    c, s = y[0], y[3]
    n2 = c * c + s * s
    is_yaw = (jnp.abs(y[1]) + jnp.abs(y[2]) <= 64 * jnp.finfo(y.dtype).eps) & (n2 > 0.5)
    n2 = jnp.where(n2 > 0, n2, 1.0)
    return jnp.stack([(c * c - s * s) / n2, 2.0 * c * s / n2]), is_yaw


def task_direction(kind, fixed_dir: Float[Array, "2"], axis: Float[Array, "2"],
                   p: Float[Array, "3"]) -> tuple[Array, Array]:
    """The horizontal approach direction (cos psi, sin psi) of a task whose
    orientation space is a horizontal approach frame (see :func:`fixed_direction`):
    :func:`task_orientation` is ``horizontal_approach_quat`` of it. Returned as two
    components, not a stacked 2-vector (vmapped, they stay plain arrays)."""
    ux, uy, on_axis = _toward_axis(axis, p)
    pta = (kind == POINT_TO_AXIS) & ~on_axis
    return jnp.where(pta, ux, fixed_dir[0]), jnp.where(pta, uy, fixed_dir[1])


def task_orientation(kind, q_fixed: Float[Array, "4"], axis: Float[Array, "2"],
                     p: Float[Array, "3"]) -> Float[Array, "4"]:
    ux, uy, on_axis = _toward_axis(axis, p)
    return jnp.where((kind == POINT_TO_AXIS) & ~on_axis, horizontal_approach_quat(ux, uy), q_fixed)


def _toward_axis(axis: Float[Array, "2"], p: Float[Array, "3"]) -> tuple[Array, Array, Array]:
    """The unit horizontal direction from p to the vertical axis through ``axis``, and
    whether p is on that axis (then the direction is meaningless)."""
    dx, dy = axis[0] - p[0], axis[1] - p[1]
    r2 = dx * dx + dy * dy
    on_axis = r2 <= ON_AXIS**2
    inv = quat.reciprocal_sqrt(jnp.where(on_axis, 1.0, r2))
    return dx * inv, dy * inv, on_axis
