"""Object-distribution measures the paper compares C with (reference/model, statistics).

- d: mean Euclidean distance of the objects' base centres to their centroid.
- h: the entropic clutteredness of Schmidt-Wolf et al. ("Through the Clutter",
  arXiv 2406.00119): a Gaussian p fitted to the objects' (x, y) (sample
  covariance S, divisor N - 1) against q uniform over the positions'
  axis-aligned bounding box (area A):
  D(p || q) = ln A - H(p), H(p) = 1 + ln 2 pi + 0.5 ln det S, h = exp(-D).
  ``variant="reference_code"`` uses ln det S in place of 0.5 ln det S, as the
  authors' public code does.

Degenerate scenes (fewer than three objects, collinear objects, det S <= 0,
zero extent) give h = 0, the limit of the formula as det S -> 0. Collinearity
is judged relative to the scale of the positions: det S <= 1e-12 (tr S)^2.
"""

from __future__ import annotations

import math

import numpy as np


def mean_distance(positions) -> float:
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    return float(np.mean(np.linalg.norm(p - p.mean(axis=0), axis=1)))


def entropic_clutteredness(positions, variant: str = "formula") -> float:
    if variant not in ("formula", "reference_code"):
        raise ValueError(f"entropy variant must be formula or reference_code, got {variant!r}")
    xy = np.asarray(positions, dtype=np.float64).reshape(-1, 3)[:, :2]
    if len(xy) < 3:
        return 0.0
    cov = np.cov(xy, rowvar=False, ddof=1)
    det = float(np.linalg.det(cov))
    extent = xy.max(axis=0) - xy.min(axis=0)
    area = float(extent[0] * extent[1])
    if det <= 1e-12 * float(np.trace(cov)) ** 2 or area <= 0.0:
        return 0.0
    half = 0.5 if variant == "formula" else 1.0
    entropy = 1.0 + math.log(2.0 * math.pi) + half * math.log(det)
    return math.exp(entropy - math.log(area))
