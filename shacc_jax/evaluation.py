"""The one public entry point: evaluate a batch of baked scenes in every mode,
from every start, for every task, in one jitted, vmapped computation.

Kernels in :mod:`shacc_jax.automaton` are written for one rollout; this
module applies vmap over tasks, starts and scenes, and jit once, here.
Baseline uses the initial spaces; shrinking and shacc the optimised ones.
With collision checking off, a rollout's path and activation do not depend on
the orientation, so shrinking and shacc share one activation pass and shacc
adds the orientation tracking (the NumPy reference test checks the modes
independently).
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp

from . import automaton as am
from . import quaternion as quat
from .metrics import scene_metrics
from .types import INVALID, MODES, Evaluation, Rollouts, SceneMetrics, Scenes


def _check_modes(modes) -> tuple[str, ...]:
    modes = tuple(modes)
    bad = [m for m in modes if m not in MODES]
    if bad or not modes or len(set(modes)) != len(modes):
        raise ValueError(f"modes must be distinct names from {MODES}, got {modes}")
    return modes


def _one_scene(sc: Scenes, modes: tuple[str, ...]):
    mask = sc.task_mask
    T = mask.shape[0]
    dtype = sc.starts.dtype
    tau = sc.activation_tol
    step = sc.v_max * sc.dt
    max_steps = sc.max_steps
    grow = tau + am.rounding_slack(dtype)
    orient = (sc.orient_kind, sc.orient_quat, sc.orient_axis)
    targets = jnp.arange(T)
    init, opt = sc.spaces("init"), sc.spaces("opt")

    def activation_pass(spaces):
        def one(p0, target):
            path = am.straight_path(spaces, target, p0, step, max_steps)
            act = am.first_activation(spaces, mask, path, tau, max_steps, grow)
            out = am.classify(act, target, path, max_steps, sc.ambiguity_nearest)
            return path, act, out

        return jax.vmap(jax.vmap(one, (None, 0)), (0, None))(sc.starts[:, :3], targets)

    passes = {}
    if "baseline" in modes:
        passes["init"] = activation_pass(init)
    if "shrinking" in modes or "shacc" in modes:
        passes["opt"] = activation_pass(opt)

    r0 = sc.starts[:, 3:]
    per_mode = []
    for mode in modes:
        path, act, out = passes["init" if mode == "baseline" else "opt"]
        if mode == "shacc":
            def track(path, act, r0_, target):
                return am.track_orientation(init, opt, mask, sc.cluster, orient, path, r0_,
                                            act.step, tau, sc.omega_max * sc.dt, max_steps,
                                            grow)

            r, meta_steps = jax.vmap(jax.vmap(track, (0, 0, None, 0)), (0, 0, 0, None))(
                path, act, r0, targets)
        else:
            r = jnp.broadcast_to(r0[:, None, :], (r0.shape[0], T, 4))
            meta_steps = jnp.zeros(out.code.shape, jnp.int32)
        dr = jax.vmap(jax.vmap(am.delta_r, (0, 0, None, 0)), (0, 0, None, None))(
            out, r, orient, targets)
        code = jnp.where(mask[None, :], out.code, INVALID)
        per_mode.append(Rollouts(code, out.activated, out.step, out.point, out.path_length,
                                 meta_steps, dr))
    rollouts = jax.tree.map(lambda *xs: jnp.stack(xs), *per_mode)
    metrics = jax.vmap(scene_metrics, (0, 0, None))(rollouts.outcome, rollouts.delta_R, mask)
    return rollouts, SceneMetrics(*metrics)


@partial(jax.jit, static_argnames=("modes",))
def _evaluate(scenes: Scenes, modes: tuple[str, ...]) -> Evaluation:
    rollouts, metrics = jax.vmap(lambda sc: _one_scene(sc, modes))(scenes)
    return Evaluation(rollouts, metrics)


def evaluate(scenes, modes=MODES) -> Evaluation:
    """Evaluate S baked scenes x M modes x N starts x T tasks.

    ``scenes``: a :class:`~shacc_jax.types.Scenes` or anything with the bake's
    arrays (a ``geometry_precompute.BakedScenes``). Every numeric setting is an
    array leaf, so new values reuse the compiled computation; shapes (S, T, N)
    and ``modes`` are static. Returns an :class:`~shacc_jax.types.Evaluation`
    whose rollout arrays are (S, M, N, T) in the order of ``modes``.
    """
    if not isinstance(scenes, Scenes):
        scenes = Scenes.from_bake(scenes)
    return _evaluate(scenes, _check_modes(modes))


def orientation_angle(a, b):
    """Angle between quaternions (SPEC section 2), re-exported for analysis code."""
    return quat.angle(a, b)
