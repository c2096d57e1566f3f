"""Intersection volumes of position spaces without a mesh boolean (clutteredness's
fast paths).

Three pair types, computed for all pairs of a scene at once, cover every
intersecting pair of the random generator's scenes:

- two *upright* cylinders or disks (axis along world z): exact, the lens area of
  their circles times the overlap of their z ranges;
- a *level* cone (axis horizontal, as the handle grasp's) and an upright cylinder or
  disk: the cut of both by a plane perpendicular to the cone's axis is a disk and a
  rectangle, whose common area has a closed form (:func:`disk_rect_area`); that area
  is integrated along the axis by Gauss-Legendre between every point where it is not
  smooth (the rectangle's edges and corners meeting the circle, the chord appearing);
- two level cones with their apexes at one height (cups of one height on one table):
  the overlap of their vertical chords, integrated across and along the first cone's
  axis between the points where it is not smooth (:func:`cone_cone_volumes`).

Each piece is then a nearly smooth function, and eight nodes give the volume to
about 1e-6 of itself (containment cases to 1e-7; tests/test_precompute_fast.py). Nodes
are mapped by t = (1 - cos theta) / 2, which makes the square-root behaviour at the
ends of each piece (a chord that opens like sqrt) smooth in theta. Every other pair
(boxes, tilted shapes, cones at two heights) is left to the mesh boolean, which is
also the reference these are tested against.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cache

import numpy as np

from .shapes import AXIS_TOL, Shape, is_level, is_upright

# Gauss nodes per smooth piece of the cone x cylinder integral. Cosine-mapped nodes take
# the square-root behaviour at a piece's own ends, but a break of the neighbouring piece
# that lies very close (the top edge's chord starting 0.5 mm before a corner event) is a
# branch point just outside this piece: with 8 nodes one such pair erred by 2.5e-5 of the
# volume, with 12 by 4.7e-7 (tests/test_precompute_fast.py holds the case), at no
# measurable cost (bench_precompute median 5.8 ms with either).
NODES_CYL = 12
# Gauss nodes per smooth piece, along and across the first axis, of the cone x cone
# integral (on 45 random pairs against 1024-gon booleans, 8 x 6 and 8 x 8 both err by at
# most 3.9e-6 of the volume, 6 x 6 by 7.6e-5).
NODES_CONE_T, NODES_CONE_U = 8, 6


@cache
def _nodes(n: int) -> tuple[np.ndarray, np.ndarray]:
    """(s, w) with int_0^1 f(s) ds ~= sum w f(s): Gauss-Legendre in theta over [0, pi]
    with s = (1 - cos theta) / 2."""
    x, wx = np.polynomial.legendre.leggauss(n)
    theta = np.pi * (x + 1.0) / 2.0
    return (1.0 - np.cos(theta)) / 2.0, wx * np.pi * np.sin(theta) / 4.0


def _pieces(lo: np.ndarray, hi: np.ndarray, breaks: np.ndarray, n: int):
    """Nodes over [lo, hi] (P,) split at ``breaks`` (P, K; NaN for none), for the
    pieces of non-zero width only: (x, w) of shape (M, n) and the pair of each piece
    (M,)."""
    hi = np.maximum(hi, lo)
    b = np.clip(np.where(np.isnan(breaks), lo[:, None], breaks), lo[:, None], hi[:, None])
    edges = np.concatenate([lo[:, None], np.sort(b, axis=1), hi[:, None]], axis=1)
    width = np.diff(edges, axis=1)
    keep = width > 0.0
    owner = np.nonzero(keep)[0]
    a, width = edges[:, :-1][keep][:, None], width[keep][:, None]
    s, w = _nodes(n)
    return a + width * s, width * w, owner


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
    corners = _strip(np.stack(np.broadcast_arrays(x1, x0, x1, x0)),
                     np.stack(np.broadcast_arrays(y1, y1, y0, y0)), r)
    return corners[0] - corners[1] - corners[2] + corners[3]


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
    """Real roots of a x^2 + b x + c (the stable form q = -(b + sign(b) sqrt(disc)) / 2,
    roots q / a and c / q, so a vanishing a leaves the linear root); NaN for none."""
    with np.errstate(divide="ignore", invalid="ignore"):
        disc = b * b - 4 * a * c
        q = -0.5 * (b + np.where(b < 0, -1.0, 1.0) * np.sqrt(np.where(disc >= 0, disc, np.nan)))
        roots = np.stack([q / a, c / q], axis=-1)
    return np.where(np.isfinite(roots), roots, np.nan)


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
    # A rectangle corner on the circle: one quartic per horizontal edge, solved together.
    dz = np.concatenate([dlo, dhi])
    tc2, uc2, r2, T2 = (np.concatenate([x, x]) for x in (tc, uc, r, T))
    A, B, C = 1 + T2 * T2, -2 * tc2, tc2 * tc2 - uc2 * uc2 - r2 * r2 - dz * dz
    q4 = 4 * uc2 * uc2
    coef = np.stack([A * A, 2 * A * B, B * B + 2 * A * C + q4, 2 * B * C - 2 * q4 * tc2,
                     C * C - q4 * (r2 * r2 - tc2 * tc2)], axis=1)
    corners = _real_roots_quartic(coef)
    P = len(tc)
    breaks = np.concatenate([np.stack(breaks, axis=1), corners[:P], corners[P:]], axis=1)
    t, w, k = _pieces(lo, hi, breaks, NODES_CYL)
    half = np.sqrt(np.maximum((r[k] ** 2)[:, None] - (t - tc[k][:, None]) ** 2, 0.0))
    ucn = uc[k][:, None]
    area = disk_rect_area(t * T[k][:, None], ucn - half, ucn + half, dlo[k][:, None],
                          dhi[k][:, None])
    return np.bincount(k, weights=np.sum(w * area, axis=1), minlength=P)


def _lin(num, den):
    """num / den, NaN where that is not a finite number (no root)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        out = num / den
    return np.where(np.isfinite(out), out, np.nan)


def cone_cone_volumes(apex1, axis1, length1, tan1, apex2, axis2, length2, tan2):
    """Volumes common to pairs of level cones whose apexes are at one height (arrays as
    in :func:`cone_cylinder_volumes`).

    In cone 1's frame (t along its axis, u across it), cone 2's axial and lateral
    coordinates s2, w2 are affine in (t, u); the vertical chords are 2 h1 =
    2 sqrt(T1^2 t^2 - u^2) and 2 h2 = 2 sqrt(T2^2 s2^2 - w2^2) (for 0 <= s2 <= L2), both
    centred on the apexes' height, so their overlap is 2 min(h1, h2). Across u, that is
    smooth between the roots of linear and quadratic equations (chords ending, cone 2's
    base and apex, h1 = h2); along t, the slice integral is smooth between the values
    of t where those roots meet, each again the root of a linear or quadratic
    equation. Gauss-Legendre (cosine-mapped) between all of them."""
    e1, e2 = axis1, axis2
    v1 = np.stack([-e1[:, 1], e1[:, 0]], axis=1)
    v2 = np.stack([-e2[:, 1], e2[:, 0]], axis=1)
    d = apex1[:, :2] - apex2[:, :2]
    s0, st, su = np.sum(d * e2, 1), np.sum(e1 * e2, 1), np.sum(v1 * e2, 1)
    w0, wt, wu = np.sum(d * v2, 1), np.sum(e1 * v2, 1), np.sum(v1 * v2, 1)
    T1, T2, L1, L2 = tan1, tan2, length1, length2
    # The t range: cone 2's extent along e1.
    p0 = -np.sum(d * e1, 1)
    sin_ = np.sum(v2 * e1, 1)
    reach = L2 * T2 * np.abs(sin_)
    lo = np.maximum(0.0, p0 + np.minimum(0.0, L2 * st - reach))
    hi = np.minimum(L1, p0 + np.maximum(0.0, L2 * st + reach))
    ev = []
    for sg in (1.0, -1.0):           # u = sg * T1 * t
        a_s, a_w = st + su * sg * T1, wt + wu * sg * T1
        for pm in (1.0, -1.0):       # T2 s2 = pm w2 on the cone-1 edge
            ev.append(_lin(pm * w0 - T2 * s0, T2 * a_s - pm * a_w))
        for c in (0.0, L2):          # s2 = c on the cone-1 edge
            ev.append(_lin(c - s0, a_s))
    for c in (0.0, L2):              # s2 = c meets T2 s2 = pm w2
        for pm in (1.0, -1.0):
            # su u = c - s0 - st t ; wu u = pm T2 c - w0 - wt t
            ev.append(_lin(su * (pm * T2 * c - w0) - wu * (c - s0), su * wt - wu * st))
    # min switch: (A + 1) u^2 + B u + (C - T1^2 t^2) = 0, B = b0 + b1 t, C = c0 + c1 t + c2 t^2
    A = (T2 * su) ** 2 - wu ** 2
    b0, b1 = 2 * (T2 * T2 * su * s0 - wu * w0), 2 * (T2 * T2 * su * st - wu * wt)
    c0 = (T2 * s0) ** 2 - w0 ** 2
    c1 = 2 * (T2 * T2 * s0 * st - w0 * wt)
    c2 = (T2 * st) ** 2 - wt ** 2 - T1 * T1
    # its double roots: B^2 - 4 (A + 1) C' = 0
    a4 = 4 * (A + 1)
    qa, qb, qc = b1 * b1 - a4 * c2, 2 * b0 * b1 - a4 * c1, b0 * b0 - a4 * c0
    ev += list(_real_roots_quadratic(qa, qb, qc).T)
    # it meets s2 = L2: u = (L2 - s0 - st t) / su = m0 + m1 t (none when su = 0), so
    # (A+1) u^2 + (b0 + b1 t) u + c0 + c1 t + c2 t^2 = 0 is a quadratic in t
    m0, m1 = _lin(L2 - s0, su), _lin(-st, su)
    ea = (A + 1) * m1 * m1 + b1 * m1 + c2
    eb = 2 * (A + 1) * m0 * m1 + b0 * m1 + b1 * m0 + c1
    ec = (A + 1) * m0 * m0 + b0 * m0 + c0
    ev += list(_real_roots_quadratic(ea, eb, ec).T)
    ev = np.stack(ev, 1)  # NaN for the roots that do not exist
    t, wt_, k = _pieces(lo, hi, ev, NODES_CONE_T)          # (Mt, NT)
    t, wt_ = t.ravel(), wt_.ravel()
    k = np.repeat(k, NODES_CONE_T)
    rho = T1[k] * t
    S, W = s0[k] + st[k] * t, w0[k] + wt[k] * t
    Su, Wu, T2k, L2k = su[k], wu[k], T2[k], L2[k]
    ub = [_lin(-S, Su), _lin(L2k - S, Su), _lin(W - T2k * S, T2k * Su - Wu),
          _lin(-W - T2k * S, T2k * Su + Wu)]
    Bk = b0[k] + b1[k] * t
    Ck = c0[k] + c1[k] * t + (c2[k] + T1[k] ** 2) * t * t - rho * rho
    ub = np.stack(ub + list(_real_roots_quadratic(A[k] + 1, Bk, Ck).T), 1)
    u, wu_, j = _pieces(-rho, rho, ub, NODES_CONE_U)      # (Mu, NU), owner t node
    tj = t[j][:, None]
    kj = k[j]
    h1 = np.sqrt(np.maximum((T1[kj][:, None] * tj) ** 2 - u * u, 0.0))
    s2 = s0[kj][:, None] + st[kj][:, None] * tj + su[kj][:, None] * u
    w2 = w0[kj][:, None] + wt[kj][:, None] * tj + wu[kj][:, None] * u
    h2 = np.sqrt(np.maximum((T2[kj][:, None] * s2) ** 2 - w2 * w2, 0.0))
    h2 = np.where((s2 >= 0) & (s2 <= L2[kj][:, None]), h2, 0.0)
    inner = np.bincount(j, weights=np.sum(wu_ * 2 * np.minimum(h1, h2), 1), minlength=len(t))
    return np.bincount(k, weights=wt_ * inner, minlength=len(lo))


def pair_kind(a: Shape, b: Shape) -> str | None:
    """'cyl_cyl', 'cone_cyl', 'cyl_cone', 'cone_cone', or None (the pair needs a
    boolean)."""
    if is_upright(a):
        return "cyl_cyl" if is_upright(b) else "cyl_cone" if is_level(b) else None
    if not is_level(a):
        return None
    if is_upright(b):
        return "cone_cyl"
    if is_level(b) and abs(a.center[2] - b.center[2]) <= AXIS_TOL:
        return "cone_cone"
    return None


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
    groups: dict[str, list[tuple[int, int, int, int]]] = {}
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
        elif k == "cone_cyl":
            vol = cone_cylinder_volumes(*_cone_arrays(a), *_cyl_arrays(b))
        else:
            vol = cone_cone_volumes(*_cone_arrays(a), *_cone_arrays(b))
        for r, x in zip(rows, vol.tolist(), strict=True):
            out[(r[2], r[3])] = x
    return out, rest
