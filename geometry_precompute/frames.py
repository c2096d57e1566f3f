"""Frames and quaternions on the CPU side (SPEC section 2), in float64.

Quaternions are (w, x, y, z). scipy's Rotation uses (x, y, z, w): conversions from
matrices go through :func:`quat_from_matrix`; ``shapes.rotation_matrix`` goes back.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def frame_from_approach(a) -> np.ndarray:
    """SPEC section 2: z = a/|a|; u = world z, or world x where |z . world z| > 0.99;
    x = normalize(u x z); y = z x x. Returns the 3x3 matrix [x y z] (columns)."""
    a = np.asarray(a, dtype=np.float64)
    z = a / np.linalg.norm(a)
    u = np.array([1.0, 0.0, 0.0]) if abs(z[2]) > 0.99 else np.array([0.0, 0.0, 1.0])
    x = np.cross(u, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=1)


def quat_from_matrix(m) -> np.ndarray:
    xyzw = Rotation.from_matrix(np.asarray(m, dtype=np.float64)).as_quat()
    q = np.concatenate([xyzw[..., 3:], xyzw[..., :3]], axis=-1)
    # A canonical sign (w >= 0) keeps baked arrays and JSON output deterministic.
    return np.where(q[..., :1] < 0, -q, q)


def yaw_matrix(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
