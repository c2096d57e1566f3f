"""Clutteredness C (SPEC section 5, the paper's eq. 1).

C = sum_{i<j} V(p_i ∩ p_j) / sum_i V(p_i), with the intersections computed
by manifold3d's boolean on the meshes of :mod:`geometry_precompute.meshes`,
and the denominator's volumes taken from the same meshes. A pair whose
bounding boxes are disjoint is skipped without a boolean.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from .meshes import shape_manifold
from .shapes import Shape


def overlap_volumes(shapes: Sequence[Shape], sections: int,
                    candidates: Iterable[tuple[int, int]] | None = None) -> tuple[list, dict]:
    """(mesh volumes, {(i, j): intersection volume} for pairs whose boxes overlap).

    ``candidates`` restricts the booleans to the given pairs: the precompute passes
    the pairs that coal found intersecting (section 6's test), since the others have
    no common volume (up to the meshes' deviation from the exact shapes), and a
    boolean costs about a millisecond."""
    mans = [shape_manifold(s, sections) for s in shapes]
    vols = [m.volume() for m in mans]
    boxes = [m.bounding_box() for m in mans]
    n = len(mans)
    if candidates is None:
        candidates = [(i, j) for i in range(n) for j in range(i + 1, n)]
    pairs = {}
    for i, j in candidates:
        bi, bj = boxes[i], boxes[j]
        if (bi[0] > bj[3] or bj[0] > bi[3] or bi[1] > bj[4] or bj[1] > bi[4]
                or bi[2] > bj[5] or bj[2] > bi[5]):
            continue
        pairs[(i, j)] = (mans[i] ^ mans[j]).volume()
    return vols, pairs


def clutteredness(shapes: Sequence[Shape], sections: int = 32,
                  candidates: Iterable[tuple[int, int]] | None = None) -> float:
    if len(shapes) < 2:
        return 0.0
    vols, pairs = overlap_volumes(shapes, sections, candidates)
    return float(sum(pairs.values()) / sum(vols))
