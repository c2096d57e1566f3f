"""Shrinking (reference/model), with the answers of its pseudocode.

All spaces that intersect another (section 6's test) and can still shrink lose
the same fraction ``sigma`` of their own parameter range at once, until no space
that intersects can shrink. That loop is computed without running it pass by pass:

- While a pair intersects, both its tasks are in the overlapping set, so both
  shrink at every pass (or sit at their minimum): after k passes the pair's spaces
  are each task's k-th shrink, a sequence known in advance.
- Parameters only fall and every template's space is monotone in them, so along
  that sequence the pair intersects up to some pass and never again: the first pass
  after which it no longer intersects is found by bisection (a handful of tests
  instead of one per pass), or the pair still intersects with both tasks at their
  minimum and never separates.
- A pass happens while some intersecting pair has a task that can still shrink, so
  the number of passes, each task's number of shrinks and the pairs that still
  intersect at the end follow from those first passes.

The parameters are floats throughout (the same IEEE operations as the pseudocode's
arrays), and tests/test_shrinking.py runs the pseudocode itself on random scenes and
compares every result, bit for bit.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .intersect import SpaceSet
from .shapes import Shape
from .templates import TaskSpace


def _shrunk(q: tuple, q_min: tuple, step: tuple) -> tuple:
    """max(q_min, q - step), componentwise (templates have one or two parameters)."""
    if len(q) == 1:
        return (max(q_min[0], q[0] - step[0]),)
    return tuple(max(m, v - d) for v, m, d in zip(q, q_min, step, strict=True))


def _above(q: tuple, q_min: tuple, slack: tuple) -> bool:
    """Some component above its minimum by more than the slack (1e-9 of its range)."""
    if len(q) == 1:
        return q[0] - q_min[0] > slack[0]
    return any(v - m > e for v, m, e in zip(q, q_min, slack, strict=True))


def shrink_sequence(space: TaskSpace, sigma: float, max_iter: int) -> list[tuple]:
    """The task's parameters after 0, 1, ... shrinks, up to the first at its minimum
    (or max_iter shrinks): element k is what k passes of the pseudocode give."""
    q = tuple(float(v) for v in space.q_init)
    q_min = tuple(float(v) for v in space.q_min)
    step = tuple(float(v) for v in sigma * (space.q_init - space.q_min))
    slack = tuple(float(v) for v in 1e-9 * (space.q_init - space.q_min))
    seq = [q]
    while len(seq) <= max_iter and _above(q, q_min, slack):
        q = _shrunk(q, q_min, step)
        seq.append(q)
    return seq


@dataclass(frozen=True)
class ShrinkResult:
    q_opt: list[np.ndarray]
    iterations: int
    still_intersecting: list[tuple[int, int]]


def shrink(spaces: Sequence[TaskSpace], sigma: float = 0.05, max_iter: int = 1000,
           space_set: SpaceSet | None = None, history: list | None = None,
           pairs: Sequence[tuple[int, int]] | None = None) -> ShrinkResult:
    """Shrinking's loop (module docstring). ``space_set`` (the initial spaces) is
    reused and updated in place when given, ``pairs`` (its intersecting pairs)
    likewise; ``history``, when given, receives every task's parameters after each
    pass."""
    coll = space_set if space_set is not None else SpaceSet([s.shape() for s in spaces])
    active = list(pairs) if pairs is not None else coll.intersecting_pairs()
    seqs = [shrink_sequence(s, sigma, max_iter) for s in spaces]
    last = [len(q) - 1 for q in seqs]  # shrinks each task can make
    shapes: dict[tuple[int, int], Shape] = {}

    def intersects_after(i: int, j: int, k: int) -> bool:
        for t in (i, j):
            kt = min(k, last[t])
            shape = shapes.get((t, kt))
            if shape is None:
                shape = shapes[(t, kt)] = spaces[t].shape_of(seqs[t][kt])
            coll.update(t, shape)
        return coll.intersects(i, j)

    # The first pass after which each pair no longer intersects (inf: never).
    first_apart = {}
    for i, j in active:
        end = max(last[i], last[j])
        if end == 0 or intersects_after(i, j, end):
            first_apart[(i, j)] = np.inf
            continue
        lo, hi = 0, end  # intersects after lo passes, not after hi
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if intersects_after(i, j, mid):
                lo = mid
            else:
                hi = mid
        first_apart[(i, j)] = hi
    # Pass k happens while a pair that intersects after k - 1 passes has a task that can
    # still shrink: the passes form a prefix, as long as the longest pair keeps going.
    iterations = int(max((min(first_apart[p], max(last[p[0]], last[p[1]])) for p in active),
                         default=0))
    iterations = min(iterations, max_iter)
    reach = [0.0] * len(spaces)
    for (i, j), k in first_apart.items():
        reach[i], reach[j] = max(reach[i], k), max(reach[j], k)
    shrinks = [int(min(iterations, last[i], reach[i])) for i in range(len(spaces))]
    if history is not None:
        for k in range(1, iterations + 1):
            history.append([np.array(seqs[i][min(k, shrinks[i])]) for i in range(len(spaces))])
    for i in range(len(spaces)):
        coll.update(i, spaces[i].shape_of(seqs[i][shrinks[i]]))
    still = [p for p in active if first_apart[p] > iterations]
    return ShrinkResult([np.array(seqs[i][shrinks[i]]) for i in range(len(spaces))],
                        iterations, still)
