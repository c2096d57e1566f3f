"""Per-scene metrics (reference/statistics), from the rollouts of one scene and mode.

Two forms of the same definitions: :func:`batch_metrics` inside the jitted
evaluation (working precision, on the device) and :func:`host_metrics` in NumPy,
which is what every table, printout and JSON file of the command line reports:
rates are exact fractions of counts in double precision, and a mean of delta_R is
summed in float64 over the joined rollouts, so that it does not depend on how the
rollouts were split into pieces, devices or chunks.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from geometry_precompute.outcomes import scene_metrics as scene_metrics_np

from .flatmap import spread, vmap_leading
from .types import OUTCOMES, SUCCESS, Rollouts, SceneMetrics


def scene_metrics(outcome: Int[Array, "N T"], delta_r: Float[Array, "N T"],
                  task_mask: Bool[Array, " T"], step: Int[Array, "N T"],
                  path_length: Float[Array, "N T"], assist: Int[Array, "N T 4"],
                  dt: Float[Array, ""]):
    """(u_scene, mean delta_R over successes (NaN if none), outcome counts, n rollouts,
    mean time to activation and path length over successes (NaN if none), the
    fractions of the steps under each kind of assistance (NaN without a step)). Padded
    tasks count nowhere."""
    valid = jnp.broadcast_to(task_mask, outcome.shape)
    n = jnp.sum(valid)
    success = valid & (outcome == SUCCESS)
    n_success = jnp.sum(success)
    u = n_success / jnp.maximum(n, 1)
    some = n_success > 0
    per_success = jnp.maximum(n_success, 1).astype(delta_r.dtype)
    mean_dr = jnp.where(some, jnp.sum(jnp.where(success, delta_r, 0.0)) / per_success, jnp.nan)
    time = jnp.where(some, jnp.sum(jnp.where(success, step, 0)).astype(delta_r.dtype) * dt
                     / per_success, jnp.nan)
    path = jnp.where(some, jnp.sum(jnp.where(success, path_length, 0.0)) / per_success, jnp.nan)
    taken = jnp.sum(jnp.where(valid[..., None], assist, 0), axis=(0, 1)).astype(delta_r.dtype)
    all_steps = jnp.sum(taken)
    fraction = jnp.where(all_steps > 0, taken / jnp.maximum(all_steps, 1.0), jnp.nan)
    counts = jnp.stack([jnp.sum(valid & (outcome == c)) for c in range(len(OUTCOMES))])
    return (u.astype(delta_r.dtype), mean_dr, counts.astype(jnp.int32), n.astype(jnp.int32),
            time, path, fraction)


def batch_metrics(rollouts: Rollouts, task_mask: Bool[Array, "S T"],
                  dt: Float[Array, " S"]) -> SceneMetrics:
    """:func:`scene_metrics` of every scene and mode of a batch."""
    pairs = rollouts.outcome.shape[:2]  # (S, M)
    return SceneMetrics(*vmap_leading(scene_metrics, 2)(
        rollouts.outcome, rollouts.delta_R, spread(task_mask, pairs, (0,)), rollouts.step,
        rollouts.path_length, rollouts.assist, spread(dt, pairs, (0,))))


def host_metrics(rollouts: Rollouts, task_mask, dt) -> SceneMetrics:
    """:func:`batch_metrics` in NumPy and double precision, of rollouts (*lead, S, M, N,
    T) (``*lead``: e.g. a points axis) with ``task_mask`` (S, T) and the scenes' ``dt``
    (*lead, S): u_scene = successes / rollouts as a float64 fraction, the means in
    float64 over the successes (NaN where there is none), outcome_counts (*lead, S, M,
    5) and n_rollouts (*lead, S, M) as int64, the assistance's fractions of the steps
    (``geometry_precompute.outcomes``, which a sweep's CPU workers use without JAX).

    Example::

        >>> import numpy as np
        >>> from shacc_jax import host_metrics
        >>> from shacc_jax.types import Rollouts
        >>> outcome = np.array([[[[0, 1], [0, 0]]]])        # S=1, M=1, N=2, T=2
        >>> delta_r = np.array([[[[0.1, np.nan], [0.3, 0.2]]]])
        >>> step = np.array([[[[10, 20], [30, 40]]]])
        >>> assist = np.stack([step, 0 * step, 0 * step, 0 * step], -1)
        >>> ro = Rollouts(outcome, None, step, None, 0.5 + 0 * delta_r, None, delta_r,
        ...               None, None, assist)
        >>> m = host_metrics(ro, np.array([[True, True]]), np.array([0.02]))
        >>> float(m.u_scene[0, 0]), round(float(m.delta_R_mean[0, 0]), 3)
        (0.75, 0.2)
        >>> round(float(m.time_mean[0, 0]), 3), m.assist_fraction[0, 0].tolist()
        (0.533, [1.0, 0.0, 0.0, 0.0])
    """
    return SceneMetrics(*scene_metrics_np(rollouts.outcome, rollouts.delta_R, task_mask,
                                          rollouts.step, rollouts.path_length,
                                          rollouts.assist, dt))
