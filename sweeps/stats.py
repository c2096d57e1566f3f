"""Statistics (reference/statistics), every one resampling scenes, through scipy.

The unit of resampling is the scene, everywhere. Rollouts of one scene are not
independent, and a sweep evaluates the same scene once per point, so:

- a mean at one sweep point resamples that point's scenes (:func:`mean_ci`);
- a difference between two modes, or two points, on the same scenes is *paired*: the
  per-scene differences are resampled (:func:`paired_diff_ci`), which is narrower than
  two independent intervals whenever the scenes' values are correlated, and is the
  right interval for "is B better than A";
- a mean over several points of a sweep (one axis, the others marginalised) first
  averages each scene over those points, then resamples scenes as clusters
  (:func:`cluster_mean_ci`); pooling the rows as if they were independent scenes gives
  intervals that are too narrow (tests/test_stats.py simulates it);
- correlations are Pearson's rho with a paired bootstrap over scenes
  (:func:`pearson_ci`), and the partial correlation controlling for a third measure
  (:func:`partial_corr_ci`: C_init against success, controlling for the task count).

All intervals are 95 % percentile-bootstrap intervals from ``scipy.stats.bootstrap``,
seeded; no resampling loop is written here.
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy import stats

LEVEL = 0.95


def _ci(res) -> list[float] | None:
    lo, hi = res.confidence_interval
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return None
    return [float(lo), float(hi)]


def _bootstrap(data: tuple, statistic, n_resamples: int, seed: int, paired: bool = False,
               vectorized: bool = True, level: float = LEVEL):
    # Resamples of a few scenes can be constant (a correlation undefined there): scipy
    # warns, and the interval comes out of the others; said by the interval, not stderr.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", stats.DegenerateDataWarning)
        warnings.simplefilter("ignore", stats.ConstantInputWarning)
        warnings.simplefilter("ignore", RuntimeWarning)
        return stats.bootstrap(data, statistic, n_resamples=n_resamples, method="percentile",
                               confidence_level=level, paired=paired, vectorized=vectorized,
                               rng=np.random.default_rng(seed))


def mean_ci(values, n_resamples: int = 10_000, seed: int = 0,
            level: float = LEVEL) -> dict:
    """{"mean": m, "ci": [lo, hi], "n": n} over the finite values, one per scene (NaN
    = a scene with no value, e.g. no success); mean None for no values, ci None for
    fewer than two."""
    x = np.asarray(values, dtype=np.float64)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return {"mean": None, "ci": None, "n": 0}
    if x.size < 2 or np.all(x == x[0]):
        return {"mean": float(x.mean()), "ci": [float(x[0]), float(x[0])] if x.size >= 2
                else None, "n": int(x.size)}
    res = _bootstrap((x,), np.mean, n_resamples, seed, level=level)
    return {"mean": float(x.mean()), "ci": _ci(res), "n": int(x.size)}


def paired_diff_ci(a, b, n_resamples: int = 10_000, seed: int = 0,
                   level: float = LEVEL) -> dict:
    """The mean over scenes of b - a, two measurements of the same scenes (two modes, two
    sweep points, two runs), with a CI resampling the scenes' differences. Scenes where
    either value is missing are left out (``n`` counts the rest)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    if a.shape != b.shape:
        raise ValueError(f"paired values need one shape, got {a.shape} and {b.shape}")
    keep = np.isfinite(a) & np.isfinite(b)
    return mean_ci(b[keep] - a[keep], n_resamples, seed, level)


def relative_change_ci(a, b, n_resamples: int = 10_000, seed: int = 0,
                       level: float = LEVEL) -> dict:
    """mean(b) / mean(a) - 1 over the same scenes (the paper's "+45 %"), with a paired
    CI resampling scenes. None where mean(a) is zero."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    keep = np.isfinite(a) & np.isfinite(b)
    a, b = a[keep], b[keep]
    if a.size == 0 or a.mean() == 0:
        return {"mean": None, "ci": None, "n": int(a.size)}
    value = float(b.mean() / a.mean() - 1.0)
    if a.size < 2 or (np.all(a == a[0]) and np.all(b == b[0])):
        return {"mean": value, "ci": None, "n": int(a.size)}

    def change(x, y, axis):
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.mean(y, axis=axis) / np.mean(x, axis=axis) - 1.0

    res = _bootstrap((a, b), change, n_resamples, seed, paired=True, level=level)
    return {"mean": value, "ci": _ci(res), "n": int(a.size)}


def cluster_mean_ci(values, scenes, n_resamples: int = 10_000, seed: int = 0,
                    level: float = LEVEL) -> dict:
    """The mean of rows that belong to scenes (several rows per scene: the points of a
    marginalised sweep axis), as the mean of each scene's own mean, with a CI that
    resamples scenes as clusters. Every scene weighs the same, however many rows it
    has."""
    values = np.asarray(values, np.float64)
    scenes = np.asarray(scenes)
    keep = np.isfinite(values)
    values, scenes = values[keep], scenes[keep]
    if values.size == 0:
        return {"mean": None, "ci": None, "n": 0}
    _, inverse = np.unique(scenes, return_inverse=True)
    per_scene = np.bincount(inverse, weights=values) / np.bincount(inverse)
    return mean_ci(per_scene, n_resamples, seed, level)


def pooled_rows_ci(values, n_resamples: int = 10_000, seed: int = 0,
                   level: float = LEVEL) -> dict:
    """The wrong interval, kept for the tests that show it is wrong: every row
    resampled as if it were an independent scene."""
    return mean_ci(values, n_resamples, seed, level)


def pearson_ci(x, y, n_resamples: int = 10_000, seed: int = 0, level: float = LEVEL) -> dict:
    """{"rho": r, "ci": [lo, hi], "p": p}: Pearson's rho (scipy.stats.pearsonr) with a
    paired percentile-bootstrap CI, resampling scenes. None where rho is undefined
    (fewer than three scenes, or a constant measure)."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.size < 3 or np.all(x == x[0]) or np.all(y == y[0]):
        return {"rho": None, "ci": None, "p": None}
    r = stats.pearsonr(x, y)

    def rho(a, b, axis):
        with np.errstate(invalid="ignore", divide="ignore"):
            return stats.pearsonr(a, b, axis=axis).statistic

    res = _bootstrap((x, y), rho, n_resamples, seed, paired=True, level=level)
    return {"rho": float(r.statistic), "ci": _ci(res), "p": float(r.pvalue)}


def _partial(x, y, z, axis=-1):
    """Partial correlation of x and y given z, from the three pairwise correlations:
    (r_xy - r_xz r_yz) / sqrt((1 - r_xz^2)(1 - r_yz^2)); vectorised over resamples."""
    def r(a, b):
        a = a - a.mean(axis=axis, keepdims=True)
        b = b - b.mean(axis=axis, keepdims=True)
        return (a * b).sum(axis=axis) / np.sqrt((a * a).sum(axis=axis) * (b * b).sum(axis=axis))

    with np.errstate(invalid="ignore", divide="ignore"):
        rxy, rxz, ryz = r(x, y), r(x, z), r(y, z)
        return (rxy - rxz * ryz) / np.sqrt((1 - rxz ** 2) * (1 - ryz ** 2))


def partial_corr_ci(x, y, z, n_resamples: int = 10_000, seed: int = 0,
                    level: float = LEVEL) -> dict:
    """{"rho": r, "ci": [lo, hi]}: the partial correlation of x and y controlling for z
    (e.g. baseline success and C_init, controlling for the task count), with a paired
    bootstrap CI over scenes. None where undefined (fewer than four scenes, a constant
    measure, or x or y a linear function of z)."""
    x, y, z = (np.asarray(v, np.float64) for v in (x, y, z))
    if x.size < 4 or any(np.all(v == v[0]) for v in (x, y, z)):
        return {"rho": None, "ci": None}
    value = float(_partial(x, y, z))
    if not np.isfinite(value):
        return {"rho": None, "ci": None}
    res = _bootstrap((x, y, z), _partial, n_resamples, seed, paired=True, level=level)
    return {"rho": value, "ci": _ci(res)}


def group_means(df, by: list[str], column: str, n_resamples: int = 2000, seed: int = 0,
                scene: str = "scene_index", marginalise: list[str] | None = None) -> list[dict]:
    """Per combination of the columns ``by``, the mean of ``column`` over scenes with
    its CI. Columns in ``marginalise`` (other sweep axes) are averaged within each
    scene first and the scenes resampled as clusters (:func:`cluster_mean_ci`); without
    them every row of a group must be a distinct scene (one sweep point), which this
    checks."""
    out = []
    for key, g in df.groupby(by, sort=True, dropna=False):
        key = key if isinstance(key, tuple) else (key,)
        if marginalise:
            ci = cluster_mean_ci(g[column].to_numpy(), g[scene].to_numpy(), n_resamples, seed)
        else:
            if g[scene].duplicated().any():
                raise ValueError(f"rows of {dict(zip(by, key, strict=True))} repeat scenes: "
                                 "name the other swept columns in `by` or `marginalise`")
            ci = mean_ci(g[column].to_numpy(), n_resamples, seed)
        out.append({**dict(zip(by, key, strict=True)), **ci})
    return out
