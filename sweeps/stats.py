"""Statistics of SPEC section 10 through scipy: Pearson's rho and percentile
bootstrap confidence intervals, resampling scenes, seeded."""

from __future__ import annotations

import numpy as np
from scipy import stats


def _ci(res) -> list[float] | None:
    lo, hi = res.confidence_interval
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return None
    return [float(lo), float(hi)]


def mean_ci(values, n_resamples: int = 10_000, seed: int = 0,
            level: float = 0.95) -> dict:
    """{"mean": m, "ci": [lo, hi]} over the finite values (NaN = a scene with no value,
    e.g. no success); mean None for no values, ci None for fewer than two."""
    x = np.asarray(values, dtype=np.float64)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return {"mean": None, "ci": None, "n": 0}
    if x.size < 2 or np.all(x == x[0]):
        return {"mean": float(x.mean()), "ci": [float(x[0]), float(x[0])] if x.size >= 2
                else None, "n": int(x.size)}
    res = stats.bootstrap((x,), np.mean, n_resamples=n_resamples, method="percentile",
                          confidence_level=level, rng=np.random.default_rng(seed))
    return {"mean": float(x.mean()), "ci": _ci(res), "n": int(x.size)}


def pearson_ci(x, y, n_resamples: int = 10_000, seed: int = 0, level: float = 0.95) -> dict:
    """{"rho": r, "ci": [lo, hi], "p": p}: Pearson's rho (scipy.stats.pearsonr) with a
    paired percentile-bootstrap CI (scipy.stats.bootstrap), resampling scenes. None
    where rho is undefined (fewer than three scenes, or a constant measure)."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.size < 3 or np.all(x == x[0]) or np.all(y == y[0]):
        return {"rho": None, "ci": None, "p": None}
    r = stats.pearsonr(x, y)

    def rho(a, b, axis):
        with np.errstate(invalid="ignore", divide="ignore"):
            return stats.pearsonr(a, b, axis=axis).statistic

    res = stats.bootstrap((x, y), rho, paired=True, vectorized=True, n_resamples=n_resamples,
                          method="percentile", confidence_level=level,
                          rng=np.random.default_rng(seed))
    return {"rho": float(r.statistic), "ci": _ci(res), "p": float(r.pvalue)}
