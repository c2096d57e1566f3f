"""Statistics against scipy on known data."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from sweeps.stats import mean_ci, pearson_ci


def test_pearson_matches_scipy_and_bootstrap():
    rng = np.random.default_rng(1)
    x = rng.normal(size=40)
    y = -0.6 * x + rng.normal(scale=0.8, size=40)
    out = pearson_ci(x, y, n_resamples=4000, seed=3)
    assert out["rho"] == pytest.approx(stats.pearsonr(x, y).statistic)
    ref = stats.bootstrap((x, y), lambda a, b: stats.pearsonr(a, b).statistic, paired=True,
                          vectorized=False, n_resamples=4000, method="percentile",
                          rng=np.random.default_rng(7))
    lo, hi = ref.confidence_interval  # another seed: agreement up to resampling noise
    assert out["ci"][0] == pytest.approx(lo, abs=0.05)
    assert out["ci"][1] == pytest.approx(hi, abs=0.05)
    same = stats.bootstrap((x, y), lambda a, b: stats.pearsonr(a, b).statistic, paired=True,
                           vectorized=False, n_resamples=4000, method="percentile",
                           rng=np.random.default_rng(3))
    np.testing.assert_allclose(out["ci"], same.confidence_interval, rtol=1e-9)
    assert out["ci"][0] < out["rho"] < out["ci"][1] < 0
    assert pearson_ci(x, y, 4000, seed=3) == out  # seeded


def test_pearson_perfect_and_degenerate():
    x = np.arange(10.0)
    assert pearson_ci(x, 2 * x + 1)["rho"] == pytest.approx(1.0)
    assert pearson_ci(x, np.ones(10))["rho"] is None
    assert pearson_ci([1.0, 2.0], [2.0, 1.0])["rho"] is None


def test_mean_ci_matches_scipy():
    x = np.random.default_rng(2).exponential(size=30)
    out = mean_ci(x, n_resamples=5000, seed=4)
    ref = stats.bootstrap((x,), np.mean, n_resamples=5000, method="percentile",
                          rng=np.random.default_rng(4))
    assert out["mean"] == pytest.approx(x.mean())
    np.testing.assert_allclose(out["ci"], ref.confidence_interval, rtol=1e-12)


def test_mean_ci_edge_cases():
    assert mean_ci([])["mean"] is None
    assert mean_ci([np.nan, 2.0]) == {"mean": 2.0, "ci": None, "n": 1}
    assert mean_ci([0.5, 0.5, 0.5])["ci"] == [0.5, 0.5]
