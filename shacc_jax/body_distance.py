"""Distances from points and segments to the objects' bodies (cylinders and boxes, in
their own frames), exact: the distance to a cylinder or box is convex along a segment,
and a bracketing search (:func:`segment_distance`) finds its minimum to 1e-7 m; a
closed-form lower bound (:func:`lower_bound`) clears most pairs without the search."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from geometry_precompute.schema import BOX

_TINY = 1e-12


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


def into_frames(mat, v):
    """v (..., 3) in the frames whose rotation matrices are mat (..., 3, 3): mat^T v,
    written out as products and sums so that it fuses with what follows."""
    return (v[..., 0:1] * mat[..., 0, :] + v[..., 1:2] * mat[..., 1, :]
            + v[..., 2:3] * mat[..., 2, :])


def lower_bound(a, d, kind, size):
    """A lower bound of the distance from segments a + t d (..., 3, object frame) to
    solid cylinders or boxes, in closed form: per box axis, or for a cylinder along its
    axis and radially, the gap between the segment's range and the solid's; the
    Euclidean norm of the gaps bounds every point's distance from below."""
    return lower_bound_xyz(tuple(a[..., i] for i in range(3)),
                            tuple(d[..., i] for i in range(3)), kind,
                            tuple(size[..., i] for i in range(3)))


def lower_bound_xyz(a, d, kind, size):
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


def in_frame_xyz(mat, v):
    """v ((x, y, z) tuple) in the frames with rotation matrices mat (..., 3, 3): mat^T v."""
    return tuple(mat[..., 0, i] * v[0] + mat[..., 1, i] * v[1] + mat[..., 2, i] * v[2]
                 for i in range(3))
