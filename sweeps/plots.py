"""Figures: the paper's Fig. 6 (correlations and per-category means) and Fig. 7
(success fields), top-down scene views and sweep plots. Plain matplotlib (its
default backend: Agg on a machine without a display, inline in a notebook); every
function returns the Figure and can save it."""

from __future__ import annotations

from collections.abc import Sequence

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import ListedColormap
from scipy.spatial import ConvexHull

MODE_COLORS = {"baseline": "#7f7f7f", "shrinking": "#1f77b4", "shacc": "#2ca02c",
               "optimized": "#9467bd"}
OUTCOME_COLORS = ["#2ca02c", "#d62728", "#ff7f0e", "#9467bd", "#8c564b"]  # success..collision


def _figure(ax, n: int = 1, figsize=(4.8, 3.4), **kw):
    """(figure, axes) to draw ``n`` panels on: new ones, or the caller's ``ax`` (one
    Axes, or a sequence of n), so that every helper's figure composes into panels."""
    if ax is None:
        fig, axes = plt.subplots(1, n, figsize=figsize, squeeze=False, **kw)
        return fig, list(axes.ravel())
    axes = list(np.atleast_1d(ax).ravel())
    if len(axes) != n:
        raise ValueError(f"this figure needs {n} axes, got {len(axes)}")
    return axes[0].figure, axes


def _save(fig, path):
    """Write the figure to ``path`` (PNG unless its suffix says otherwise), atomically
    (``fileio.write_atomic``): a full disk or Ctrl-C leaves no half picture."""
    if path is not None:
        import io
        from pathlib import Path

        from geometry_precompute.fileio import write_atomic

        buf = io.BytesIO()
        fig.savefig(buf, dpi=110, bbox_inches="tight",
                    format=Path(path).suffix.lstrip(".").lower() or "png")
        write_atomic(path, buf.getvalue())
    return fig


def correlation_panels(u: np.ndarray, measures: dict, correlations: dict, path=None,
                       ax=None):
    """Fig. 6a: baseline u_scene against each measure, with a least-squares line and
    rho with its bootstrap CI in the title. ``ax``: one Axes per measure."""
    fig, axes = _figure(ax, len(measures), (4.2 * len(measures), 3.6), sharey=True)
    for a, (name, x) in zip(axes, measures.items(), strict=True):
        x = np.asarray(x, float)
        a.scatter(x, u, s=18, alpha=0.8)
        if np.ptp(x) > 0:
            slope, intercept = np.polyfit(x, u, 1)
            xs = np.linspace(x.min(), x.max(), 50)
            a.plot(xs, slope * xs + intercept, color="k", lw=1)
        c = correlations.get(name, {})
        if c.get("rho") is not None:
            ci = c.get("ci") or [np.nan, np.nan]
            a.set_title(f"{name}: rho = {c['rho']:.2f} [{ci[0]:.2f}, {ci[1]:.2f}]")
        else:
            a.set_title(f"{name}: rho undefined")
        a.set_xlabel(name)
        a.grid(alpha=0.3)
    axes[0].set_ylabel("u_scene (baseline)")
    if ax is None:
        fig.tight_layout()
    return _save(fig, path)


def category_bars(categories: dict, metric: str, modes: Sequence[str], path=None,
                  ylabel: str | None = None, ax=None):
    """Fig. 6b-d: per category and mode, the mean of ``metric`` with CI error bars."""
    names = [c for c in categories if categories[c]["n_scenes"] > 0]
    fig, (a,) = _figure(ax, 1, (1.6 * len(names) + 2, 3.4))
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
        a.bar(xs, means, width, yerr=errs, capsize=3, label=mode,
              color=MODE_COLORS.get(mode))
    a.set_xticks(np.arange(len(names)), names)
    a.set_ylabel(ylabel or metric)
    a.legend(fontsize=8)
    a.grid(axis="y", alpha=0.3)
    if ax is None:
        fig.tight_layout()
    return _save(fig, path)


def success_fields(outcome: np.ndarray, grid: tuple[int, int], y_range, z_range,
                   task_names: Sequence[str], modes: Sequence[str], path=None,
                   title: str | None = None, ax=None):
    """Fig. 7: per task (columns) and mode (rows), the outcome of the rollout from each
    start of the grid. ``outcome`` is (modes, starts, tasks) with starts y-major.
    ``ax``: modes x tasks Axes (row by row)."""
    ny, nz = grid
    M, _, T = outcome.shape
    if ax is None:
        fig, axes = plt.subplots(M, T, figsize=(3.0 * T, 2.8 * M), squeeze=False)
    else:
        fig, flat = _figure(ax, M * T)
        axes = np.array(flat, dtype=object).reshape(M, T)
    cmap = ListedColormap(OUTCOME_COLORS)
    for m in range(M):
        for t in range(T):
            field = outcome[m, :, t].reshape(ny, nz).T  # rows z, columns y
            a = axes[m, t]
            a.imshow(field, origin="lower", cmap=cmap, vmin=-0.5, vmax=4.5,
                     extent=(y_range[0], y_range[1], z_range[0], z_range[1]), aspect="auto")
            rate = float(np.mean(outcome[m, :, t] == 0))
            a.set_title(f"{modes[m]}: {task_names[t]} ({100 * rate:.0f} %)", fontsize=9)
            a.set_xlabel("y (m)")
            if t == 0:
                a.set_ylabel("z (m)")
    handles = [plt.Rectangle((0, 0), 1, 1, color=c) for c in OUTCOME_COLORS[:4]]
    fig.legend(handles, ["success", "wrong", "ambiguous", "timeout"], loc="lower center",
               ncol=4, fontsize=8)
    if title:
        fig.suptitle(title)
    if ax is None:
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
    from geometry_precompute.bodies import object_body

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


def space_shadows_yz(shapes, sections: int = 32) -> list[np.ndarray]:
    """Each space's outline seen from the start plane (its projection onto y-z): the
    convex hull of its mesh vertices, as closed polylines."""
    from geometry_precompute.meshes import shape_trimesh

    out = []
    for s in shapes:
        pts = shape_trimesh(s, sections).vertices[:, 1:]
        ring = pts[ConvexHull(pts).vertices]
        out.append(np.vstack([ring, ring[:1]]))
    return out


def success_fields_with_spaces(outcome: np.ndarray, delta_r: np.ndarray, grid, y_range,
                               z_range, result, modes: Sequence[str], path=None, ax=None):
    """Fig. 7 with more: per task (columns) the outcome field of each mode (rows, outcome
    kinds coloured), the initial (red) and optimised (blue) spaces seen from the start
    plane, and a last row with ShaCC's delta_R field over its successes. ``ax``:
    (modes + 1) x tasks Axes (row by row)."""
    ny, nz = grid
    M, _, T = outcome.shape
    if ax is None:
        fig, axes = plt.subplots(M + 1, T, figsize=(3.0 * T, 2.6 * (M + 1)), squeeze=False)
    else:
        fig, flat = _figure(ax, (M + 1) * T)
        axes = np.array(flat, dtype=object).reshape(M + 1, T)
    cmap = ListedColormap(OUTCOME_COLORS)
    extent = (y_range[0], y_range[1], z_range[0], z_range[1])
    shadows_init = space_shadows_yz(result.shapes_init)
    shadows_opt = space_shadows_yz(result.shapes_opt)
    names = result.task_ids
    for t in range(T):
        for m in range(M):
            ax = axes[m, t]
            ax.imshow(outcome[m, :, t].reshape(ny, nz).T, origin="lower", cmap=cmap,
                      vmin=-0.5, vmax=4.5, extent=extent, aspect="auto")
            rate = float(np.mean(outcome[m, :, t] == 0))
            ax.set_title(f"{modes[m]}: {names[t]} ({100 * rate:.0f} %)", fontsize=8)
        ax = axes[M, t]
        im = ax.imshow(delta_r[:, t].reshape(ny, nz).T, origin="lower", cmap="viridis",
                       vmin=0.0, vmax=np.pi, extent=extent, aspect="auto")
        ax.set_title(f"shacc delta_R: {names[t]}", fontsize=8)
        for m in range(M + 1):
            ax = axes[m, t]
            for ring in shadows_init:
                ax.plot(ring[:, 0], ring[:, 1], color="red", lw=0.6, alpha=0.7)
            for ring in shadows_opt:
                ax.plot(ring[:, 0], ring[:, 1], color="blue", lw=0.6, alpha=0.7)
            ax.set_xlim(extent[0], extent[1])
            ax.set_ylim(extent[2], extent[3])
            ax.tick_params(labelsize=7)
    fig.colorbar(im, ax=list(axes[M, :]), shrink=0.8, label="delta_R (rad)")
    handles = [plt.Rectangle((0, 0), 1, 1, color=c) for c in OUTCOME_COLORS[:4]]
    fig.legend(handles, ["success", "wrong", "ambiguous", "timeout"], loc="upper center",
               ncol=4, fontsize=8)
    return _save(fig, path)


def scene_gallery(results, columns: int = 4, path=None, ax=None):
    """Top-down views of several scenes (initial red, optimised blue, clusters).
    ``ax``: one Axes per scene."""
    if ax is None:
        rows = -(-len(results) // columns)
        fig, axes = plt.subplots(rows, columns, figsize=(3.3 * columns, 3.4 * rows),
                                 squeeze=False)
        axes = list(axes.ravel())
    else:
        fig, axes = _figure(ax, len(results))
    for a, r in zip(axes, results, strict=False):
        scene_top_view(r, ax=a)
    for a in axes[len(results):]:
        a.axis("off")
    if ax is None:
        fig.tight_layout()
    return _save(fig, path)


def swept_axes(scenes_df, exclude: Sequence[str] = ()) -> list[str]:
    """The settings a sweep's scenes table varies (``set.NAME`` columns with more than
    one value), by name."""
    out = []
    for col in scenes_df.columns:
        if col.startswith("set.") and col[4:] not in exclude:
            if scenes_df[col].map(_label).nunique(dropna=False) > 1:
                out.append(col[4:])
    return out


def _label(v) -> str:
    """A swept value as a label (a list such as a start grid included)."""
    if isinstance(v, list | tuple | np.ndarray):
        return "[" + ", ".join(_label(x) for x in v) + "]"
    if isinstance(v, float | np.floating):
        return f"{float(v):g}"
    return str(v)


def sweep_lines(scenes_df, axis: str, metric: str, modes: Sequence[str], path=None,
                n_resamples: int = 2000, seed: int = 0, others: str = "lines", ax=None):
    """``metric`` ("success" or "delta_R_mean") against one swept setting, per mode:
    the mean over scenes with a 95 % bootstrap CI over scenes (``sweeps.stats``).
    ``axis`` is a setting name (the table's column ``set.<axis>``).

    The other settings the sweep varies are never pooled silently: with ``others =
    "lines"`` each combination of their values is a line of its own (colour per mode,
    line style per combination); with ``"marginalise"`` one line per mode averages each
    scene over the other settings first and resamples the scenes as clusters, which
    the title says. Both give scene-level intervals."""
    from .stats import group_means

    col = f"set.{axis}"
    df = scenes_df.copy()
    other = swept_axes(df, exclude=[axis])
    df["_x"] = df[col].map(lambda v: float(v) if _is_number(v) else _label(v))
    df["_combo"] = df[[f"set.{o}" for o in other]].apply(
        lambda r: ", ".join(f"{o}={_label(v)}" for o, v in zip(other, r, strict=True)), axis=1) \
        if other and others == "lines" else ""
    fig, (a,) = _figure(ax)
    styles = ["-", "--", ":", "-."]
    combos = sorted(df["_combo"].unique())
    for mode in modes:
        for k, combo in enumerate(combos):
            g = df[df["_combo"] == combo]
            pts = group_means(g, ["_x"], f"{mode}.{metric}", n_resamples, seed,
                              marginalise=other if others == "marginalise" else None)
            xs = [p["_x"] for p in pts]
            ms = np.array([np.nan if p["mean"] is None else p["mean"] for p in pts])
            lo = np.array([m if p["ci"] is None else p["ci"][0]
                           for p, m in zip(pts, ms, strict=True)])
            hi = np.array([m if p["ci"] is None else p["ci"][1]
                           for p, m in zip(pts, ms, strict=True)])
            label = mode if not combo else f"{mode}, {combo}"
            a.errorbar(xs, ms, yerr=[ms - lo, hi - ms], marker="o", capsize=3, label=label,
                       color=MODE_COLORS.get(mode), ls=styles[k % len(styles)])
    a.set_xlabel(axis)
    a.set_ylabel(metric)
    if other and others == "marginalise":
        a.set_title(f"mean over {', '.join(other)} (scenes resampled as clusters)",
                    fontsize=8)
    a.legend(fontsize=6 if len(combos) > 2 else 8)
    a.grid(alpha=0.3)
    if ax is None:
        fig.tight_layout()
    return _save(fig, path)


def sweep_heatmap(scenes_df, axis_x: str, axis_y: str, metric: str, mode: str, path=None,
                  ax=None):
    """Mean ``metric`` of ``mode`` over scenes at each point of a two-axis sweep (each
    cell one point: its own scenes). Other swept settings must be fixed first (a
    table with repeated scenes in a cell is refused)."""
    df = scenes_df.copy()
    for a_ in (axis_x, axis_y):
        df[a_] = df[f"set.{a_}"].map(lambda v: float(v) if _is_number(v) else _label(v))
    if df.duplicated([axis_x, axis_y, "scene_index"]).any():
        rest = ", ".join(swept_axes(scenes_df, [axis_x, axis_y]))
        raise ValueError(f"cells of {axis_x} x {axis_y} repeat scenes: select one value of "
                         f"the other swept settings ({rest}) first")
    table = df.pivot_table(index=axis_y, columns=axis_x, values=f"{mode}.{metric}",
                           aggfunc="mean")
    fig, (a,) = _figure(ax, 1, (4.8, 3.8))
    im = a.imshow(table.to_numpy(), origin="lower", cmap="viridis", aspect="auto")
    a.set_xticks(range(table.shape[1]), [_label(v) for v in table.columns])
    a.set_yticks(range(table.shape[0]), [_label(v) for v in table.index])
    for (i, j), v in np.ndenumerate(table.to_numpy()):
        a.text(j, i, f"{v:.2f}", ha="center", va="center", color="w", fontsize=8)
    a.set_xlabel(axis_x)
    a.set_ylabel(axis_y)
    a.set_title(f"{mode}: {metric}")
    fig.colorbar(im, ax=a)
    if ax is None:
        fig.tight_layout()
    return _save(fig, path)


def _is_number(v) -> bool:
    try:
        float(v)
    except (TypeError, ValueError):
        return False
    return True
