"""The user's command model: what a simulated user commands at each step.

The perfect user moves in a straight line to the closest point of its task's space
(``automaton``'s closed form). An imperfect one is stepped (reference/model, "Simulated
users"); one step, every parameter on:

1. the gripper is at p_k = q_k + A sin(2 pi f k dt + phi) e (``user_tremor`` A at
   ``user_tremor_hz`` f; e uniform on the sphere and phi in [0, 2 pi), drawn once);
   q_k is the commanded position, q_0 the start;
2. the target: the task first headed for (a change of mind, drawn once with
   probability ``user_switch``: another task of the scene, uniformly) until the
   distance from p_k to its space has fallen to (1 - ``user_switch_at``) of its value
   at the start, then the rollout's own task;
3. the command d = c(p_k) - p_k, c the closest point of the target's space
   (``user_aim`` "space") or its aim point ("object"); no step where |d| = 0;
4. u, d's direction, turned by w_k's part across it: by the angle |w_k x u| about
   w_k's part across u (a wandering hand: w_0 ~ N(0, ``user_noise``^2 I), w_{k+1} = a
   w_k + sqrt(1 - a^2) ``user_noise`` xi_k, a = exp(-dt / ``user_noise_tau``), a = 0
   for tau 0: white noise);
5. with ``user_input`` "modes" (a two-mode joystick), the command |d| u is split into
   its horizontal and vertical parts; the first step takes the mode of the longer;
   the user switches when the current mode's part is shorter than half the other's,
   which costs ``user_mode_switch_s`` without motion; it moves along the current part;
6. the step: min(v_max dt, the length of what is commanded) along it; q_{k+1} = q_k +
   step.

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
    """Where the user is the perfect one: every user parameter at its default (no
    noise, tremor or change of mind, a 3-D input, aiming at the space, steps checked
    where they land)."""
    return ((params.user_noise <= 0) & (params.user_tremor <= 0) & (params.user_switch <= 0)
            & ~params.user_input_modes & ~params.user_aim_object & ~params.activation_swept)


def turn_by(u: V3, w: V3) -> V3:
    """The unit vector u turned by w's part across it: by the angle theta = |w x u|
    about (w x u) / theta, Rodrigues' formula with an axis perpendicular to u:
    u cos(theta) + (w x u) sin(theta) / theta (its limit u + w x u at theta = 0)."""
    c = (w[1] * u[2] - w[2] * u[1], w[2] * u[0] - w[0] * u[2], w[0] * u[1] - w[1] * u[0])
    theta = length(c)
    sin, cos = sincos(theta)
    small = theta < 1e-4
    # sin(t) / t; its series where t is small (the division would lose digits).
    scale = jnp.where(small, 1.0 - theta * theta / 6.0, sin / jnp.where(small, 1.0, theta))
    return xyz(lambda i: cos * u[i] + scale * c[i])


def turn_across(u: Float[Array, "3"], w: Float[Array, "3"]) -> Float[Array, "3"]:
    """:func:`turn_by` on (3,) arrays.

    >>> import jax.numpy as jnp
    >>> v = turn_across(jnp.array([0., 0, 1]), jnp.array([jnp.pi / 2, 0, 0]))
    >>> [round(float(x), 6) + 0.0 for x in v]
    [0.0, -1.0, 0.0]
    """
    return jnp.stack(turn_by((u[0], u[1], u[2]), (w[0], w[1], w[2])))


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
    closest point of the lane's own task's space and of the first-headed one to the
    gripper, the step's three N(0, 1) numbers, the tremor's displacement after the
    step."""

    closest: V3
    closest_decoy: V3
    xi: V3
    wave: Array


def aim(lane: Lane, s: State, decoys: bool = True) -> Aim:
    """The first half of a step (one lane): the closest points and the step's draws.
    Without ``decoys`` (``Layout.switching``: no user of the batch changes its mind,
    so every lane's first-headed task is its own) the second closest point is the
    first."""
    dtype = s.k.dtype

    def closest(own):
        kind, center, orientation, dims, trig = own
        rot = quat.matrix_entries(orientation)
        return shapes.project_components(kind, center, rot, dims, trig, s.p)

    draw = step_draws_of(lane.step_key, s.k.astype(jnp.int32), dtype)
    xi = (draw.xi[..., 0], draw.xi[..., 1], draw.xi[..., 2])
    own = closest(lane.own)
    return Aim(own, closest(lane.decoy_own) if decoys else own, xi, wave(lane, s.k + 1.0))


def heading(lane: Lane, s: State, seen: Aim) -> tuple[Array | None, V3]:
    """(whether the user heads for its own task at this step, the point it steers at):
    a change of mind turns once the distance to the first-headed task's space has
    fallen to (1 - user_switch_at) of its value at the start."""
    x = lane.x
    own = xyz(lambda i: jnp.where(x.user_aim_object, lane.aim[i], seen.closest[i]))
    if s.turned is None or s.d0 is None:  # no change of mind (Layout.switching)
        return None, own
    near = length(xyz(lambda i: seen.closest_decoy[i] - s.p[i])) <= \
        (1.0 - x.user_switch_at) * s.d0
    turned = s.turned | near
    decoy = xyz(lambda i: jnp.where(x.user_aim_object, lane.decoy_aim[i],
                                    seen.closest_decoy[i]))
    return turned, xyz(lambda i: jnp.where(turned, own[i], decoy[i]))


def move(lane: Lane, s: State, seen: Aim) -> Move:
    """One step of the user, without any check (one lane), on components (module
    docstring, points 2 to 6)."""
    x, dtype = lane.x, s.k.dtype
    step_length = am.rollout_numbers(x, dtype)["step_length"]
    turned, c = heading(lane, s, seen)
    d = xyz(lambda i: c[i] - s.p[i])
    norm = length(d)
    moving = norm > 0
    u = xyz(lambda i: d[i] / jnp.where(moving, norm, 1.0))
    cmd = turn_by(u, s.w)  # the commanded direction
    if s.mode is None:  # no joystick in the program (Layout.joystick): 3-D input
        mode = pause = None
        size = jnp.minimum(step_length, norm)
        delta = xyz(lambda i: jnp.where(moving, size * cmd[i], 0.0))
    else:
        mode, pause, delta = _joystick(lane, s, norm, cmd, moving, step_length)
    k = s.k + 1.0
    q = xyz(lambda i: s.q[i] + delta[i])
    # A perfect user's lane takes the closed form's samples (the same points).
    sample = am.sample(straight(lane, step_length), k)
    tremor = xyz(lambda i: seen.wave * lane.once.tremor_axis[i])
    p = xyz(lambda i: jnp.where(lane.perfect, sample[i], q[i] + tremor[i]))
    travelled = jnp.where(lane.perfect, jnp.minimum(k * step_length, lane.length),
                          s.travelled + length(delta))
    gap = xyz(lambda i: p[i] - s.p[i])
    w = xyz(lambda i: lane.ou_a * s.w[i] + lane.ou_b * seen.xi[i])
    return Move(k, q, p, delta, travelled, s.moved + length(gap), w, mode, pause, turned)


def _joystick(lane: Lane, s: State, norm: Array, cmd: V3, moving: Array,
              step_length: Array) -> tuple[Array, Array, V3]:
    """The two-mode joystick's step (module docstring, point 5): (mode, pause, the
    displacement)."""
    x = lane.x
    assert s.mode is not None and s.pause is not None  # Layout.joystick
    # The two-mode joystick: the command's horizontal and vertical parts.
    horizontal = norm * jnp.sqrt(cmd[0] * cmd[0] + cmd[1] * cmd[1])
    vertical = norm * jnp.abs(cmd[2])
    undecided = s.mode < 0
    mode = jnp.where(undecided, jnp.where(vertical > horizontal, 1, 0), s.mode)
    current = jnp.where(mode == 0, horizontal, vertical)
    other = jnp.where(mode == 0, vertical, horizontal)
    waiting = s.pause > 0
    switch = x.user_input_modes & ~waiting & ~undecided & moving & (current < 0.5 * other)
    mode = jnp.where(switch, 1 - mode, mode)
    pause = jnp.where(waiting, s.pause - 1,
                      jnp.where(switch, jnp.maximum(lane.switch_steps - 1, 0), 0))
    still = x.user_input_modes & (waiting | (switch & (lane.switch_steps > 0)))
    # Along the command (3-D input), or along the current mode's part of it.
    masked = xyz(lambda i: cmd[i] * jnp.where((mode == 0) == (i < 2), 1.0, 0.0))
    masked_len = length(masked)
    part_len = jnp.where(x.user_input_modes, norm * masked_len, norm)
    size = jnp.minimum(step_length, part_len)
    unit = xyz(lambda i: jnp.where(x.user_input_modes,
                                   masked[i] / jnp.where(masked_len > 0, masked_len, 1.0),
                                   cmd[i]))
    go = moving & ~still & (part_len > 0)
    delta = xyz(lambda i: jnp.where(go, size * unit[i], 0.0))
    return mode.astype(s.mode.dtype), pause.astype(s.pause.dtype), delta
