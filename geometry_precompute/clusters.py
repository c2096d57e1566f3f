"""Clusters (SPEC section 6): connected components of the graph linking tasks
whose initial position spaces intersect (coal, touching does not count)."""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .intersect import SpaceSet


def intersecting_pairs(spaces: SpaceSet) -> list[tuple[int, int]]:
    return [(i, j) for i, j in spaces.candidate_pairs() if spaces.intersects(i, j)]


def clusters_from_pairs(n: int, pairs: list[tuple[int, int]]) -> list[list[int]]:
    """Components in task order: each listed by ascending task index, ordered by
    their first task. Singletons included."""
    if n == 0:
        return []
    rows = np.array([p[0] for p in pairs], dtype=int)
    cols = np.array([p[1] for p in pairs], dtype=int)
    graph = coo_matrix((np.ones(len(pairs)), (rows, cols)), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    comps: dict[int, list[int]] = {}
    for i, lab in enumerate(labels):
        comps.setdefault(int(lab), []).append(i)
    return sorted(comps.values(), key=lambda c: c[0])
