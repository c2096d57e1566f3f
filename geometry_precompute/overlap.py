"""Intersection volumes of position spaces without a mesh boolean (SPEC section 5's
fast paths).

Two pair types, computed for all pairs of a scene at once, cover 87 % of the
intersecting pairs of the random generator's scenes:

- two *upright* cylinders or disks (axis along world z): exact, the lens area of
  their circles times the overlap of their z ranges;
- a *level* cone (axis horizontal, as the handle grasp's) and an upright cylinder or
  disk: the cut of both by a plane perpendicular to the cone's axis is a disk and a
  rectangle, whose common area has a closed form (:func:`disk_rect_area`); that area
  is integrated along the axis by Gauss-Legendre between every point where it is not
  smooth (the rectangle's edges and corners meeting the circle, the chord appearing),
  so each piece is a nearly smooth function and eight nodes give it to about 1e-6
  (containment cases to 1e-7; tests/test_overlap.py).

Two level cones are left to the boolean: a two-dimensional quadrature of their
chords was tried and dropped, because the lines where the two chords' ends cross
bend with the slice and left errors of up to 5 % of the pair's volume at a cost
above the boolean's (docs/DECISIONS.md).

Nodes are mapped by t = (1 - cos theta) / 2, which makes the square-root behaviour at
the ends of each piece (a chord that opens like sqrt) smooth in theta. Every other
pair (boxes, tilted shapes) is left to the mesh boolean, which is also the reference
these are tested against (tests/test_overlap.py).
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cache

import numpy as np

from .shapes import Shape

# A shape is taken as upright or level when its axis is within this of the ideal.
AXIS_TOL = 1e-12
# Gauss nodes per smooth piece of the cone x cylinder integral.
NODES_CYL = 8


@cache
def _nodes(n: int) -> tuple[np.ndarray, np.ndarray]:
    """(s, w) with int_0^1 f(s) ds ~= sum w f(s): Gauss-Legendre in theta over [0, pi]
    with s = (1 - cos theta) / 2."""
    x, wx = np.polynomial.legendre.leggauss(n)
    theta = np.pi * (x + 1.0) / 2.0
    return (1.0 - np.cos(theta)) / 2.0, wx * np.pi * np.sin(theta) / 4.0


def _pieces(lo: np.ndarray, hi: np.ndarray, breaks: np.ndarray, n: int):
    """Nodes and weights over [lo, hi] (leading axes ...), split at ``breaks`` (..., K;
    NaN for none). Returns (x, w) of shape (..., K + 1, n)."""
    hi = np.maximum(hi, lo)
    b = np.clip(np.where(np.isnan(breaks), lo[..., None], breaks), lo[..., None],
                hi[..., None])
    edges = np.concatenate([lo[..., None], np.sort(b, axis=-1), hi[..., None]], axis=-1)
    a, width = edges[..., :-1, None], np.diff(edges, axis=-1)[..., None]
    s, w = _nodes(n)
    return a + width * s, width * w


def lens_area(r1, r2, d):
    """Area common to two circles of radii r1, r2 whose centres are d apart."""
    r1, r2, d = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (r1, r2, d)))
    small = np.minimum(r1, r2)
    out = np.where(d >= r1 + r2, 0.0, np.pi * small * small)
    part = (d < r1 + r2) & (d > np.abs(r1 - r2))
    if np.any(part):
        a, b, c = r1[part], r2[part], d[part]
        x = np.clip((c * c + a * a - b * b) / (2 * c * a), -1.0, 1.0)
        y = np.clip((c * c + b * b - a * a) / (2 * c * b), -1.0, 1.0)
        k = (-c + a + b) * (c + a - b) * (c - a + b) * (c + a + b)
        out[part] = a * a * np.arccos(x) + b * b * np.arccos(y) - 0.5 * np.sqrt(np.maximum(k, 0))
    return out


def _strip(x, y, r):
    """int_0^x clip(y, -s, s) dx' with s = sqrt(r^2 - x'^2), for |x| <= r."""
    ay = np.minimum(np.abs(y), r)
    ax = np.abs(x)
    xc = np.sqrt(np.maximum(r * r - ay * ay, 0.0))
    inner = np.minimum(ax, xc)
    rr = np.maximum(r, 1e-300)

    def cap(v):  # int_0^v sqrt(r^2 - x^2) dx
        return 0.5 * (v * np.sqrt(np.maximum(r * r - v * v, 0.0))
                      + r * r * np.arcsin(np.clip(v / rr, -1.0, 1.0)))

    val = ay * inner + np.where(ax > xc, cap(ax) - cap(xc), 0.0)
    return np.sign(x) * np.sign(y) * val


def disk_rect_area(r, x0, x1, y0, y1):
    """Area common to the disk of radius r at the origin and [x0, x1] x [y0, y1]."""
    x0, x1 = np.clip(x0, -r, r), np.clip(x1, -r, r)
    x1 = np.maximum(x1, x0)
    y1 = np.maximum(y1, y0)
    return (_strip(x1, y1, r) - _strip(x0, y1, r) - _strip(x1, y0, r)
            + _strip(x0, y0, r))


def _real_roots_quartic(coef: np.ndarray) -> np.ndarray:
    """Real roots of the quartics in the rows of coef (highest power first), NaN for
    missing ones. A row whose two leading coefficients vanish (parallel axes) is
    solved as the quadratic it is."""
    scale = np.max(np.abs(coef), axis=1, keepdims=True) + 1e-300
    lead = np.abs(coef[:, :1]) > 1e-12 * scale
    a = np.where(lead, coef[:, :1], 1.0)
    comp = np.zeros((len(coef), 4, 4))
    comp[:, 0, :] = np.where(lead, -coef[:, 1:] / a, 0.0)
    comp[:, 1, 0] = comp[:, 2, 1] = comp[:, 3, 2] = 1.0
    roots = np.linalg.eigvals(comp)
    real = np.where(np.abs(roots.imag) <= 1e-7 * (1.0 + np.abs(roots)), roots.real, np.nan)
    real = np.where(lead, real, np.nan)
    quad = ~lead[:, 0] & (np.abs(coef[:, 1]) <= 1e-12 * scale[:, 0])
    if np.any(quad):
        c = coef[quad]
        with np.errstate(divide="ignore", invalid="ignore"):
            real[quad, :2] = _real_roots_quadratic(c[:, 2], c[:, 3], c[:, 4])
    return real


def _real_roots_quadratic(a, b, c):
    disc = b * b - 4 * a * c
    sq = np.sqrt(np.where(disc >= 0, disc, np.nan))
    return np.stack([(-b - sq) / (2 * a), (-b + sq) / (2 * a)], axis=-1)


def cone_cylinder_volumes(apex, axis, length, tan_a, center, radius, height):
    """Volumes common to level cones and upright cylinders, pair by pair (arrays of
    shape (P, 3), (P, 2) unit horizontal axes, then (P,) values)."""
    e = axis
    v = np.stack([-e[:, 1], e[:, 0]], axis=1)
    d = center[:, :2] - apex[:, :2]
    tc, uc = np.sum(d * e, axis=1), np.sum(d * v, axis=1)
    r, T = radius, tan_a
    dlo = center[:, 2] - height / 2 - apex[:, 2]
    dhi = center[:, 2] + height / 2 - apex[:, 2]
    lo, hi = np.maximum(0.0, tc - r), np.minimum(length, tc + r)
    breaks = [np.abs(dlo) / T, np.abs(dhi) / T]
    c0 = tc * tc + uc * uc - r * r
    for sign in (1.0, -1.0):  # a rectangle edge tangent to the slice's circle
        breaks += list(_real_roots_quadratic(1 + T * T, -2 * (tc + sign * uc * T), c0).T)
    for dz in (dlo, dhi):  # a rectangle corner on the circle
        A, B, C = 1 + T * T, -2 * tc, tc * tc - uc * uc - r * r - dz * dz
        q4 = 4 * uc * uc
        coef = np.stack([A * A, 2 * A * B, B * B + 2 * A * C + q4, 2 * B * C - 2 * q4 * tc,
                         C * C - q4 * (r * r - tc * tc)], axis=1)
        breaks += list(_real_roots_quartic(coef).T)
    t, w = _pieces(lo, hi, np.stack(breaks, axis=1), NODES_CYL)
    rho = t * T[:, None, None]
    half = np.sqrt(np.maximum(r[:, None, None] ** 2 - (t - tc[:, None, None]) ** 2, 0.0))
    ucn = uc[:, None, None]
    area = disk_rect_area(rho, ucn - half, ucn + half, dlo[:, None, None], dhi[:, None, None])
    return np.sum(w * area, axis=(1, 2))


def _upright(s: Shape) -> bool:
    return s.kind in ("cylinder", "disk") and abs(s.rotation[2, 2] - 1.0) <= AXIS_TOL


def _level(s: Shape) -> bool:
    return s.kind == "cone" and abs(s.rotation[2, 2]) <= AXIS_TOL


def pair_kind(a: Shape, b: Shape) -> str | None:
    """'cyl_cyl', 'cone_cyl', 'cyl_cone', or None (the pair needs a boolean)."""
    if _upright(a):
        return "cyl_cyl" if _upright(b) else "cyl_cone" if _level(b) else None
    return "cone_cyl" if _level(a) and _upright(b) else None


def _cone_arrays(shapes: Sequence[Shape]):
    apex = np.array([s.center for s in shapes], dtype=np.float64).reshape(-1, 3)
    ax = np.array([s.rotation[:2, 2] for s in shapes]).reshape(-1, 2)
    ax /= np.linalg.norm(ax, axis=1, keepdims=True)
    length = np.array([s.dims[0] for s in shapes])
    tan_a = np.tan(np.array([s.dims[1] for s in shapes]))
    return apex, ax, length, tan_a


def _cyl_arrays(shapes: Sequence[Shape]):
    c = np.array([s.center for s in shapes], dtype=np.float64).reshape(-1, 3)
    return c, np.array([s.dims[0] for s in shapes]), np.array([s.dims[1] for s in shapes])


def fast_volumes(shapes: Sequence[Shape], pairs: Sequence[tuple[int, int]]
                 ) -> tuple[dict, list[tuple[int, int]]]:
    """({pair: volume} for the pairs with a fast path, [pairs left for the boolean])."""
    groups: dict[str, list[tuple[int, int]]] = {}
    rest = []
    for i, j in pairs:
        k = pair_kind(shapes[i], shapes[j])
        if k is None:
            rest.append((i, j))
        elif k == "cyl_cone":
            groups.setdefault("cone_cyl", []).append((j, i, i, j))
        else:
            groups.setdefault(k, []).append((i, j, i, j))
    out: dict[tuple[int, int], float] = {}
    for k, rows in groups.items():
        a = [shapes[r[0]] for r in rows]
        b = [shapes[r[1]] for r in rows]
        if k == "cyl_cyl":
            ca, ra, ha = _cyl_arrays(a)
            cb, rb, hb = _cyl_arrays(b)
            dist = np.hypot(ca[:, 0] - cb[:, 0], ca[:, 1] - cb[:, 1])
            dz = (np.minimum(ca[:, 2] + ha / 2, cb[:, 2] + hb / 2)
                  - np.maximum(ca[:, 2] - ha / 2, cb[:, 2] - hb / 2))
            vol = lens_area(ra, rb, dist) * np.maximum(dz, 0.0)
        else:
            vol = cone_cylinder_volumes(*_cone_arrays(a), *_cyl_arrays(b))
        for r, x in zip(rows, vol.tolist(), strict=True):
            out[(r[2], r[3])] = x
    return out, rest
