"""The Automaton rollout of the Automaton (reference/model), for one scene, one start, one task.

The step rule moves p towards c, the closest point of the target's space P_i,
by at most s = v_max dt per step. For a convex P_i every point of the segment
[p, c] has the same closest point c, so the path is that straight segment,
walked in steps of s: p_k = p0 + min(k s, D) u, with D = |c0 - p0|, u the unit
direction and K = ceil(D / s) the step that lands on c0 (c0 itself from then).
Outcomes never need the loop of 3 mm steps:

1. Activation (every mode). The set of t with sdf_j(p0 + t u) <= tau is an
   interval for each convex space j; :func:`shapes.ray_interval` gives a
   closed-form superset of it. The first sample index inside any superset is
   a candidate; the exact SDFs at that sample decide. If nothing activates
   there (the sample fell in the thin rim of a superset), the next candidate
   is tried. Every sample skipped lies outside every superset, so the first
   activation found is exactly the step rule's.
2. Orientation (``shacc`` only). R changes only at samples inside a meta
   region, which all lie after the first sample inside a superset of a
   cluster member's initial space (:func:`meta_window`). The meta region test
   and its target R_M(p_k) depend on the sample only, not on R, so they are
   computed for many samples at once (``meta.meta_target``); the rate-limited
   geodesic tracking then runs over them in order (:func:`rotate_along`),
   exactly as the step rule does.

The NumPy reference in ``tests/reference_automaton.py`` runs the step rule
literally; ``tests/test_automaton.py`` checks both agree rollout by rollout.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from . import quaternion as quat
from . import shapes
from .orientation import task_orientation
from .rows import rows
from .types import AMBIGUOUS, SUCCESS, TIMEOUT, WRONG, Geometry, Params

TIE = 1e-6


def rounding_slack(dtype) -> float:
    """How far the ray intervals are widened beyond tau: covers the rounding of the
    quadratics (about 1e-7 m in float32 for coordinates of about a metre)."""
    return 128.0 * float(jnp.finfo(dtype).eps)


class Path(NamedTuple):
    p0: Float[Array, "3"]
    c0: Float[Array, "3"]
    u: Float[Array, "3"]
    length: Float[Array, ""]  # D
    landing: Float[Array, ""]  # K, as a float (clamped to max_steps + 1)
    step_length: Float[Array, ""]  # s = v_max dt


def straight_path(spaces: shapes.Prepared, target: Int[Array, ""], p0: Float[Array, "3"],
                  step_length: Float[Array, ""], max_steps: Array) -> Path:
    c0 = shapes.prepared_project(rows(spaces, target), p0)
    diff = c0 - p0
    length = shapes._safe_norm(diff)
    u = jnp.where(length > 0, diff / jnp.where(length > 0, length, 1.0), 0.0)
    landing = jnp.minimum(jnp.ceil(length / step_length), max_steps.astype(length.dtype) + 1.0)
    return Path(p0, c0, u, length, landing, step_length)


def sample(path: Path, k: Float[Array, ""]) -> Float[Array, "3"]:
    """p_k of the step rule: on the segment, and exactly c0 from step K on."""
    return jnp.where(k >= path.landing, path.c0, path.p0 + (k * path.step_length) * path.u)


def first_sample(lo: Array, hi: Array, kmin: Array, path: Path, max_steps: Array) -> Array:
    """First sample index >= kmin whose t = min(k s, D) lies in [lo, hi]; inf if none
    up to max_steps. Works elementwise (one interval per task)."""
    inf = jnp.asarray(jnp.inf, path.length.dtype)
    k1 = jnp.maximum(kmin, jnp.ceil(lo / path.step_length))
    on_segment = (k1 < path.landing) & (k1 * path.step_length <= hi)
    at_end = (kmin <= path.landing) & (lo <= path.length) & (path.length <= hi)
    cand = jnp.where(on_segment, k1, jnp.where(at_end, path.landing, inf))
    return jnp.where(cand <= max_steps.astype(cand.dtype), cand, inf)


def last_sample(lo: Array, hi: Array, path: Path, max_steps: Array) -> Array:
    """Last sample index <= max_steps whose t = min(k s, D) lies in [lo, hi]; -inf if
    none (the counterpart of :func:`first_sample`)."""
    inf = jnp.asarray(jnp.inf, path.length.dtype)
    steps = max_steps.astype(path.length.dtype)
    rests = (lo <= path.length) & (path.length <= hi) & (path.landing <= steps)
    k = jnp.minimum(jnp.minimum(jnp.floor(hi / path.step_length), path.landing - 1.0), steps)
    on_segment = (k >= 0) & (k * path.step_length >= lo)
    return jnp.where(rests, steps, jnp.where(on_segment, k, -inf))


class Activation(NamedTuple):
    step: Float[Array, ""]  # inf when no activation within max_steps
    active: Bool[Array, " T"]
    sdf: Float[Array, " T"]


def first_activation(spaces: shapes.Prepared, mask: Bool[Array, " T"], path: Path, tau: Array,
                     max_steps: Array, grow: Array) -> Activation:
    lo, hi = shapes.all_ray_intervals(spaces, path.p0, path.u, grow)
    inf = jnp.asarray(jnp.inf, lo.dtype)
    lo = jnp.where(mask, lo, inf)
    hi = jnp.where(mask, hi, -inf)
    T = mask.shape[0]
    steps = max_steps.astype(lo.dtype)

    def body(carry):
        kmin, _, _, _, _ = carry
        # The landing sample K lies on the target's own space: always a candidate.
        landing = jnp.where((kmin <= path.landing) & (path.landing <= steps),
                            path.landing, inf)
        k = jnp.minimum(jnp.min(first_sample(lo, hi, kmin, path, max_steps)), landing)
        none = ~jnp.isfinite(k)
        p = sample(path, jnp.where(none, 0.0, k))
        sd = jnp.where(mask, shapes.all_sdf(spaces, p), inf)
        active = (sd <= tau) & ~none
        hit = jnp.any(active)
        return k + 1.0, hit | none, jnp.where(hit, k, inf), active, sd

    init = (jnp.zeros((), lo.dtype), jnp.zeros((), bool), inf, jnp.zeros(T, bool),
            jnp.full(T, inf))
    _, _, k, active, sd = jax.lax.while_loop(lambda c: ~c[1], body, init)
    return Activation(k, active, sd)


class Outcome(NamedTuple):
    code: Int[Array, ""]
    activated: Int[Array, ""]
    step: Int[Array, ""]
    point: Float[Array, "3"]
    path_length: Float[Array, ""]


def classify(act: Activation, target: Int[Array, ""], path: Path, max_steps: Array,
             nearest_rule: Bool[Array, ""]) -> Outcome:
    """the Automaton's outcomes. ``activated`` is the task of A with the smallest
    sdf, the lower index on a tie, -1 on timeout. Values within ``TIE`` (1e-6 m) of
    the smallest count as tied: at a landing point on the boundary of two spaces
    (symmetric scenes) the two sdfs differ only by rounding, and a fixed tolerance
    makes the choice the same in float32, float64 and the NumPy reference."""
    found = jnp.isfinite(act.step)
    code, activated = outcome_codes(act, target, nearest_rule)
    k = jnp.where(found, act.step, max_steps.astype(act.step.dtype))
    return Outcome(code, activated, k.astype(jnp.int32), sample(path, k),
                   jnp.minimum(k * path.step_length, path.length))


def outcome_codes(act: Activation, target: Int[Array, ""],
                  nearest_rule: Bool[Array, ""]) -> tuple[Int[Array, ""], Int[Array, ""]]:
    """The outcome code and the activated task (-1 on timeout) of an activation (the
    rules of :func:`classify`), for every user."""
    found = jnp.isfinite(act.step)
    smallest = jnp.min(jnp.where(act.active, act.sdf, jnp.inf))
    tied = act.active & (act.sdf <= smallest + TIE)
    nearest = jnp.argmax(tied).astype(jnp.int32)  # the first (lowest) index of the tie
    n_active = jnp.sum(act.active)
    target_in = act.active[target]
    code_fail = jnp.where(target_in, jnp.where(n_active == 1, SUCCESS, AMBIGUOUS), WRONG)
    code_nearest = jnp.where(nearest == target, SUCCESS, WRONG)
    code = jnp.where(found, jnp.where(nearest_rule, code_nearest, code_fail), TIMEOUT)
    return code.astype(jnp.int32), jnp.where(found, nearest, -1)


def meta_window(init: shapes.Prepared, mask: Bool[Array, " T"], cluster: Int[Array, " T"],
                path: Path, activation_step: Array, max_steps: Array,
                grow: Array) -> tuple[Array, Array]:
    """(first, last) sample at which ``shacc`` may rotate: from the first sample inside a
    cluster member's initial-space interval to the step before activation (or
    max_steps on timeout). Empty when first > last."""
    member = mask & (cluster >= 0)
    lo, hi = shapes.all_ray_intervals(init, path.p0, path.u, grow)
    inf = jnp.asarray(jnp.inf, lo.dtype)
    lo = jnp.where(member, lo, inf)
    hi = jnp.where(member, hi, -inf)
    k_enter = jnp.min(first_sample(lo, hi, jnp.ones((), lo.dtype), path, max_steps))
    k_last = jnp.where(jnp.isfinite(activation_step), activation_step - 1.0,
                       max_steps.astype(lo.dtype))
    return jnp.where(jnp.isfinite(k_enter), k_enter, k_last + 1.0), k_last


def rotate_along(r0: Float[Array, "4"], inside: Bool[Array, " W"], targets: Float[Array, "W 4"],
                 max_angle: Array) -> tuple[Float[Array, "4"], Int[Array, ""]]:
    """the Automaton's rotation rule over W consecutive samples: R turns towards each
    sample's R_M by at most ``max_angle`` where the sample is in a meta region. The
    targets do not depend on R, so they are computed for all samples beforehand (in
    parallel); only this scan is sequential."""
    r, _ = _rotation_scan(r0, inside, targets, max_angle, emit=False)
    return r, jnp.sum(inside.astype(jnp.int32))


def rotate_along_path(r0: Float[Array, "4"], inside: Bool[Array, " W"],
                      targets: Float[Array, "W 4"], max_angle: Array
                      ) -> tuple[Float[Array, "4"], Float[Array, "W 4"]]:
    """:func:`rotate_along` that also returns R at each of the W samples, before that
    sample's rotation: the gripper pose the collision check sees there."""
    return _rotation_scan(r0, inside, targets, max_angle, emit=True)


def _rotation_scan(r0, inside, targets, max_angle, emit: bool):
    # Without collisions nothing reads the per-sample R, so it is not emitted (on the GPU
    # the tracking is most of the time, and the extra writes would cost).
    def turn(r, x):
        ok, target = x
        return jnp.where(ok, quat.rotate_towards(r, target, max_angle), r), r if emit else None

    return jax.lax.scan(turn, r0, (inside, targets))


def target_orientation(orient, target: Int[Array, ""], p: Float[Array, "3"]) -> Array:
    kind, q_fixed, axis = orient
    return task_orientation(*rows((kind, q_fixed, axis), target), p)


def delta_r(outcome: Outcome, r: Float[Array, "4"], orient, target: Int[Array, ""]) -> Array:
    """the Automaton's delta_R, for successes only (NaN otherwise)."""
    d = quat.angle(r, target_orientation(orient, target, outcome.point))
    return jnp.where(outcome.code == SUCCESS, d, jnp.nan)


def rollout_numbers(params: Params, dtype) -> dict:
    """One scene's settings as the kernels use them: tau, the step length v_max dt,
    max_steps, tau widened by the rounding slack, the largest turn per step."""
    tau = params.activation_tol
    return dict(tau=tau, step_length=params.v_max * params.dt, max_steps=params.max_steps,
                grow=tau + rounding_slack(dtype), max_angle=params.omega_max * params.dt)


def activation_pass(geometry: Geometry, params: Params, which: str):
    """Phase 1 for one scene: (path, activation, outcome), each (N, T, ...), on the
    ``init`` or ``opt`` spaces."""
    return activation_pass_on(geometry.starts, geometry.task_mask, params,
                              geometry.spaces(which))


def activation_pass_on(starts: Float[Array, "N 7"], task_mask: Bool[Array, " T"],
                       params: Params, spaces):
    """:func:`activation_pass` on one scene's ``starts`` and ``task_mask`` and the
    prepared ``spaces`` (``Geometry.spaces``)."""
    x = rollout_numbers(params, starts.dtype)

    def one(p0, target):
        path = straight_path(spaces, target, p0, x["step_length"], x["max_steps"])
        act = first_activation(spaces, task_mask, path, x["tau"], x["max_steps"],
                               x["grow"])
        out = classify(act, target, path, x["max_steps"], params.ambiguity_nearest)
        return path, act, out

    # Two vmaps here, not one over the N x T lanes (``flatmap``): XLA then simplifies
    # the program otherwise, and 15 recorded fields (points, path lengths, delta_R)
    # changed in their last bits (an ulp, towards a single lane's own arithmetic).
    T = task_mask.shape[0]
    return jax.vmap(jax.vmap(one, (None, 0)), (0, None))(starts[:, :3],
                                                         jnp.arange(T, dtype=jnp.int32))
