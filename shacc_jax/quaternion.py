"""Quaternion maths, (w, x, y, z), unit norm, q and -q the same rotation (reference/conventions).

Every function works on one quaternion (shape (4,)); batching is vmap's job.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float


def _eps(x: Array) -> np.floating:
    return jnp.finfo(x.dtype).eps


# Small matrix products are written as broadcast multiply-sums: XLA fuses them into
# the surrounding elementwise code, where a batched dot_general of 3x3 or 4x4 matrices
# becomes one small library call per matrix on CPU (measured: phase 2 of the
# Automaton went from 2.0 s to 0.1 s on the 12 manual scenes).
def matvec(m: Array, v: Array) -> Array:
    return jnp.stack([dot(m[i], v) for i in range(m.shape[0])])


def ordered_sum(x: Array, axis: int = 0) -> Array:
    """The sum over a short axis as explicit additions in index order.

    Every float sum in the kernels goes through this (or :func:`dot`, :func:`norm`):
    XLA chooses a reduction's order (and ``jnp.dot``'s, a batched matrix product)
    from the shapes of the whole program, so a rollout's last bits would depend on
    how many other rollouts share its call, and a sweep split into pieces by the
    memory budget would write other numbers (measured: delta_R up to 7e-4 rad apart
    in the shacc mode, from 1e-7 m in a projection). Written out, every rollout's
    arithmetic is the same in any batch."""
    x = jnp.moveaxis(x, axis, 0)
    out = x[0]
    for i in range(1, x.shape[0]):
        out = out + x[i]
    return out


def dot(a: Array, b: Array) -> Array:
    """<a, b> of two short vectors (:func:`ordered_sum`)."""
    return ordered_sum(a * b)


def norm(v: Array, axis: int = 0) -> Array:
    """|v| over a short axis (:func:`ordered_sum`)."""
    return jnp.sqrt(ordered_sum(v * v, axis))


def sqrt_divisor(x: Array) -> Array:
    """sqrt(x), to divide by: every ``a / sqrt(b)`` of the kernels is ``a /
    sqrt_divisor(b)``, which rounds the same on every processor (an IEEE square root,
    then an IEEE division).

    XLA rewrites ``a / sqrt(b)`` into ``a * rsqrt(b)``, and its CPU backend computes
    ``rsqrt`` from the processor's approximate reciprocal square root (``rsqrtps``)
    refined by Newton steps. That approximation is not specified to the bit: Intel and
    AMD processors differ in its last bits, and so did a side grasp's orientation, and
    delta_R (through the arccos of a dot product near 1) by up to 1e-3 rad. The
    ``maximum`` with the smallest normal number, which changes no x >= that number,
    keeps the divisor from being a square root that XLA can match
    (tests/test_determinism.py checks the programs for it)."""
    return jnp.maximum(jnp.sqrt(x), jnp.finfo(jnp.result_type(x)).tiny)


def reciprocal_sqrt(x: Array) -> Array:
    """1 / sqrt(x) for x > 0, the same on every processor (:func:`sqrt_divisor`)."""
    return 1.0 / sqrt_divisor(x)


def multiply(a: Float[Array, "4"], b: Float[Array, "4"]) -> Float[Array, "4"]:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return jnp.stack([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ])


def conjugate(q: Float[Array, "4"]) -> Float[Array, "4"]:
    return q * jnp.array([1.0, -1.0, -1.0, -1.0], q.dtype)


def normalize(q: Float[Array, "4"]) -> Float[Array, "4"]:
    return q / jnp.maximum(norm(q), _eps(q))


def to_matrix(q: Float[Array, "4"]) -> Float[Array, "3 3"]:
    return jnp.array(matrix_entries(q))


def matrix_entries(q: Float[Array, "4"]) -> tuple:
    """:func:`to_matrix`'s nine entries as rows of a tuple, not stacked: vmapped, each
    entry is a plain row of the batch (a stacked matrix made XLA's CPU backend slower
    per step of the stepped users than reading a stored one)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    return ((1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
            (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
            (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)))


def from_matrix(m: Float[Array, "3 3"]) -> Float[Array, "4"]:
    """Shepperd's method: the candidate built from the largest of (trace, m00, m11,
    m22) is well conditioned; the others are computed on clamped arguments so no
    branch ever takes the square root of a negative number (NaN-free gradients)."""
    t = m[0, 0] + m[1, 1] + m[2, 2]
    cands = jnp.stack([
        jnp.stack([1 + t, m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]]),
        jnp.stack([m[2, 1] - m[1, 2], 1 + m[0, 0] - m[1, 1] - m[2, 2],
                   m[0, 1] + m[1, 0], m[0, 2] + m[2, 0]]),
        jnp.stack([m[0, 2] - m[2, 0], m[0, 1] + m[1, 0],
                   1 - m[0, 0] + m[1, 1] - m[2, 2], m[1, 2] + m[2, 1]]),
        jnp.stack([m[1, 0] - m[0, 1], m[0, 2] + m[2, 0], m[1, 2] + m[2, 1],
                   1 - m[0, 0] - m[1, 1] + m[2, 2]]),
    ])
    diag = jnp.stack([t, m[0, 0], m[1, 1], m[2, 2]])
    k = jnp.argmax(diag)
    q = cands[k]
    q = q / (2.0 * jnp.sqrt(jnp.maximum(cands[k, k], _eps(m))))
    return normalize(q * jnp.where(q[0] < 0, -1.0, 1.0))


def angle(a: Float[Array, "4"], b: Float[Array, "4"]) -> Float[Array, ""]:
    """The angle between two orientations (reference/conventions),
    2 arccos(min(1, |<a, b>|)), computed as 2 atan2(|v|, |w|) of their relative
    rotation a^-1 b = (w, v), w = <a, b>: the same angle, accurate to float32's
    resolution everywhere. The arccos of a dot product near 1 loses half the digits
    (one rounding of <a, b> near 1 is 3.5e-4 rad of angle), so delta_R near zero
    differed by up to 1e-3 rad for differences in the last bit of an orientation."""
    r = multiply(conjugate(a), b)
    v = jnp.sqrt(r[1] * r[1] + r[2] * r[2] + r[3] * r[3])
    return 2.0 * jnp.arctan2(v, jnp.abs(r[0]))


def _geodesic_sign(q: Float[Array, "4"], d: Float[Array, ""],
                   v: Float[Array, "3"]) -> Float[Array, ""]:
    """The sign that makes ``target`` the near one of its two quaternions, given
    d = <q, target> and v the relative rotation's vector part; at d = 0 the tie rule of
    :func:`rotate_towards`."""
    tie_sign = jnp.where(v[0] != 0, jnp.sign(v[0]),
                         jnp.where(v[1] != 0, jnp.sign(v[1]), jnp.where(v[2] < 0, -1.0, 1.0)))
    return jnp.where(jnp.abs(d) > 8 * _eps(q), jnp.sign(d), tie_sign)


def rotate_towards(q: Float[Array, "4"], target: Float[Array, "4"],
                   max_angle: Float[Array, ""]) -> Float[Array, "4"]:
    """Rotate ``q`` towards ``target`` along the geodesic by at most ``max_angle``
    (slerp); reaches ``target`` when it is within ``max_angle``.

    At exactly opposite orientations (angle pi, <q, target> = 0) the two geodesics
    turn about +v and -v, v the relative rotation's axis in the EE frame. The tie
    is broken towards a positive turn about the EE's x axis (v . x > 0; then y,
    then z where v . x = 0): our reading of the Automaton's rule.
    """
    d = dot(q, target)
    sign = _geodesic_sign(q, d, multiply(conjugate(q), target)[1:])
    t = target * sign
    cos_half = jnp.minimum(1.0, jnp.abs(d))
    half = jnp.arccos(cos_half)  # half the rotation angle
    theta = 2.0 * half
    frac = jnp.clip(max_angle / jnp.where(theta > 0, theta, 1.0), 0.0, 1.0)
    sin_half = jnp.sin(half)
    safe = sin_half > 8 * _eps(q)
    s = jnp.where(safe, sin_half, 1.0)
    a = jnp.where(safe, jnp.sin((1.0 - frac) * half) / s, 1.0 - frac)
    b = jnp.where(safe, jnp.sin(frac * half) / s, frac)
    stepped = normalize(a * q + b * t)
    return jnp.where(theta <= max_angle, t, stepped)


def turn_towards(q: Float[Array, "4"], target: Float[Array, "4"],
                 half_turn: tuple[Array, Array]) -> Float[Array, "4"]:
    """:func:`rotate_towards` written without inverse trigonometry, given (sin, cos) of
    half of ``max_angle``: within ``max_angle`` (|<q, target>| >= cos(max_angle / 2))
    the target, else q turned by ``max_angle`` about the relative rotation's axis, q
    (cos(max_angle / 2), sin(max_angle / 2) v / |v|): the slerp's point, since
    slerp(q, t, f) = q (q^-1 t)^f and f times the half angle is max_angle / 2. The
    same ties. Equal to :func:`rotate_towards` up to rounding (tests/test_quaternion.py);
    the stepped users take it, whose CPU kernel pays a libm call per element for each
    arccos and sine (``trig`` module docstring), while the closed form keeps the slerp
    its recorded answers were made with."""
    sin_m, cos_m = half_turn
    d = dot(q, target)
    v = multiply(conjugate(q), target)[1:]
    sign = _geodesic_sign(q, d, v)
    n = jnp.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    scale = sign * sin_m / jnp.where(n > 0, n, 1.0)
    stepped = normalize(multiply(q, jnp.stack([cos_m, scale * v[0], scale * v[1],
                                               scale * v[2]])))
    return jnp.where(jnp.abs(d) >= cos_m, target * sign, stepped)


def markley_average(quats: Float[Array, "n 4"], weights: Float[Array, " n"],
                    squarings: int = 24) -> Float[Array, "4"]:
    """Weighted quaternion average of Markley et al. 2007 (reference/model): the unit
    eigenvector of the largest eigenvalue of M = sum_i w_i q_i q_i^T.

    Sign-invariant (q q^T is) and linear in the weights. The eigenvector comes from
    repeated squaring: P <- P^2 / tr(P^2) converges to the projector v v^T at a rate
    (lambda_2 / lambda_1)^(2^k); 24 squarings leave (1 - 1e-6)^(1.7e7) < 1e-7 for any
    gap float32 can resolve. P is symmetric, so the squarings work on its 10 distinct
    entries as scalar expressions: 40 multiply-adds each, which XLA vectorises across
    the batch (measured 1.8 us -> 0.1 us per average on CPU against 4x4 array products,
    and several times faster than a batched ``eigh``). Checked against scipy's
    Rotation.mean in tests/test_quaternion.py. One average; see
    :func:`markley_average_batch` for many at once.
    """
    return markley_average_batch(jnp.moveaxis(quats, -1, 0), weights, squarings)


def markley_average_batch(quats: Array, weights: Array,
                          squarings: int = 24) -> Array:
    """:func:`markley_average` of many sets at once, laid out with the quaternion
    components first and the n averaged items next: every intermediate is a whole
    (*batch) array."""
    tiny = jnp.finfo(quats.dtype).tiny

    def normalise(e):
        inv = 1.0 / jnp.maximum(e[0] + e[4] + e[7] + e[9], tiny)
        return tuple(v * inv for v in e)

    def square(_, e):
        # (P^2)_ij = sum_k P_ik P_kj over the 10 stored entries, then trace-normalised.
        # A tuple of arrays, not one stacked array: each entry is then one contiguous
        # array, which XLA vectorises.
        return normalise(tuple(sum(e[_SLOT[i][k]] * e[_SLOT[k][j]] for k in range(4))
                               for i, j in _UPPER))

    m = normalise(tuple(ordered_sum(weights * quats[i] * quats[j]) for i, j in _UPPER))
    # Rolled on every backend: in the batch layout of the meta targets this measured
    # 0.330 s against 0.642 s fully unrolled for 10.8 M rollouts on an H100 (every lane
    # on the Markley path), and it was already the faster form on CPU.
    m = jax.lax.fori_loop(0, squarings, square, m)
    # The column of the largest diagonal entry (the first on a tie) is the
    # best-conditioned multiple of v.
    best = [m[_SLOT[i][0]] for i in range(4)]
    best_diag = m[0]
    for j in range(1, 4):
        take = m[_SLOT[j][j]] > best_diag
        best = [jnp.where(take, m[_SLOT[i][j]], b) for i, b in enumerate(best)]
        best_diag = jnp.where(take, m[_SLOT[j][j]], best_diag)
    norm = jnp.sqrt(best[0] * best[0] + best[1] * best[1] + best[2] * best[2] + best[3] * best[3])
    inv = 1.0 / jnp.maximum(norm, _eps(norm)) * jnp.where(best[0] < 0, -1.0, 1.0)
    return jnp.stack([b * inv for b in best])


_UPPER = [(0, 0), (0, 1), (0, 2), (0, 3), (1, 1), (1, 2), (1, 3), (2, 2), (2, 3), (3, 3)]
_SLOT = [[_UPPER.index((min(i, j), max(i, j))) for j in range(4)] for i in range(4)]
