"""Per-scene metrics of SPEC section 10, from the rollouts of one scene and mode."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from .types import OUTCOMES, SUCCESS, SceneMetrics


def scene_metrics(outcome: Int[Array, "N T"], delta_r: Float[Array, "N T"],
                  task_mask: Bool[Array, " T"]):
    """(u_scene, mean delta_R over successes (NaN if none), outcome counts, n rollouts).
    Padded tasks count nowhere."""
    valid = jnp.broadcast_to(task_mask, outcome.shape)
    n = jnp.sum(valid)
    success = valid & (outcome == SUCCESS)
    n_success = jnp.sum(success)
    u = n_success / jnp.maximum(n, 1)
    mean_dr = jnp.where(n_success > 0,
                        jnp.sum(jnp.where(success, delta_r, 0.0)) / jnp.maximum(n_success, 1),
                        jnp.nan)
    counts = jnp.stack([jnp.sum(valid & (outcome == c)) for c in range(len(OUTCOMES))])
    return u.astype(delta_r.dtype), mean_dr, counts.astype(jnp.int32), n.astype(jnp.int32)


def batch_metrics(outcome: Int[Array, "S M N T"], delta_r: Float[Array, "S M N T"],
                  task_mask: Bool[Array, "S T"]) -> SceneMetrics:
    """:func:`scene_metrics` of every scene and mode of a batch."""
    return SceneMetrics(*jax.vmap(jax.vmap(scene_metrics, (0, 0, None)))(
        outcome, delta_r, task_mask))
