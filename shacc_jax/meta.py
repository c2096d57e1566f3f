"""The meta skill of the meta skill (reference/model), at one EE position.

p is in the meta region p_M(K) of cluster K when sdf_i^init(p) <= tau for some
member i of K (the Automaton only asks before activation, so p is outside
every optimised space). Where p is within tau of members of two clusters
(initial spaces of different clusters may touch), the cluster of the member
with the smallest sdf^init is taken, the lower task index on a tie.

R_M(p) is the Markley average of the members' orientations R_i(p), weighted
w_i = (1 / d_i^2) / sum_j (1 / d_j^2), d_i = max(sdf_i^opt(p), 1e-6). Padded
tasks and tasks of other clusters get weight zero.

Every orientation space of the side, handle and drawer grasps is a horizontal
approach frame, q = yaw(psi) * q_forward. For such quaternions the Markley
average has a closed form: right multiplication by q_forward is orthogonal, so
M's top eigenvector is yaw(psi_M) * q_forward with the top eigenvector
(cos psi_M/2, sin psi_M/2) of the 2 x 2 matrix sum_i w_i (c_i, s_i)(c_i, s_i)^T,
c_i = cos psi_i/2, s_i = sin psi_i/2; and that is the half angle of
psi_M = atan2(sum_i w_i sin psi_i, sum_i w_i cos psi_i) (the double-angle
identities give tan 2 theta = 2 m01 / (m00 - m11)). So R_M is the approach frame
of the weighted sum of the members' unit approach directions
(:func:`meta_target_yaw_batch`); the general Markley average (:func:`meta_target_batch`) is
needed only where a cluster has a top grasp. Where that sum vanishes, M's top
eigenvalue is double and any average is as good: we take psi_M = 0.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from . import quaternion as quat
from . import shapes
from .orientation import fixed_direction, horizontal_approach_quat, task_direction, task_orientation

MIN_DISTANCE = 1e-6


def meta_target_batch(init: shapes.Prepared, opt: shapes.Prepared, mask: Array, cluster: Array,
                      orient_kind: Array, orient_quat: Array, axis: Array, p: Array,
                      tau: Array, sd: tuple[Array, Array] | None = None
                      ) -> tuple[Array, Array]:
    """(p is in a meta region, R_M(p) of that region's cluster), the Markley average, in
    the layout of :func:`meta_target_yaw_batch` (orient_quat (4, T, *batch)): returns
    (inside (*batch), R_M (4, *batch)). ``sd``: the sdfs of ``init`` and ``opt`` at p
    where the caller has them already."""
    inside, w = _region_and_weights(init, opt, mask, cluster, p, tau, sd)
    qs = task_orientation(orient_kind, orient_quat, axis, p)  # (4, T, *batch)
    return inside, quat.markley_average_batch(qs, normalised(w))


def inverse_square_weights(sd_opt: Array, in_cluster: Array) -> Array:
    """the meta skill's unnormalised weights 1 / d_i^2, d_i = max(sdf_i^opt, 1e-6)."""
    d = jnp.maximum(sd_opt, MIN_DISTANCE)
    return jnp.where(in_cluster, 1.0 / (d * d), 0.0)


def normalised(w: Array) -> Array:
    """Weights over axis 0 (tasks) scaled to sum to one."""
    return w / jnp.maximum(quat.ordered_sum(w, 0)[None], jnp.finfo(w.dtype).tiny)


def _region_and_weights(init, opt, mask, cluster, p, tau, sd=None) -> tuple[Array, Array]:
    """(p is in a meta region (*batch), the unnormalised weights 1 / d_i^2 of the
    chosen cluster's members (T, *batch)), in the batch layout; ``sd``: (sdf^init,
    sdf^opt) at p, computed here where None."""
    member = mask & (cluster >= 0)
    sd_init, sd_opt = sd if sd is not None else (shapes.prepared_sdf(init, p),
                                                 shapes.prepared_sdf(opt, p))
    inside = member & (sd_init <= tau)
    chosen = _chosen_cluster(inside, sd_init, cluster)
    w = inverse_square_weights(sd_opt, member & (cluster == chosen))
    return jnp.any(inside, axis=0), w


def _chosen_cluster(inside: Array, sd: Array, cluster: Array) -> Array:
    """``cluster[argmin(where(inside, sd, inf))]`` over axis 0 (tasks), the lowest index
    on a tie, as plain min reductions that XLA vectorises across the batch axes; the
    tasks axis kept, of length one."""
    key = jnp.where(inside, sd, jnp.inf)
    T = key.shape[0]
    index = jnp.arange(T, dtype=cluster.dtype).reshape((T,) + (1,) * (key.ndim - 1))
    first = jnp.min(jnp.where(key == jnp.min(key, axis=0, keepdims=True), index, T), axis=0,
                    keepdims=True)
    return jnp.sum(jnp.where(index == first, cluster, 0), axis=0, keepdims=True,
                   dtype=cluster.dtype)


def yaw_directions(orient_quat: Float[Array, "T 4"]
                   ) -> tuple[Float[Array, "T 2"], Bool[Array, " T"]]:
    """Per task: the fixed approach direction of its orientation space (the on-axis
    one for point-to-axis tasks) and whether that space is a horizontal approach
    frame everywhere. Both orientation kinds qualify exactly when their ``quat`` is one
    (a point-to-axis frame is horizontal off the axis)."""
    return jax.vmap(fixed_direction)(orient_quat)


def meta_target_yaw_batch(init: shapes.Prepared, opt: shapes.Prepared, mask: Array,
                          cluster: Array, orient_kind: Array, fixed_dir: Array, axis: Array,
                          p: Array, tau: Array, sd: tuple[Array, Array] | None = None
                          ) -> tuple[Array, Array]:
    """R_M for scenes whose cluster members all have horizontal approach frames
    (``Geometry.yaw_meta``): the closed form of the module docstring, no eigenvector
    iteration (tested equal to the Markley average in tests/test_quaternion.py). On
    arrays laid out for XLA: per-task arrays are
    (T, *batch), vectors put their components first, (3, T, *batch) or (2, T, *batch)
    (``shapes.components_first``), and p is (3, *batch); any shapes that broadcast
    work. Returns (inside (*batch), R_M (4, *batch)). The task reductions run over a
    leading axis, so each is a few elementwise operations on whole batch arrays;
    written per point and vmapped, the reductions over a trailing axis of T took most
    of the time on CPU. ``sd``: as for :func:`meta_target_batch`."""
    # The weights' normalisation does not change the direction of the sum.
    inside, w = _region_and_weights(init, opt, mask, cluster, p, tau, sd)
    return inside, yaw_average(w, *task_direction(orient_kind, fixed_dir, axis, p))


def yaw_average(w: Array, ux: Array, uy: Array) -> Array:
    """The weighted Markley average of horizontal approach frames with approach
    directions (ux, uy) and weights w over axis 0 (the module docstring's closed form):
    the approach frame of the weighted sum of the directions, psi 0 where it vanishes,
    w first non-negative. The weights need not sum to one."""
    ax, ay = quat.ordered_sum(w * ux, 0), quat.ordered_sum(w * uy, 0)
    n = jnp.sqrt(ax * ax + ay * ay)
    ok = n > jnp.finfo(n.dtype).tiny
    inv = 1.0 / jnp.where(ok, n, 1.0)
    q = horizontal_approach_quat(jnp.where(ok, ax * inv, 1.0), jnp.where(ok, ay * inv, 0.0))
    return q * jnp.where(q[:1] < 0, -1.0, 1.0)
