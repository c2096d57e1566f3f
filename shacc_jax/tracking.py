"""The shacc mode's orientation tracking over lanes (reference/model).

Along a rollout's path, R turns towards the meta target R_M by at most
omega_max dt per sample while the EE is in a meta region, from the first sample
inside a cluster member's initial space (``automaton.meta_window``) to the step
before activation. The targets do not depend on R, so for a block of lanes x
samples (``lanes.run``) they are computed in one parallel pass on (tasks, lanes,
samples) arrays (:func:`block_targets`), and only the rotation rule is a scan
(``automaton.rotate_along``). The pass takes the closed form of R_M where every
cluster member's orientation space is a horizontal approach frame (``meta``
module docstring; docs/DECISIONS.md).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from . import automaton as am
from . import shapes
from .meta import meta_target_batch, meta_target_yaw_batch, yaw_directions
from .types import Geometry, Params


class Lanes(NamedTuple):
    """Every (scene, start, task) rollout of a batch as one flat axis of L lanes."""

    scene: Int[Array, " L"]
    start: Int[Array, " L"]
    task: Int[Array, " L"]
    path: am.Path  # leaves (L, ...)

    @classmethod
    def of(cls, path: am.Path) -> Lanes:
        """Lanes of a batch's paths (leaves (S, N, T, ...)), in (scene, start, task)
        order."""
        S, N, T = path.length.shape
        L = S * N * T

        def index(axis):
            shape = [1, 1, 1]
            shape[axis] = (S, N, T)[axis]
            return jnp.broadcast_to(jnp.arange(shape[axis]).reshape(shape), (S, N, T)).reshape(L)

        return cls(index(0), index(1), index(2),
                   jax.tree.map(lambda a: a.reshape(L, *a.shape[3:]), path))

    def points(self, lanes: Int[Array, " B"], k: Float[Array, "B W"]) -> Float[Array, "3 B W"]:
        """p_k of the step rule (``automaton.sample``) at samples k of the lanes, with
        components first."""
        def vec(a):  # (L, 3) -> (3, B, 1)
            return a[lanes].T[:, :, None]

        p = self.path
        kk = k[None]
        landing = p.landing[lanes][None, :, None]
        step_length = p.step_length[lanes][None, :, None]
        return jnp.where(kk >= landing, vec(p.c0), vec(p.p0) + (kk * step_length) * vec(p.u))


class Prepared(NamedTuple):
    """What the targets need per scene, computed once per batch: both sets of spaces
    prepared for queries, and each task's fixed approach direction."""

    init: shapes.Prepared
    opt: shapes.Prepared
    fixed_dir: Float[Array, "S T 2"]


def prepare(geometry: Geometry) -> Prepared:
    fixed_dir, _ = jax.vmap(yaw_directions)(geometry.orient_quat)
    return Prepared(jax.vmap(lambda g: g.spaces("init"))(geometry),
                    jax.vmap(lambda g: g.spaces("opt"))(geometry), fixed_dir)


def block_targets(geometry: Geometry, params: Params, prep: Prepared, lanes: Lanes,
                  idx: Int[Array, " B"], k: Float[Array, "B W"], formula: str
                  ) -> tuple[Bool[Array, "B W"], Float[Array, "B W 4"]]:
    """(in a meta region, R_M) at the samples k of the lanes ``idx``, on whole (tasks,
    lanes, samples) arrays: ``meta_target_yaw_batch`` for ``formula`` "yaw" (every
    cluster member's frame is a horizontal approach), ``meta_target_batch`` (the Markley
    average) for "general"."""
    s = lanes.scene[idx]

    def tasks(a, n=0):  # (S, T, *c) -> (*c, T, B, 1): components, tasks, lanes
        g = a[s]
        g = jnp.moveaxis(g, tuple(range(2, 2 + n)), tuple(range(n)))
        return jnp.swapaxes(g, -1, -2)[..., None]

    def spaces(sp: shapes.Prepared) -> shapes.Prepared:
        return shapes.Prepared(tasks(sp.kind), tasks(sp.center, 1), tasks(sp.rot, 2),
                               tasks(sp.dims, 1), tasks(sp.trig, 1))

    p = lanes.points(idx, k)[:, None]  # (3, 1, B, W): components, tasks, lanes, samples
    common = (spaces(prep.init), spaces(prep.opt), tasks(geometry.task_mask),
              tasks(geometry.cluster), tasks(geometry.orient_kind))
    tau = params.activation_tol[s][None, :, None]  # (1, B, 1): tasks, lanes, samples
    if formula == "yaw":
        orient = (tasks(prep.fixed_dir, 1), tasks(geometry.orient_axis, 1))
        inside, q = meta_target_yaw_batch(*common, *orient, p, tau)
    else:
        orient = (tasks(geometry.orient_quat, 1), tasks(geometry.orient_axis, 1))
        inside, q = meta_target_batch(*common, *orient, p, tau)
    return inside, jnp.moveaxis(q, 0, -1)


class BlockRotation(NamedTuple):
    """One block of the rotation rule (:func:`block_rotation`): the orientation at the
    block's end (B, 4), at each of its samples (B, W, 4; None unless asked for), and
    whether the meta skill turned the gripper at each sample (B, W)."""

    end: Float[Array, "B 4"]
    at: Float[Array, "B W 4"] | None
    turned: Bool[Array, "B W"]


def block_rotation(geometry: Geometry, params: Params, prep: Prepared, lanes: Lanes,
                   idx: Int[Array, " B"], k: Float[Array, "B W"], in_window: Bool[Array, "B W"],
                   r: Float[Array, "B 4"], formula: str, per_sample: bool) -> BlockRotation:
    """The meta skill's rotation over W samples k of the lanes ``idx``, from their
    orientations ``r``: the targets of the whole block in one pass
    (:func:`block_targets`), then the rotation rule sample by sample wherever a sample
    lies in the lane's meta window (``in_window``) and in a meta region. With
    ``per_sample`` the orientation at every sample too (the collision checks pose the
    gripper with it)."""
    inside, goal = block_targets(geometry, params, prep, lanes, idx, k, formula)
    angle = (params.omega_max * params.dt)[lanes.scene[idx]]
    turned = inside & in_window
    if per_sample:
        end, at = jax.vmap(am.rotate_along_path)(r, turned, goal, angle)
        return BlockRotation(end, at, turned)
    end, _ = jax.vmap(am.rotate_along)(r, turned, goal, angle)
    return BlockRotation(end, None, turned)
