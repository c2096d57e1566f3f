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


def scene_metrics(outcome, delta_r, task_mask, step=None, path_length=None, assist=None,
                  dt=None) -> tuple[np.ndarray, ...]:
    """(u_scene, delta_R_mean, outcome_counts, n_rollouts, time_mean, path_length_mean,
    assist_fraction) of rollouts (*lead, S, M, N, T) (``*lead``: e.g. a points axis)
    with ``task_mask`` (S, T): u_scene float64, delta_R_mean float64 (NaN where a scene
    and mode has no success), outcome_counts (*lead, S, M, 5) and n_rollouts (*lead, S,
    M) int64. Padded tasks count nowhere.

    From the rollouts' ``step`` and the scenes' ``dt`` (*lead, S), ``path_length`` and
    ``assist`` (..., 4): the means over successes of the time to activation (step dt, s)
    and of the path length (m), NaN without a success, and the fraction of all the
    rollouts' steps under each kind of assistance (*lead, S, M, 4), NaN where no rollout
    took a step. A field not given (None: not copied back from the device) leaves its
    metric NaN."""
    outcome = np.asarray(outcome)
    valid = np.broadcast_to(np.asarray(task_mask, bool)[:, None, None, :], outcome.shape)
    counts = np.stack([np.sum(valid & (outcome == c), axis=(-2, -1))
                       for c in range(len(OUTCOMES))], axis=-1).astype(np.int64)
    n = np.sum(valid, axis=(-2, -1)).astype(np.int64)
    success = valid & (outcome == SUCCESS)
    n_success = counts[..., SUCCESS]
    nan = np.full(n_success.shape, np.nan)

    def success_mean(values, scale=1.0):
        if values is None:
            return nan
        total = np.sum(np.where(success, np.asarray(values, np.float64), 0.0), axis=(-2, -1))
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(n_success > 0, total * scale / np.maximum(n_success, 1), np.nan)

    with np.errstate(invalid="ignore", divide="ignore"):
        u = n_success / np.maximum(n, 1)
    mean = success_mean(delta_r)
    time_mean = nan if step is None or dt is None else success_mean(
        step, np.asarray(dt, np.float64)[..., :, None])  # (*lead, S, 1): over the modes
    path_mean = success_mean(path_length)
    if assist is None:
        fraction = np.full((*n_success.shape, 4), np.nan)
    else:
        taken = np.sum(np.where(valid[..., None], np.asarray(assist, np.int64), 0),
                       axis=(-3, -2)).astype(np.float64)  # (*lead, S, M, 4)
        all_steps = taken.sum(axis=-1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            fraction = np.where(all_steps > 0, taken / np.maximum(all_steps, 1), np.nan)
    return u.astype(np.float64), mean, counts, n, time_mean, path_mean, fraction
