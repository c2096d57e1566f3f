"""Gripper-object collisions (reference/model, mujoco), exact, on the accelerator.

The gripper is three capsules posed by the EE pose (p, R): two fingers parallel to
the approach axis (EE z), at EE y = +-opening/2, from the palm (z = -finger_length)
to the tool centre point p (z = 0), and a palm across them along EE y. Its
dimensions are per-scene settings (``gripper.*``), so a sweep varies them without
recompiling. The objects are the scene's cylinders and boxes, posed and sized as in
the exported MJCF.

A capsule penetrates a convex body by more than eps exactly when its axis segment
comes within (radius - eps) of the body, so the check is a segment-to-solid distance:
the distance to a cylinder or box is convex along the segment and a bracketing search
finds its minimum to 1e-7 m. This replaced MJX's collision pipeline, whose
capsule-cylinder routine (a few gradient steps on the SDFs) reported distances up to
8 mm too large near contact and cost 250-1 100x a rollout (benchmarks/RESULTS.md). CPU
MuJoCo's ``mj_geomDistance`` on the same geoms is the reference in the tests.

Most of the work is skipped without changing an outcome: :func:`path_window` keeps only
the samples of a rollout at which the gripper can reach an object (closed form), and
:func:`first_penetration` runs the search only on the (pose, capsule, object) pairs
that a closed-form :func:`lower_bound` does not clear.

The table is not an obstacle: start poses a few centimetres above it in random
orientations would otherwise collide before moving (docs/DECISIONS.md).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from geometry_precompute.schema import BOX, MESH

from . import automaton as am
from . import quaternion as quat
from .shapes import slab_interval

PENETRATION_EPS = 1e-4  # m: a penetration deeper than this is a collision
# Slack of the path cull (m): far above float32 rounding of metre-scale coordinates.
CULL_MARGIN = 1e-3
_TINY = 1e-12


def _dot(u, v):
    """u . v over the last axis (3), written out: a reduction ends an XLA GPU fusion and
    writes its inputs to memory, where these products and sums fuse with what follows."""
    return u[..., 0] * v[..., 0] + u[..., 1] * v[..., 1] + u[..., 2] * v[..., 2]


def gripper_reach(dims: Float[Array, "4"]) -> Array:
    """Radius of a sphere about p that contains the whole gripper."""
    length, r_f, opening, r_p = dims[0], dims[1], dims[2], dims[3]
    return jnp.sqrt(length ** 2 + (0.5 * opening) ** 2) + jnp.maximum(r_f, r_p)


def scene_objects(obj_kind, obj_center, obj_quat, obj_size, obj_mask):
    """One scene's objects for :func:`deepest`: kinds (O,), centres (O, 3), rotation
    matrices (O, 3, 3), sizes (O, 3) (a cylinder's [radius, half height, -], a box's
    half extents) and the mask (O,)."""
    return obj_kind, obj_center, jax.vmap(quat.to_matrix)(obj_quat), obj_size, obj_mask


def point_distance(x, kind, size):
    """Euclidean distance from points x ((x, y, z) tuple of arrays), in an object's frame,
    to the solid cylinder or box (``size`` likewise a tuple; 0 inside). Elementwise
    only, so that many evaluations fuse into one kernel."""
    radial = jnp.sqrt(x[0] * x[0] + x[1] * x[1])
    dr = jnp.maximum(radial - size[0], 0.0)
    dz = jnp.maximum(jnp.abs(x[2]) - size[1], 0.0)
    out = [jnp.maximum(jnp.abs(xi) - si, 0.0) for xi, si in zip(x, size, strict=True)]
    return jnp.where(kind == BOX, jnp.sqrt(out[0] * out[0] + out[1] * out[1] + out[2] * out[2]),
                     jnp.sqrt(dr * dr + dz * dz))


def segment_distance(a, d, kind, size):
    """Distance from segments a + t d, t in [0, 1] (..., 3, object frame), to solid
    cylinders or boxes (``size`` (..., 3)). The distance to a convex body is convex along
    a segment, so a search brackets the minimum: GRID_POINTS evenly spaced points per
    step, the bracket narrowed to the best one's neighbours. The result is never below
    the exact distance and at most |d| (2 / (GRID_POINTS + 1))^GRID_STEPS / 2 above it.

    (A golden-section search needs fewer evaluations, but each of its steps depends on
    the last evaluation, so on a GPU every evaluation became a kernel writing the
    bracket to memory; a grid step's points are independent and fuse into one kernel.
    Faster on the H100 and on the CPU: benchmarks/RESULTS.md.)"""
    def f(t):
        return point_distance(tuple(a[..., i] + t * d[..., i] for i in range(3)), kind,
                               tuple(size[..., i] for i in range(3)))

    return _grid_minimum(f, jnp.zeros(a.shape[:-1], a.dtype))


# The grid search's points per step and steps: the bracket ends at (2/9)^10 = 2.9e-7 of
# the segment (3e-8 m for a 0.1 m palm), the best point within half of that of the
# minimum, far below PENETRATION_EPS.
GRID_POINTS = 8
GRID_STEPS = 10


def _grid_minimum(f, zero):
    """The minimum of a convex f on [0, 1] (elementwise over zero's shape): for convex f
    the minimiser lies between the neighbours of the best of evenly spaced points. The
    steps are a loop, not unrolled: each is one fused kernel either way, and the
    unrolled form took twice as long to compile (36 against 18 s on an H100)."""
    def step(_, state):
        lo, width, best = state
        h = width / (GRID_POINTS + 1)
        low, at = f(lo + h), jnp.zeros_like(zero)
        for i in range(1, GRID_POINTS):
            v = f(lo + (i + 1) * h)
            better = v < low
            low, at = jnp.where(better, v, low), jnp.where(better, float(i), at)
        return lo + at * h, 2.0 * h, jnp.minimum(best, low)

    one = jnp.ones_like(zero)
    return jax.lax.fori_loop(0, GRID_STEPS, step, (zero, one, jnp.minimum(f(zero), f(one))))[2]


def _into_frames(mat, v):
    """v (..., 3) in the frames whose rotation matrices are mat (..., 3, 3): mat^T v,
    written out as products and sums so that it fuses with what follows."""
    return (v[..., 0:1] * mat[..., 0, :] + v[..., 1:2] * mat[..., 1, :]
            + v[..., 2:3] * mat[..., 2, :])


def pair_axes(objects, p: Float[Array, "3"], q: Float[Array, "4"],
              dims: Float[Array, "4"]) -> tuple[Array, Array, Array]:
    """The gripper's capsule axes at the EE pose (p, q) in each object's frame: starts
    (3, O, 3) and extents (3, O, 3), as segments a + t d, t in [0, 1]; and the
    capsules' radii (3,). ``objects``: :func:`scene_objects`' output."""
    _, centre, mat, _, _ = objects
    starts, extents, radii = capsule_segments(p, q, dims)
    a_loc = _into_frames(mat[None], starts[:, None, :] - centre[None, :, :])
    d_loc = _into_frames(mat[None], extents[:, None, :])
    return a_loc, d_loc, radii


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


def deepest(objects, p: Float[Array, "3"], q: Float[Array, "4"], dims: Float[Array, "4"],
            hulls: Hulls | None = None, scene=None, cutoff: float | None = None) -> Array:
    """Smallest (capsule axis to object distance - capsule radius) over the gripper's
    capsules and the scene's objects (``scene_objects``' output), at the EE pose (p, q).
    Where a capsule and an object are apart this is their distance, as CPU MuJoCo's
    ``mj_geomDistance`` reports it; where they overlap it is at most minus the depth
    of the overlap's smallest separating move short of the capsule radius, and it is
    below -eps exactly when MuJoCo's penetration depth exceeds eps (a capsule overlaps
    a convex body by more than eps iff its axis comes within radius - eps of it).

    A mesh object (``hulls``, the batch's, and ``scene``, this scene's index in it) is
    its convex hull. Its bounding cylinder's distance bounds the hull's from below, and
    only pairs whose bound lies below ``cutoff`` can count: with a ``cutoff`` given,
    each is measured exactly (:func:`hull_distance`), one pair per round of a loop that
    ends when no pair is left. Without one (the penetration decision, -eps), a first
    loop clips each such pair by the hull's planes (:func:`hull_clips`): a pair that
    meets the hull counts with -radius, one that misses the planes moved out by
    radius - eps with -eps (it cannot penetrate), and only the pairs left open are
    measured, in a second loop."""
    kind, _, _, size, mask = objects
    a_loc, d_loc, radius = pair_axes(objects, p, q, dims)
    dist = segment_distance(a_loc, d_loc, kind[None, :], size[None, :, :])
    gap = dist - radius[:, None]
    if hulls is not None:
        todo = ((kind == MESH) & mask)[None, :] & (
            gap < (-PENETRATION_EPS if cutoff is None else cutoff))
        if cutoff is None:
            gap, todo = _pair_loop(todo, gap, lambda c, o, g: _clipped(
                hulls.plane[scene, o], a_loc[c, o], d_loc[c, o], radius[c], g))
        gap = _pair_loop(todo, gap, lambda c, o, g: (hull_distance(
            hulls.tri[scene, o], hulls.plane[scene, o], a_loc[c, o], d_loc[c, o])
            - radius[c], False))[0]
    return jnp.min(jnp.where(mask[None, :], gap, jnp.inf))


def _clipped(plane, a, d, radius, gap):
    """A mesh pair's gap as the hull's planes settle it, and whether they leave it open
    (:func:`deepest`)."""
    meets, near = hull_clips(plane, a, d, radius - PENETRATION_EPS)
    return (jnp.where(meets, -radius, jnp.where(near, gap, -PENETRATION_EPS)),
            near & ~meets)


def _pair_loop(todo: Bool[Array, "C O"], gap: Float[Array, "C O"], measure):
    """``measure(c, o, gap) -> (gap, open)`` of each pair ``todo`` marks, one pair per
    round of a while loop (vmapped, it runs as many rounds as the lane with most pairs
    needs); the gaps, and the pairs left open."""
    O = gap.shape[1]
    order = jnp.argsort(~todo.reshape(-1), stable=True)
    count = jnp.sum(todo)

    def body(state):
        i, out, still = state
        c, o = order[i] // O, order[i] % O
        value, left = measure(c, o, out[c, o])
        return i + 1, out.at[c, o].set(value), still.at[c, o].set(left)

    _, gap, still = jax.lax.while_loop(lambda state: state[0] < count, body,
                                       (jnp.zeros((), count.dtype), gap,
                                        jnp.zeros_like(todo)))
    return gap, still


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


def lower_bound(a, d, kind, size):
    """A lower bound of the distance from segments a + t d (..., 3, object frame) to
    solid cylinders or boxes, in closed form: per box axis, or for a cylinder along its
    axis and radially, the gap between the segment's range and the solid's; the
    Euclidean norm of the gaps bounds every point's distance from below."""
    return _lower_bound_xyz(tuple(a[..., i] for i in range(3)),
                            tuple(d[..., i] for i in range(3)), kind,
                            tuple(size[..., i] for i in range(3)))


def _lower_bound_xyz(a, d, kind, size):
    """:func:`lower_bound` on (x, y, z) tuples of arrays: elementwise only, so that the
    pose, the frames and the bound fuse into one kernel."""
    gaps = []
    for ai, di, si in zip(a, d, size, strict=True):
        lo, hi = jnp.minimum(ai, ai + di), jnp.maximum(ai, ai + di)
        gaps.append(jnp.maximum(jnp.maximum(lo - si, -si - hi), 0.0))
    box = jnp.sqrt(gaps[0] * gaps[0] + gaps[1] * gaps[1] + gaps[2] * gaps[2])
    t = jnp.clip(-(a[0] * d[0] + a[1] * d[1])
                 / jnp.maximum(d[0] * d[0] + d[1] * d[1], _TINY), 0.0, 1.0)
    rx, ry = a[0] + t * d[0], a[1] + t * d[1]
    gap_r = jnp.maximum(jnp.sqrt(rx * rx + ry * ry) - size[0], 0.0)
    lo_z, hi_z = jnp.minimum(a[2], a[2] + d[2]), jnp.maximum(a[2], a[2] + d[2])
    gap_z = jnp.maximum(jnp.maximum(lo_z - size[1], -size[1] - hi_z), 0.0)
    return jnp.where(kind == BOX, box, jnp.sqrt(gap_r * gap_r + gap_z * gap_z))


def capsule_axes(p, q, dims):
    """The gripper's three capsules at poses (p, q) (..., 3), (..., 4): the one
    definition, which every check, the path cull and the pictures use. Each capsule
    is (start, extent, radius): its axis is the segment start + t extent, t in [0, 1],
    in world coordinates, start and extent (x, y, z) tuples. The fingers run from the
    palm (EE z = -finger_length) to the tool centre point, at EE y = +-opening/2; the
    palm runs across them along EE y. Written elementwise (``dims`` (..., 4):
    [finger_length, finger_radius, opening, palm_radius], broadcasts), so that the
    fused pair check computes it without (..., 3) intermediates.

    >>> import jax.numpy as jnp
    >>> (s, e, r), _, (ps, pe, pr) = capsule_axes(jnp.zeros(3), jnp.array([1., 0, 0, 0]),
    ...                                          jnp.array([0.1, 0.01, 0.08, 0.02]))
    >>> [round(float(v), 3) for v in (*s, *e, r)]
    [0.0, 0.04, -0.1, 0.0, 0.0, 0.1, 0.01]
    >>> [round(float(v), 3) for v in (*ps, *pe, pr)]
    [0.0, -0.04, -0.1, 0.0, 0.08, 0.0, 0.02]
    """
    w, x, y, z = (q[..., i] for i in range(4))
    ey = (2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x))  # R[:, 1]
    ez = (2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y))  # R[:, 2]
    length, r_f, opening, r_p = (dims[..., i] for i in range(4))
    palm = tuple(p[..., i] - length * ez[i] for i in range(3))  # the palm's centre
    half = 0.5 * opening
    return [(tuple(palm[i] + half * ey[i] for i in range(3)),
             tuple(length * ez[i] for i in range(3)), r_f),
            (tuple(palm[i] - half * ey[i] for i in range(3)),
             tuple(length * ez[i] for i in range(3)), r_f),
            (tuple(palm[i] - half * ey[i] for i in range(3)),
             tuple(opening * ey[i] for i in range(3)), r_p)]


def capsule_segments(p: Float[Array, "3"], q: Float[Array, "4"],
                     dims: Float[Array, "4"]) -> tuple[Array, Array, Array]:
    """:func:`capsule_axes` of one pose as arrays: starts (3, 3), extents (3, 3) and
    radii (3,), one row per capsule (the fingers, then the palm)."""
    axes = capsule_axes(p, q, dims)
    return (jnp.stack([jnp.stack(start) for start, _, _ in axes]),
            jnp.stack([jnp.stack(extent) for _, extent, _ in axes]),
            jnp.stack([radius for _, _, radius in axes]))


def gripper_geoms(p: Float[Array, "3"], q: Float[Array, "4"],
                  dims: Float[Array, "4"]) -> tuple[Array, Array, Array]:
    """:func:`capsule_axes` in MuJoCo's layout (the pictures, and the tests against
    MuJoCo): centres (3, 3), rotation matrices (3, 3, 3) whose z is each axis, and
    capsule sizes (3, 2) [radius, half length]."""
    starts, extents, radii = capsule_segments(p, q, dims)
    R = quat.to_matrix(q)
    x, y, z = R[:, 0], R[:, 1], R[:, 2]
    palm = jnp.stack([x, -z, y], axis=1)  # local z along the EE's y axis
    half = jnp.stack([0.5 * dims[0], 0.5 * dims[0], 0.5 * dims[2]])
    return (starts + 0.5 * extents, jnp.stack([R, R, palm]),
            jnp.stack([radii, half], axis=1))


def _in_frame_xyz(mat, v):
    """v ((x, y, z) tuple) in the frames with rotation matrices mat (..., 3, 3): mat^T v."""
    return tuple(mat[..., 0, i] * v[0] + mat[..., 1, i] * v[1] + mat[..., 2, i] * v[2]
                 for i in range(3))


# Objects a rollout is checked against when it can touch no more than these (most can
# touch one to three); rollouts that can touch more are checked against all.
OBJECT_SLOTS = 4

# Share of the (sample, capsule, object) pairs a round of the exact search takes (on
# random 10-task scenes 1.6 % of the pairs pass the lower bound).
ROUND_SHARE = 32


def first_penetration(objects, p: Float[Array, "B W 3"], q: Float[Array, "B W 4"],
                      dims: Float[Array, "B 4"], live: Bool[Array, "B W"],
                      hulls: Hulls | None = None, ids=None) -> Int[Array, " B"]:
    """The first of W poses of each of B lanes at which the gripper penetrates an object
    by more than eps (W for none), as :func:`penetrates` decides pose by pose, among the
    poses where ``live`` (``objects``: each lane's scene, :func:`scene_objects`' output
    with a leading B axis; ``hulls`` and ``ids``, the lanes' scenes (B,) and objects'
    indices (B, O) in them, where some object is a mesh).

    Per (pose, capsule, object) pair, in one fused pass: the closed-form
    :func:`lower_bound` clears most pairs, and an upper bound (the distance of the axis'
    ends and middle to the object) settles the pairs that surely penetrate (not for a
    mesh, whose bound is its bounding cylinder's). Only the pairs between the two, at
    poses before the lane's first sure penetration, are searched exactly: numbered (a
    running count over the poses, then over each pose's pairs), gathered into rounds of
    1/ROUND_SHARE of all pairs, as many rounds as they need; a mesh's pairs get rounds
    of their own: first a clip by the hull's planes (:func:`hull_clips`), then
    :func:`hull_distance` for the pairs the planes leave open. (Looking each round's
    pairs up by a binary search of the running count instead of scattering them was
    slower on an H100: benchmarks/RESULTS.md.)"""
    kind, centre, mat, size, mask = objects
    B, W = live.shape
    O = kind.shape[1]
    # Poses (B, W, 1) against objects (B, 1, O), component by component: one fused kernel
    # from the poses to the flags, no (..., 3) intermediate written to memory.
    pose_axes = capsule_axes(p[:, :, None, :], q[:, :, None, :], dims[:, None, None, :])
    o_centre = tuple(centre[:, None, :, i] for i in range(3))
    o_mat, o_kind = mat[:, None], kind[:, None, :]
    o_size = tuple(size[:, None, :, i] for i in range(3))
    near = live[:, :, None] & mask[:, None, :]
    solid = o_kind != MESH  # the bounds are a mesh's bounding cylinder's
    maybe, sure = [], jnp.zeros((B, W), bool)
    for start, extent, radius in pose_axes:
        a = _in_frame_xyz(o_mat, tuple(s - c for s, c in zip(start, o_centre, strict=True)))
        d = _in_frame_xyz(o_mat, extent)
        thr = radius - PENETRATION_EPS
        # 1e-6 m of slack: the bound's rounding must not clear a pair the search finds.
        maybe.append(near & (_lower_bound_xyz(a, d, o_kind, o_size) < thr + 1e-6))
        upper = point_distance(a, o_kind, o_size)
        for t in (0.5, 1.0):
            upper = jnp.minimum(upper, point_distance(
                tuple(ai + t * di for ai, di in zip(a, d, strict=True)), o_kind, o_size))
        sure = sure | jnp.any(near & solid & (upper < thr), axis=2)
    first_sure = jnp.where(jnp.any(sure, axis=1), jnp.argmax(sure, axis=1), W)
    # Only poses before the lane's first sure penetration can decide its first one.
    before_sure = jnp.arange(W)[None, :] < first_sure[:, None]
    flags = [f & before_sure[:, :, None] for f in maybe]
    flat_p, flat_q = p.reshape(B * W, 3), q.reshape(B * W, 4)

    def pair_axis(i):
        """Pair i's pose, capsule and object, and the capsule's axis in its frame."""
        pose, pair = i // (3 * O), i % (3 * O)
        lane, c, o = pose // W, pair // O, pair % O
        o_centre, o_mat = centre[lane, o], mat[lane, o]
        starts, extents, radii = capsule_segments(flat_p[pose], flat_q[pose], dims[lane])
        return (pose, lane, o, _into_frames(o_mat, starts[c] - o_centre),
                _into_frames(o_mat, extents[c]), radii[c])

    def solid_pair(i):
        pose, lane, o, a_loc, d_loc, radius = pair_axis(i)
        dist = segment_distance(a_loc, d_loc, kind[lane, o], size[lane, o])
        return pose, dist < radius - PENETRATION_EPS

    def pairs(fs):  # (B W, 3 O): per pose, the pairs capsule by capsule
        return jnp.concatenate([f.reshape(B * W, O) for f in fs], axis=1)

    hit = _searched(pairs(flags if hulls is None else [f & solid for f in flags]),
                    solid_pair, B * W)[0]
    if hulls is not None:
        scene, obj = ids

        def mesh_clip(i):
            """The hull's planes settle most pairs: met (a penetration) or missed with
            the margin (none); the rest are left open."""
            pose, lane, o, a_loc, d_loc, radius = pair_axis(i)
            meets, near = hull_clips(hulls.plane[scene[lane], obj[lane, o]], a_loc, d_loc,
                                     radius - PENETRATION_EPS)
            return pose, meets, near & ~meets

        def mesh_pair(i):
            pose, lane, o, a_loc, d_loc, radius = pair_axis(i)
            s, k = scene[lane], obj[lane, o]
            dist = hull_distance(hulls.tri[s, k], hulls.plane[s, k], a_loc, d_loc)
            return pose, dist < radius - PENETRATION_EPS

        met, open_pairs = _searched(pairs([f & ~solid for f in flags]), mesh_clip, B * W,
                                    leave_open=True)
        assert open_pairs is not None
        hit = hit | met | _searched(open_pairs, mesh_pair, B * W)[0]
    hit = hit.reshape(B, W) & before_sure
    return jnp.where(jnp.any(hit, axis=1), jnp.argmax(hit, axis=1), first_sure)


def _searched(candidate: Bool[Array, "n P"], one_pair, n_poses: int,
              leave_open: bool = False) -> tuple[Array, Array | None]:
    """Which of n_poses poses have a pair that ``one_pair`` finds penetrating, among the
    pairs ``candidate`` marks (per pose, its P pairs): numbered by a running count over
    the poses and each pose's pairs, and gathered into rounds of K pairs. With
    ``leave_open``, ``one_pair`` also says which pairs it left undecided, and they come
    back marked the same way (for a round of another ``one_pair``)."""
    P = candidate.shape[1]
    # The running count within each pose, written out over its pairs (no scan).
    within, total = [], jnp.zeros(n_poses, jnp.int32)
    for k in range(P):
        total = total + candidate[:, k].astype(jnp.int32)
        within.append(total)
    count = total
    before = jnp.cumsum(count) - count
    rank = (before[:, None] + jnp.stack(within, axis=1) - 1).reshape(-1)
    flat = candidate.reshape(-1)
    n = flat.shape[0]
    K = max(1, -(-n // ROUND_SHARE))
    rounds = (before[-1] + count[-1] + K - 1) // K

    def one_round(j, state):
        hit, still = state
        slot = rank - j * K
        take = flat & (slot >= 0) & (slot < K)
        idx = jnp.full(K, n, jnp.int32).at[jnp.where(take, slot, K)].set(
            jnp.arange(n, dtype=jnp.int32), mode="drop")
        out = jax.vmap(one_pair)(jnp.minimum(idx, n - 1))
        hit = hit.at[jnp.where(idx < n, out[0], n_poses)].max(out[1], mode="drop")
        if leave_open:
            still = still.at[idx].set(out[2], mode="drop")
        return hit, still

    still = jnp.zeros(n if leave_open else 0, bool)
    hit, still = jax.lax.fori_loop(0, rounds, one_round, (jnp.zeros(n_poses, bool), still))
    return hit, still.reshape(n_poses, P) if leave_open else None


class LaneObjects(NamedTuple):
    """What the lane pass's collision step reads (:func:`lane_objects`): every scene's
    objects (:func:`scene_objects`, leading axis S), the gripper's sizes (S, 4), each
    lane's touchable objects first, in object order and padded to whole groups of
    ``per_group`` (L, G per_group), how many each lane can touch (L,), and the mesh
    objects' hulls (None without any)."""

    objects: tuple
    gripper: Float[Array, "S 4"]
    order: Int[Array, "L GJ"]
    n_touch: Int[Array, " L"]
    per_group: int
    hulls: Hulls | None = None

    @property
    def groups(self) -> int:
        """G: how many groups of ``per_group`` objects a lane's objects form."""
        return self.order.shape[1] // self.per_group


def lane_objects(geometry, params, touch: Bool[Array, "L O"]) -> LaneObjects:
    """:class:`LaneObjects` of a batch whose lanes can touch the objects ``touch``
    (each lane's collision window, :func:`path_window`), with the batch's mesh hulls
    where it has any. Most lanes can touch at most
    OBJECT_SLOTS objects and are checked once; a lane that can touch more is checked
    once per group of them, and the group that collides first decides."""
    L, O = touch.shape
    J = min(O, OBJECT_SLOTS)
    G = -(-O // J)
    objects = jax.vmap(lambda g: scene_objects(
        g.obj_kind, g.obj_center, g.obj_quat, g.obj_size, g.obj_mask))(geometry)
    order = jnp.argsort(~touch, axis=1, stable=True)
    order = jnp.concatenate([order, jnp.zeros((L, G * J - O), order.dtype)], axis=1)
    return LaneObjects(objects, params.gripper(), order, jnp.sum(touch, axis=1), J,
                       Hulls.of(geometry))


def block_first_penetration(lane_obj: LaneObjects, scene: Int[Array, " B"],
                            idx: Int[Array, " B"], group, p: Float[Array, "B W 3"],
                            q: Float[Array, "B W 4"], valid: Bool[Array, "B W"]
                            ) -> Int[Array, " B"]:
    """:func:`first_penetration` of a block of lanes ``idx`` (their scenes ``scene``)
    against their touchable objects of group ``group``; objects a lane cannot touch
    in its window are left out exactly. (B,): the first sample of the block at which
    the gripper penetrates one (W for none)."""
    kind, centre, mat, size, mask = lane_obj.objects
    J = lane_obj.per_group
    take = jax.lax.dynamic_slice_in_dim(lane_obj.order[idx], group * J, J, axis=1)
    rank = group * J + jnp.arange(J)
    picked = [x[scene[:, None], take] for x in (kind, centre, mat, size)]
    reachable = mask[scene[:, None], take] & (rank[None, :] < lane_obj.n_touch[idx][:, None])
    return first_penetration((*picked, reachable), p, q, lane_obj.gripper[scene], valid,
                             lane_obj.hulls, (scene, take))


def penetrates(objects, p, q, dims, hulls: Hulls | None = None, scene=None) -> Bool[Array, ""]:
    """Whether the gripper at (p, q) penetrates an object by more than eps
    (:func:`deepest`)."""
    return deepest(objects, p, q, dims, hulls, scene) < -PENETRATION_EPS


def _line_sphere(u, c, rho):
    """The t with |t u - c| <= rho (u a unit vector or zero)."""
    inf = jnp.asarray(jnp.inf, rho.dtype)
    b = _dot(u, c)
    uu = _dot(u, u)
    disc = b * b - uu * (_dot(c, c) - rho * rho)
    root = jnp.sqrt(jnp.maximum(disc, 0.0))
    moving = uu > _TINY
    safe = jnp.where(moving, uu, 1.0)
    still = _dot(c, c) <= rho * rho  # u = 0: all t or none
    lo = jnp.where(moving, jnp.where(disc >= 0, (b - root) / safe, inf),
                   jnp.where(still, -inf, inf))
    hi = jnp.where(moving, jnp.where(disc >= 0, (b + root) / safe, -inf),
                   jnp.where(still, inf, -inf))
    return lo, hi


def _line_capsule(u, a, e, rho):
    """The t with dist(t u, segment [a, a + e]) <= rho: the capsule's two end spheres
    and its body (an infinite cylinder cut by the slab of the segment). The union is
    convex, so its t form one interval."""
    inf = jnp.asarray(jnp.inf, rho.dtype)
    lo_a, hi_a = _line_sphere(u, a, rho)
    lo_b, hi_b = _line_sphere(u, a + e, rho)
    length = jnp.sqrt(_dot(e, e))
    axis = e / jnp.maximum(length, _TINY)[..., None]
    ua, aa = _dot(u, axis), _dot(a, axis)
    up, ap = u - ua[..., None] * axis, a - aa[..., None] * axis
    A = _dot(up, up)
    B = _dot(up, ap)
    disc = B * B - A * (_dot(ap, ap) - rho * rho)
    ok = (A > _TINY) & (disc >= 0)  # near-parallel lines: the end spheres cover them
    safe = jnp.where(ok, A, 1.0)
    root = jnp.sqrt(jnp.maximum(disc, 0.0))
    s_lo, s_hi = slab_interval(-aa, ua, 0.0, length)
    lo_c = jnp.maximum(jnp.where(ok, (B - root) / safe, inf), s_lo)
    hi_c = jnp.minimum(jnp.where(ok, (B + root) / safe, -inf), s_hi)
    body = lo_c <= hi_c
    lo = jnp.minimum(jnp.minimum(lo_a, lo_b), jnp.where(body, lo_c, inf))
    hi = jnp.maximum(jnp.maximum(hi_a, hi_b), jnp.where(body, hi_c, -inf))
    return lo, hi


def line_rounded_parallelogram(u, c0, e1, e2, rho):
    """The t with dist(t u, {c0 + x e1 + y e2 : x, y in [0, 1]}) <= rho: the four edge
    capsules and the slab of thickness 2 rho over the parallelogram's face. Convex, so
    one interval (from, to), empty when from > to. (The path cull's set of steps at
    which a capsule axis, moved along u, comes within rho of another.)

    >>> import jax.numpy as jnp
    >>> lo, hi = line_rounded_parallelogram(jnp.array([1., 0, 0]), jnp.array([1., 0, 0]),
    ...     jnp.array([0., 1, 0]), jnp.array([0., 0, 1]), jnp.asarray(0.5))
    >>> round(float(lo), 3), round(float(hi), 3)
    (0.5, 1.5)
    """
    inf = jnp.asarray(jnp.inf, rho.dtype)
    lo, hi = inf, -inf
    for a, e in ((c0, e1), (c0 + e2, e1), (c0, e2), (c0 + e1, e2)):
        l, h = _line_capsule(u, a, e, rho)
        lo, hi = jnp.minimum(lo, l), jnp.maximum(hi, h)
    n = jnp.cross(e1, e2)
    area = jnp.sqrt(_dot(n, n))
    flat = area > 1e-6  # a thinner face lies within 1e-6 m of its edges
    safe = jnp.where(flat, area, 1.0)[..., None]
    n = n / safe
    m1, m2 = jnp.cross(e2, n) / safe, jnp.cross(n, e1) / safe  # dual basis of the face
    f_lo, f_hi = slab_interval(-_dot(c0, n), _dot(u, n), -rho, rho)
    for m in (m1, m2):
        l, h = slab_interval(-_dot(c0, m), _dot(u, m), 0.0, 1.0)
        f_lo, f_hi = jnp.maximum(f_lo, l), jnp.minimum(f_hi, h)
    face = flat & (f_lo <= f_hi)
    return (jnp.minimum(lo, jnp.where(face, f_lo, inf)),
            jnp.maximum(hi, jnp.where(face, f_hi, -inf)))


class Bounds(NamedTuple):
    """One scene's objects as the path cull sees them (O,): each bounding capsule's axis
    (start and extent) and radius, and each bounding sphere (about the centre)."""

    start: Array
    extent: Array
    radius: Array
    sphere: Array


def object_bounds(obj_kind, obj_center, obj_quat, obj_size) -> Bounds:
    """A cylinder's bounding capsule is its own axis with its radius; a box's runs along
    its longest half extent. Computed once per scene, used by every path."""
    mats = jax.vmap(quat.to_matrix)(obj_quat)
    longest = jnp.argmax(obj_size, axis=-1)
    box_axis = jnp.take_along_axis(mats, longest[:, None, None], axis=2)[:, :, 0]
    box_half = jnp.max(obj_size, axis=-1)
    box_radius = jnp.sqrt(jnp.maximum(quat.ordered_sum(obj_size ** 2, -1) - box_half ** 2, 0.0))
    is_box = obj_kind == BOX
    half = jnp.where(is_box[:, None], box_axis * box_half[:, None],
                     mats[:, :, 2] * obj_size[:, 1:2])
    radius = jnp.where(is_box, box_radius, obj_size[:, 0])
    sphere = jnp.where(is_box, quat.norm(obj_size, -1),
                       jnp.hypot(obj_size[:, 0], obj_size[:, 1]))
    return Bounds(obj_center - half, 2.0 * half, radius, sphere)


def path_window(bounds: Bounds, obj_center, obj_mask, gripper: Float[Array, "4"],
                r0: Float[Array, "4"], path: am.Path, turn_from: Array,
                max_steps: Array) -> tuple[Array, Array]:
    """Per object (O,): the first and last sample of one path at which the gripper can
    touch it; empty when first > last. One scene's objects (``object_bounds``), one path.

    Before ``turn_from`` (the first sample at which the meta skill may rotate; inf
    without one) the gripper keeps the start orientation ``r0`` and moves along the
    straight path, so each capsule's axis sweeps a parallelogram and it can reach an
    object only where its axis comes within (capsule radius + the object's bounding
    capsule radius) of the object's bounding axis: one interval of t per (capsule,
    object) pair, in closed form. From ``turn_from`` on the orientation is not known
    beforehand, and the gripper's bounding sphere about p against the object's
    bounding sphere decides. Both are necessary for a penetration, so no sample that
    can collide is left out."""
    dtype = path.length.dtype
    inf = jnp.asarray(jnp.inf, dtype)
    start, extent, radius, sphere = bounds
    g_start, g_extent, g_radius = capsule_segments(path.p0, r0, gripper)
    # Pairs (capsules, objects): t u within rho of the parallelogram of axis offsets.
    c0 = start[None, :, :] - g_start[:, None, :]
    rho = g_radius[:, None] + radius[None, :] + CULL_MARGIN
    lo, hi = line_rounded_parallelogram(jnp.broadcast_to(path.u, c0.shape), c0,
                                        jnp.broadcast_to(extent, c0.shape),
                                        jnp.broadcast_to(-g_extent[:, None, :], c0.shape),
                                        rho)
    lo, hi = jnp.where(obj_mask[None, :], lo, inf), jnp.where(obj_mask[None, :], hi, -inf)
    zero = jnp.zeros((), dtype)
    first = jnp.min(am.first_sample(lo, hi, zero, path, max_steps), axis=0)
    last = jnp.minimum(jnp.max(am.last_sample(lo, hi, path, max_steps), axis=0),
                       turn_from - 1.0)
    first = jnp.where(first <= last, first, inf)
    last = jnp.where(jnp.isfinite(first), last, -inf)
    # From turn_from on: bounding spheres.
    reach = gripper_reach(gripper) + sphere + CULL_MARGIN
    offsets = obj_center - path.p0[None]
    s_lo, s_hi = _line_sphere(jnp.broadcast_to(path.u, offsets.shape), offsets, reach)
    s_lo, s_hi = jnp.where(obj_mask, s_lo, inf), jnp.where(obj_mask, s_hi, -inf)
    kmin = jnp.where(jnp.isfinite(turn_from), turn_from, inf)
    s_first = am.first_sample(s_lo, s_hi, jnp.minimum(kmin, max_steps.astype(dtype) + 1.0), path,
                              max_steps)
    s_first = jnp.where(jnp.isfinite(kmin), s_first, inf)
    s_last = jnp.where(jnp.isfinite(s_first), am.last_sample(s_lo, s_hi, path, max_steps),
                       -inf)
    return jnp.minimum(first, s_first), jnp.maximum(last, s_last)
