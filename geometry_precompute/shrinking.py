"""Shrinking (SPEC section 7), exactly as its pseudocode says.

All spaces that intersect another (section 6's test) and can still shrink lose
the same fraction ``sigma`` of their own parameter range at once, until no space
that intersects can shrink. Parameters only ever decrease and every template's
space is monotone in its parameters, so a pair that stops intersecting never
intersects again: each pass retests only the pairs that intersected before it and
of which a space shrank, and the loop ends within ceil(1 / sigma) passes.

A retest is skipped when its answer is certain: the overlap (penetration depth)
of two convex spaces falls by at most the distances their surfaces moved
(support functions), and a pass moves a surface by at most :func:`step_bound`. A
pair that overlapped by more than the sum of its moves since its last test, with
coal's depth discounted by ``COAL_DEPTH_MARGIN``, still intersects.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .intersect import INTERSECT_TOL, SpaceSet
from .shapes import Shape
from .templates import TaskSpace

# How far coal's penetration depth (EPA) may overstate the truth: 100x its tolerance.
COAL_DEPTH_MARGIN = 1e-4


def step_bound(old: Shape, new: Shape) -> float:
    """An upper bound on how far any point of ``old`` lies from ``new`` (new inside old,
    same rotation): the most a surface moved."""
    moved = math.dist(old.center, new.center)
    (a, b, c), (a2, b2, c2) = old.dims, new.dims
    if old.kind == "cone":
        return moved + (a - a2) + abs(a * math.tan(b) - a2 * math.tan(b2))
    return moved + 2.0 * (abs(a - a2) + abs(b - b2) + abs(c - c2))


@dataclass(frozen=True)
class ShrinkResult:
    q_opt: list[np.ndarray]
    iterations: int
    still_intersecting: list[tuple[int, int]]


def shrink(spaces: Sequence[TaskSpace], sigma: float = 0.05, max_iter: int = 1000,
           space_set: SpaceSet | None = None, history: list | None = None,
           pairs: Sequence[tuple[int, int]] | None = None) -> ShrinkResult:
    """Run SPEC section 7's loop. ``space_set`` (the initial spaces) is reused and
    updated in place when given, ``pairs`` (its intersecting pairs) likewise;
    ``history``, when given, receives a copy of every task's parameters after each
    pass."""
    # Parameters as tuples of floats: the same IEEE arithmetic as NumPy's, without its
    # per-call cost in a loop of a few hundred steps.
    q = [tuple(float(v) for v in s.q_init) for s in spaces]
    q_min = [tuple(float(v) for v in s.q_min) for s in spaces]
    step = [tuple(float(v) for v in sigma * (s.q_init - s.q_min)) for s in spaces]
    slack = [tuple(float(v) for v in 1e-9 * (s.q_init - s.q_min)) for s in spaces]
    can_shrink = [any(v - m > e for v, m, e in zip(q[i], q_min[i], slack[i], strict=True))
                  for i in range(len(spaces))]
    coll = space_set if space_set is not None else SpaceSet([s.shape() for s in spaces])
    active = list(pairs) if pairs is not None else coll.intersecting_pairs()
    iterations = 0
    shapes = list(coll.shapes)
    sure = {p: 0.0 for p in active}  # overlap known to remain, by each pair's last test
    for _ in range(max_iter):
        shrinkable = sorted({i for p in active for i in p if can_shrink[i]})
        if not shrinkable:
            break
        move = {}
        for i in shrinkable:
            q[i] = qi = tuple(max(m, v - d) for v, m, d in zip(q[i], q_min[i], step[i],
                                                               strict=True))
            can_shrink[i] = any(v - m > e for v, m, e in zip(qi, q_min[i], slack[i],
                                                             strict=True))
            new = spaces[i].shape_of(qi)
            move[i] = step_bound(shapes[i], new)
            shapes[i] = new
            coll.update(i, new)
        iterations += 1
        if history is not None:
            history.append([np.array(x) for x in q])
        kept = []
        for i, j in active:
            if i in move or j in move:
                sure[(i, j)] -= move.get(i, 0.0) + move.get(j, 0.0)
                if not sure[(i, j)] > INTERSECT_TOL:
                    d, exact = coll.depth(i, j)
                    if not d > INTERSECT_TOL:
                        continue
                    sure[(i, j)] = d if exact else d - COAL_DEPTH_MARGIN
            kept.append((i, j))
        active = kept
    return ShrinkResult([np.array(x) for x in q], iterations, active)
