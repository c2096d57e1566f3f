"""Figures: the paper's Fig. 6 (correlations and per-category means) and Fig. 7
(success fields), and top-down scene views. Plain matplotlib on the Agg backend;
every function returns the Figure and can save it."""

from __future__ import annotations

from collections.abc import Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import ListedColormap
from scipy.spatial import ConvexHull

MODE_COLORS = {"baseline": "#7f7f7f", "shrinking": "#1f77b4", "shacc": "#2ca02c"}
OUTCOME_COLORS = ["#2ca02c", "#d62728", "#ff7f0e", "#9467bd", "#8c564b"]  # success..collision


def _save(fig, path):
    if path is not None:
        fig.savefig(path, dpi=110, bbox_inches="tight")
    return fig


def correlation_panels(u: np.ndarray, measures: dict, correlations: dict, path=None):
    """Fig. 6a: baseline u_scene against each measure, with a least-squares line and
    rho with its bootstrap CI in the title."""
    fig, axes = plt.subplots(1, len(measures), figsize=(4.2 * len(measures), 3.6),
                             sharey=True)
    for ax, (name, x) in zip(np.atleast_1d(axes), measures.items(), strict=True):
        x = np.asarray(x, float)
        ax.scatter(x, u, s=18, alpha=0.8)
        if np.ptp(x) > 0:
            slope, intercept = np.polyfit(x, u, 1)
            xs = np.linspace(x.min(), x.max(), 50)
            ax.plot(xs, slope * xs + intercept, color="k", lw=1)
        c = correlations.get(name, {})
        if c.get("rho") is not None:
            ci = c.get("ci") or [np.nan, np.nan]
            ax.set_title(f"{name}: rho = {c['rho']:.2f} [{ci[0]:.2f}, {ci[1]:.2f}]")
        else:
            ax.set_title(f"{name}: rho undefined")
        ax.set_xlabel(name)
        ax.grid(alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("u_scene (baseline)")
    fig.tight_layout()
    return _save(fig, path)


def category_bars(categories: dict, metric: str, modes: Sequence[str], path=None,
                  ylabel: str | None = None):
    """Fig. 6b-d: per category and mode, the mean of ``metric`` with CI error bars."""
    names = [c for c in categories if categories[c]["n_scenes"] > 0]
    fig, ax = plt.subplots(figsize=(1.6 * len(names) + 2, 3.4))
    width = 0.8 / len(modes)
    for k, mode in enumerate(modes):
        means, errs = [], [[], []]
        for c in names:
            entry = categories[c][mode][metric]
            m = entry["mean"] if entry["mean"] is not None else np.nan
            lo, hi = entry["ci"] if entry["ci"] else (m, m)
            means.append(m)
            errs[0].append(max(m - lo, 0.0) if np.isfinite(m) else 0.0)
            errs[1].append(max(hi - m, 0.0) if np.isfinite(m) else 0.0)
        xs = np.arange(len(names)) + (k - (len(modes) - 1) / 2) * width
        ax.bar(xs, means, width, yerr=errs, capsize=3, label=mode,
               color=MODE_COLORS.get(mode))
    ax.set_xticks(np.arange(len(names)), names)
    ax.set_ylabel(ylabel or metric)
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    return _save(fig, path)


def success_fields(outcome: np.ndarray, grid: tuple[int, int], y_range, z_range,
                   task_names: Sequence[str], modes: Sequence[str], path=None,
                   title: str | None = None):
    """Fig. 7: per task (columns) and mode (rows), the outcome of the rollout from each
    start of the grid. ``outcome`` is (modes, starts, tasks) with starts y-major."""
    ny, nz = grid
    M, _, T = outcome.shape
    fig, axes = plt.subplots(M, T, figsize=(3.0 * T, 2.8 * M), squeeze=False)
    cmap = ListedColormap(OUTCOME_COLORS)
    for m in range(M):
        for t in range(T):
            field = outcome[m, :, t].reshape(ny, nz).T  # rows z, columns y
            ax = axes[m, t]
            ax.imshow(field, origin="lower", cmap=cmap, vmin=-0.5, vmax=4.5,
                      extent=(y_range[0], y_range[1], z_range[0], z_range[1]), aspect="auto")
            rate = float(np.mean(outcome[m, :, t] == 0))
            ax.set_title(f"{modes[m]}: {task_names[t]} ({100 * rate:.0f} %)", fontsize=9)
            ax.set_xlabel("y (m)")
            if t == 0:
                ax.set_ylabel("z (m)")
    handles = [plt.Rectangle((0, 0), 1, 1, color=c) for c in OUTCOME_COLORS[:4]]
    fig.legend(handles, ["success", "wrong", "ambiguous", "timeout"], loc="lower center",
               ncol=4, fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    return _save(fig, path)


def _outline_xy(shape) -> np.ndarray:
    """The shape's footprint on the table (x, y) as a closed polyline."""
    a, b, _ = shape.dims
    rot = shape.rotation
    center = np.asarray(shape.center)
    if shape.kind in ("cylinder", "disk"):
        t = np.linspace(0, 2 * np.pi, 73)
        local = np.stack([a * np.cos(t), a * np.sin(t), np.zeros_like(t)], 1)
    elif shape.kind == "cone":
        # The footprint of a cone is the convex hull of its apex and base rim.
        r = a * np.tan(b)
        t = np.linspace(0, 2 * np.pi, 73)
        rim = np.stack([r * np.cos(t), r * np.sin(t), np.full_like(t, a)], 1)
        pts = (np.vstack([[0.0, 0.0, 0.0], rim]) @ rot.T + center)[:, :2]
        ring = pts[ConvexHull(pts).vertices]
        return np.vstack([ring, ring[:1]])
    else:
        local = np.array([[-a, -b, 0], [a, -b, 0], [a, b, 0], [-a, b, 0], [-a, -b, 0]])
    return (local @ rot.T + center)[:, :2]


def scene_top_view(result, ax=None, path=None, show_clusters: bool = True):
    """Top-down view: objects, initial (red) and optimised (blue) position spaces,
    clusters by label (the paper's Fig. 5a)."""
    from geometry_precompute.templates import object_body

    own = ax is None
    if own:
        fig, ax = plt.subplots(figsize=(4.5, 4.5))
    else:
        fig = ax.figure
    cluster_of = {i: k for k, c in enumerate(result.meta_clusters()) for i in c}
    for i, (si, so) in enumerate(zip(result.shapes_init, result.shapes_opt, strict=True)):
        ring = _outline_xy(si)
        ax.fill(ring[:, 0], ring[:, 1], color="red", alpha=0.12)
        ax.plot(ring[:, 0], ring[:, 1], color="red", lw=1)
        ring = _outline_xy(so)
        ax.plot(ring[:, 0], ring[:, 1], color="blue", lw=1.3)
        if show_clusters and i in cluster_of:
            ax.annotate(f"K{cluster_of[i]}", so.center[:2], fontsize=7, color="blue")
    for o in result.scene.objects:
        ring = _outline_xy(object_body(o))
        ax.fill(ring[:, 0], ring[:, 1], color="k", alpha=0.6)
        ax.annotate(o.id, (o.position[0], o.position[1]), fontsize=7, color="w",
                    ha="center", va="center")
    ax.set_aspect("equal")
    ax.set_title(f"{result.scene.name}\nC_init {result.C_init:.2f} -> C_final "
                 f"{result.C_final:.2f}", fontsize=9)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(alpha=0.3)
    if own:
        fig.tight_layout()
        _save(fig, path)
    return fig
