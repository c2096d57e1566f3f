"""The one entry point: evaluate a batch of baked scenes in every mode, from every
start, for every task, in one jitted computation, :func:`evaluate`.

Kernels are written for one rollout (``automaton``); this module composes them:
the activation pass (vmapped over tasks, starts and scenes), then, for the shacc
mode and for collision checks, work over each rollout's window of samples through
the lane scheduler (``lanes``) with one per-block step that joins the orientation
tracking (``tracking``) and the gripper checks (``collision``), then the outcomes
and per-scene metrics. Baseline uses the initial spaces; shrinking and shacc the
optimised ones. Without collision checks a rollout's path and activation do not
depend on the orientation, so shrinking and shacc share one activation pass (the
NumPy reference test checks the modes independently).

Inputs are the bake's three parts (``geometry_precompute.schema``): Geometry and
Params are pytrees of arrays, Layout is static. Params may carry a leading axis of
P sweep points: they are folded into the scenes axis (geometry repeated), so the lane
scheduler sorts the lanes of all points together, and the outputs get a leading P.
"""

from __future__ import annotations

from dataclasses import replace
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array

from geometry_precompute.schema import PARAMS, lanes_per_block_default

from . import automaton as am
from . import collision as col
from . import lanes as lane_scheduler
from . import path_cull as cull
from . import populations, stepping, tracking
from .flatmap import spread, stacked, unstacked, vmap_leading
from .metrics import batch_metrics
from .types import (
    COLLISION,
    INTENT_MODES,
    INVALID,
    Evaluation,
    Geometry,
    Layout,
    Params,
    Rollouts,
)

_TRAILING = {f.name: f.shape[1:] for f in PARAMS}  # a Params leaf's axes after S


class Windows(NamedTuple):
    """Per lane (L = S N T, in lane order): the samples the lane pass visits. The meta
    window (tracking) and the collision window, each from .. to (empty when from >
    to); the joined window's first sample and length (0: nothing to do); and which
    objects the gripper can touch in the collision window (L, O)."""

    meta_from: Array
    meta_to: Array
    collide_from: Array
    collide_to: Array
    start: Array
    length: Array
    touch: Array


class LaneState(NamedTuple):
    """What the lane pass carries per lane (L,): the orientation (L, 4), the meta
    steps counted, and the first colliding sample (inf for none)."""

    r: Array
    meta_steps: Array
    hit: Array


def _windows(geometry: Geometry, params: Params, path: am.Path, act_step: Array,
             prep: tracking.Prepared | None, collide: bool) -> Windows:
    """The lanes' :class:`Windows`.
    ``path`` and ``act_step``: (S, N, T); ``prep``: the tracking's prepared spaces, None
    without tracking. Mapped over scenes, then starts and tasks, so that a scene's
    arrays are read in place rather than gathered once per lane."""
    dtype = geometry.starts.dtype
    inf = jnp.asarray(jnp.inf, dtype)
    S, N, T = act_step.shape
    bounds = (jax.vmap(cull.object_bounds)(geometry.obj_kind, geometry.obj_center,
                                          geometry.obj_quat, geometry.obj_size)
              if collide else None)
    init = prep.init if prep is not None else None

    def per_scene(g, p, path, k_act, init, bounds):
        x = am.rollout_numbers(p, dtype)

        def one(start, path, k_act):
            if init is not None:
                m_from, m_to = am.meta_window(init, g.task_mask, g.cluster, path, k_act,
                                              x["max_steps"], x["grow"])
            else:
                m_from, m_to = inf, -inf
            if collide:
                turn_from = jnp.where(m_from <= m_to, m_from, inf)
                first, last = cull.path_window(bounds, g.obj_center, g.obj_mask, p.gripper(),
                                              start[3:], path, turn_from, x["max_steps"])
                end = jnp.where(jnp.isfinite(k_act), k_act, x["max_steps"].astype(dtype))
                touch = p.collision & (first <= jnp.minimum(last, end))
                c_from = jnp.min(jnp.where(touch, first, inf))
                c_to = jnp.minimum(jnp.max(jnp.where(touch, last, -inf)), end)
            else:
                c_from, c_to = inf, -inf
                touch = jnp.zeros(g.obj_mask.shape, bool)
            return m_from, m_to, c_from, c_to, touch

        return vmap_leading(one, 2)(spread(g.starts, k_act.shape, (0,)), path, k_act)

    out = jax.vmap(per_scene)(geometry, params, path, act_step, init, bounds)
    m_from, m_to, c_from, c_to, touch = (a.reshape(S * N * T, *a.shape[3:]) for a in out)
    # Padded target tasks get an empty window: their outcome is INVALID anyway, and in a
    # batch of 5- to 10-task scenes padded to 10 they are up to half of the lanes.
    real = jnp.broadcast_to(geometry.task_mask[:, None, :], (S, N, T)).reshape(-1)
    m_ok, c_ok = m_from <= m_to, c_from <= c_to
    w_from = jnp.minimum(jnp.where(m_ok, m_from, inf), jnp.where(c_ok, c_from, inf))
    w_to = jnp.maximum(jnp.where(m_ok, m_to, -inf), jnp.where(c_ok, c_to, -inf))
    length = jnp.where(real & (m_ok | c_ok), w_to - w_from + 1.0, 0.0)
    w_from = jnp.where(length > 0, w_from, 0.0)
    return Windows(m_from, m_to, c_from, c_to, w_from, length, touch)


def _lane_pass(geometry: Geometry, params: Params, path: am.Path, act: am.Activation,
               layout: Layout, track: bool) -> LaneState:
    """Orientation tracking (``track``, the shacc mode) and gripper collision checks
    (``layout.collision_checks``) over every (scene, start, task) lane. Returns the
    lanes' final :class:`LaneState`, each (S, N, T, ...): R, the meta steps and the
    first colliding sample (inf for none).

    Each lane's window (:class:`Windows`) joins its meta window with the samples at
    which the gripper can touch an object (``path_cull.path_window``), up to the
    activation sample. The lane scheduler (``lanes``) runs blocks of lanes x W samples;
    per block (:func:`_block_step`): the rotation rule (``tracking.block_rotation``),
    then the collision checks of all B x W poses at once against the lanes' touchable
    objects (``collision.block_first_penetration``), J at a time (a lane that can touch
    more than J runs once per group of J; the run that collides first counts). A
    collision at sample k ends the lane: R stays as it was at k and the rotations from
    k on are not counted (the step rule checks collisions before it rotates). With
    ``layout.meta_formula`` "both", the lanes of yaw-only scenes and the others get a
    pass each, each compiled for its own target formula."""
    collide = layout.collision_checks
    S, N, T = act.step.shape
    L = S * N * T
    dtype = geometry.starts.dtype
    lanes = tracking.Lanes.of(path)
    prep = tracking.prepare(geometry) if track else None
    win = _windows(geometry, params, path, act.step, prep, collide)
    lane_obj = col.lane_objects(geometry, params, win.touch) if collide else None
    state = LaneState(geometry.starts[lanes.scene, lanes.start, 3:], jnp.zeros(L, jnp.int32),
                      jnp.full(L, jnp.inf, dtype))
    lanes_per_block = layout.lanes_per_block or lanes_per_block_default(
        jax.default_backend(), collide)

    def one_pass(length, formula):
        step = partial(_block_step, geometry, params, layout, lanes, prep, win, lane_obj,
                       formula)
        if lane_obj is None or lane_obj.groups == 1:
            return lane_scheduler.run(length, lanes_per_block, layout.samples_per_block,
                                      state, partial(step, 0))

        # One compiled pass, run per object group over the lanes that have objects in it.
        def group_pass(g):
            busy = jnp.where((g == 0) | (lane_obj.n_touch > g * lane_obj.per_group), length,
                             0.0)
            return lane_scheduler.run(busy, lanes_per_block, layout.samples_per_block,
                                      state, partial(step, g))

        r, n, hit = jax.lax.map(group_pass, jnp.arange(lane_obj.groups))
        # The group that collides first ended the lane; without a collision all agree
        # with group 0 (argmin of all-inf is 0).
        pick = jnp.argmin(hit, axis=0)
        return LaneState(r[pick, jnp.arange(L)], n[pick, jnp.arange(L)],
                         hit[pick, jnp.arange(L)])

    if not track or layout.meta_formula != "both":
        result = one_pass(win.length, layout.meta_formula)
    else:
        yaw_lane = geometry.yaw_meta[lanes.scene]
        yaw_part = one_pass(jnp.where(yaw_lane, win.length, 0.0), "yaw")
        general_part = one_pass(jnp.where(yaw_lane, 0.0, win.length), "general")
        result = LaneState(*(jnp.where(yaw_lane.reshape((L,) + (1,) * (a.ndim - 1)), a, b)
                             for a, b in zip(yaw_part, general_part, strict=True)))
    return LaneState(*(a.reshape(S, N, T, *a.shape[1:]) for a in result))


def _block_step(geometry: Geometry, params: Params, layout: Layout, lanes: tracking.Lanes,
                prep: tracking.Prepared | None, win: Windows,
                lane_obj: col.LaneObjects | None, formula: str, group, idx, start, valid,
                rows: LaneState) -> LaneState:
    """One block of the lane pass (``lanes.run``'s ``per_block``): the lanes ``idx``
    at the W samples from ``start`` of their windows (``valid``: within the window),
    with their state ``rows``; tracking where ``prep`` is given, collision checks of
    object group ``group`` where ``lane_obj`` is."""
    W = layout.samples_per_block
    B = idx.shape[0]
    offsets = jnp.arange(W, dtype=start.dtype)
    k = win.start[idx][:, None] + start + offsets[None, :]
    alive = ~jnp.isfinite(rows.hit)
    if prep is not None:
        in_meta = valid & (k >= win.meta_from[idx][:, None]) & (k <= win.meta_to[idx][:, None])
        rot = tracking.block_rotation(geometry, params, prep, lanes, idx, k, in_meta, rows.r,
                                      formula, per_sample=lane_obj is not None)
    else:
        rot = tracking.BlockRotation(rows.r, jnp.broadcast_to(rows.r[:, None, :], (B, W, 4)),
                                     jnp.zeros((B, W), bool))
    r_end = rot.end
    if lane_obj is not None:
        assert rot.at is not None
        # A lane that collided in an earlier block is not checked again.
        in_window = (valid & alive[:, None] & (k >= win.collide_from[idx][:, None])
                     & (k <= win.collide_to[idx][:, None]))
        p = jnp.moveaxis(lanes.points(idx, k), 0, -1)
        first = col.block_first_penetration(lane_obj, lanes.scene[idx], idx, group, p,
                                            rot.at, in_window)
        hit_now = first < W
        first = jnp.minimum(first, W - 1)
        upto = jnp.where(hit_now, first, W)
        r_end = jnp.where(hit_now[:, None], rot.at[jnp.arange(B), first], r_end)
        hit = jnp.where(hit_now, k[jnp.arange(B), first], rows.hit)
    else:
        upto = jnp.full(B, W)
        hit = rows.hit
    counted = rot.turned & (offsets[None, :] < upto[:, None].astype(start.dtype))
    n = rows.meta_steps + jnp.where(alive, jnp.sum(counted, axis=1), 0).astype(
        rows.meta_steps.dtype)
    return LaneState(jnp.where(alive[:, None], r_end, rows.r), n, hit)


def _collided(out: am.Outcome, path: am.Path, hit: Array) -> am.Outcome:
    """the Automaton's ``collision`` outcome where the gripper penetrated an object at
    sample ``hit`` (at or before the activation sample)."""
    found = jnp.isfinite(hit)
    k = jnp.where(found, hit, 0.0)
    point = vmap_leading(am.sample, 3)(path, k)
    return am.Outcome(
        jnp.where(found, COLLISION, out.code),
        jnp.where(found, -1, out.activated),
        jnp.where(found, k.astype(out.step.dtype), out.step),
        jnp.where(found[..., None], point, out.point),
        jnp.where(found, jnp.minimum(k * path.step_length, path.length), out.path_length))


def _with_assist(out: am.Outcome, r, meta_steps, assist=None) -> tuple:
    """A mode's (Outcome, R, meta steps, assistance): ``assist``, the steps under each
    kind of assistance (..., 4), where the mode counts them; else the paper's modes':
    the meta skill's steps are the scene's, the rest none."""
    if assist is None:
        zero = jnp.zeros_like(meta_steps)
        assist = jnp.stack([out.step - meta_steps, meta_steps, zero, zero], axis=-1)
    return out, r, meta_steps, assist


def _assemble(task_mask, orient, drawn, out: am.Outcome, r, meta_steps, assist) -> Rollouts:
    """One scene's rollouts of one mode (``task_mask`` and ``orient``, the scene's
    task mask and (orient_kind, orient_quat, orient_axis); ``drawn``: its users' drawn
    settings, (N, T, U); the rest :func:`_with_assist`'s, (N, T, ...))."""
    lanes = out.code.shape
    dr = vmap_leading(lambda o, r, t: am.delta_r(o, r, orient, t), 2)(
        out, r, spread(jnp.arange(lanes[1], dtype=jnp.int32), lanes, (1,)))
    code = jnp.where(task_mask[None, :], out.code, INVALID)
    return Rollouts(code, out.activated, out.step, out.point, out.path_length, meta_steps, dr,
                    r, drawn, assist)


def _check_shapes(geometry: Geometry, params: Params, layout: Layout) -> int:
    """Shapes against the layout (static information, read while tracing); returns the
    number of sweep points (0: params without a points axis)."""
    S, T = geometry.task_mask.shape
    got = {"n_tasks": T, "n_starts": geometry.starts.shape[1],
           "n_objects": geometry.obj_mask.shape[1]}
    for name, value in got.items():
        if value != getattr(layout, name):
            raise ValueError(f"Layout.{name} is {getattr(layout, name)} but the geometry "
                             f"has {value} (build the layout from this bake)")
    if geometry.start_index.shape != geometry.starts.shape[:2]:
        raise ValueError(f"Geometry.start_index has shape {geometry.start_index.shape}, "
                         f"the starts {geometry.starts.shape[:2]} (replace both together: "
                         "each start's index in its whole grid)")
    # Each leaf is (S, ...) or (P, S, ...), its trailing axes the schema's.
    lead = {a.shape[:a.ndim - len(_TRAILING[k])] for k, a in zip(Params._fields, params,
                                                                  strict=True)}
    if len(lead) != 1 or len(next(iter(lead))) not in (1, 2) or next(iter(lead))[-1] != S:
        raise ValueError(f"every Params leaf must have shape (S, ...) or (P, S, ...) with S = "
                         f"{S} scenes, got leading axes {sorted(lead)}")
    return next(iter(lead))[0] if len(next(iter(lead))) == 2 else 0


def _stepped(geometry: Geometry, params: Params, layout: Layout) -> list[tuple]:
    """Per mode (Outcome, R, meta steps) of a batch with imperfect simulated users:
    every rollout stepped (``stepping.stepped_pass``).

    The shrinking and shacc modes move through the same spaces with the same random
    numbers, and the meta skill turns only R: without collision checks (where R moves
    the gripper's capsules) their paths and outcomes are the same, so one pass with the
    meta skill serves both, as the closed form's activation pass does, and the
    shrinking mode keeps the start's R and no meta steps. Where ``stepping.FOLD`` says
    so (CPUs), baseline runs in shacc's pass (or shrinking's) and ho in shacc_ho's
    (``stepping.folded_pass``): one loop fewer to compile, the same bits."""
    modes = layout.modes
    backend = jax.default_backend()
    shared = "shrinking" in modes and "shacc" in modes and not layout.collision_checks
    run = [m for m in modes if not (m == "shrinking" and shared)]
    folded: dict[str, str] = {}  # a mode run in its partner's pass (stepping.folded_pass)
    if stepping.FOLD.get(backend, stepping.FOLD["accelerator"]):
        for mode in run:
            into = [m for m in stepping.FOLDS.get(mode, ()) if m in run
                    and m not in folded.values()]
            if into:
                folded[mode] = into[0]
    passes = {}
    for mode in run:
        if mode in folded:
            passes[mode], passes[folded[mode]] = stepping.folded_pass(
                geometry, params, layout, mode, folded[mode], backend)
        elif mode not in folded.values():  # else computed with the mode folded into it
            passes[mode] = stepping.stepped_pass(geometry, params, layout, mode, backend)
    if shared:
        out = passes["shacc"][0]
        S, N, T = out.code.shape
        real = geometry.task_mask[:, None, :, None]  # a padded task's R stays zero
        r0 = jnp.where(real, geometry.starts[:, :, None, 3:], 0.0)
        passes["shrinking"] = (out, jnp.broadcast_to(r0, (S, N, T, 4)).astype(out.point.dtype),
                               jnp.zeros((S, N, T), jnp.int32))
    return [passes[mode] for mode in modes]


def _closed_form(geometry: Geometry, params: Params, layout: Layout) -> list[tuple]:
    """Per mode (Outcome, R, meta steps) of the perfect user: the activation pass in
    closed form, then the lane pass where the mode tracks or collisions are checked."""
    modes = layout.modes
    which = (["init"] if "baseline" in modes else []) + (
        ["opt"] if "shrinking" in modes or "shacc" in modes else [])

    def kinds(g: Geometry):
        return jax.tree.map(lambda *xs: jnp.stack(xs), *[g.spaces(w) for w in which])

    # Both kinds of spaces in one pass, traced and compiled once, mapped over the
    # (scene, kind) pairs as one axis.
    pairs = (geometry.task_mask.shape[0], len(which))
    per_scene = jax.tree.map(lambda a: spread(a, pairs, (0,)),
                             (geometry.starts, geometry.task_mask, params))
    both = vmap_leading(am.activation_pass_on, 2)(*per_scene, jax.vmap(kinds)(geometry))
    passes = {w: jax.tree.map(lambda a, i=i: a[:, i], both) for i, w in enumerate(which)}
    S_all, N = geometry.starts.shape[:2]
    T = geometry.task_mask.shape[1]
    r0 = jnp.broadcast_to(geometry.starts[:, :, None, 3:], (S_all, N, T, 4))
    no_meta = jnp.zeros((S_all, N, T), jnp.int32)
    of_mode = {m: passes["init" if m == "baseline" else "opt"] for m in modes}
    lane = _lane_passes(geometry, params, layout, of_mode)
    per_mode = []
    for mode in modes:
        path, _, out = of_mode[mode]
        if mode in lane:
            r, meta_steps, hit = lane[mode]
            out = _collided(out, path, hit)
        else:
            r, meta_steps = r0, no_meta
        per_mode.append((out, r, meta_steps))
    return per_mode


def _lane_passes(geometry: Geometry, params: Params, layout: Layout, of_mode: dict) -> dict:
    """The closed form's lane passes ((R, meta steps, first collision) per mode): the
    shacc mode's, which tracks, and with collision checks every mode's. Where
    ``stepping.FOLD`` says so (CPUs), they run as one pass: the other modes' lanes on
    copies of the scenes without clusters, where the gripper never enters a meta
    region, so the tracking turns nothing and the collision checks see the start's R,
    as in a pass of their own (the same bits); one pass fewer to trace and compile
    per mode. ``of_mode``: each mode's (path, activation, outcome)."""
    modes = [m for m in of_mode if m == "shacc" or layout.collision_checks]
    backend = jax.default_backend()
    if len(modes) < 2 or not stepping.FOLD.get(backend, stepping.FOLD["accelerator"]):
        return {m: _lane_pass(geometry, params, of_mode[m][0], of_mode[m][1], layout,
                              m == "shacc") for m in modes}
    track = "shacc" in modes
    modes = sorted(modes, key=lambda m: m != "shacc")  # shacc's lanes on the scenes
    plain = geometry._replace(cluster=jnp.full_like(geometry.cluster, -1))
    copies = [geometry if m == "shacc" else plain for m in modes]
    got = _lane_pass(stacked(*copies), stacked(*[params] * len(modes)),
                     stacked(*[of_mode[m][0] for m in modes]),
                     stacked(*[of_mode[m][1] for m in modes]), layout, track)
    return dict(zip(modes, unstacked(got, len(modes)), strict=True))


def _per_mode(geometry: Geometry, params: Params, layout: Layout) -> list[tuple]:
    """Per mode of ``layout.modes``, in order, (Outcome, R, meta steps[, assistance]):
    every mode stepped where the users are imperfect; else the paper's modes in closed
    form and the intent modes (whose assistance changes the path) stepped."""
    if layout.stepped_users:
        return _stepped(geometry, params, layout)
    closed = tuple(m for m in layout.modes if m not in INTENT_MODES)
    stepped = tuple(m for m in layout.modes if m in INTENT_MODES)
    got: dict[str, tuple] = {}
    for modes, run in ((closed, _closed_form), (stepped, _stepped)):
        if modes:
            got.update(zip(modes, run(geometry, params, replace(layout, modes=modes)),
                           strict=True))
    return [got[m] for m in layout.modes]


@partial(jax.jit, static_argnames="layout")
def evaluate(geometry: Geometry, params: Params, layout: Layout) -> Evaluation:
    """Evaluate S scenes x M modes x N starts x T tasks (M = ``layout.modes``).

    ``geometry``, ``params``, ``layout``: a bake's three parts
    (:func:`~shacc_jax.types.inputs` builds them). Every rollout setting is a Params
    leaf, so new values reuse the compiled program. With Params leaves of shape
    (P, S), the P sweep points are evaluated in this one call. Returns an
    :class:`~shacc_jax.types.Evaluation` whose rollout arrays are (S, M, N, T), or
    (P, S, M, N, T) with a points axis. Traceable: nothing reads array values on the
    host, so it may be wrapped (``jax.jit(...).lower``, ``shard_map``) like any JAX
    function.

    The rollouts (:class:`~shacc_jax.types.Rollouts`, each (S, M, N, T)): ``outcome``
    (codes of ``shacc_jax.OUTCOMES``), ``activated`` (task index, -1 none), ``steps``,
    ``delta_R`` (rad, NaN unless success), ``meta_steps``, ``path_length`` (m) and
    more; the metrics (:class:`~shacc_jax.types.SceneMetrics`, (S, M)): ``u_scene``,
    ``delta_R_mean`` (rad), ``outcome_counts`` (S, M, 5), ``n_rollouts``.

    Example::

        geometry, params, layout = shacc_jax.inputs(bake(results))
        ev = shacc_jax.evaluate(geometry, params, layout)
        ev.rollouts.outcome[0, 0]    # (N, T) outcome codes of scene 0, baseline
    """
    points = _check_shapes(geometry, params, layout)
    S = geometry.task_mask.shape[0]
    if points:
        geometry = jax.tree.map(lambda a: jnp.tile(a, (points,) + (1,) * (a.ndim - 1)),
                                geometry)
        params = Params._make(a.reshape(points * S, *a.shape[2:]) for a in params)
    per_mode = _per_mode(geometry, params, layout)
    S_all, N = geometry.starts.shape[:2]
    drawn = (jax.vmap(populations.drawn_values)(geometry, params) if layout.populations else
             jnp.zeros((S_all, N, geometry.task_mask.shape[1], 0), geometry.starts.dtype))
    # The modes stacked (S, M, ...) and assembled in one map: traced once, not per mode.
    by_mode = jax.tree.map(lambda *xs: jnp.stack(xs, axis=1),
                           *[_with_assist(*one) for one in per_mode])
    pairs = (S_all, len(per_mode))
    per_scene = jax.tree.map(lambda a: spread(a, pairs, (0,)), (
        geometry.task_mask, (geometry.orient_kind, geometry.orient_quat, geometry.orient_axis),
        drawn))
    rollouts = vmap_leading(_assemble, 2)(*per_scene, *by_mode)
    result = Evaluation(rollouts, batch_metrics(rollouts, geometry.task_mask, params.dt))
    if points:
        result = jax.tree.map(lambda a: a.reshape(points, S, *a.shape[1:]), result)
    return result
