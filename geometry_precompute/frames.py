"""Frames and quaternions on the CPU side (SPEC section 2), in float64.

Quaternions are (w, x, y, z). scipy's Rotation uses (x, y, z, w): conversions from
matrices go through :func:`quat_from_matrix`; ``shapes.rotation_matrix`` goes back.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation


def frame_from_approach(a) -> np.ndarray:
    """SPEC section 2: z = a/|a|; u = world z, or world x where |z . world z| > 0.99;
    x = normalize(u x z); y = z x x. Returns the 3x3 matrix [x y z] (columns).

    Written out in floats: 4 us against 70 us through np.cross and np.linalg.norm,
    with bit-identical results (tests/test_overlap.py checks 2 x 10^4 directions)."""
    ax, ay, az = (float(v) for v in a)
    n = math.sqrt(ax * ax + ay * ay + az * az)
    zx, zy, zz = ax / n, ay / n, az / n
    ux, uy, uz = (1.0, 0.0, 0.0) if abs(zz) > 0.99 else (0.0, 0.0, 1.0)
    xx, xy, xz = uy * zz - uz * zy, uz * zx - ux * zz, ux * zy - uy * zx
    m = math.sqrt(xx * xx + xy * xy + xz * xz)
    xx, xy, xz = xx / m, xy / m, xz / m
    yx, yy, yz = zy * xz - zz * xy, zz * xx - zx * xz, zx * xy - zy * xx
    return np.array([[xx, yx, zx], [xy, yy, zy], [xz, yz, zz]])


def _from_matrix(m: np.ndarray) -> Rotation:
    # The matrices given here are rotations by construction; scipy's check of that
    # costs 5x the conversion and does not change the result (tests/test_overlap.py).
    try:
        return Rotation.from_matrix(m, assume_valid=True)
    except TypeError:  # scipy releases before the keyword
        return Rotation.from_matrix(m)


def quat_from_matrix(m) -> np.ndarray:
    xyzw = _from_matrix(np.asarray(m, dtype=np.float64)).as_quat()
    q = np.concatenate([xyzw[..., 3:], xyzw[..., :3]], axis=-1)
    # A canonical sign (w >= 0) keeps baked arrays and JSON output deterministic.
    return np.where(q[..., :1] < 0, -q, q)


def yaw_matrix(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
