"""Memory: how much an evaluation needs, how much it may use, and evaluation in pieces
when a valid batch is larger than that.

A batch's device memory grows with scenes x starts x tasks x modes (the rollout
outputs, the activation pass and the tracking blocks). Before anything is allocated,
:func:`evaluate_in_pieces` compares that estimate with the budget and, when it is too
large, evaluates the start grid in pieces that fit, every piece padded to one size (one
compiled program), and joins them: each rollout depends only on its own start, so the
joined rollouts equal one piece's, and the per-scene metrics are computed once over
the joined rollouts. Where even one start pose of the batch does not fit, it stops with
an error that says how much memory it needs.

The budget: ``$SHACC_MEMORY_BUDGET`` (bytes; suffixes K, M, G allowed) if set, else half
of what the device has free (an accelerator's free memory, or the host's available
memory on a CPU).
"""

from __future__ import annotations

import os
from dataclasses import replace
from types import SimpleNamespace

import jax
import numpy as np

import shacc_jax
from geometry_precompute import BakedScenes, InputError
from geometry_precompute.bake import batch_layout
from shacc_jax.metrics import host_metrics
from shacc_jax.types import Evaluation, Rollouts

# Memory one rollout needs during evaluation (rollout outputs, the activation pass, the
# tracking blocks, and with collision checks each rollout's per-object windows and the
# checks' blocks), with a safety factor of about 1.2 over the largest measured: peak
# device memory on an H100 (10 000 and 1 000 random 10-task scenes) 251-393 bytes
# without checks and 2 194-3 051 with; XLA's memory analysis of the CPU program (100
# and 1 000 scenes) 1 004-1 089 and 3 554-5 420 (benchmarks/RESULTS.md, memory per
# rollout).
BYTES_PER_ROLLOUT = {("accelerator", False): 600, ("accelerator", True): 3700,
                     ("cpu", False): 1300, ("cpu", True): 6500}
ENV = "SHACC_MEMORY_BUDGET"


MAX_BUDGET = 2**60  # bytes: an exbibyte, beyond any machine


def _parse_bytes(text: str) -> int:
    """``SHACC_MEMORY_BUDGET``: bytes, with an optional K, M, G or T suffix (powers of
    1024), from 1 byte to :data:`MAX_BUDGET`."""
    units = {"K": 2**10, "M": 2**20, "G": 2**30, "T": 2**40}
    t = text.strip().upper().removesuffix("B")
    scale = units.get(t[-1:], 1)
    number = t[:-1] if t[-1:] in units else t
    value: float
    try:
        value = int(number) * scale if len(number) <= 30 else -1
    except ValueError:
        try:
            value = float(number) * scale
        except (ValueError, OverflowError):
            value = -1
    if not 1 <= value <= MAX_BUDGET:  # NaN, inf and 400-digit numbers fail here too
        raise InputError(f"${ENV}", ENV, f"must be a number of bytes from 1 to 2^60 such as "
                         f"2G, got {text[:40]!r}")
    return int(value)


def budget() -> int:
    """Bytes one evaluation may use."""
    if os.environ.get(ENV):
        return _parse_bytes(os.environ[ENV])
    dev = jax.local_devices()[0]
    stats = dev.memory_stats() if hasattr(dev, "memory_stats") else None
    if stats and "bytes_limit" in stats:
        free = stats["bytes_limit"] - stats.get("bytes_in_use", 0)
    else:
        free = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    return int(0.5 * free)


def bytes_per_rollout(collision: bool, platform: str | None = None) -> int:
    """:data:`BYTES_PER_ROLLOUT` of the program that runs (``platform``: "cpu" or
    another JAX backend; default the one in use), with or without collision checks."""
    platform = platform or jax.default_backend()
    return BYTES_PER_ROLLOUT[("cpu" if platform == "cpu" else "accelerator", bool(collision))]


def bytes_needed(n_scenes: int, n_starts: int, n_tasks: int, n_modes: int,
                 collision: bool = False) -> int:
    return bytes_per_rollout(collision) * n_scenes * n_starts * n_tasks * n_modes


def _size(n: float) -> str:
    for unit, scale in (("GB", 2**30), ("MB", 2**20), ("KB", 2**10)):
        if n >= scale:
            return f"{n / scale:,.1f} {unit}"
    return f"{int(n)} bytes"


def search_scenes_per_call(baked: BakedScenes, limit: int | None = None) -> int:
    """Scenes the optimized mode's search may take in one call: each holds population x
    search starts x tasks activation rollouts at once."""
    limit = budget() if limit is None else limit
    # The larger of a generation (population x search starts) and the final validation
    # (the candidates, Shrinking's and the initial sizes x validation starts).
    at_once = max(int(np.max(baked.optimize_population)) * baked.opt_starts.shape[1],
                  (int(np.max(baked.optimize_candidates)) + 2)
                  * int(np.max(baked.optimize_validation_starts)))
    per_scene = bytes_per_rollout(False) * at_once * baked.n_tasks
    if per_scene > limit:
        raise InputError("<memory>", "optimize_population x optimize_starts", "the search "
                         f"of one scene ({baked.n_tasks} tasks) needs {_size(per_scene)}, "
                         f"more than the budget of {_size(limit)}; lower them or raise "
                         f"${ENV}")
    return limit // per_scene


def evaluate_in_pieces(baked: BakedScenes, modes, evaluate=None,
                       limit: int | None = None, params=None,
                       metrics: bool = True) -> Evaluation:
    """``evaluate(geometry, params, layout)`` (default ``shacc_jax.evaluate_on_devices``)
    of a bake's ``modes``, as NumPy arrays, split over the start grid when the batch
    needs more than ``limit`` bytes (default :func:`budget`). ``params``: P Params of
    this bake's scenes (sweep points over its geometry), evaluated in one call with a
    points axis; the results then have a leading axis P. Rollouts fields that
    ``evaluate`` leaves None (``evaluate_on_devices``' ``fields``) stay None; a split
    batch needs outcome and delta_R for its metrics."""
    run = evaluate or shacc_jax.evaluate_on_devices
    stacked = None if params is None else jax.tree.map(
        lambda *xs: np.stack([np.asarray(x) for x in xs]), *params)

    def run_bake(b):
        geometry, own, layout = shacc_jax.inputs(b, modes)
        if stacked is None:
            return run(geometry, own, layout)
        # The layout of the geometry with every point's settings (collision checks if any
        # point has them on).
        layout = batch_layout(SimpleNamespace(**{**b.arrays(), **stacked._asdict()}), modes)
        return run(geometry, stacked, layout)

    limit = budget() if limit is None else limit
    S, N, T, M = baked.n_scenes, baked.n_starts, baked.n_tasks, len(modes)
    P = 1 if params is None else len(params)
    lead = 0 if params is None else 1  # a points axis before the scenes axis
    collision = bool(np.any(baked.collision if stacked is None else stacked.collision))
    per_start = bytes_needed(S, 1, T, M, collision) * P
    # At least two starts in every program, even a one-start grid (padded by repeating
    # it): where an axis has length one, XLA simplifies the arithmetic around it
    # differently, and a rollout's last bits would depend on its piece
    # (shacc_jax/determinism.py).
    n_per = N if per_start * N <= limit and N >= 2 else limit // per_start
    if n_per < 2:
        raise InputError("<memory>", "batch", f"two start poses of this batch ({P} x {S} "
                         f"scenes x {T} tasks x {M} modes) need {_size(2 * per_start)}, more "
                         f"than the budget of {_size(limit)}; evaluate fewer scenes at once "
                         f"or raise ${ENV}")
    if n_per >= N:
        rollouts = jax.tree.map(np.asarray, run_bake(baked)).rollouts
    else:
        pieces = []
        for a in range(0, N, n_per):
            idx = np.minimum(np.arange(a, a + n_per), N - 1)  # last piece padded: one shape
            out = run_bake(replace(baked, starts=baked.starts[:, idx]))
            keep = min(n_per, N - a)
            pieces.append([None if x is None else np.take(np.asarray(x), np.arange(keep),
                                                          axis=2 + lead)
                           for x in out.rollouts])
        # Fields that ``evaluate`` did not copy to the host stay None.
        rollouts = Rollouts._make(None if parts[0] is None else
                                  np.concatenate(parts, axis=2 + lead)
                                  for parts in zip(*pieces, strict=True))
    # Metrics once, in double precision, over the joined rollouts: the same numbers
    # whether the batch ran in one piece or several (shacc_jax.metrics). ``metrics``
    # False leaves them to the caller (a sweep computes them on a CPU worker).
    return Evaluation._make((rollouts, host_metrics(rollouts.outcome, rollouts.delta_R,
                                                    baked.task_mask) if metrics else None))
