"""Distances from a capsule's segment to a mesh object's convex hull (its faces'
triangles and planes, baked): the segment clipped by the hull's planes (does it meet
the hull?) and otherwise its distance to the nearest face."""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, Float


class Hulls(NamedTuple):
    """The convex hulls of a batch's mesh objects (``Geometry.obj_hull`` and
    ``obj_hull_plane``): triangles (S, O, F, 3, 3), corners counter-clockwise seen from
    outside, and their planes (S, O, F, 4) (outward unit normal, offset), in each
    object's frame. F is 0 where no scene of the batch checks collisions against a
    mesh; a primitive object's rows are padding."""

    tri: Float[Array, "S O F 3 3"]
    plane: Float[Array, "S O F 4"]

    @classmethod
    def of(cls, geometry) -> Hulls | None:
        """The batch's hulls, or None where it has none (decided by the static F)."""
        if geometry.obj_hull.shape[2] == 0:
            return None
        return cls(geometry.obj_hull, geometry.obj_hull_plane)


def _clip_meets(alpha, beta, axis: int = -1):
    """Whether some t in [0, 1] satisfies every alpha + t beta <= 0 along ``axis`` (a
    segment against an intersection of half-spaces: Cyrus and Beck's clipping)."""
    tiny = 1e-30
    inf = jnp.asarray(jnp.inf, alpha.dtype)
    enter, leave = beta < -tiny, beta > tiny
    t = -alpha / jnp.where(enter | leave, beta, 1.0)
    lo = jnp.maximum(jnp.max(jnp.where(enter, t, -inf), axis=axis), 0.0)
    hi = jnp.minimum(jnp.min(jnp.where(leave, t, inf), axis=axis), 1.0)
    never = jnp.any(~(enter | leave) & (alpha > 0), axis=axis)
    return (lo <= hi) & ~never


def _segment_segment_sq(a, d, p, e):
    """Squared distance between segments a + s d and p + t e (s, t in [0, 1]), written
    out over the last axis (3) so that it broadcasts and fuses (Ericson, Real-Time
    Collision Detection, 5.1.9: the closest points of the lines, clamped to the
    segments; neither segment may be a point)."""
    r = tuple(ai - pi for ai, pi in zip(a, p, strict=True))
    dd = sum(di * di for di in d)
    ee = sum(ei * ei for ei in e)
    de = sum(di * ei for di, ei in zip(d, e, strict=True))
    dr = sum(di * ri for di, ri in zip(d, r, strict=True))
    er = sum(ei * ri for ei, ri in zip(e, r, strict=True))
    denom = dd * ee - de * de
    # Near-parallel lines: any s will do, and 0 is as good as any.
    ok = denom > 1e-7 * dd * ee
    s = jnp.where(ok, jnp.clip((de * er - dr * ee) / jnp.where(ok, denom, 1.0), 0.0, 1.0), 0.0)
    t = (de * s + er) / ee
    s = jnp.where(t < 0, jnp.clip(-dr / dd, 0.0, 1.0),
                  jnp.where(t > 1, jnp.clip((de - dr) / dd, 0.0, 1.0), s))
    t = jnp.clip(t, 0.0, 1.0)
    gap = [ri + s * di - t * ei for ri, di, ei in zip(r, d, e, strict=True)]
    return gap[0] * gap[0] + gap[1] * gap[1] + gap[2] * gap[2]


def hull_distance(tri: Float[Array, "F 3 3"], plane: Float[Array, "F 4"], a: Float[Array, "3"],
                  d: Float[Array, "3"]) -> Array:
    """Euclidean distance from the segment a + t d, t in [0, 1], to a convex hull (0 where
    they meet), in the hull's frame. The hull is given by its triangles ``tri``
    (corners counter-clockwise seen from outside) and their planes ``plane`` (outward
    unit normal n and offset b: the hull is every n . x <= b).

    Exact: the segment meets the hull where clipping it by the planes leaves a piece
    (Cyrus and Beck); else the closest points of the two are a point of the segment
    and a point of a hull edge (segment to segment), or an end of the segment and a
    point inside a face (the end's projection on the face's plane lies inside the
    triangle); a closest point inside both the segment and a face needs the segment
    parallel to the face, and then an end or an edge is as close. Padding triangles
    repeat a real one. (MuJoCo takes a mesh's convex hull for its collisions too, and
    its ``mj_geomDistance`` is the reference in the tests.)

    >>> import jax.numpy as jnp
    >>> import numpy as np, trimesh
    >>> box = trimesh.creation.box((0.2, 0.2, 0.2))
    >>> tri = jnp.asarray(box.triangles, jnp.float32)
    >>> plane = jnp.asarray(np.c_[box.face_normals, (box.face_normals * box.triangles[:, 0])
    ...                     .sum(1)], jnp.float32)
    >>> a, d = jnp.array([0.3, 0.3, 0.0]), jnp.array([0.0, 0.0, 0.05])
    >>> round(float(hull_distance(tri, plane, a, d)), 4)  # sqrt(0.2^2 + 0.2^2)
    0.2828
    """
    n = tuple(plane[:, i] for i in range(3))
    b = plane[:, 3]
    av, dv = tuple(a[i] for i in range(3)), tuple(d[i] for i in range(3))
    sa = n[0] * av[0] + n[1] * av[1] + n[2] * av[2] - b  # (F,): the planes at a
    sd = n[0] * dv[0] + n[1] * dv[1] + n[2] * dv[2]
    meets = _clip_meets(sa, sd, axis=0)
    v = [tuple(tri[:, k, i] for i in range(3)) for k in range(3)]
    inf = jnp.asarray(jnp.inf, a.dtype)
    best = inf
    inside = [jnp.ones_like(b, bool), jnp.ones_like(b, bool)]  # each end over each face
    ends = (av, tuple(ai + di for ai, di in zip(av, dv, strict=True)))
    for k in range(3):
        p, q = v[k], v[(k + 1) % 3]
        e = tuple(qi - pi for qi, pi in zip(q, p, strict=True))
        best = jnp.minimum(best, jnp.min(_segment_segment_sq(av, dv, p, e)))
        # The side plane through this edge, outward from the triangle: e x n.
        m = (e[1] * n[2] - e[2] * n[1], e[2] * n[0] - e[0] * n[2], e[0] * n[1] - e[1] * n[0])
        for j, x in enumerate(ends):
            side = sum(mi * (xi - pi) for mi, xi, pi in zip(m, x, p, strict=True))
            inside[j] = inside[j] & (side <= 0)
    for j, x in enumerate(ends):
        h = n[0] * x[0] + n[1] * x[1] + n[2] * x[2] - b
        best = jnp.minimum(best, jnp.min(jnp.where(inside[j] & (h >= 0), h * h, inf)))
    return jnp.where(meets, 0.0, jnp.sqrt(best))


def hull_clips(plane: Float[Array, "F 4"], a: Float[Array, "3"], d: Float[Array, "3"],
               margin) -> tuple[Array, Array]:
    """Whether the segment a + t d, t in [0, 1], meets the convex hull of planes
    ``plane`` (then its distance is 0), and whether it meets the hull's planes moved out
    by ``margin`` (a polytope that holds every point within ``margin`` of the hull: a
    segment that misses it is farther than ``margin``). Two clips (Cyrus and Beck), a
    few operations a plane: where neither decides, :func:`hull_distance` does.

    >>> import jax.numpy as jnp
    >>> cube = jnp.array([[1., 0, 0, .1], [-1, 0, 0, .1], [0, 1, 0, .1], [0, -1, 0, .1],
    ...                   [0, 0, 1, .1], [0, 0, -1, .1]])
    >>> [bool(v) for v in hull_clips(cube, jnp.array([.15, 0, 0]), jnp.array([0, 0, .1]), .01)]
    [False, False]
    >>> [bool(v) for v in hull_clips(cube, jnp.array([.105, 0, 0]), jnp.array([0, 0, .1]), .01)]
    [False, True]
    """
    n = tuple(plane[:, i] for i in range(3))
    sa = n[0] * a[0] + n[1] * a[1] + n[2] * a[2] - plane[:, 3]
    sd = n[0] * d[0] + n[1] * d[1] + n[2] * d[2]
    return _clip_meets(sa, sd, axis=0), _clip_meets(sa - margin, sd, axis=0)
