"""The user's command model: what a simulated user commands at each step.

The perfect user moves in a straight line to the closest point of its task's space
(``automaton``'s closed form). An imperfect one, stepped (reference/model, "Simulated
users"):

- ``user_tremor`` A at ``user_tremor_hz`` f: the gripper is at p_k = q_k + A sin(2 pi f
  k dt + phi) e, q_k the commanded position (q_0 the start), e a unit axis uniform on
  the sphere and phi uniform in [0, 2 pi), both drawn once per rollout;
- each step the user looks at the gripper: d = c(p_k) - p_k, c the closest point of the
  task's space (``user_aim`` "space") or the task's aim point (``Geometry.aim_point``,
  "object"); with probability ``user_lag`` (never the first step) the step repeats
  the previous step's displacement, else it is min(v_max dt, |d|) along d's direction
  turned by an angle |N(0, user_noise^2)| about an axis uniform on the circle across
  it (no step when |d| = 0); q_{k+1} = q_k + step.

A lane whose user is perfect (:func:`is_perfect`) takes the closed form's sample
positions, so it meets the same activation as the closed form. The random numbers are
the rollout's stream (``streams``).
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from . import automaton as am
from . import quaternion as quat
from . import shapes
from .rollout_state import Lane, Move, State
from .streams import step_draws_of
from .trig import sincos
from .types import Params
from .vec3 import V3, length, xyz


def is_perfect(params: Params) -> Bool[Array, "..."]:
    """Where the user is the perfect one: every user parameter zero, aiming at the
    space."""
    return ((params.user_noise <= 0) & (params.user_lag <= 0) & (params.user_tremor <= 0)
            & ~params.user_aim_object & ~params.activation_swept)


def turn_across(u: Float[Array, "3"], angle: Array, axis_angle: Array) -> Float[Array, "3"]:
    """The unit vector u turned by ``angle`` about the axis a = cos(psi) e1 + sin(psi) e2
    across it, psi = ``axis_angle``; (e1, e2, u) right-handed, e1 from the world x
    axis (the y axis where u is within 25 degrees of x). Rodrigues' formula with a
    perpendicular to u: u cos(angle) + (a x u) sin(angle).

    >>> import jax.numpy as jnp
    >>> v = turn_across(jnp.array([0., 0, 1]), jnp.pi / 2, 0.0)
    >>> [round(float(x), 6) + 0.0 for x in v]
    [0.0, -1.0, 0.0]
    """
    return jnp.stack(_turn_across(u[0], u[1], u[2], sincos(angle), sincos(axis_angle)))


def _turn_across(ux, uy, uz, angle_sc, axis_sc) -> tuple[Array, Array, Array]:
    """:func:`turn_across` on scalar components (vmapped over lanes, every intermediate
    a plain row of the batch, no 3-vector products), given (sin, cos) of the angle and
    of the axis' angle."""
    big = jnp.abs(ux) > 0.9
    hu = jnp.where(big, uy, ux)  # <h, u>
    e1x = jnp.where(big, 0.0, 1.0) - hu * ux
    e1y = jnp.where(big, 1.0, 0.0) - hu * uy
    e1z = -hu * uz
    n = quat.sqrt_divisor(e1x * e1x + e1y * e1y + e1z * e1z)  # >= 0.43 here
    e1x, e1y, e1z = e1x / n, e1y / n, e1z / n
    e2x, e2y, e2z = uy * e1z - uz * e1y, uz * e1x - ux * e1z, ux * e1y - uy * e1x
    # a x u = cos(psi) (e1 x u) + sin(psi) (e2 x u) = -cos(psi) e2 + sin(psi) e1
    (sa, ca), (sp, cp) = angle_sc, axis_sc
    return (ca * ux + sa * (sp * e1x - cp * e2x), ca * uy + sa * (sp * e1y - cp * e2y),
            ca * uz + sa * (sp * e1z - cp * e2z))


def straight(lane: Lane, step_length: Array) -> am.Path:
    """The perfect user's straight path (``automaton.straight_path``'s numbers)."""
    steps = lane.x.max_steps.astype(lane.length.dtype)
    landing = jnp.minimum(jnp.ceil(lane.length / step_length), steps + 1.0)
    return am.Path(lane.p0, lane.c0, lane.u, lane.length, landing, step_length)


def wave(lane: Lane, k: Array) -> Array:
    """A sin(2 pi f k dt + phi), the tremor's displacement along its axis at step k. The
    phase is reduced to whole cycles first (f dt k less its nearest integer), so a
    long rollout's argument stays within a few radians (:func:`trig.sincos`)."""
    x = lane.x
    cycles = x.user_tremor_hz * x.dt * k
    sin, _ = sincos(2.0 * jnp.pi * (cycles - jnp.round(cycles)) + lane.once.tremor_phase)
    return x.user_tremor * sin


def shake(lane: Lane, k: Array) -> Array:
    return wave(lane, k) * lane.once.tremor_axis


class Aim(NamedTuple):
    """What a step's move reads more than once, computed once (:func:`move`): the
    closest point of the task's space to the gripper, (sin, cos) of the noise angle and
    of its axis' angle, the lag's uniform number, the tremor's displacement after the
    step."""

    closest: V3
    angle: tuple[Array, Array]
    axis: tuple[Array, Array]
    lag: Array
    wave: Array


def aim(lane: Lane, s: State) -> Aim:
    """The first half of a step (one lane): the closest point and the step's draws."""
    x, dtype = lane.x, s.k.dtype
    kind, center, orientation, dims, trig = lane.own
    rot = quat.matrix_entries(orientation)
    closest = shapes.project_components(kind, center, rot, dims, trig, s.p)
    draw = step_draws_of(lane.step_key, s.k.astype(jnp.int32), dtype)
    return Aim(closest, sincos(x.user_noise * draw.noise), sincos(draw.axis_angle), draw.lag,
               wave(lane, s.k + 1.0))


def move(lane: Lane, s: State, seen: Aim) -> Move:
    """One step of the user, without any check (one lane), on components."""
    x, dtype = lane.x, s.k.dtype
    step_length = am.rollout_numbers(x, dtype)["step_length"]
    c = xyz(lambda i: jnp.where(x.user_aim_object, lane.aim[i], seen.closest[i]))
    d = xyz(lambda i: c[i] - s.p[i])
    norm = length(d)
    moving = norm > 0
    u = xyz(lambda i: d[i] / jnp.where(moving, norm, 1.0))
    turned = _turn_across(u[0], u[1], u[2], seen.angle, seen.axis)
    size = jnp.minimum(step_length, norm)
    lagging = (s.k > 0) & (seen.lag < x.user_lag)
    delta = xyz(lambda i: jnp.where(lagging, s.last[i],
                                    jnp.where(moving, size * turned[i], 0.0)))
    k = s.k + 1.0
    q = xyz(lambda i: s.q[i] + delta[i])
    # A perfect user's lane takes the closed form's samples (the same points).
    sample = am.sample(straight(lane, step_length), k)
    tremor = xyz(lambda i: seen.wave * lane.once.tremor_axis[i])
    p = xyz(lambda i: jnp.where(lane.perfect, sample[i], q[i] + tremor[i]))
    travelled = jnp.where(lane.perfect, jnp.minimum(k * step_length, lane.length),
                          s.travelled + length(delta))
    gap = xyz(lambda i: p[i] - s.p[i])
    return Move(k, q, p, delta, travelled, s.moved + length(gap))
