"""The assistance a stepped rollout gets: what the robot does to the user's step and to
the orientation. Today two policies: none (the baseline and shrinking modes: R stays
as it is), and the meta skill (the shacc mode: inside a meta region R turns towards
the cluster's average, section "Merging" of reference/model). The intent-inference
policies go here.

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
from .meta import meta_target_batch, meta_target_yaw_batch, yaw_directions
from .trig import sincos
from .types import Geometry


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
