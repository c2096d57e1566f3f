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

__all__ = ["LEVEL", "cluster_mean_ci", "format_ci", "group_means", "mean_ci", "paired_diff_ci",
           "partial_corr_ci", "pearson_ci", "pooled_rows_ci", "relative_change_ci"]


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
    fewer than two.

    :param values: (S,) one value per scene (a success rate, an angle in rad, ...).
    :param n_resamples: bootstrap resamples; ``seed`` seeds them; ``level`` is the
        interval's coverage (0.95).

    Example::

        >>> from sweeps.analysis.stats import mean_ci
        >>> r = mean_ci([0.5, 0.75, 1.0, 0.25, float("nan")], seed=0)
        >>> r["mean"], r["n"]            # the NaN scene is left out
        (0.625, 4)
        >>> r["ci"][0] <= r["mean"] <= r["ci"][1]
        True
    """
    x = np.asarray(values, dtype=np.float64)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return {"mean": None, "ci": None, "n": 0}
    if x.size < 2 or np.all(x == x[0]):
        return {"mean": float(x.mean()), "ci": [float(x[0]), float(x[0])] if x.size >= 2
                else None, "n": int(x.size)}
    res = _bootstrap((x,), np.mean, n_resamples, seed, level=level)
    return {"mean": float(x.mean()), "ci": _ci(res), "n": int(x.size)}


def format_ci(entry: dict | None, digits: int = 2) -> str:
    """``"m [lo, hi]"`` of a :func:`mean_ci`-shaped dict (``"m"`` without an interval,
    ``"n/a"`` without a mean), as the reports print them.

    :param entry: {"mean": m, "ci": [lo, hi] or None, ...}, or None.
    :param digits: decimals.

    Example::

        >>> from sweeps.analysis.stats import format_ci
        >>> format_ci({"mean": 0.5, "ci": [0.25, 0.75], "n": 4})
        '0.50 [0.25, 0.75]'
    """
    if entry is None or entry.get("mean") is None:
        return "n/a"
    m = entry["mean"]
    ci = entry.get("ci")
    if ci is None:
        return f"{m:.{digits}f}"
    return f"{m:.{digits}f} [{ci[0]:.{digits}f}, {ci[1]:.{digits}f}]"


def paired_diff_ci(a, b, n_resamples: int = 10_000, seed: int = 0,
                   level: float = LEVEL) -> dict:
    """The mean over scenes of b - a, two measurements of the same scenes (two modes, two
    sweep points, two runs), with a CI resampling the scenes' differences. Scenes where
    either value is missing are left out (``n`` counts the rest).

    :param a: (S,) the first measurement per scene (e.g. baseline success).
    :param b: (S,) the second, same scenes in the same order (e.g. shacc success).
    :returns: as :func:`mean_ci`, of b - a.

    Example::

        >>> from sweeps.analysis.stats import paired_diff_ci
        >>> d = paired_diff_ci([0.2, 0.5, 0.4, 0.6], [0.5, 0.7, 0.6, 0.9], seed=0)
        >>> round(d["mean"], 3), d["ci"][0] > 0     # B better than A, and surely so
        (0.25, True)
    """
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    if a.shape != b.shape:
        raise ValueError(f"paired values need one shape, got {a.shape} and {b.shape}")
    keep = np.isfinite(a) & np.isfinite(b)
    return mean_ci(b[keep] - a[keep], n_resamples, seed, level)


def relative_change_ci(a, b, n_resamples: int = 10_000, seed: int = 0,
                       level: float = LEVEL) -> dict:
    """mean(b) / mean(a) - 1 over the same scenes (the paper's "+45 %"), with a paired
    CI resampling scenes. None where mean(a) is zero.

    :param a: (S,) the reference measurement per scene; ``b`` (S,) the same scenes'
        other one. The result's ``mean`` is a fraction (0.45 for +45 %).

    Example::

        >>> from sweeps.analysis.stats import relative_change_ci
        >>> r = relative_change_ci([0.4, 0.5, 0.6], [0.6, 0.7, 0.9], seed=0)
        >>> round(r["mean"], 3), r["n"]
        (0.467, 3)
    """
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
    has.

    :param values: (R,) one value per row; ``scenes`` (R,) the scene each row belongs to
        (any hashable labels).

    Example::

        >>> from sweeps.analysis.stats import cluster_mean_ci
        >>> r = cluster_mean_ci([0.2, 0.4, 0.9, 0.8, 0.7], ["a", "a", "b", "b", "b"], seed=0)
        >>> round(r["mean"], 3), r["n"]    # (0.3 + 0.8) / 2 over two scenes
        (0.55, 2)
    """
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
    resampled as if it were an independent scene. Use :func:`cluster_mean_ci` instead.

    :param values: (R,) one value per row, rows of the same scene counted as others.

    Example::

        >>> from sweeps.analysis.stats import pooled_rows_ci
        >>> pooled_rows_ci([0.2, 0.4, 0.9, 0.8, 0.7], seed=0)["n"]   # rows, not scenes
        5
    """
    return mean_ci(values, n_resamples, seed, level)


def pearson_ci(x, y, n_resamples: int = 10_000, seed: int = 0, level: float = LEVEL) -> dict:
    """{"rho": r, "ci": [lo, hi], "p": p}: Pearson's rho (scipy.stats.pearsonr) with a
    paired percentile-bootstrap CI, resampling scenes. None where rho is undefined
    (fewer than three scenes, or a constant measure).

    :param x: (S,) one measure per scene (e.g. C_init); ``y`` (S,) another (success).

    Example::

        >>> from sweeps.analysis.stats import pearson_ci
        >>> r = pearson_ci([0.0, 0.1, 0.3, 0.5], [0.9, 0.8, 0.5, 0.3], seed=0)
        >>> r["rho"] < -0.9, r["p"] < 0.05
        (True, True)
    """
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
    measure, or x or y a linear function of z).

    :param x: (S,), ``y`` (S,), ``z`` (S,): three measures of the same scenes.

    Example::

        >>> from sweeps.analysis.stats import partial_corr_ci
        >>> c = [0.0, 0.1, 0.3, 0.5, 0.2]
        >>> u = [0.9, 0.8, 0.5, 0.3, 0.6]
        >>> tasks = [3, 4, 2, 5, 3]
        >>> r = partial_corr_ci(c, u, tasks, seed=0)
        >>> -1 <= r["rho"] <= 1
        True
    """
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
    checks.

    :param df: a pandas DataFrame, one row per scene and sweep point (the sweep's
        ``scenes`` table).
    :param by: the columns to group by (e.g. ``["point"]`` or ``["set.v_max"]``).
    :param column: the measure (e.g. ``"shacc.success"``).
    :param scene: the column naming the scene (``scene_index`` in a sweep).
    :returns: one dict per group: the ``by`` values and :func:`mean_ci`'s keys.

    Example::

        >>> import pandas as pd
        >>> from sweeps.analysis.stats import group_means
        >>> df = pd.DataFrame({"point": [0, 0, 1, 1], "scene_index": [0, 1, 0, 1],
        ...                    "shacc.success": [0.5, 0.7, 0.6, 0.9]})
        >>> [(g["point"], round(g["mean"], 3)) for g in group_means(df, ["point"],
        ...                                                         "shacc.success")]
        [(0, 0.6), (1, 0.75)]
    """
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
