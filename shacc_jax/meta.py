"""The meta skill of SPEC section 8, at one EE position.

p is in the meta region p_M(K) of cluster K when sdf_i^init(p) <= tau for some
member i of K (the Automaton only asks before activation, so p is outside
every optimised space). Where p is within tau of members of two clusters
(initial spaces of different clusters may touch), the cluster of the member
with the smallest sdf^init is taken, the lower task index on a tie.

R_M(p) is the Markley average of the members' orientations R_i(p), weighted
w_i = (1 / d_i^2) / sum_j (1 / d_j^2), d_i = max(sdf_i^opt(p), 1e-6). Padded
tasks and tasks of other clusters get weight zero.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from . import quaternion as quat
from . import shapes
from .orientation import task_orientation

_all_orient = jax.vmap(task_orientation, in_axes=(0, 0, 0, None))
MIN_DISTANCE = 1e-6


def meta_weights(opt: shapes.Prepared, in_cluster: Bool[Array, " T"],
                 p: Float[Array, "3"]) -> Array:
    d = jnp.maximum(shapes.all_sdf(opt, p), MIN_DISTANCE)
    w = jnp.where(in_cluster, 1.0 / (d * d), 0.0)
    return w / jnp.maximum(jnp.sum(w), jnp.finfo(w.dtype).tiny)


def meta_target(init: shapes.Prepared, opt: shapes.Prepared, mask: Bool[Array, " T"],
                cluster: Int[Array, " T"], orient, p: Float[Array, "3"],
                tau: Array) -> tuple[Array, Float[Array, "4"]]:
    """(p is in a meta region, R_M(p) of that region's cluster)."""
    member = mask & (cluster >= 0)
    sd = shapes.all_sdf(init, p)
    inside = member & (sd <= tau)
    chosen = cluster[jnp.argmin(jnp.where(inside, sd, jnp.inf))]
    w = meta_weights(opt, member & (cluster == chosen), p)
    kind, q_fixed, axis = orient
    qs = _all_orient(kind, q_fixed, axis, p)
    return jnp.any(inside), quat.markley_average(qs, w)
