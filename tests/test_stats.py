"""Statistics against scipy on known data."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from sweeps.analysis.stats import mean_ci, pearson_ci


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


def _sweep(rng, n_scenes=40, levels_a=3, levels_b=4, scene_sd=0.15, noise_sd=0.05):
    """A two-axis sweep over the same scenes: value = mu(a, b) + scene effect + noise."""
    import pandas as pd

    mu = 0.5 + 0.05 * np.arange(levels_a)[:, None] - 0.02 * np.arange(levels_b)[None, :]
    effect = rng.normal(0.0, scene_sd, n_scenes)
    rows = [(a, b, s, mu[a, b] + effect[s] + rng.normal(0.0, noise_sd))
            for a in range(levels_a) for b in range(levels_b) for s in range(n_scenes)]
    return pd.DataFrame(rows, columns=["a", "b", "scene_index", "y"]), mu


def test_scene_level_intervals_cover_and_pooled_rows_do_not():
    """400 simulated two-axis sweeps with a per-scene random effect: the interval of the
    mean over the other axis at each level of one axis, with scenes resampled as
    clusters, covers the true mean in 93-97 % of them; pooling the rows as if they were
    independent scenes does not (it is too narrow)."""
    from sweeps.analysis.stats import group_means, pooled_rows_ci

    rng = np.random.default_rng(11)
    hits, pooled_hits, trials = 0, 0, 0
    for k in range(400):
        df, mu = _sweep(rng)
        truth = mu.mean(axis=1)  # the mean over b at each level of a
        got = group_means(df, ["a"], "y", n_resamples=999, seed=k, marginalise=["b"])
        for row in got:
            lo, hi = row["ci"]
            hits += lo <= truth[row["a"]] <= hi
            g = df[df.a == row["a"]]
            plo, phi = pooled_rows_ci(g.y.to_numpy(), 999, k)["ci"]
            pooled_hits += plo <= truth[row["a"]] <= phi
            trials += 1
    assert 0.93 <= hits / trials <= 0.97, hits / trials
    assert pooled_hits / trials < 0.85, pooled_hits / trials


def test_group_means_refuse_to_pool_repeated_scenes():
    from sweeps.analysis.stats import group_means

    df, _ = _sweep(np.random.default_rng(0), n_scenes=5)
    with pytest.raises(ValueError, match="repeat scenes"):
        group_means(df, ["a"], "y")
    per_point = group_means(df, ["a", "b"], "y", n_resamples=200)
    assert len(per_point) == 12 and all(r["n"] == 5 for r in per_point)


def test_paired_intervals_are_narrower_on_correlated_scenes():
    from sweeps.analysis.stats import paired_diff_ci, relative_change_ci

    rng = np.random.default_rng(5)
    a = rng.uniform(0.2, 0.8, 50)
    b = np.clip(a + 0.05 + rng.normal(0, 0.02, 50), 0, 1)
    paired = paired_diff_ci(a, b, 4000, 1)
    ia, ib = mean_ci(a, 4000, 1), mean_ci(b, 4000, 2)
    unpaired = (ib["ci"][0] - ia["ci"][1], ib["ci"][1] - ia["ci"][0])
    assert paired["mean"] == pytest.approx(np.mean(b - a))
    assert paired["ci"][1] - paired["ci"][0] < 0.3 * (unpaired[1] - unpaired[0])
    assert paired["ci"][0] > 0 > unpaired[0]  # only the paired interval sees the gain
    rel = relative_change_ci(a, b, 4000, 1)
    assert rel["mean"] == pytest.approx(b.mean() / a.mean() - 1)
    assert rel["ci"][0] < rel["mean"] < rel["ci"][1]


def test_partial_correlation_against_regression_residuals():
    """The partial correlation of x and y given z equals the correlation of their
    residuals after regressing each on z; a confounded correlation falls towards zero."""
    from sweeps.analysis.stats import partial_corr_ci

    rng = np.random.default_rng(8)
    z = rng.integers(5, 11, 200).astype(float)  # a task count
    x = 0.05 * z + rng.normal(0, 0.05, 200)      # C_init grows with the task count
    y = -0.08 * z + rng.normal(0, 0.08, 200)     # success falls with it
    out = partial_corr_ci(x, y, z, 2000, 0)
    rx = x - np.polyval(np.polyfit(z, x, 1), z)
    ry = y - np.polyval(np.polyfit(z, y, 1), z)
    assert out["rho"] == pytest.approx(stats.pearsonr(rx, ry).statistic)
    assert pearson_ci(x, y, 2000, 0)["rho"] < -0.5
    assert abs(out["rho"]) < 0.25 and out["ci"][0] < out["rho"] < out["ci"][1]  # z explains it
    assert partial_corr_ci(x, y, np.ones(200))["rho"] is None
