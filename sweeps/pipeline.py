"""Glue between the halves: scenes -> precompute -> bake -> jitted evaluation ->
NumPy results and SPEC section 12a's JSON. Reproduce and sweeps reuse it."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

import shacc_jax
from geometry_precompute import (
    BakedScenes,
    PrecomputeResult,
    bake,
)
from shacc_jax.types import OUTCOMES, Evaluation

from .memory import evaluate_in_pieces
from .output import precompute_json


@dataclass(frozen=True)
class Evaluated:
    results: list[PrecomputeResult]
    baked: BakedScenes
    evaluation: Evaluation  # NumPy arrays
    modes: tuple[str, ...]
    seconds: dict


def evaluate_results(results: Sequence[PrecomputeResult], modes=shacc_jax.MODES,
                     max_tasks: int | None = None) -> Evaluated:
    t0 = time.perf_counter()
    baked = bake(results, max_tasks)
    t1 = time.perf_counter()
    ev = evaluate_in_pieces(baked, tuple(modes), shacc_jax.evaluate)
    t2 = time.perf_counter()
    return Evaluated(list(results), baked, ev, tuple(modes),
                     {"bake": t1 - t0, "evaluate": t2 - t1})


def _none_if_nan(x: float):
    return None if not np.isfinite(x) else float(x)


def scene_json(ev: Evaluated, s: int) -> dict:
    """SPEC section 12a's object for scene ``s`` of an evaluated batch."""
    r = ev.results[s]
    ids = r.task_ids
    T = len(ids)
    out = precompute_json(r)
    out["starts"] = ev.baked.starts[s].tolist()
    ro, me = ev.evaluation.rollouts, ev.evaluation.metrics
    modes = {}
    for m, mode in enumerate(ev.modes):
        code = ro.outcome[s, m, :, :T]
        act = ro.activated[s, m, :, :T]
        dr = ro.delta_R[s, m, :, :T]
        modes[mode] = {
            "success_rate": float(me.u_scene[s, m]),
            "delta_R_mean": _none_if_nan(me.delta_R_mean[s, m]),
            "outcome": [[OUTCOMES[c] for c in row] for row in code.tolist()],
            "activated": [[ids[a] if a >= 0 else None for a in row] for row in act.tolist()],
            "delta_R": [[_none_if_nan(v) for v in row] for row in dr.tolist()],
        }
    out["modes"] = modes
    return out
