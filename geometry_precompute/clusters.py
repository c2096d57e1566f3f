"""Clusters (reference/model): connected components of the graph linking tasks
whose initial position spaces intersect (touching does not count; the pairs come
from :meth:`~geometry_precompute.intersect.SpaceSet.intersecting_pairs`).

Union-find rather than scipy.sparse.csgraph: for the ten-odd tasks of a scene it
takes 6 us against scipy's 200 us (of a 6 ms budget per scene)."""

from __future__ import annotations


def clusters_from_pairs(n: int, pairs: list[tuple[int, int]]) -> list[list[int]]:
    """Components in task order: each listed by ascending task index, ordered by
    their first task. Singletons included."""
    parent = list(range(n))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, j in pairs:
        a, b = root(i), root(j)
        if a != b:
            parent[max(a, b)] = min(a, b)
    comps: dict[int, list[int]] = {}
    for i in range(n):
        comps.setdefault(root(i), []).append(i)
    return sorted(comps.values(), key=lambda c: c[0])
