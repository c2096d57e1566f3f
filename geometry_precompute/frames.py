"""Frames and quaternions on the CPU side (reference/conventions), in float64.

Quaternions are (w, x, y, z). scipy's Rotation uses (x, y, z, w): conversions from
matrices go through :func:`quat_from_matrix`; ``shapes.rotation_matrix`` goes back.
"""

from __future__ import annotations

import math

import numpy as np

IDENTITY = (1.0, 0.0, 0.0, 0.0)


def frame_from_approach(a) -> np.ndarray:
    """reference/conventions: z = a/|a|; u = world z, or world x where |z . world z| > 0.99;
    x = normalize(u x z); y = z x x. Returns the 3x3 matrix [x y z] (columns).

    Written out in floats: 4 us against 70 us through np.cross and np.linalg.norm,
    with the same results to two units in the last place (bit for bit unless OpenBLAS,
    which np.linalg.norm's dot product runs on, picks its AVX-512 kernel for the
    processor; tests/test_precompute_fast.py)."""
    return np.array(_frame_rows(a))


def _frame_rows(a) -> tuple[tuple[float, float, float], ...]:
    ax, ay, az = (float(v) for v in a)
    n = math.sqrt(ax * ax + ay * ay + az * az)
    zx, zy, zz = ax / n, ay / n, az / n
    ux, uy, uz = (1.0, 0.0, 0.0) if abs(zz) > 0.99 else (0.0, 0.0, 1.0)
    xx, xy, xz = uy * zz - uz * zy, uz * zx - ux * zz, ux * zy - uy * zx
    m = math.sqrt(xx * xx + xy * xy + xz * xz)
    xx, xy, xz = xx / m, xy / m, xz / m
    yx, yy, yz = zy * xz - zz * xy, zz * xx - zx * xz, zx * xy - zy * xx
    return ((xx, yx, zx), (xy, yy, zy), (xz, yz, zz))


def quat_of_approach(a) -> tuple[float, float, float, float]:
    """quat_of_rotation(frame_from_approach(a)), without the arrays between."""
    return quat_of_rotation(_frame_rows(a))


def random_quats(n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 4) uniformly random rotations, bit for bit those of
    ``quat_from_matrix(Rotation.random(n, rng=rng).as_matrix())`` and drawing the same
    numbers from ``rng``: scipy's method written out (four normal draws a rotation as
    x, y, z, w, normalised, then its matrix), each converted by
    :func:`quat_of_rotation`. Without scipy: importing scipy.spatial was a tenth of a
    warm ``shacc evaluate`` (tests/test_precompute_fast.py holds the bits). Each NumPy
    operation is one rounded IEEE operation (none is fused with the next), so the
    result is the same on every processor."""
    s = rng.normal(size=(n, 4))
    x, y, z, w = s[:, 0], s[:, 1], s[:, 2], s[:, 3]
    norm = np.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    x2, y2, z2, w2 = x * x, y * y, z * z, w * w
    xy, zw, xz, yw, yz, xw = x * y, z * w, x * z, y * w, y * z, x * w
    m = np.stack([x2 - y2 - z2 + w2, 2 * (xy - zw), 2 * (xz + yw),
                  2 * (xy + zw), -x2 + y2 - z2 + w2, 2 * (yz - xw),
                  2 * (xz - yw), 2 * (yz + xw), -x2 - y2 + z2 + w2], axis=-1)
    return np.array([quat_of_rotation(r) for r in m.reshape(n, 3, 3)],
                    dtype=np.float64).reshape(n, 4)


def _from_matrix(m: np.ndarray):
    # scipy.spatial is imported on first use: it is a third of a second, and importing
    # the package (as the JAX half does for the bake's schema) should not pay it.
    from scipy.spatial.transform import Rotation  # deferred: 668 ms to import

    # The matrices given here are rotations by construction; scipy's check of that
    # costs 5x the conversion and does not change the result (tests/test_precompute_fast.py).
    try:
        return Rotation.from_matrix(m, assume_valid=True)
    except TypeError:  # scipy releases before the keyword
        return Rotation.from_matrix(m)


def quat_from_matrix(m) -> np.ndarray:
    xyzw = _from_matrix(np.asarray(m, dtype=np.float64)).as_quat()
    q = np.concatenate([xyzw[..., 3:], xyzw[..., :3]], axis=-1)
    # A canonical sign (w >= 0) keeps baked arrays and JSON output deterministic.
    return np.where(q[..., :1] < 0, -q, q)


def quat_of_rotation(m) -> tuple[float, float, float, float]:
    """:func:`quat_from_matrix` of one rotation matrix, in floats: scipy's own method
    (the largest of the trace and the diagonal picks the formula, then normalise),
    4 us against 20 us through scipy, bit-identical (tests/test_precompute_fast.py)."""
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = (
        (float(v) for v in row) for row in m)
    rows = ((m00, m01, m02), (m10, m11, m12), (m20, m21, m22))
    tr = m00 + m11 + m22
    choice = max(range(4), key=lambda i: ((m00, m11, m22, tr)[i], -i))  # first on ties
    if choice == 3:
        x, y, z, w = m21 - m12, m02 - m20, m10 - m01, 1 + tr
    else:
        i = choice
        j, k = (i + 1) % 3, (i + 2) % 3
        q = [0.0, 0.0, 0.0]
        q[i] = 1 - tr + 2 * rows[i][i]
        q[j] = rows[j][i] + rows[i][j]
        q[k] = rows[k][i] + rows[i][k]
        (x, y, z), w = q, rows[k][j] - rows[j][k]
    n = math.sqrt(x * x + y * y + z * z + w * w)
    w, x, y, z = w / n, x / n, y / n, z / n
    return (-w, -x, -y, -z) if w < 0 else (w, x, y, z)


def yaw_matrix(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
