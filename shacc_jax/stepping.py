"""The stepping engine: every rollout of one mode stepped, for imperfect users.

A step composes named parts, each in its own module: the user's command
(``user_models``: where the user looks, what it commands, where the gripper ends up),
the activation check (``activation``: sdfs, the activated task, collisions) and the
assistance (``assistance``: today the meta skill's turn of R), all on one lane's
constants and state (``rollout_state``) with the rollout's random numbers
(``streams``, ``populations``). The scheduler (``lanes.run_queue``) runs the lanes
through a block of slots, refilling a slot from a queue when its rollout ends.

Per step, every live lane moves; the lanes whose clearance allows it skip the check
(``activation``), and at most 1 / share of the slots are gathered and checked in full.
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool

from geometry_precompute.schema import lanes_per_block_default

from . import automaton as am
from . import lanes as scheduler
from . import quaternion as quat
from . import shapes
from .activation import CLEARANCE_MARGIN, SceneView, check, sdfs
from .assistance import CORRECT, WRONG, assist_position, first_assistance, prepare
from .flatmap import stacked, unstacked
from .hulls import Hulls
from .populations import with_population
from .rollout_state import Lane, State
from .rows import row, rows
from .streams import rollout_draws, rollout_key, step_key
from .types import INTENT_MODES, Geometry, Layout, Params
from .user_models import aim, is_perfect, move, shake
from .vec3 import length, of, xyz

# A block checks in full at most a 1 / share of its lanes per step (1: all, without
# gathering the others out); a lane that needs a full check and finds no place waits a
# step (its rollout is unchanged by waiting). The mode with the meta skill needs a full
# check on about 40 % of its live steps (inside a meta region R turns every step), the
# others on about 8 %; the intent modes' assistance reads every task each step, so they
# check every lane every step.
FULL_CHECK_SHARE = {"meta": 4, "other": 8, "intent": 1}
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
# Per kind of mode, whether an iteration's steps are a loop of one traced step
# (``lanes.run_queue``; XLA knows its trip count, so it adds no round trip) rather than
# each step traced and compiled on its own. On an H100 (10.8 M rollouts, two calls,
# 2026-12-07): every user setting ran 1.282-1.284 s with the loop against 1.322 s
# unrolled, and compiled in 12.9-13.6 s against 41-46 s. The intent modes ran 4.093 s
# with the loop (19 s to compile), 3.843 s with two steps unrolled in it (27 s),
# against 3.517 s unrolled (69 s): XLA fuses across their unrolled steps, so they keep
# them.
ROLLED = {"meta": True, "other": True, "intent": False}
# Per backend, whether a mode on the initial spaces without the meta skill runs in the
# pass of its partner (FOLDS) rather than in a loop of its own: one loop fewer to
# compile. On the 2-core CPU (benchmarks/bench_phases.py, three shipped scenes), the
# program with every user setting for the paper's three modes traced, lowered and
# compiled in 6.7-6.8 s against 9.4-10.5 s (benchmarks/RESULTS.md). On an
# H100 (as above) it saved 5 s of the 13 s compile but ran 1.296 s against 1.282 s, and
# the intent modes 4.94 s against 4.09 s: accelerators keep a loop per mode.
FOLD = {"cpu": True, "accelerator": False}
# The modes that run in a partner's pass (:func:`folded_pass`), partners in order of
# preference: the partner with no clusters and its optimised spaces set to the initial
# ones steps exactly as the mode does (no meta region, so the meta skill never turns
# R; shacc_ho is then ho).
FOLDS = {"baseline": ("shacc", "shrinking"), "ho": ("shacc_ho",)}


def _make_lane(geometry: Geometry, params: Params, spaces: shapes.Prepared, which: str,
               populations: bool, intent: bool, scene: Array, start: Array,
               target: Array) -> Lane:
    """One lane's constants (vmapped over a block); with ``populations``, its drawn user
    settings. With ``intent`` (an intent mode: the robot changes the step) no lane takes
    the perfect user's straight path."""
    g, x, sp = rows(geometry, scene), rows(params, scene), rows(spaces, scene)
    dtype = geometry.starts.dtype
    pose = row(g.starts, start)
    key = rollout_key(x.user_seed, g.scene_key, target, row(g.start_index, start))
    if populations:
        x = with_population(key, x, dtype)
    # Drawn (or plain): the distributions are not carried in the lane's state.
    x = x._replace(user_dist=jnp.zeros((), jnp.int32), user_dist_args=jnp.zeros((), dtype),
                   user_dist_values=jnp.zeros((), dtype))
    n = am.rollout_numbers(x, dtype)

    def space(task):
        return rows((g.kind, getattr(g, f"center_{which}"), getattr(g, f"quat_{which}"),
                     getattr(g, f"dims_{which}"), sp.trig), task)

    path = am.straight_path(sp, target, pose[:3], n["step_length"], n["max_steps"])
    once = rollout_draws(key, dtype)
    # A change of mind (drawn with probability user_switch): first another of the
    # scene's real tasks, each as likely; a one-task scene has none to head for.
    n_real = jnp.sum(g.task_mask).astype(jnp.int32)
    pick_other = jnp.minimum((once.other * (n_real - 1).astype(dtype)).astype(jnp.int32),
                             jnp.maximum(n_real - 2, 0))
    other = jnp.where(pick_other >= target, pick_other + 1, pick_other)
    decoy = jnp.where((once.switch < x.user_switch) & (n_real > 1), other, target)
    # The wandering hand: w_{k+1} = a w_k + sqrt(1 - a^2) user_noise xi_k.
    tau = x.user_noise_tau
    ou_a = jnp.where(tau > 0, jnp.exp(-x.dt / jnp.where(tau > 0, tau, 1.0)), 0.0)
    ou_b = jnp.sqrt(jnp.maximum(1.0 - ou_a * ou_a, 0.0)) * x.user_noise
    switch_steps = jnp.round(x.user_mode_switch_s / x.dt)
    perfect = is_perfect(x) & (not intent)
    return Lane(scene, target, x, pose[:3], pose[3:], row(g.task_mask, target), perfect,
                step_key(key), once, space(target), row(g.aim_point, target),
                path.c0, path.u, path.length, decoy, space(decoy), row(g.aim_point, decoy),
                ou_a.astype(dtype), ou_b.astype(dtype), switch_steps.astype(jnp.int32))


def _distance_to_decoy(lane: Lane, p: Array) -> Array:
    """The distance from p to the space of the task the lane heads for first."""
    kind, center, orientation, dims, trig = lane.decoy_own
    c = shapes.project_components(kind, center, quat.matrix_entries(orientation), dims, trig,
                                  of(p))
    return length(xyz(lambda i: c[i] - p[i]))


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


class Result(NamedTuple):
    """Every lane's answers, (L, ...) in lane order, written as lanes end."""

    code: Array
    activated: Array
    step: Array
    point: Array
    path_length: Array
    r: Array
    meta_steps: Array
    correct: Array | None = None
    wrong: Array | None = None


def stepped_pass(geometry: Geometry, params: Params, layout: Layout, mode: str,
                 backend: str = "cpu") -> tuple:
    """Every rollout of one mode, stepped: the Outcome (S, N, T), R at the end (S, N,
    T, 4) and the meta steps (S, N, T); for an intent mode also the steps under each
    kind of assistance (S, N, T, 4). The mode decides the spaces (the initial ones for
    baseline, blend and ho, the optimised ones for the others) and the assistance (the
    meta skill in shacc and shacc_ho, ``assistance``'s intent policies in blend, ho
    and shacc_ho, which check every step in full); the layout the checks, the slots and
    the scheme of the loop.

    One loop of steps over ``layout.lanes_per_block`` slots, each holding one rollout
    (a lane: scene, start, task). Each step moves every live lane
    (``user_models.move``); the lanes whose clearance allows it skip the check, and at
    most a 1 / share of the slots are gathered and checked in full
    (``activation.check``; the share and the steps per loop iteration are
    ``layout.stepping``, or the mode's :data:`FULL_CHECK_SHARE` and the backend's
    :data:`STEPPING`; with ``layout.populations`` the lanes draw their user settings,
    ``populations.with_population``). A slot whose rollout has ended (an activation,
    a collision or max_steps) writes its answers and takes the next lane of the queue
    (``lanes.run_queue``). The queue holds the real lanes sorted by the perfect user's
    landing step, longest first, so that the last rollouts, which run while slots
    empty, are short ones; padded tasks are not run."""
    which = "init" if mode in ("baseline", "blend", "ho") else "opt"
    track = mode in ("shacc", "shacc_ho")  # the meta weights reuse the check's sdfs of "opt"
    intent = mode if mode in INTENT_MODES else None
    lanes_per_block = layout.lanes_per_block or lanes_per_block_default(
        backend, stepped_users=True)
    S, N, T = geometry.starts.shape[0], geometry.starts.shape[1], geometry.task_mask.shape[1]
    L = S * N * T
    dtype = geometry.starts.dtype
    spaces = jax.vmap(lambda g: g.spaces(which))(geometry)
    meta = prepare(geometry) if track else None
    scene = jnp.repeat(jnp.arange(S, dtype=jnp.int32), N * T)
    start = jnp.tile(jnp.repeat(jnp.arange(N, dtype=jnp.int32), T), S)
    task = jnp.tile(jnp.arange(T, dtype=jnp.int32), S * N)
    # Per-lane arrays keep the lane axis last ((3, B), (T, B)): the per-lane code's
    # small vectors are then rows of whole arrays, which XLA vectorises across lanes.
    # The hulls are read where the gripper is near a mesh, not gathered for every lane.
    per_lane = geometry._replace(obj_hull=None, obj_hull_plane=None)  # type: ignore[arg-type]
    make = jax.vmap(partial(_make_lane, per_lane, params, spaces, which, layout.populations,
                            intent is not None), out_axes=-1)
    lanes = partial(jax.vmap, in_axes=-1, out_axes=-1)

    def landing(s, n, t):
        x = am.rollout_numbers(rows(params, s), dtype)
        path = am.straight_path(rows(spaces, s), t,
                                geometry.starts[s, n, :3], x["step_length"], x["max_steps"])
        return jnp.where(geometry.task_mask[s, t], path.landing, -1.0)

    order = jnp.argsort(-jax.vmap(landing)(scene, start, task)).astype(jnp.int32)
    n_real = (jnp.sum(geometry.task_mask) * N).astype(jnp.int32)
    B = min(lanes_per_block, L)
    kind = "intent" if intent else "meta" if track else "other"
    share, unroll = layout.stepping or (FULL_CHECK_SHARE[kind],
                                        STEPPING[backend if backend in STEPPING
                                                 else "accelerator"])
    F = max(1, B // share)

    hulls = Hulls.of(geometry) if layout.collision_checks else None

    def scene_of(scene) -> SceneView:
        return SceneView(rows(per_lane, scene), rows(spaces, scene),
                         None if meta is None else rows(meta, scene), hulls)

    def checked(ln, p, r, step=None, sd=None):
        return check(scene_of(ln.scene), ln, p, r, layout, track, step, sd, intent)

    def once(tree, token):
        # On a CPU, values read by several fusions are computed once (:func:`_once`).
        return _once(tree, token) if backend == "cpu" else tree

    def begin(ids, occupied):
        """The lanes ``ids`` and their states before the first step (checked at the
        start)."""
        lane = make(scene[ids], start[ids], task[ids])
        n = ids.shape[0]
        p_start = jnp.where(lane.perfect, lane.p0,
                            lane.p0 + lanes(shake)(lane, jnp.zeros(n, dtype)))
        first = lanes(checked)(lane, p_start, lane.r0)
        zero = jnp.zeros(n, dtype)
        correct = wrong = assist = None
        if intent is not None:
            # V_j(p_0), the distances from the gripper's start to every space, and the
            # first step's position assistance from the posterior there.
            def at_start(ln, p):
                view = scene_of(ln.scene)
                return first_assistance(ln, view.spaces, view.geometry.task_mask, p, intent)

            v0, assist = lanes(at_start)(lane, first.p)
            lane = lane._replace(v0=v0)
            correct = wrong = jnp.zeros(n, jnp.int32)
        live = occupied & lane.real & ~first.done & (lane.x.max_steps > 0)
        w0 = lanes(lambda ln: of(ln.x.user_noise * ln.once.noise0))(lane)
        mode = pause = turned = d0 = None
        if layout.joystick:
            mode, pause = jnp.full(n, -1, jnp.int32), jnp.zeros(n, jnp.int32)
        if layout.switching:
            # The distance from the start to the first-headed task's space (a change
            # of mind turns when it has fallen far enough).
            turned = lane.decoy == lane.target
            d0 = lanes(_distance_to_decoy)(lane, first.p)
        return lane, State(zero, of(lane.p0), of(first.p), w0, mode, pause, turned, d0,
                           lane.r0, jnp.zeros(n, jnp.int32), zero, first.done, first.code,
                           first.activated, first.clear, zero, live, correct, wrong, assist)

    def finish(ln, e):
        code = jnp.where(e.done, e.code, am.TIMEOUT)
        activated = jnp.where(e.done, e.activated, -1)
        k = jnp.where(e.done, e.k, ln.x.max_steps.astype(dtype))
        return Result(code, activated, k.astype(jnp.int32), jnp.stack(e.p), e.travelled, e.r,
                      e.meta_steps, e.correct, e.wrong)

    def step(s: State, lane: Lane) -> State:
        # Steps are never negative: a condition true at run time that XLA cannot fold.
        token = s.k[0] >= 0
        m = lanes(move)(lane, s, once(lanes(partial(aim, decoys=layout.switching))(lane, s),
                                      token))
        if intent is not None:
            m = lanes(assist_position)(lane, s, m)
        tol = lane.x.activation_tol + CLEARANCE_MARGIN
        need = s.live & (s.clear - m.moved <= tol)

        def full(ln, st, mv):
            def at_gripper(ln, mv):
                view = scene_of(ln.scene)
                return sdfs(view.spaces, view.meta, jnp.stack(mv.p), track)
            sd = once(lanes(at_gripper)(ln, mv), token)
            return lanes(lambda ln, st, mv, sd: checked(ln, jnp.stack(mv.p), st.r, (st, mv),
                                                        sd))(ln, st, mv, sd)

        if F >= B:  # share 1, every lane checked: no gathering
            got = need
            c = full(lane, s, m)
            sub_s = s

            def put(a, v):
                return jnp.where(got, v, a)
        else:
            idx, at, got = scheduler.first_true(need, F)
            pick = (lambda a: a[..., idx])  # noqa: E731
            sub_s, sub_m, sub_lane = (jax.tree.map(pick, t) for t in (s, m, lane))
            c = full(sub_lane, sub_s, sub_m)

            def put(a, v):
                return scheduler.put_at(a, at, v)

        go = s.live & (~need | got)

        def adv(new, old):
            return jax.tree.map(lambda a, b: jnp.where(go, a, b), new, old)

        p_new = tuple(put(m.p[i], c.p[i]) for i in range(3))
        t = State(adv(m.k, s.k), adv(m.q, s.q), adv(p_new, s.p), adv(m.w, s.w),
                  adv(m.mode, s.mode), adv(m.pause, s.pause), adv(m.turned, s.turned), s.d0,
                  put(s.r, c.r),
                  put(s.meta_steps, sub_s.meta_steps + c.counted.astype(jnp.int32)),
                  adv(put(m.travelled, c.travelled), s.travelled),
                  put(s.done, c.done), put(s.code, c.code), put(s.activated, c.activated),
                  put(s.clear, c.clear), adv(put(m.moved, jnp.zeros_like(c.clear)), s.moved),
                  s.live, *counts(s, sub_s, c, put))
        steps = lane.x.max_steps.astype(dtype)
        return t._replace(live=s.live & ~(go & (t.done | (t.k >= steps))))

    def counts(s, sub_s, c, put):
        """The intent modes' counts of steps towards the lane's task and another, and the
        next step's position assistance."""
        if intent is None:
            return None, None, None
        return (put(s.correct, sub_s.correct + (c.kind == CORRECT).astype(jnp.int32)),
                put(s.wrong, sub_s.wrong + (c.kind == WRONG).astype(jnp.int32)),
                jax.tree.map(put, s.assist, c.assist))

    counters = (jnp.zeros(L, jnp.int32), jnp.zeros(L, jnp.int32)) if intent else (None, None)
    result = Result(jnp.full(L, am.TIMEOUT, jnp.int32), jnp.full(L, -1, jnp.int32),
                    jnp.zeros(L, jnp.int32), jnp.zeros((L, 3), dtype), jnp.zeros(L, dtype),
                    jnp.zeros((L, 4), dtype), jnp.zeros(L, jnp.int32), *counters)
    result = scheduler.run_queue(order, n_real, B, REFILL_SHARE, unroll, begin, step,
                                 finish, result, ROLLED[kind])
    out = am.Outcome(result.code, result.activated, result.step, result.point,
                     result.path_length)
    parts: tuple = (out, result.r, result.meta_steps)
    if intent is not None:
        assert result.correct is not None and result.wrong is not None
        scene_steps, correct, wrong = result.meta_steps, result.correct, result.wrong
        parts += (jnp.stack([result.step - scene_steps - correct - wrong, scene_steps, correct,
                             wrong], axis=-1),)
    return jax.tree.map(lambda a: a.reshape(S, N, T, *a.shape[1:]), parts)


def folded_pass(geometry: Geometry, params: Params, layout: Layout, mode: str, into: str,
                backend: str = "cpu") -> tuple[tuple, tuple]:
    """:func:`stepped_pass` of ``mode`` and of its partner ``into`` (:data:`FOLDS`) in one
    loop: the lanes of ``into`` and those of a copy of every scene without clusters
    whose optimised spaces are its initial ones, on which ``into`` steps as ``mode``
    does (same scene keys, so the same random numbers). Returns (``mode``'s parts,
    ``into``'s parts), each as :func:`stepped_pass` gives them."""
    if into not in FOLDS.get(mode, ()):
        raise ValueError(f"mode {mode!r} cannot run in the pass of {into!r} "
                         f"(stepping.FOLDS: {FOLDS})")
    plain = geometry._replace(center_opt=geometry.center_init, quat_opt=geometry.quat_init,
                              dims_opt=geometry.dims_init,
                              cluster=jnp.full_like(geometry.cluster, -1))
    both = stepped_pass(stacked(plain, geometry), stacked(params, params), layout, into,
                        backend)
    got, into_got = unstacked(both, 2)
    return got, into_got
