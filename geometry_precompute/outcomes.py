"""Per-scene metrics of rollouts (reference/statistics), in NumPy and double precision.

What every table, printout and JSON file reports, from the joined rollouts of a batch:
u_scene = successes / rollouts as an exact fraction of counts, the mean delta_R over
successes summed in float64, and the outcome counts. Here, in the CPU half, so that a
sweep's CPU workers (which never import JAX) compute them beside its tables;
``shacc_jax.host_metrics`` gives the same as a ``SceneMetrics``.
"""

from __future__ import annotations

import numpy as np

from .schema import OUTCOMES, SUCCESS


def scene_metrics(outcome, delta_r, task_mask) -> tuple[np.ndarray, ...]:
    """(u_scene, delta_R_mean, outcome_counts, n_rollouts) of rollouts (*lead, S, M, N, T)
    (``*lead``: e.g. a points axis) with ``task_mask`` (S, T): u_scene float64,
    delta_R_mean float64 (NaN where a scene and mode has no success), outcome_counts
    (*lead, S, M, 5) and n_rollouts (*lead, S, M) int64. Padded tasks count nowhere."""
    outcome = np.asarray(outcome)
    valid = np.broadcast_to(np.asarray(task_mask, bool)[:, None, None, :], outcome.shape)
    counts = np.stack([np.sum(valid & (outcome == c), axis=(-2, -1))
                       for c in range(len(OUTCOMES))], axis=-1).astype(np.int64)
    n = np.sum(valid, axis=(-2, -1)).astype(np.int64)
    success = valid & (outcome == SUCCESS)
    n_success = counts[..., SUCCESS]
    total = np.sum(np.where(success, np.asarray(delta_r, np.float64), 0.0), axis=(-2, -1))
    with np.errstate(invalid="ignore", divide="ignore"):
        u = n_success / np.maximum(n, 1)
        mean = np.where(n_success > 0, total / np.maximum(n_success, 1), np.nan)
    return u.astype(np.float64), mean, counts, n
