"""d and h (reference/model) on hand-computed and degenerate cases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from geometry_precompute.spread import entropic_clutteredness, mean_distance


def test_mean_distance_hand_computed():
    pts = [(1, 0, 0), (-1, 0, 0), (0, 2, 0), (0, -2, 0)]
    assert mean_distance(pts) == pytest.approx(1.5)
    assert mean_distance([(0.3, 0.4, 0)]) == 0.0


def test_entropy_hand_computed():
    # Square corners of side 2: S = diag(4/3, 4/3), det = 16/9, A = 4.
    pts = [(0, 0, 0), (2, 0, 0), (0, 2, 0), (2, 2, 0)]
    det = 16 / 9
    h_formula = math.exp(1 + math.log(2 * math.pi) + 0.5 * math.log(det) - math.log(4))
    h_code = math.exp(1 + math.log(2 * math.pi) + math.log(det) - math.log(4))
    assert entropic_clutteredness(pts) == pytest.approx(h_formula)
    assert entropic_clutteredness(pts, "reference_code") == pytest.approx(h_code)
    assert h_formula == pytest.approx(2 * math.pi * math.e * (4 / 3) / 4)


def test_entropy_scale_behaviour():
    rng = np.random.default_rng(0)
    pts = np.c_[rng.normal(size=(8, 2)), np.zeros(8)]
    # The formula variant is scale invariant (both terms scale with the area).
    assert entropic_clutteredness(pts * 3) == pytest.approx(entropic_clutteredness(pts))
    assert entropic_clutteredness(pts) > 0


@pytest.mark.parametrize("pts", [
    [(0, 0, 0), (1, 1, 0), (2, 2, 0), (3, 3, 0)],   # collinear
    [(0, 0, 0), (1, 0, 0)],                         # two objects
    [(0.5, 0.5, 0)],                                # one object
    [(0.2, 0.2, 0)] * 4,                            # coincident
    [(0, 0, 0), (1, 0, 0), (2, 0, 0)],              # zero extent in y
])
@pytest.mark.parametrize("variant", ["formula", "reference_code"])
def test_entropy_degenerate_is_zero_not_nan(pts, variant):
    assert entropic_clutteredness(pts, variant) == 0.0


def test_unknown_variant():
    with pytest.raises(ValueError):
        entropic_clutteredness([(0, 0, 0)] * 3, "other")
