"""One-point forms of the JAX half's batched kernels, for tests: the library computes
the meta target on (tasks, lanes, samples) arrays only (``tracking.block_targets``);
these wrap it for a single point so tests can compare it with references."""

from __future__ import annotations

import jax.numpy as jnp

from shacc_jax import shapes
from shacc_jax.meta import (
    inverse_square_weights,
    meta_target_batch,
    meta_target_yaw_batch,
    normalised,
)


def components_first(s: shapes.Prepared) -> shapes.Prepared:
    """Prepared shapes of shape (*batch, *components) rearranged to (*components,
    *batch): rot (3, 3, ...), center, dims and trig (3, ...), kind as is."""
    def lead(a, n):
        return jnp.moveaxis(a, tuple(range(a.ndim - n, a.ndim)), tuple(range(n)))

    return shapes.Prepared(s.kind, lead(s.center, 1), lead(s.rot, 2), lead(s.dims, 1),
                           lead(s.trig, 1))


def meta_weights(opt, in_cluster, p):
    """The meta skill's normalised weights (reference/model) at one point."""
    return normalised(inverse_square_weights(shapes.all_sdf(opt, p), in_cluster))


def meta_target(init, opt, mask, cluster, orient, p, tau):
    """(p is in a meta region, R_M(p)) at one point, the Markley average."""
    kind, q_fixed, axis = orient
    return meta_target_batch(components_first(init), components_first(opt), mask, cluster,
                             kind, q_fixed.T, axis.T, p, tau)


def meta_target_yaw(init, opt, mask, cluster, orient_kind, fixed_dir, axis, p, tau):
    """The closed form at one point."""
    return meta_target_yaw_batch(components_first(init), components_first(opt), mask, cluster,
                                 orient_kind, fixed_dir.T, axis.T, p, tau)
