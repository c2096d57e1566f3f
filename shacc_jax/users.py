"""Simulated users beyond the perfect one (reference/model, "Simulated users"), stepped.

The perfect user moves in a straight line to the closest point of its task's space,
which the Automaton's closed form (``automaton``) evaluates without stepping. An
imperfect user is stepped, one rollout per lane, as the step rule reads:

- ``user_tremor`` A at ``user_tremor_hz`` f: the gripper is at p_k = q_k + A sin(2 pi f
  k dt + phi) e, q_k the commanded position (q_0 the start), e a unit axis uniform on
  the sphere and phi uniform in [0, 2 pi), both drawn once per rollout;
- each step the user looks at the gripper: d = c(p_k) - p_k, c the closest point of the
  task's space (``user_aim`` "space") or the task's aim point (``Geometry.aim_point``,
  "object"); with probability ``user_lag`` (never the first step) the step repeats
  the previous step's displacement, else it is min(v_max dt, |d|) along d's direction
  turned by an angle |N(0, user_noise^2)| about an axis uniform on the circle across
  it (no step when |d| = 0); q_{k+1} = q_k + step;
- activation is checked at p_{k+1} (and at p_0 before the first step), then the meta
  skill turns R at p_{k+1} (the shacc mode), as for the perfect user.

The random numbers come from JAX's counter-based threefry stream keyed by (seed,
scene, task, start) (:func:`rollout_key`) and folded with the step: never by batch
position or mode, so a rollout draws the same numbers in every mode (modes compare
pair by pair) and in every batch, piece or device it runs in.
:func:`user_draws` gives them as arrays, which the tests' NumPy Automaton replays.

A lane whose user is perfect (all three parameters zero, aiming at the space) takes
the closed form's sample positions, so it meets the same activation as the closed
form; a batch whose users are all perfect is never stepped (``Layout.stepped_users``).
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from geometry_precompute.population import NORMAL, POPULATED, UNIFORM, VALUES

from . import automaton as am
from . import collision as col
from . import quaternion as quat
from . import shapes
from .meta import meta_target_batch, meta_target_yaw_batch, yaw_directions
from .trig import sincos
from .types import COLLISION, Geometry, Params

# Sphere-tracing steps from a step's first interval entry to the entry into a space
# (activation_check = swept).
SPHERE_TRACING_STEPS = 16


def rollout_key(seed: Int[Array, ""], scene_key: Int[Array, ""], task: Int[Array, ""],
                start: Int[Array, ""]) -> Array:
    """The key of one rollout's random numbers: threefry, folded with the scene's own
    number (``Geometry.scene_key``), the task index and the start index.

    >>> import jax.numpy as jnp
    >>> a = rollout_key(jnp.int32(0), jnp.int32(7), jnp.int32(1), jnp.int32(2))
    >>> b = rollout_key(jnp.int32(0), jnp.int32(7), jnp.int32(1), jnp.int32(3))
    >>> bool((jax.random.key_data(a) != jax.random.key_data(b)).any())
    True
    """
    key = jax.random.key(seed.astype(jnp.uint32), impl="threefry2x32")
    for part in (scene_key, task, start):
        key = jax.random.fold_in(key, part.astype(jnp.uint32))
    return key


class StepDraws(NamedTuple):
    """One step's random numbers: |N(0, 1)| (the noise angle in units of
    ``user_noise``), the noise axis' angle on the circle across the direction, in [0,
    2 pi), and a uniform number in [0, 1) that decides the lag."""

    noise: Float[Array, "..."]
    axis_angle: Float[Array, "..."]
    lag: Float[Array, "..."]


class RolloutDraws(NamedTuple):
    """A rollout's random numbers drawn once: the tremor's unit axis and its phase."""

    tremor_axis: Float[Array, "... 3"]
    tremor_phase: Float[Array, "..."]


def step_draws(key: Array, k: Int[Array, ""], dtype) -> StepDraws:
    """The random numbers of step k (0 for the step from p_0 to p_1) of the rollout
    ``key``: two threefry blocks, counters (k, 0) and (k, 1) under the rollout's step
    key, give three 32-bit words; each becomes a float in [0, 1) of 24 bits, the first
    |N(0, 1)| by the inverse of the half-normal's distribution function."""
    return _step_draws(_step_key(key), k, dtype)


def _step_key(key: Array) -> Array:
    """The raw threefry key of a rollout's per-step numbers (``key`` folded with 1)."""
    return jax.random.key_data(jax.random.fold_in(key, 1))


def _step_draws(step_key: Array, k: Int[Array, ""], dtype) -> StepDraws:
    return _draws_of(_step_words(step_key, k), dtype)


def _step_words(step_key: Array, k: Int[Array, ""]) -> tuple[Array, Array, Array]:
    """The three 32-bit words of step k: the first word of the threefry blocks with
    counters (k, 0) and (k, 1), then the second word of the first (``threefry_2x32`` of
    the counters [k, k, 0, 1], its first three words)."""
    kk = k.astype(jnp.uint32)
    a0, a1 = _threefry(step_key[0], step_key[1], kk, jnp.zeros_like(kk))
    b0, _ = _threefry(step_key[0], step_key[1], kk, jnp.ones_like(kk))
    return a0, b0, a1


# Threefry-2x32 of Salmon et al. (2011), 20 rounds, as JAX computes it.
_ROTATIONS = ((13, 15, 26, 6), (17, 29, 16, 24))


def _threefry(k0: Array, k1: Array, x0: Array, x1: Array) -> tuple[Array, Array]:
    """One threefry-2x32 block, written out: equal bit for bit to ``threefry_2x32``
    (tests/test_users.py), which on a CPU runs as a loop of five iterations, each a
    dozen small loops over the batch."""
    ks = (k0, k1, k0 ^ k1 ^ jnp.uint32(0x1BD11BDA))
    x0, x1 = x0 + ks[0], x1 + ks[1]
    for i in range(5):
        for r in _ROTATIONS[i % 2]:
            x0 = x0 + x1
            x1 = ((x1 << jnp.uint32(r)) | (x1 >> jnp.uint32(32 - r))) ^ x0
        x0, x1 = x0 + ks[(i + 1) % 3], x1 + ks[(i + 2) % 3] + jnp.uint32(i + 1)
    return x0, x1


def _draws_of(words: tuple[Array, Array, Array], dtype) -> StepDraws:
    u = (jnp.stack(words) >> 8).astype(jnp.float32) * (1.0 / (1 << 24))
    noise = jnp.sqrt(2.0) * jax.scipy.special.erfinv(u[0])
    return StepDraws(noise.astype(dtype), (2.0 * jnp.pi * u[1]).astype(dtype), u[2].astype(dtype))


def rollout_draws(key: Array, dtype) -> RolloutDraws:
    """The numbers the rollout ``key`` draws once: e uniform on the sphere (from z
    uniform in [-1, 1] and an angle uniform in [0, 2 pi)) and phi in [0, 2 pi)."""
    u = jax.random.uniform(jax.random.fold_in(key, 0), (3,), dtype)
    z = 2.0 * u[0] - 1.0
    rho = jnp.sqrt(jnp.maximum(1.0 - z * z, 0.0))
    lon = 2.0 * jnp.pi * u[1]
    return RolloutDraws(jnp.stack([rho * jnp.cos(lon), rho * jnp.sin(lon), z]),
                        2.0 * jnp.pi * u[2])


def user_draws(seed, scene_key, task, start, n_steps: int, dtype=jnp.float32
               ) -> tuple[StepDraws, RolloutDraws]:
    """Every random number of one rollout, as arrays: its first ``n_steps`` steps'
    (:class:`StepDraws`, each (n_steps,)) and its once-drawn ones. What the stepped
    kernel draws, for slow references to replay.

    >>> steps, once = user_draws(0, 7, 1, 2, n_steps=5)
    >>> steps.noise.shape, once.tremor_axis.shape
    ((5,), (3,))
    """
    key = rollout_key(*(jnp.asarray(v, jnp.int32) for v in (seed, scene_key, task, start)))
    steps = jax.vmap(lambda k: step_draws(key, k, dtype))(jnp.arange(n_steps, dtype=jnp.int32))
    return steps, rollout_draws(key, dtype)


def population_values(key: Array, x: Params, dtype) -> Float[Array, "4"]:
    """The values of the populated user settings (``POPULATED``: user_noise, user_lag,
    user_tremor, user_tremor_hz) of the rollout ``key`` under one scene's settings ``x``:
    a setting without a population keeps its value; one with draws from a uniform
    number u in [0, 1) of the rollout's stream (``key`` folded with 2, one per
    setting): uniform low + u (high - low); the normal truncated to [low, high] by its
    inverse distribution function on [F(low), F(high)]; a list's entry floor(u n).

    >>> import jax.numpy as jnp
    >>> from shacc_jax.types import Params
    >>> x = Params._make(jnp.zeros(()) for _ in Params._fields)._replace(
    ...     user_noise=jnp.float32(0.3), user_dist=jnp.array([0, 1, 0, 0]),
    ...     user_dist_args=jnp.array([[0, 0, 0, 0], [0.2, 0.4, 0.2, 0.4]] + [[0] * 4] * 2,
    ...                              jnp.float32), user_dist_values=jnp.zeros((4, 16)))
    >>> v = population_values(jax.random.key(0), x, jnp.float32)
    >>> float(v[0]), 0.2 <= float(v[1]) < 0.4
    (0.30000001192092896, True)
    """
    u = jax.random.uniform(jax.random.fold_in(key, 2), (len(POPULATED),), dtype)
    plain = jnp.stack([getattr(x, k) for k in POPULATED]).astype(dtype)
    a = x.user_dist_args.astype(dtype)
    uniform = a[:, 0] + u * (a[:, 1] - a[:, 0])
    mean, sd, lo, hi = a[:, 0], jnp.where(a[:, 1] > 0, a[:, 1], 1.0), a[:, 2], a[:, 3]
    f_lo = jax.scipy.special.ndtr((lo - mean) / sd)
    f_hi = jax.scipy.special.ndtr((hi - mean) / sd)
    normal = jnp.clip(mean + sd * jax.scipy.special.ndtri(f_lo + u * (f_hi - f_lo)), lo, hi)
    n = jnp.maximum(a[:, 0].astype(jnp.int32), 1)
    index = jnp.minimum((u * n.astype(dtype)).astype(jnp.int32), n - 1)
    listed = jnp.take_along_axis(x.user_dist_values.astype(dtype), index[:, None], 1)[:, 0]
    kind = x.user_dist
    return jnp.select([kind == UNIFORM, kind == NORMAL, kind == VALUES],
                      [uniform, normal, listed], plain)


def with_population(key: Array, x: Params, dtype) -> Params:
    """One rollout's settings ``x`` with its drawn values of the populated settings
    (:func:`population_values`)."""
    v = population_values(key, x, dtype)
    return x._replace(**{k: v[i] for i, k in enumerate(POPULATED)})


def drawn_values(geometry: Geometry, params: Params) -> Float[Array, "N T 4"]:
    """Every rollout's drawn user settings of one scene (:func:`population_values`),
    (N, T, 4): what ``Rollouts.user`` holds for each mode."""
    dtype = geometry.starts.dtype
    T = geometry.task_mask.shape[0]

    def one(index, task):
        key = rollout_key(params.user_seed, geometry.scene_key, task, index)
        return population_values(key, params, dtype)

    tasks = jnp.arange(T, dtype=jnp.int32)
    return jax.vmap(lambda i: jax.vmap(lambda t: one(i, t))(tasks))(geometry.start_index)


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


# A lane's 3-vector in the loop's state: three arrays, not one stacked (3,) array.
# XLA's CPU backend computes a stacked result's whole expression once per component,
# and batched 3-vector products become library calls: the baseline mode's stepped pass
# (50 scenes, 2-core CPU) took 0.30 s with the vectors stacked and 0.26 s on components.
V3 = tuple[Array, Array, Array]


def _length(v) -> Array:
    """|v| of one lane's 3-vector (a (3,) array or :data:`V3`) as explicit sums (the
    same in any batch, ``determinism``)."""
    return jnp.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


def _v3(v: Array) -> V3:
    return (v[0], v[1], v[2])


def _xyz(component) -> V3:
    """The :data:`V3` of ``component(i)``, i = 0, 1, 2."""
    return (component(0), component(1), component(2))


def _components_first(sp: shapes.Prepared) -> shapes.Prepared:
    """One scene's prepared spaces (leading T) in the meta kernels' layout: (T,) and
    components first, (3, T), (3, 3, T)."""
    return shapes.Prepared(sp.kind, sp.center.T, jnp.moveaxis(sp.rot, 0, -1), sp.dims.T,
                           sp.trig.T)


# A step gets the full check (every space's sdf, the meta region) only where it may
# need it: sdfs are exact distances, so 1-Lipschitz, and a gripper that has moved a
# path of length m since a full check that found every space (and meta region) at least
# ``clear`` away is at least clear - m from each. Steps with clear - m > tau + this
# margin (m; it covers rounding) cannot activate a space nor turn R, and skip the check.
CLEARANCE_MARGIN = 1e-4
# A block checks in full at most a 1 / share of its lanes per step (1: all, without
# gathering the others out); a lane that needs a full check and finds no place waits a
# step (its rollout is unchanged by waiting). The mode with the meta skill needs a full
# check on about 40 % of its live steps (inside a meta region R turns every step), the
# others on about 8 %.
FULL_CHECK_SHARE = {"meta": 4, "other": 8}
# A refill gives at most this share of the slots new lanes; it waits until that many
# are free (or none is live).
REFILL_SHARE = 4
# Per backend, the steps per loop iteration (each iteration costs a device-to-host
# round trip for its condition on an accelerator). Measured on an H100, 10.8 M
# rollouts, 2^19 slots (benchmarks/RESULTS.md): with 4 steps an iteration and a share of
# 4 for every mode, shares 1, 4 and 8 took 2.30, 1.62 and 1.95 s; after the kernel's
# memory traffic was cut, 8 steps an iteration took 1.035 s against 1.126 s for 4 (55
# s to compile against 31 s); with the shares above and refills of a quarter of the
# slots (were a sixteenth), 0.971 s.
STEPPING = {"cpu": 1, "accelerator": 8}


class _Lane(NamedTuple):
    """A lane's constants: its scene, task and settings, the start pose, the random
    numbers drawn once, its task's space (kind, centre, quaternion, dims, the cone's
    trigonometry: the rotation matrix is made where used, which reads fewer numbers a
    step than a stored one; the trigonometry costs more to recompute on a CPU) and aim
    point, the perfect user's path (closest point, direction, length; the rest of
    ``automaton.Path`` is p0 and numbers of the settings). Every step reads them all:
    the move is bound by memory, so nothing is stored twice."""

    scene: Array
    target: Array
    x: Params
    p0: Array
    r0: Array
    real: Array
    perfect: Array
    step_key: Array
    once: RolloutDraws
    own: tuple[Array, Array, Array, Array, Array]
    aim: Array
    c0: Array
    u: Array
    length: Array


def _path(lane: _Lane, step_length: Array) -> am.Path:
    """The perfect user's straight path (``automaton.straight_path``'s numbers)."""
    steps = lane.x.max_steps.astype(lane.length.dtype)
    landing = jnp.minimum(jnp.ceil(lane.length / step_length), steps + 1.0)
    return am.Path(lane.p0, lane.c0, lane.u, lane.length, landing, step_length)


class _Move(NamedTuple):
    """A step's move, before its check: the step count, the commanded and gripper
    positions, the displacement, the path length, the gripper's path since the last
    full check."""

    k: Array
    q: V3
    p: V3
    delta: V3
    travelled: Array
    moved: Array


class _Check(NamedTuple):
    """A full check's answers at the gripper: its position (the entry point under the
    swept check), the path length, ended (activated or collided), the outcome code and
    activated task should it have ended (``automaton.outcome_codes``; a collision's
    code and -1), R after the meta skill's turn, whether the step counts as a meta
    step, the clearance."""

    p: Array
    travelled: Array
    done: Array
    code: Array
    activated: Array
    r: Array
    counted: Array
    clear: Array


class _State(NamedTuple):
    k: Array          # steps taken
    q: V3             # commanded position
    p: V3             # gripper position
    last: V3          # the previous step's displacement
    r: Array          # orientation (4,)
    meta_steps: Array
    travelled: Array  # path length of the commanded position, m
    done: Array       # activated or collided
    code: Array       # the outcome code where done (a check's answer, not the T sdfs:
    activated: Array  # writing those back was a tenth of a step's time on a GPU)
    clear: Array      # the clearance found at the last full check
    moved: Array      # the gripper's path since, m
    live: Array       # still stepping


def _wave(lane: _Lane, k: Array) -> Array:
    """A sin(2 pi f k dt + phi), the tremor's displacement along its axis at step k. The
    phase is reduced to whole cycles first (f dt k less its nearest integer), so a
    long rollout's argument stays within a few radians (:func:`trig.sincos`)."""
    x = lane.x
    cycles = x.user_tremor_hz * x.dt * k
    sin, _ = sincos(2.0 * jnp.pi * (cycles - jnp.round(cycles)) + lane.once.tremor_phase)
    return x.user_tremor * sin


def _shake(lane: _Lane, k: Array) -> Array:
    return _wave(lane, k) * lane.once.tremor_axis


class _Aim(NamedTuple):
    """What a step's move reads more than once, computed once (:func:`_move`): the
    closest point of the task's space to the gripper, (sin, cos) of the noise angle and
    of its axis' angle, the lag's uniform number, the tremor's displacement after the
    step."""

    closest: V3
    angle: tuple[Array, Array]
    axis: tuple[Array, Array]
    lag: Array
    wave: Array


def _aim(lane: _Lane, s: _State) -> _Aim:
    """The first half of a step (one lane): the closest point and the step's draws."""
    x, dtype = lane.x, s.k.dtype
    kind, center, orientation, dims, trig = lane.own
    rot = quat.matrix_entries(orientation)
    closest = shapes.project_components(kind, center, rot, dims, trig, s.p)
    draw = _step_draws(lane.step_key, s.k.astype(jnp.int32), dtype)
    return _Aim(closest, sincos(x.user_noise * draw.noise), sincos(draw.axis_angle), draw.lag,
                _wave(lane, s.k + 1.0))


def _move(lane: _Lane, s: _State, aim: _Aim) -> _Move:
    """One step of the user, without any check (one lane), on components."""
    x, dtype = lane.x, s.k.dtype
    step_length = am.rollout_numbers(x, dtype)["step_length"]
    c = _xyz(lambda i: jnp.where(x.user_aim_object, lane.aim[i], aim.closest[i]))
    d = _xyz(lambda i: c[i] - s.p[i])
    length = _length(d)
    moving = length > 0
    u = _xyz(lambda i: d[i] / jnp.where(moving, length, 1.0))
    turned = _turn_across(u[0], u[1], u[2], aim.angle, aim.axis)
    size = jnp.minimum(step_length, length)
    lagging = (s.k > 0) & (aim.lag < x.user_lag)
    delta = _xyz(lambda i: jnp.where(lagging, s.last[i],
                                     jnp.where(moving, size * turned[i], 0.0)))
    k = s.k + 1.0
    q = _xyz(lambda i: s.q[i] + delta[i])
    # A perfect user's lane takes the closed form's samples (the same points).
    sample = am.sample(_path(lane, step_length), k)
    shake = _xyz(lambda i: aim.wave * lane.once.tremor_axis[i])
    p = _xyz(lambda i: jnp.where(lane.perfect, sample[i], q[i] + shake[i]))
    travelled = jnp.where(lane.perfect, jnp.minimum(k * step_length, lane.length),
                          s.travelled + _length(delta))
    gap = _xyz(lambda i: p[i] - s.p[i])
    return _Move(k, q, p, delta, travelled, s.moved + _length(gap))


def _sdfs(spaces: shapes.Prepared, meta, p: Array, track: bool) -> tuple[Array, Array | None]:
    """Every space's sdf at p (one lane), and with ``track`` every initial space's (the
    meta region's)."""
    own = shapes.all_sdf(spaces, p)
    return own, shapes.prepared_sdf(meta[0], p[:, None]) if track else None


def _check(g: Geometry, spaces: shapes.Prepared, meta, lane: _Lane, p: Array, r: Array,
           track: bool, formula: str, swept_checks: bool, collide: bool,
           step=None, hulls: col.Hulls | None = None, sd=None) -> _Check:
    """The full check at the gripper position p (one lane): every space's sdf and the
    activation; with ``step`` (the state before and the move), the swept check's entry
    point (traced only where ``swept_checks``) and the meta skill's turn of R. With
    ``collide`` (traced only where some scene checks collisions), the gripper's
    capsules at (p, R before the turn) against the objects first: a penetration ends
    the rollout as a collision, without activating or turning. ``g``, ``spaces``,
    ``meta``: the lane's scene; ``hulls``: the batch's mesh hulls (not gathered per lane:
    a mesh is read only where the gripper is near it); ``sd``: the sdfs at p
    (:func:`_sdfs`) where the caller has them."""
    x, dtype = lane.x, p.dtype
    n = am.rollout_numbers(x, dtype)
    tau = n["tau"]
    inf = jnp.asarray(jnp.inf, dtype)

    own, sd_init = sd if sd is not None else _sdfs(spaces, meta, p, track)
    sd = jnp.where(g.task_mask, own, inf)
    active = sd <= tau
    travelled = jnp.zeros((), dtype) if step is None else step[1].travelled
    if step is not None and swept_checks:
        p, active, sd, travelled = _swept_entry(spaces, g.task_mask, lane, step[0], step[1],
                                                p, active, sd, n)
    clear = jnp.min(sd)
    hit = jnp.zeros((), bool)
    if collide:
        objects = col.scene_objects(g.obj_kind, g.obj_center, g.obj_quat, g.obj_size,
                                    g.obj_mask)
        dims = x.gripper()
        hit = x.collision & col.penetrates(objects, p, r, dims, hulls, lane.scene)
        active = active & ~hit
        # No capsule reaches beyond gripper_reach from p: objects farther than that
        # cannot be touched, a bound as 1-Lipschitz as the spaces' sdfs.
        kind, centre, mat, size, mask = objects
        local = jnp.einsum("oji,oj->oi", mat, p[None, :] - centre)
        apart = col.point_distance(tuple(local.T), kind, tuple(size.T))
        gap = jnp.min(jnp.where(mask, apart, inf)) - col.gripper_reach(dims)
        clear = jnp.where(x.collision, jnp.minimum(clear, gap + tau), clear)
    done = jnp.any(active) | hit
    code, activated = am.outcome_codes(am.Activation(jnp.zeros((), dtype), active, sd),
                                       lane.target, x.ambiguity_nearest)
    code = jnp.where(hit, COLLISION, code)
    activated = jnp.where(hit, -1, activated)
    counted = jnp.zeros((), bool)
    if track:
        assert sd_init is not None  # _sdfs gives it where track
        init, opt, fixed_dir = meta
        member = g.task_mask & (g.cluster >= 0)
        pp = p[:, None]  # (components, tasks)
        clear = jnp.minimum(clear, jnp.min(jnp.where(member, sd_init, inf)))
        if step is not None:
            common = (init, opt, g.task_mask, g.cluster, g.orient_kind)
            both = (sd_init, sd)
            goals = []
            if formula in ("yaw", "both"):
                inside, goal = meta_target_yaw_batch(*common, fixed_dir.T, g.orient_axis.T, pp,
                                                     tau, both)
                goals.append(goal)
            if formula in ("general", "both"):
                inside, goal = meta_target_batch(*common, g.orient_quat.T, g.orient_axis.T,
                                                 pp, tau, both)
                goals.append(goal)
            # The region test is the same; the target's formula is not.
            goal = jnp.where(g.yaw_meta, goals[0], goals[1]) if formula == "both" else goals[0]
            half_turn = sincos(0.5 * n["max_angle"])
            turned = jnp.where(inside, quat.turn_towards(r, goal, half_turn), r)
            r = jnp.where(done, r, turned)
            counted = inside & ~done
    return _Check(p, travelled, done, code, activated, r, counted, clear)


def _swept_entry(spaces, mask, lane: _Lane, s: _State, m: _Move, p, active, sd, n):
    """activation_check = swept: where the gripper's segment from s.p to p first
    enters a space, that point activates (for the lanes that ask for it)."""
    dtype = p.dtype
    inf = jnp.asarray(jnp.inf, dtype)
    tau = n["tau"]
    start = jnp.stack(s.p)
    seg = p - start
    seg_len = _length(seg)
    along = seg / jnp.where(seg_len > 0, seg_len, 1.0)
    lo, hi = shapes.all_ray_intervals(spaces, start, along, n["grow"])
    enters = mask & (lo <= hi) & (lo <= seg_len) & (hi >= 0) & (seg_len > 0)
    # The intervals contain the spaces' tau-sublevel sets (a little more, near edges):
    # from the first interval's start, steps that never pass an entry reach the first
    # entry into any space. Two such steps, the longer taken: sphere tracing's (the sdfs
    # are 1-Lipschitz, so min sdf - tau) and each space's Newton step along the segment
    # (its sdf is convex, so outside the tangent's root lies before its own entry: exact
    # at once through a face, where sphere tracing alone crawls along a grazing
    # segment, 1.3 mm short of a disk's top after 16 steps in a test).
    t_hit = jnp.min(jnp.where(enters, jnp.maximum(lo, 0.0), inf))
    t_hit = jnp.where(jnp.isfinite(t_hit), t_hit, 0.0)

    def gaps(t):
        return jnp.where(mask, shapes.all_sdf(spaces, start + t * along), inf) - tau

    def trace(_, t):
        gap, slope = jax.jvp(gaps, (t,), (jnp.ones_like(t),))
        newton = jnp.where(gap <= 0, 0.0, jnp.where(slope < 0, gap / jnp.where(
            slope < 0, -slope, 1.0), inf))
        return t + jnp.maximum(jnp.maximum(jnp.min(gap), 0.0), jnp.min(newton))

    t_hit = jax.lax.fori_loop(0, SPHERE_TRACING_STEPS, trace, t_hit)
    p_hit = start + t_hit * along
    sd_hit = jnp.where(mask, shapes.all_sdf(spaces, p_hit), inf)
    # The entry point lies on the boundary of tau; rounding may put it a hair outside,
    # which the closed form's interval slack covers.
    act_hit = sd_hit <= n["grow"]
    swept = (lane.x.activation_swept & jnp.any(enters) & jnp.any(act_hit)
             & (t_hit <= seg_len))
    p = jnp.where(swept, p_hit, p)
    active = jnp.where(swept, act_hit, active)
    sd = jnp.where(swept, sd_hit, sd)
    step_len = _length(m.delta)
    travelled = jnp.where(swept, s.travelled + step_len
                          * (t_hit / jnp.where(seg_len > 0, seg_len, 1.0)), m.travelled)
    return p, active, sd, travelled


def _lanes(geometry: Geometry, params: Params, spaces: shapes.Prepared, which: str,
           populations: bool, scene: Array, start: Array, target: Array) -> _Lane:
    """One lane's constants (vmapped over a block); with ``populations``, its drawn user
    settings."""
    pick = (lambda a: a[scene])  # noqa: E731
    g, x, sp = (jax.tree.map(pick, t) for t in (geometry, params, spaces))
    dtype = geometry.starts.dtype
    pose = g.starts[start]
    key = rollout_key(x.user_seed, g.scene_key, target, g.start_index[start])
    if populations:
        x = with_population(key, x, dtype)
    # Drawn (or plain): the distributions are not carried in the lane's state.
    x = x._replace(user_dist=jnp.zeros((), jnp.int32), user_dist_args=jnp.zeros((), dtype),
                   user_dist_values=jnp.zeros((), dtype))
    n = am.rollout_numbers(x, dtype)
    own = (g.kind[target], getattr(g, f"center_{which}")[target],
           getattr(g, f"quat_{which}")[target], getattr(g, f"dims_{which}")[target],
           sp.trig[target])
    path = am.straight_path(sp, target, pose[:3], n["step_length"], n["max_steps"])
    return _Lane(scene, target, x, pose[:3], pose[3:], g.task_mask[target], is_perfect(x),
                 _step_key(key), rollout_draws(key, dtype), own, g.aim_point[target],
                 path.c0, path.u, path.length)


def _once(tree, token: Bool[Array, ""]):
    """``tree`` as it is, computed once: ``token`` must be true at run time, unknown to
    XLA, and not batched. XLA's CPU backend fuses a value into each fusion that reads
    it, so a value read by several (a point's three components, the sdfs that decide
    activation, clearance and the meta weights) is computed in each, and it removes
    ``jax.lax.optimization_barrier`` before fusion. A conditional's results are
    buffers, so the value is computed once, before the branch. Measured on 2 CPU cores,
    50 scenes (benchmarks/RESULTS.md): the shacc mode's stepped pass 0.805 s to 0.665 s
    with the sdfs computed once. Not for accelerators, where a conditional waits for
    its predicate on the host."""
    return jax.lax.cond(token, lambda t: t, lambda t: jax.tree.map(jnp.zeros_like, t), tree)


def _first(mask: Array, size: int) -> tuple[Array, Array, Array]:
    """The indices of the first ``size`` true entries of ``mask`` (B,) in order, 0 after
    them; where each index is to be written back (B + i past their count: dropped); and
    which entries were taken.
    A scatter of the entries' positions with unique indices, which the GPU writes in
    parallel: ``jnp.nonzero`` with a size is a scatter that XLA may not assume unique,
    61 us a step at 2^19 lanes on an H100, the largest kernel of the loop."""
    B = mask.shape[0]
    lane = jnp.arange(B, dtype=jnp.int32)
    pos = jnp.cumsum(mask, dtype=jnp.int32) - 1
    taken = mask & (pos < size)
    idx = jnp.zeros(size, jnp.int32).at[jnp.where(taken, pos, size + lane)].set(
        lane, mode="drop", unique_indices=True)
    slots = jnp.arange(size, dtype=jnp.int32)
    count = jnp.minimum(pos[-1] + 1, size)
    return idx, jnp.where(slots < count, idx, B + slots), taken


def _put(a: Array, at: Array, v: Array) -> Array:
    """``a`` with the lanes ``at`` (last axis; out of range: dropped) set to ``v``; the
    indices are unique (:func:`_first`)."""
    return a.at[..., at].set(v, mode="drop", unique_indices=True)


class _Result(NamedTuple):
    """Every lane's answers, (L, ...) in lane order, written as lanes end."""

    code: Array
    activated: Array
    step: Array
    point: Array
    path_length: Array
    r: Array
    meta_steps: Array


class _Pass(NamedTuple):
    """The loop's carry: the slots' lanes and states, each slot's lane (-1: empty), the
    next lane of the queue to start, the answers."""

    lane: _Lane
    state: _State
    slot: Array
    next: Array
    result: _Result


def stepped_pass(geometry: Geometry, params: Params, which: str, track: bool,
                 formula: str, lanes_per_block: int, swept_checks: bool = False,
                 backend: str = "cpu", collision_checks: bool = False,
                 stepping: tuple[int, int] | None = None, populations: bool = False
                 ) -> tuple[am.Outcome, Array, Array]:
    """Every rollout of one mode, stepped: the Outcome (S, N, T), R at the end (S, N,
    T, 4) and the meta steps (S, N, T). ``which``: the mode's spaces (``init`` or
    ``opt``); ``track``: with the meta skill; ``formula``: ``Layout.meta_formula``.

    One loop of steps over ``lanes_per_block`` slots, each holding one rollout (a lane:
    scene, start, task). Each step moves every live lane (``_move``); the lanes whose
    clearance allows it skip the check, and at most a 1 / share of the slots are
    gathered and checked in full (``_check``; the share and the steps per loop
    iteration are ``stepping``, or the mode's :data:`FULL_CHECK_SHARE` and the
    backend's :data:`STEPPING`; ``populations``: the
    lanes draw their user settings, :func:`with_population`). A slot whose rollout
    has ended (an activation, a collision or max_steps) writes its answers and takes the
    next lane of the queue, once a 1 / REFILL_SHARE of the slots are free. The queue
    holds the real lanes sorted by the perfect user's landing step, longest first, so
    that the last rollouts, which run while slots empty, are short ones; padded tasks
    are not run."""
    if track and which != "opt":  # the meta weights reuse the check's sdfs of "opt"
        raise ValueError(f"the meta skill tracks on the opt spaces, not {which!r}")
    S, N, T = geometry.starts.shape[0], geometry.starts.shape[1], geometry.task_mask.shape[1]
    L = S * N * T
    dtype = geometry.starts.dtype
    spaces = jax.vmap(lambda g: g.spaces(which))(geometry)
    meta = None
    if track:
        meta = jax.vmap(lambda g: (_components_first(g.spaces("init")),
                                   _components_first(g.spaces("opt")),
                                   yaw_directions(g.orient_quat)[0]))(geometry)
    scene = jnp.repeat(jnp.arange(S, dtype=jnp.int32), N * T)
    start = jnp.tile(jnp.repeat(jnp.arange(N, dtype=jnp.int32), T), S)
    task = jnp.tile(jnp.arange(T, dtype=jnp.int32), S * N)
    # Per-lane arrays keep the lane axis last ((3, B), (T, B)): the per-lane code's
    # small vectors are then rows of whole arrays, which XLA vectorises across lanes.
    # The hulls are read where the gripper is near a mesh, not gathered for every lane.
    per_lane = geometry._replace(obj_hull=None, obj_hull_plane=None)  # type: ignore[arg-type]
    make = jax.vmap(partial(_lanes, per_lane, params, spaces, which, populations), out_axes=-1)
    lanes = partial(jax.vmap, in_axes=-1, out_axes=-1)

    def landing(s, n, t):
        x = am.rollout_numbers(jax.tree.map(lambda a: a[s], params), dtype)
        path = am.straight_path(jax.tree.map(lambda a: a[s], spaces), t,
                                geometry.starts[s, n, :3], x["step_length"], x["max_steps"])
        return jnp.where(geometry.task_mask[s, t], path.landing, -1.0)

    order = jnp.argsort(-jax.vmap(landing)(scene, start, task)).astype(jnp.int32)
    n_real = (jnp.sum(geometry.task_mask) * N).astype(jnp.int32)
    B = min(lanes_per_block, L)
    share, unroll = stepping or (FULL_CHECK_SHARE["meta" if track else "other"],
                                 STEPPING[backend if backend in STEPPING else "accelerator"])
    F = max(1, B // share)
    R = max(1, B // REFILL_SHARE)

    hulls = col.Hulls.of(geometry) if collision_checks else None

    def scene_of(scene):
        pick = (lambda a: a[scene])  # noqa: E731
        return (jax.tree.map(pick, per_lane), jax.tree.map(pick, spaces),
                None if meta is None else jax.tree.map(pick, meta))

    def check(ln, p, r, step=None, sd=None):
        return _check(*scene_of(ln.scene), ln, p, r, track, formula, swept_checks,
                      collision_checks, step, hulls, sd)

    def once(tree, token):
        # On a CPU, values read by several fusions are computed once (:func:`_once`).
        return _once(tree, token) if backend == "cpu" else tree

    def begin(ids, occupied):
        """The lanes ``ids`` and their states before the first step (checked at the
        start)."""
        lane = make(scene[ids], start[ids], task[ids])
        n = ids.shape[0]
        p_start = jnp.where(lane.perfect, lane.p0,
                            lane.p0 + lanes(_shake)(lane, jnp.zeros(n, dtype)))
        first = lanes(check)(lane, p_start, lane.r0)
        zero = jnp.zeros(n, dtype)
        live = occupied & lane.real & ~first.done & (lane.x.max_steps > 0)
        return lane, _State(zero, _v3(lane.p0), _v3(first.p), (zero, zero, zero), lane.r0,
                            jnp.zeros(n, jnp.int32), zero, first.done, first.code,
                            first.activated, first.clear, zero, live)

    def finish(ln, e):
        code = jnp.where(e.done, e.code, am.TIMEOUT)
        activated = jnp.where(e.done, e.activated, -1)
        k = jnp.where(e.done, e.k, ln.x.max_steps.astype(dtype))
        return _Result(code, activated, k.astype(jnp.int32), jnp.stack(e.p), e.travelled, e.r,
                       e.meta_steps)

    def write(result, slot, lane, state, which_slots, valid):
        """Write the answers of the slots ``which_slots`` (where ``valid``)."""
        pick = (lambda a: a[..., which_slots])  # noqa: E731
        done = jax.vmap(finish, in_axes=-1)(jax.tree.map(pick, lane), jax.tree.map(pick, state))
        at = jnp.where(valid, slot[which_slots],
                       L + jnp.arange(which_slots.shape[0], dtype=jnp.int32))
        return jax.tree.map(lambda a, v: a.at[at].set(v, mode="drop", unique_indices=True),
                            result, done)

    def step(s: _State, lane: _Lane) -> _State:
        # Steps are never negative: a condition true at run time that XLA cannot fold.
        token = s.k[0] >= 0
        m = lanes(_move)(lane, s, once(lanes(_aim)(lane, s), token))
        tol = lane.x.activation_tol + CLEARANCE_MARGIN
        need = s.live & (s.clear - m.moved <= tol)

        def full(ln, st, mv):
            def sdfs(ln, mv):
                _, sp, mt = scene_of(ln.scene)
                return _sdfs(sp, mt, jnp.stack(mv.p), track)
            sd = once(lanes(sdfs)(ln, mv), token)
            return lanes(lambda ln, st, mv, sd: check(ln, jnp.stack(mv.p), st.r, (st, mv), sd))(
                ln, st, mv, sd)

        if F >= B:  # share 1, every lane checked: no gathering
            got = need
            c = full(lane, s, m)
            sub_s = s

            def put(a, v):
                return jnp.where(got, v, a)
        else:
            idx, at, got = _first(need, F)
            pick = (lambda a: a[..., idx])  # noqa: E731
            sub_s, sub_m, sub_lane = (jax.tree.map(pick, t) for t in (s, m, lane))
            c = full(sub_lane, sub_s, sub_m)

            def put(a, v):
                return _put(a, at, v)

        go = s.live & (~need | got)

        def adv(new, old):
            return jax.tree.map(lambda a, b: jnp.where(go, a, b), new, old)

        p_new = tuple(put(m.p[i], c.p[i]) for i in range(3))
        t = _State(adv(m.k, s.k), adv(m.q, s.q), adv(p_new, s.p),
                   adv(m.delta, s.last), put(s.r, c.r),
                   put(s.meta_steps, sub_s.meta_steps + c.counted.astype(jnp.int32)),
                   adv(put(m.travelled, c.travelled), s.travelled),
                   put(s.done, c.done), put(s.code, c.code), put(s.activated, c.activated),
                   put(s.clear, c.clear), adv(put(m.moved, jnp.zeros_like(c.clear)), s.moved),
                   s.live)
        steps = lane.x.max_steps.astype(dtype)
        return t._replace(live=s.live & ~(go & (t.done | (t.k >= steps))))

    def refill(c: _Pass) -> _Pass:
        """Slots whose rollout has ended write it and take the next lanes of the
        queue."""
        state = c.state
        free = (c.slot >= 0) & ~state.live
        idx, at, _ = _first(free, R)
        n_free = jnp.minimum(jnp.sum(free, dtype=jnp.int32), R)
        slots = jnp.arange(R, dtype=jnp.int32)
        result = write(c.result, c.slot, c.lane, state, idx, slots < n_free)
        n_new = jnp.minimum(n_free, n_real - c.next)
        new = slots < n_new
        ids = order[jnp.minimum(c.next + slots, L - 1)]
        lane_new, state_new = begin(ids, new)
        put = (lambda a, v: _put(a, at, v))  # noqa: E731
        slot = put(c.slot, jnp.where(new, ids, -1))
        return _Pass(jax.tree.map(put, c.lane, lane_new), jax.tree.map(put, state, state_new),
                     slot, c.next + n_new, result)

    def body(c: _Pass) -> _Pass:
        state = c.state
        for _ in range(unroll):  # steps of ended lanes change nothing
            state = step(state, c.lane)
        c = c._replace(state=state)
        # Refilling touches every lane array: done once enough slots are free (or none
        # is live), not every step.
        n_free = jnp.sum((c.slot >= 0) & ~state.live, dtype=jnp.int32)
        return jax.lax.cond((n_free >= R) | ~jnp.any(state.live), refill, lambda c: c, c)

    first = jnp.arange(B, dtype=jnp.int32)
    lane, state = begin(order[first], first < n_real)
    result = _Result(jnp.full(L, am.TIMEOUT, jnp.int32), jnp.full(L, -1, jnp.int32),
                     jnp.zeros(L, jnp.int32), jnp.zeros((L, 3), dtype), jnp.zeros(L, dtype),
                     jnp.zeros((L, 4), dtype), jnp.zeros(L, jnp.int32))
    init = _Pass(lane, state, jnp.where(first < n_real, order[first], -1),
                 jnp.minimum(n_real, B), result)
    end = jax.lax.while_loop(lambda c: jnp.any(c.state.live) | (c.next < n_real), body, init)
    result = write(end.result, end.slot, end.lane, end.state, first, end.slot >= 0)
    out = am.Outcome(result.code, result.activated, result.step, result.point,
                     result.path_length)
    return jax.tree.map(lambda a: a.reshape(S, N, T, *a.shape[1:]),
                        (out, result.r, result.meta_steps))


def is_perfect(params: Params) -> Bool[Array, "..."]:
    """Where the user is the perfect one: every user parameter zero, aiming at the
    space."""
    return ((params.user_noise <= 0) & (params.user_lag <= 0) & (params.user_tremor <= 0)
            & ~params.user_aim_object & ~params.activation_swept)
