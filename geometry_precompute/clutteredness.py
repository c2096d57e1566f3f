"""Clutteredness C (clutteredness (reference/model), the paper's eq. 1).

C = sum_{i<j} V(p_i ∩ p_j) / sum_i V(p_i). Two ways to get the numerator:

- ``method="fast"`` (what the precompute uses): the pairs that
  :mod:`geometry_precompute.overlap` covers (upright cylinders and disks, level
  cones with them) exactly or by quadrature, every other pair by manifold3d's
  boolean on the meshes of :mod:`geometry_precompute.meshes`; the denominator is the
  exact volumes;
- ``method="boolean"``: every pair by the boolean and the denominator from the same
  meshes, the reference the fast paths are tested against.

A pair whose bounding boxes are disjoint is skipped.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from .meshes import shape_manifold
from .overlap import fast_volumes
from .shapes import Shape, aabbs_overlap

METHODS = ("fast", "boolean")


def overlap_volumes(shapes: Sequence[Shape], sections: int,
                    candidates: Iterable[tuple[int, int]] | None = None,
                    method: str = "fast") -> tuple[list, dict]:
    """(volumes, {(i, j): intersection volume}) for the pairs whose boxes overlap, or
    for the ``candidates`` given.

    The precompute passes the pairs that section 6's test found intersecting, since
    the others have no common volume."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    n = len(shapes)
    if candidates is None:
        candidates = [(i, j) for i in range(n) for j in range(i + 1, n)]
        boxes = [s.aabb() for s in shapes]
        pairs = [(i, j) for i, j in candidates if aabbs_overlap(boxes[i], boxes[j])]
    else:  # pairs found intersecting: their boxes overlap
        pairs = list(candidates)
    if method == "fast":
        vols = [s.volume() for s in shapes]
        out, rest = fast_volumes(shapes, pairs)
        mans = {k: shape_manifold(shapes[k], sections) for k in {k for p in rest for k in p}}
    else:
        mans = {k: shape_manifold(shapes[k], sections) for k in range(n)}
        vols = [mans[k].volume() for k in range(n)]
        out, rest = {}, pairs
    for i, j in rest:
        out[(i, j)] = (mans[i] ^ mans[j]).volume()
    return vols, {p: out[p] for p in pairs}


def clutteredness_of_sets(sets: Sequence[tuple[Sequence[Shape], Iterable[tuple[int, int]]]],
                          sections: int = 32) -> list[float]:
    """C of several sets of shapes, each with its candidate pairs, from one
    :func:`overlap_volumes` call (the precompute's C_init and C_final together: the
    fast paths cost mostly per call, not per pair)."""
    shapes: list[Shape] = []
    candidates: list[tuple[int, int]] = []
    bounds = []
    for set_shapes, set_pairs in sets:
        k = len(shapes)
        shapes.extend(set_shapes)
        candidates.extend((i + k, j + k) for i, j in set_pairs)
        bounds.append((k, len(shapes)))
    vols, pairs = overlap_volumes(shapes, sections, candidates)
    out = []
    for lo, hi in bounds:
        if hi - lo < 2:
            out.append(0.0)
            continue
        inter = sum(v for (i, _), v in pairs.items() if lo <= i < hi)
        out.append(float(inter / sum(vols[lo:hi])))
    return out


def clutteredness(shapes: Sequence[Shape], sections: int = 32,
                  candidates: Iterable[tuple[int, int]] | None = None,
                  method: str = "fast") -> float:
    if len(shapes) < 2:
        return 0.0
    vols, pairs = overlap_volumes(shapes, sections, candidates, method)
    return float(sum(pairs.values()) / sum(vols))
