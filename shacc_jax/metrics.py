"""Per-scene metrics (reference/statistics), from the rollouts of one scene and mode.

Two forms of the same definitions: :func:`batch_metrics` inside the jitted
evaluation (working precision, on the device) and :func:`host_metrics` in NumPy,
which is what every table, printout and JSON file of the command line reports:
rates are exact fractions of counts in double precision, and a mean of delta_R is
summed in float64 over the joined rollouts, so that it does not depend on how the
rollouts were split into pieces, devices or chunks.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from geometry_precompute.outcomes import scene_metrics as scene_metrics_np

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
                        jnp.sum(jnp.where(success, delta_r, 0.0))
                        / jnp.maximum(n_success, 1).astype(delta_r.dtype),
                        jnp.nan)
    counts = jnp.stack([jnp.sum(valid & (outcome == c)) for c in range(len(OUTCOMES))])
    return u.astype(delta_r.dtype), mean_dr, counts.astype(jnp.int32), n.astype(jnp.int32)


def batch_metrics(outcome: Int[Array, "S M N T"], delta_r: Float[Array, "S M N T"],
                  task_mask: Bool[Array, "S T"]) -> SceneMetrics:
    """:func:`scene_metrics` of every scene and mode of a batch."""
    return SceneMetrics(*jax.vmap(jax.vmap(scene_metrics, (0, 0, None)))(
        outcome, delta_r, task_mask))


def host_metrics(outcome, delta_r, task_mask) -> SceneMetrics:
    """:func:`batch_metrics` in NumPy and double precision, of rollouts (*lead, S, M, N,
    T) (``*lead``: e.g. a points axis) with ``task_mask`` (S, T): u_scene = successes /
    rollouts as a float64 fraction, delta_R_mean the float64 mean of the successes'
    delta_R (NaN where there is none), outcome_counts (*lead, S, M, 5) and n_rollouts
    (*lead, S, M) as int64 (``geometry_precompute.outcomes``, which a sweep's CPU workers
    use without JAX).

    Example::

        >>> import numpy as np
        >>> from shacc_jax import host_metrics
        >>> outcome = np.array([[[[0, 1], [0, 0]]]])        # S=1, M=1, N=2, T=2
        >>> delta_r = np.array([[[[0.1, np.nan], [0.3, 0.2]]]])
        >>> m = host_metrics(outcome, delta_r, np.array([[True, True]]))
        >>> float(m.u_scene[0, 0]), round(float(m.delta_R_mean[0, 0]), 3)
        (0.75, 0.2)
    """
    return SceneMetrics(*scene_metrics_np(outcome, delta_r, task_mask))
