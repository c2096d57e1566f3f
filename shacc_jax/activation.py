"""The activation check of a stepped rollout: at the gripper's position, every space's
sdf, which space activates, and (where a scene checks them) whether the gripper's
capsules penetrate an object first.

``activation_check = steps`` (the paper's reading) checks the step positions only;
``swept`` activates every space the step's segment enters, at the first entry point
(:func:`swept_entry`). A full check also reports the clearance, how far the gripper is
from every space (and meta region, ``assistance``): sdfs are exact distances, so
1-Lipschitz, and a gripper that has moved a path of length m since a check that found
everything at least ``clear`` away cannot activate anything while clear - m stays
above tau + :data:`CLEARANCE_MARGIN`, and skips the check.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array

from . import automaton as am
from . import body_distance as bodies
from . import collision as col
from . import gripper as grip
from . import shapes
from .assistance import SCENE, MetaSpaces, intent_orientation, meta_skill
from .hulls import Hulls
from .rollout_state import Check, Lane, Move, State
from .types import COLLISION, Geometry, Layout
from .vec3 import length

# Sphere-tracing steps from a step's first interval entry to the entry into a space
# (activation_check = swept).
SPHERE_TRACING_STEPS = 16
# The clearance's margin (m) over tau: it covers rounding.
CLEARANCE_MARGIN = 1e-4


class SceneView(NamedTuple):
    """What a check reads of its lane's scene: the scene's geometry, its mode's spaces,
    its meta spaces (None without the meta skill) and the batch's mesh hulls (not
    gathered per lane: a mesh is read only where the gripper is near it; None without
    collision checks)."""

    geometry: Geometry
    spaces: shapes.Prepared
    meta: MetaSpaces | None
    hulls: Hulls | None


def sdfs(spaces: shapes.Prepared, meta: MetaSpaces | None, p: Array,
         track: bool) -> tuple[Array, Array | None]:
    """Every space's sdf at p (one lane), and with ``track`` every initial space's (the
    meta region's)."""
    own = shapes.all_sdf(spaces, p)
    return own, shapes.prepared_sdf(meta.init, p[:, None]) if track and meta is not None \
        else None


def check(scene: SceneView, lane: Lane, p: Array, r: Array, layout: Layout, track: bool,
          step: tuple[State, Move] | None = None,
          sd: tuple[Array, Array | None] | None = None, intent: str | None = None) -> Check:
    """The full check at the gripper position p (one lane): every space's sdf and the
    activation; with ``step`` (the state before and the move), the swept check's entry
    point (traced only where ``layout.swept_checks``) and, with ``track``, the meta
    skill's turn of R (``assistance.meta_skill``). Where the layout checks collisions,
    the gripper's capsules at (p, R before the turn) against the objects first: a
    penetration ends the rollout as a collision, without activating or turning.
    ``scene``: the lane's scene; ``sd``: the sdfs at p (:func:`sdfs`) where the caller
    has them. ``intent``: the intent mode (``assistance.intent_orientation`` turns R
    after a step; every step is checked in full: the clearance is -inf)."""
    g, spaces = scene.geometry, scene.spaces
    x, dtype = lane.x, p.dtype
    n = am.rollout_numbers(x, dtype)
    tau = n["tau"]
    inf = jnp.asarray(jnp.inf, dtype)

    own, sd_init = sd if sd is not None else sdfs(spaces, scene.meta, p, track)
    dist = jnp.where(g.task_mask, own, inf)
    active = dist <= tau
    travelled = jnp.zeros((), dtype) if step is None else step[1].travelled
    if step is not None and layout.swept_checks:
        p, active, dist, travelled = swept_entry(spaces, g.task_mask, lane, step[0], step[1],
                                                  p, active, dist, n)
    clear = jnp.min(dist)
    hit = jnp.zeros((), bool)
    if layout.collision_checks:
        objects = col.scene_objects(g.obj_kind, g.obj_center, g.obj_quat, g.obj_size,
                                    g.obj_mask)
        dims = x.gripper()
        hit = x.collision & col.penetrates(objects, p, r, dims, scene.hulls, lane.scene)
        active = active & ~hit
        # No capsule reaches beyond gripper_reach from p: objects farther than that
        # cannot be touched, a bound as 1-Lipschitz as the spaces' sdfs.
        kind, centre, mat, size, mask = objects
        local = jnp.einsum("oji,oj->oi", mat, p[None, :] - centre)
        apart = bodies.point_distance(tuple(local.T), kind, tuple(size.T))
        gap = jnp.min(jnp.where(mask, apart, inf)) - grip.gripper_reach(dims)
        clear = jnp.where(x.collision, jnp.minimum(clear, gap + tau), clear)
    done = jnp.any(active) | hit
    code, activated = am.outcome_codes(am.Activation(jnp.zeros((), dtype), active, dist),
                                       lane.target, x.ambiguity_nearest)
    code = jnp.where(hit, COLLISION, code)
    activated = jnp.where(hit, -1, activated)
    counted = jnp.zeros((), bool)
    r_before = r
    if track:
        assert sd_init is not None and scene.meta is not None  # sdfs gives it where track
        r, counted, clear = meta_skill(g, scene.meta, p, r, sd_init, dist, done, clear, tau,
                                       n["max_angle"], layout.meta_formula, step is not None)
    if intent is None:
        return Check(p, travelled, done, code, activated, r, counted, clear)
    kind = jnp.zeros((), jnp.int32)  # none: the check at the start turns nothing
    assist = None  # at the start: stepping's begin, once it knows V_j(p_0)
    if step is not None:
        r, kind, assist = intent_orientation(g, spaces, lane, p, r_before, dist, done, intent,
                                             n["max_angle"], r if track else None,
                                             counted if track else None, layout.intent_yaw)
    return Check(p, travelled, done, code, activated, r, kind == SCENE, jnp.full_like(clear,
                 -jnp.inf), kind, assist)


def swept_entry(spaces, mask, lane: Lane, s: State, m: Move, p, active, sd, n):
    """activation_check = swept: where the gripper's segment from s.p to p first
    enters a space, that point activates (for the lanes that ask for it)."""
    dtype = p.dtype
    inf = jnp.asarray(jnp.inf, dtype)
    tau = n["tau"]
    start = jnp.stack(s.p)
    seg = p - start
    seg_len = length(seg)
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
    step_len = length(m.delta)
    travelled = jnp.where(swept, s.travelled + step_len
                          * (t_hit / jnp.where(seg_len > 0, seg_len, 1.0)), m.travelled)
    return p, active, sd, travelled
