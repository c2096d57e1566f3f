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

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from . import automaton as am
from . import quaternion as quat
from . import shapes
from .meta import meta_target_batch, meta_target_yaw_batch, yaw_directions
from .types import Geometry, Params

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
    ``key``."""
    a, b = jax.random.split(jax.random.fold_in(jax.random.fold_in(key, 1),
                                               k.astype(jnp.uint32)))
    u = jax.random.uniform(b, (2,), dtype)
    return StepDraws(jnp.abs(jax.random.normal(a, (), dtype)), 2.0 * jnp.pi * u[0], u[1])


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


def turn_across(u: Float[Array, "3"], angle: Array, axis_angle: Array) -> Float[Array, "3"]:
    """The unit vector u turned by ``angle`` about the axis a = cos(psi) e1 + sin(psi)
    e2 across it, psi = ``axis_angle``; (e1, e2, u) right-handed, e1 from the world x
    axis (the y axis where u is within 25 degrees of x). Rodrigues' formula with a
    perpendicular to u: u cos(angle) + (a x u) sin(angle).

    >>> import jax.numpy as jnp
    >>> v = turn_across(jnp.array([0., 0, 1]), jnp.pi / 2, 0.0)
    >>> [round(float(x), 6) + 0.0 for x in v]
    [0.0, -1.0, 0.0]
    """
    h = jnp.where(jnp.abs(u[0]) > 0.9, jnp.array([0.0, 1.0, 0.0], u.dtype),
                  jnp.array([1.0, 0.0, 0.0], u.dtype))
    e1 = h - jnp.dot(h, u) * u
    e1 = e1 / jnp.sqrt(jnp.dot(e1, e1))
    e2 = jnp.cross(u, e1)
    # a x u = cos(psi) (e1 x u) + sin(psi) (e2 x u) = -cos(psi) e2 + sin(psi) e1
    across = jnp.sin(axis_angle) * e1 - jnp.cos(axis_angle) * e2
    return jnp.cos(angle) * u + jnp.sin(angle) * across


def _components_first(sp: shapes.Prepared) -> shapes.Prepared:
    """One scene's prepared spaces (leading T) in the meta kernels' layout: (T,) and
    components first, (3, T), (3, 3, T)."""
    return shapes.Prepared(sp.kind, sp.center.T, jnp.moveaxis(sp.rot, 0, -1), sp.dims.T,
                           sp.trig.T)


class _State(NamedTuple):
    k: Array          # steps taken
    q: Array          # commanded position (3,)
    p: Array          # gripper position (3,)
    last: Array       # the previous step's displacement (3,)
    r: Array          # orientation (4,)
    meta_steps: Array
    travelled: Array  # path length of the commanded position, m
    done: Array       # activated
    active: Array     # (T,) the active set at the end
    sdf: Array        # (T,) the sdfs there


def _rollout(g: Geometry, x: Params, spaces: shapes.Prepared, meta, formula: str,
             p0: Float[Array, "3"], r0: Float[Array, "4"], target: Int[Array, ""],
             start: Int[Array, ""], track: bool, swept_checks: bool):
    """One stepped rollout: (Outcome, R at the end, steps in a meta region). The swept
    activation check is traced only where ``swept_checks`` (some scene asks for it)."""
    dtype = p0.dtype
    n = am.rollout_numbers(x, dtype)
    step_length, tau, max_steps = n["step_length"], n["tau"], n["max_steps"]
    key = rollout_key(x.user_seed, g.scene_key, target, start)
    once = rollout_draws(key, dtype)
    perfect = is_perfect(x)
    path = am.straight_path(spaces, target, p0, step_length, max_steps)
    own = jax.tree.map(lambda a: a[target], spaces)
    omega_dt = 2.0 * jnp.pi * x.user_tremor_hz * x.dt
    inf = jnp.asarray(jnp.inf, dtype)

    def shake(k):
        return x.user_tremor * jnp.sin(omega_dt * k + once.tremor_phase) * once.tremor_axis

    def check(p):
        sd = jnp.where(g.task_mask, shapes.all_sdf(spaces, p), inf)
        return sd <= tau, sd

    def turn(r, p):
        if not track:
            return r, jnp.zeros((), bool)
        init, opt, fixed_dir = meta
        common = (init, opt, g.task_mask, g.cluster, g.orient_kind)
        pp = p[:, None]  # (components, tasks)
        goals = []
        if formula in ("yaw", "both"):
            inside, goal = meta_target_yaw_batch(*common, fixed_dir.T, g.orient_axis.T, pp,
                                                 tau)
            goals.append(goal)
        if formula in ("general", "both"):
            inside, goal = meta_target_batch(*common, g.orient_quat.T, g.orient_axis.T, pp,
                                             tau)
            goals.append(goal)
        if formula == "both":  # the region test is the same; the target's formula is not
            goal = jnp.where(g.yaw_meta, goals[0], goals[1])
        return jnp.where(inside, quat.rotate_towards(r, goal, n["max_angle"]), r), inside

    def swept_entry(s: _State, p, active, sd, delta, travelled):
        """activation_check = swept: where the gripper's segment from s.p to p first
        enters a space, that point activates (for the lanes that ask for it)."""
        seg = p - s.p
        seg_len = jnp.sqrt(jnp.dot(seg, seg))
        along = seg / jnp.where(seg_len > 0, seg_len, 1.0)
        lo, hi = shapes.all_ray_intervals(spaces, s.p, along, n["grow"])
        enters = g.task_mask & (lo <= hi) & (lo <= seg_len) & (hi >= 0) & (seg_len > 0)
        # The intervals contain the spaces' tau-sublevel sets (a little more, near
        # edges): from the first interval's start, sphere tracing (the sdf is
        # 1-Lipschitz, so a step of min sdf - tau never passes an entry) reaches the
        # first entry into any space.
        t_hit = jnp.min(jnp.where(enters, jnp.maximum(lo, 0.0), inf))
        t_hit = jnp.where(jnp.isfinite(t_hit), t_hit, 0.0)

        def trace(_, t):
            gap = jnp.min(jnp.where(g.task_mask, shapes.all_sdf(spaces, s.p + t * along), inf))
            return t + jnp.maximum(gap - tau, 0.0)

        t_hit = jax.lax.fori_loop(0, SPHERE_TRACING_STEPS, trace, t_hit)
        p_hit = s.p + t_hit * along
        sd_hit = jnp.where(g.task_mask, shapes.all_sdf(spaces, p_hit), inf)
        # The entry point lies on the boundary of tau; rounding may put it a hair
        # outside, which the closed form's interval slack covers.
        act_hit = sd_hit <= n["grow"]
        swept = (x.activation_swept & jnp.any(enters) & jnp.any(act_hit)
                 & (t_hit <= seg_len))
        p = jnp.where(swept, p_hit, p)
        active = jnp.where(swept, act_hit, active)
        sd = jnp.where(swept, sd_hit, sd)
        travelled = jnp.where(swept, s.travelled + jnp.sqrt(jnp.dot(delta, delta))
                              * (t_hit / jnp.where(seg_len > 0, seg_len, 1.0)), travelled)
        return p, active, sd, travelled

    def step(s: _State) -> _State:
        c = jnp.where(x.user_aim_object, g.aim_point[target], shapes.prepared_project(own, s.p))
        d = c - s.p
        length = jnp.sqrt(jnp.dot(d, d))
        moving = length > 0
        u = d / jnp.where(moving, length, 1.0)
        draw = step_draws(key, s.k.astype(jnp.int32), dtype)
        turned = turn_across(u, x.user_noise * draw.noise, draw.axis_angle)
        fresh = jnp.where(moving, jnp.minimum(step_length, length) * turned, 0.0)
        lagging = (s.k > 0) & (draw.lag < x.user_lag)
        delta = jnp.where(lagging, s.last, fresh)
        k = s.k + 1.0
        q = s.q + delta
        # A perfect user's lane takes the closed form's samples (the same points).
        p = jnp.where(perfect, am.sample(path, k), q + shake(k))
        active, sd = check(p)
        travelled = jnp.where(perfect, jnp.minimum(k * step_length, path.length),
                              s.travelled + jnp.sqrt(jnp.dot(delta, delta)))
        if swept_checks:
            p, active, sd, travelled = swept_entry(s, p, active, sd, delta, travelled)
        done = jnp.any(active)
        r, inside = turn(s.r, p)
        r = jnp.where(done, s.r, r)
        counted = inside & ~done
        return _State(k, q, p, delta, r, s.meta_steps + counted.astype(jnp.int32), travelled,
                      done, active, sd)

    p_start = jnp.where(perfect, p0, p0 + shake(jnp.zeros((), dtype)))
    active0, sd0 = check(p_start)
    init = _State(jnp.zeros((), dtype), p0, p_start, jnp.zeros(3, dtype), r0,
                  jnp.zeros((), jnp.int32), jnp.zeros((), dtype), jnp.any(active0), active0, sd0)
    steps = max_steps.astype(dtype)
    # A padded target task's rollout is not run (its outcome is INVALID).
    real = g.task_mask[target]
    end = jax.lax.while_loop(lambda s: real & ~s.done & (s.k < steps), step, init)
    act = am.Activation(jnp.where(end.done, end.k, inf), end.active, end.sdf)
    code, activated = am.outcome_codes(act, target, x.ambiguity_nearest)
    k = jnp.where(end.done, end.k, steps)
    out = am.Outcome(code, activated, k.astype(jnp.int32), end.p, end.travelled)
    return out, end.r, end.meta_steps


def stepped_pass(geometry: Geometry, params: Params, which: str, track: bool,
                 formula: str, lanes_per_block: int,
                 swept_checks: bool = False) -> tuple[am.Outcome, Array, Array]:
    """Every rollout of one mode, stepped: the Outcome (S, N, T), R at the end (S, N,
    T, 4) and the meta steps (S, N, T). ``which``: the mode's spaces (``init`` or
    ``opt``); ``track``: with the meta skill; ``formula``: ``Layout.meta_formula``.

    The lanes (scene, start, task) run in blocks of ``lanes_per_block``, one block after
    another, each stepping until its last lane ends (an activation or max_steps): a
    block is only as long as its slowest lane, not the batch's. The lanes are sorted by
    the perfect user's landing step first, so that a block's lanes take about as many
    steps as each other; padded tasks come last and take none."""
    S, N, T = geometry.starts.shape[0], geometry.starts.shape[1], geometry.task_mask.shape[1]
    L = S * N * T
    spaces = jax.vmap(lambda g: g.spaces(which))(geometry)
    meta = None
    if track:
        meta = jax.vmap(lambda g: (_components_first(g.spaces("init")),
                                   _components_first(g.spaces("opt")),
                                   yaw_directions(g.orient_quat)[0]))(geometry)
    scene = jnp.repeat(jnp.arange(S, dtype=jnp.int32), N * T)
    start = jnp.tile(jnp.repeat(jnp.arange(N, dtype=jnp.int32), T), S)
    task = jnp.tile(jnp.arange(T, dtype=jnp.int32), S * N)

    def landing(s, n, t):
        x = am.rollout_numbers(jax.tree.map(lambda a: a[s], params), geometry.starts.dtype)
        path = am.straight_path(jax.tree.map(lambda a: a[s], spaces), t,
                                geometry.starts[s, n, :3], x["step_length"], x["max_steps"])
        return jnp.where(geometry.task_mask[s, t], path.landing, -1.0)

    B = min(lanes_per_block, L)
    n_blocks = -(-L // B)
    order = jnp.argsort(-jax.vmap(landing)(scene, start, task))
    order = jnp.concatenate([order, jnp.full(n_blocks * B - L, order[-1])])

    def one(lane):
        s, n, t = scene[lane], start[lane], task[lane]
        pick = (lambda a: a[s])  # noqa: E731
        g, x = jax.tree.map(pick, geometry), jax.tree.map(pick, params)
        pose = geometry.starts[s, n]
        return _rollout(g, x, jax.tree.map(pick, spaces),
                        None if meta is None else jax.tree.map(pick, meta), formula,
                        pose[:3], pose[3:], t, geometry.start_index[s, n], track,
                        swept_checks)

    out = jax.lax.map(jax.vmap(one), order.reshape(n_blocks, B))
    inverse = jnp.zeros(L, order.dtype).at[order[:L]].set(jnp.arange(L, dtype=order.dtype))
    return jax.tree.map(lambda a: a.reshape(n_blocks * B, *a.shape[2:])[inverse].reshape(
        S, N, T, *a.shape[2:]), out)


def is_perfect(params: Params) -> Bool[Array, "..."]:
    """Where the user is the perfect one: every user parameter zero, aiming at the
    space."""
    return ((params.user_noise <= 0) & (params.user_lag <= 0) & (params.user_tremor <= 0)
            & ~params.user_aim_object & ~params.activation_swept)
