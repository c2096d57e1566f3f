"""The assistance a stepped rollout gets: what the robot does to the user's step and to
the orientation. Today two policies: none (the baseline and shrinking modes: R stays
as it is), the meta skill (the shacc mode: inside a meta region R turns towards the
cluster's average, section "Merging" of reference/model), and the intent-inference
policies (reference/model, "Intent inference"): ``blend`` (policy blending with
confidence arbitration), ``ho`` (hindsight optimization) and ``shacc_ho`` (``ho`` with
Shrinking's spaces and the meta skill inside meta regions), each from the posterior
over the scene's tasks (:func:`posterior`).

The meta skill works on its own layout (:func:`prepare`): each scene's initial and
optimised spaces with components first, and the members' fixed approach directions.
Its clearance (how far the gripper is from every meta region) joins the activation
check's, so a step that cannot reach a region skips the full check.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array

from . import quaternion as quat
from . import shapes
from .meta import meta_target_batch, meta_target_yaw_batch, yaw_average, yaw_directions
from .orientation import task_direction, task_orientation
from .rollout_state import Assist, Lane, Move, State
from .rows import row, rows
from .trig import sincos
from .types import ASSISTANCE, Geometry
from .vec3 import V3, length, of, xyz

NONE, SCENE, CORRECT, WRONG = (ASSISTANCE.index(k) for k in ("none", "scene", "correct",
                                                             "wrong"))


class MetaSpaces(NamedTuple):
    """One scene's spaces as the meta kernels read them (components first): the
    initial spaces (the regions), the optimised ones (the weights) and each task's
    fixed approach direction."""

    init: shapes.Prepared
    opt: shapes.Prepared
    fixed_dir: Array


def components_first(sp: shapes.Prepared) -> shapes.Prepared:
    """One scene's prepared spaces (leading T) in the meta kernels' layout: (T,) and
    components first, (3, T), (3, 3, T)."""
    return shapes.Prepared(sp.kind, sp.center.T, jnp.moveaxis(sp.rot, 0, -1), sp.dims.T,
                           sp.trig.T)


def prepare(geometry: Geometry) -> MetaSpaces:
    """Every scene's :class:`MetaSpaces` (leading S)."""
    return jax.vmap(lambda g: MetaSpaces(components_first(g.spaces("init")),
                                         components_first(g.spaces("opt")),
                                         yaw_directions(g.orient_quat)[0]))(geometry)


def meta_skill(g: Geometry, meta: MetaSpaces, p: Array, r: Array, sd_init: Array,
               sd: Array, done: Array, clear: Array, tau: Array, max_angle: Array,
               formula: str, turn: bool) -> tuple[Array, Array, Array]:
    """The meta skill at the gripper position p (one lane) with the check's sdfs
    (``sd_init`` of the initial spaces, ``sd`` of the mode's, masked): (R after the
    turn, whether the step counts as a meta step, the clearance lowered to the nearest
    meta region). With ``turn`` False (the check at the start pose) R is left alone.
    ``formula``: ``Layout.meta_formula``."""
    inf = jnp.asarray(jnp.inf, p.dtype)
    member = g.task_mask & (g.cluster >= 0)
    pp = p[:, None]  # (components, tasks)
    clear = jnp.minimum(clear, jnp.min(jnp.where(member, sd_init, inf)))
    counted = jnp.zeros((), bool)
    if turn:
        common = (meta.init, meta.opt, g.task_mask, g.cluster, g.orient_kind)
        both = (sd_init, sd)
        goals = []
        if formula in ("yaw", "both"):
            inside, goal = meta_target_yaw_batch(*common, meta.fixed_dir.T, g.orient_axis.T,
                                                 pp, tau, both)
            goals.append(goal)
        if formula in ("general", "both"):
            inside, goal = meta_target_batch(*common, g.orient_quat.T, g.orient_axis.T,
                                             pp, tau, both)
            goals.append(goal)
        # The region test is the same; the target's formula is not.
        goal = jnp.where(g.yaw_meta, goals[0], goals[1]) if formula == "both" else goals[0]
        half_turn = sincos(0.5 * max_angle)
        turned = jnp.where(inside, quat.turn_towards(r, goal, half_turn), r)
        r = jnp.where(done, r, turned)
        counted = inside & ~done
    return r, counted, clear


# --- intent inference -----------------------------------------------------------------


def posterior(v: Array, v0: Array, mask: Array, beta: Array) -> Array:
    """The MaxEnt posterior over a scene's tasks (T,): P(j) proportional to
    exp(-(V_j(p) - V_j(p_0)) / beta), V_j the distance left to task j's space, over
    the real tasks (``mask``; zero for padded ones), a uniform prior. The sum runs
    over the tasks in index order (``quaternion.ordered_sum``), so a lane's answer does
    not depend on its batch."""
    logit = jnp.where(mask, -(v - v0) / beta, -jnp.inf)
    top = jnp.max(logit)
    e = jnp.where(mask, jnp.exp(logit - top), 0.0)
    return e / quat.ordered_sum(e, 0)


def best_and_confidence(prob: Array, mask: Array) -> tuple[Array, Array]:
    """(g*, the task of largest probability, the lower index on a tie; the
    confidence, its probability less the second largest (0 for the second where the
    scene has one task))."""
    T = prob.shape[0]
    index = jnp.arange(T, dtype=jnp.int32)
    top = jnp.max(jnp.where(mask, prob, -1.0))
    best = jnp.min(jnp.where(mask & (prob == top), index, T)).astype(jnp.int32)
    second = jnp.max(jnp.where(mask & (index != best), prob, 0.0))
    return best, top - second


def inferred(v: Array, v0: Array, mask: Array, beta: Array) -> tuple[Array, Array, Array]:
    """At the gripper, from every task's distance left ``v`` (V_j = max(sdf_j, 0)) and
    at the start ``v0``: the posterior (:func:`posterior`), g* and the confidence
    (:func:`best_and_confidence`)."""
    prob = posterior(v, v0, mask, beta)
    return (prob, *best_and_confidence(prob, mask))


def first_assistance(lane: Lane, spaces: shapes.Prepared, mask: Array, p: Array,
                     mode: str) -> tuple[Array, Assist]:
    """At the start p (one lane): V_j(p_0), every task's distance left, and the first
    step's position assistance, from the posterior there (uniform over the real
    tasks)."""
    v0 = jnp.maximum(shapes.all_sdf(spaces, p), 0.0)
    return v0, position_assistance(lane, spaces, p, *inferred(v0, v0, mask, lane.x.intent_beta),
                                   mode)


def _towards_each(spaces: shapes.Prepared, p: V3) -> tuple[V3, Array]:
    """At p, per task (T,): the unit direction towards its space's closest point (0
    where p is on or in it) and that point's distance, which is V_j = max(sdf_j, 0)
    (the closest point of a space to a point inside is the point itself)."""
    closest = jax.vmap(lambda sp: shapes.project_components(sp.kind, sp.center, sp.rot,
                                                            sp.dims, sp.trig, p))(spaces)
    d = xyz(lambda i: closest[i] - p[i])
    dist = length(d)
    inv = jnp.where(dist > 0, 1.0 / jnp.where(dist > 0, dist, 1.0), 0.0)
    return xyz(lambda i: d[i] * inv), dist


def position_assistance(lane: Lane, spaces: shapes.Prepared, p: Array, prob: Array,
                        best: Array, conf: Array, mode: str) -> Assist:
    """The intent modes' position assistance for the lane's next step, from the
    posterior ``prob`` at the gripper p (its g* ``best`` and confidence ``conf``):
    ``blend`` takes (1 - c) user + c (the step towards g*'s closest point) where the
    confidence c reaches ``blend_threshold``; ``ho`` and ``shacc_ho`` add ``ho_gain``
    v_max dt times the posterior-weighted sum of the unit directions towards every
    task's closest point. Computed where the check is, so that the posterior at the
    gripper serves both the check's orientation assistance and the next step."""
    x = lane.x
    step_length = x.v_max * x.dt
    if mode == "blend":
        # Only g*'s space: one projection, not one onto every space.
        unit, dist = _towards_each(jax.tree.map(lambda a: row(a, best)[None], spaces), of(p))
        size = jnp.minimum(step_length, dist[0])
        pull = xyz(lambda i: conf * size * unit[i][0])
        return Assist(conf, pull, conf >= x.blend_threshold)
    unit, dist = _towards_each(spaces, of(p))
    pull = xyz(lambda i: x.ho_gain * step_length * quat.ordered_sum(prob * unit[i], 0))
    return Assist(jnp.zeros_like(conf), pull, jnp.ones((), bool))


def assist_position(lane: Lane, s: State, m: Move) -> Move:
    """The intent modes' position assistance (``s.assist``, from the posterior where
    the gripper is, :func:`position_assistance`) on one lane's move (the user's step
    ``m.delta`` from the gripper at s.p); the assisted step at most v_max dt. The
    move's positions, path length and the path since the last check follow the new
    step."""
    assert s.assist is not None  # the intent modes' states carry it
    x = lane.x
    step_length = x.v_max * x.dt
    share, pull, on = s.assist
    user = m.delta
    new = xyz(lambda i: (1.0 - share) * user[i] + pull[i])
    n = length(new)
    scale = jnp.where(n > step_length, step_length / jnp.where(n > 0, n, 1.0), 1.0)
    delta = xyz(lambda i: jnp.where(on, new[i] * scale, user[i]))
    q = xyz(lambda i: s.q[i] + delta[i])
    p = xyz(lambda i: m.p[i] - m.q[i] + q[i])  # the tremor rides on the commanded position
    gap = xyz(lambda i: p[i] - s.p[i])
    return m._replace(q=q, p=p, delta=delta, travelled=s.travelled + length(delta),
                      moved=s.moved + length(gap))


def weighted_yaw_average(g: Geometry, weights: Array, p: Array) -> Array:
    """The weighted Markley average of the tasks' orientations at p where every one is a
    horizontal approach frame (``Layout.intent_yaw``): the meta skill's closed form
    (``meta.yaw_average``)."""
    fixed = yaw_directions(g.orient_quat)[0]  # (T, 2)
    return yaw_average(weights, *task_direction(g.orient_kind, fixed.T, g.orient_axis.T, p))


def intent_orientation(g: Geometry, spaces: shapes.Prepared, lane: Lane, p: Array, r: Array,
                       dist: Array, done: Array, mode: str, max_angle: Array,
                       meta_turned: Array | None, inside_meta: Array | None,
                       yaw: bool = False) -> tuple[Array, Array, Assist]:
    """The intent modes' orientation assistance at the gripper p after a step (one
    lane; ``dist``: the mode's sdfs there, masked): (R after the turn, the step's kind
    of assistance, an index of ASSISTANCE; and the next step's position assistance
    from the same posterior, :func:`position_assistance`). ``blend``: towards g*'s orientation where
    the confidence reaches the threshold (correct where g* is the lane's task, else
    wrong), else none. ``ho``: towards the posterior-weighted Markley average of every
    task's orientation, always (correct where the largest weight is the lane's task).
    ``shacc_ho``: inside a meta region the meta skill's turn (``meta_turned``,
    ``inside_meta``: scene), elsewhere ``ho``'s. An ended step turns nothing and counts
    as none. ``yaw``: ``Layout.intent_yaw`` (the average in closed form)."""
    x = lane.x
    assert lane.v0 is not None
    prob, best, conf = inferred(jnp.maximum(dist, 0.0), lane.v0, g.task_mask, x.intent_beta)
    if mode == "blend":
        on = conf >= x.blend_threshold
        goal = task_orientation(*rows((g.orient_kind, g.orient_quat, g.orient_axis), best), p)
    else:
        on = jnp.ones((), bool)
        if yaw:
            goal = weighted_yaw_average(g, prob, p)
        else:
            qs = jax.vmap(task_orientation, in_axes=(0, 0, 0, None))(
                g.orient_kind, g.orient_quat, g.orient_axis, p)  # (T, 4)
            goal = quat.markley_average(qs, prob)
    kind = jnp.where(on, jnp.where(best == lane.target, CORRECT, WRONG), NONE)
    turned = quat.turn_towards(r, goal, sincos(0.5 * max_angle))
    r_new = jnp.where(on & ~done, turned, r)
    if inside_meta is not None and meta_turned is not None:  # shacc_ho
        r_new = jnp.where(inside_meta, meta_turned, r_new)
        kind = jnp.where(inside_meta, SCENE, kind)
    return (r_new, jnp.where(done, NONE, kind).astype(jnp.int32),
            position_assistance(lane, spaces, p, prob, best, conf, mode))
