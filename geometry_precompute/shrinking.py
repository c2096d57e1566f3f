"""Shrinking (SPEC section 7), exactly as its pseudocode says.

All spaces that intersect another (coal, section 6's test) and can still
shrink lose the same fraction ``sigma`` of their own parameter range at once,
until no space that intersects can shrink. Parameters only ever decrease,
so a task that stops intersecting never intersects again and the loop ends
within ceil(1 / sigma) passes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .intersect import SpaceSet
from .templates import TaskSpace


@dataclass(frozen=True)
class ShrinkResult:
    q_opt: list[np.ndarray]
    iterations: int
    still_intersecting: list[tuple[int, int]]


def _above_min(q: np.ndarray, space: TaskSpace) -> bool:
    rng = space.q_init - space.q_min
    return bool(np.any(q - space.q_min > 1e-9 * rng))


def shrink(spaces: Sequence[TaskSpace], sigma: float = 0.05, max_iter: int = 1000,
           space_set: SpaceSet | None = None, history: list | None = None) -> ShrinkResult:
    """Run SPEC section 7's loop. ``space_set`` (the initial spaces' coal objects) is
    reused and updated in place when given; ``history``, when given, receives a copy
    of every task's parameters after each pass."""
    q = [s.q_init.copy() for s in spaces]
    coll = space_set if space_set is not None else SpaceSet([s.shape() for s in spaces])
    iterations = 0
    for _ in range(max_iter):
        overlapping: set[int] = set()
        for i, j in coll.candidate_pairs():
            if (i in overlapping and j in overlapping) or not coll.intersects(i, j):
                continue
            overlapping.update((i, j))
        shrinkable = [i for i in sorted(overlapping) if _above_min(q[i], spaces[i])]
        if not shrinkable:
            break
        for i in shrinkable:
            s = spaces[i]
            q[i] = np.maximum(s.q_min, q[i] - sigma * (s.q_init - s.q_min))
            coll.update(i, s.shape(q[i]))
        iterations += 1
        if history is not None:
            history.append([x.copy() for x in q])
    still = [(i, j) for i, j in coll.candidate_pairs() if coll.intersects(i, j)]
    return ShrinkResult(q, iterations, still)
