"""Figures: the paper's Fig. 6 (correlations and per-category means) and Fig. 7
(success fields), top-down scene views and sweep plots. Plain matplotlib (its
default backend: Agg on a machine without a display, inline in a notebook); every
function returns the Figure and can save it."""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.artist import Artist
from matplotlib.colors import ListedColormap
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.text import Text
from matplotlib.transforms import Bbox
from scipy.spatial import ConvexHull

MODE_COLORS = {"baseline": "#7f7f7f", "shrinking": "#1f77b4", "shacc": "#2ca02c",
               "optimized": "#9467bd", "blend": "#ff7f0e", "ho": "#d62728",
               "shacc_ho": "#17becf"}
# A marker per mode as well as a colour: lines that coincide stay told apart.
MODE_MARKERS = {"baseline": "s", "shrinking": "^", "shacc": "o", "optimized": "D",
                "blend": "v", "ho": "P", "shacc_ho": "X"}
OUTCOME_COLORS = ["#2ca02c", "#d62728", "#ff7f0e", "#9467bd", "#8c564b"]  # success..collision

__all__ = ["MODE_COLORS", "MODE_MARKERS", "OUTCOME_COLORS", "assistance_bars",
           "category_bars", "correlation_panels",
           "robustness_lines", "scene_gallery", "scene_top_view", "space_shadows_yz",
           "success_fields", "success_fields_with_spaces", "sweep_heatmap", "sweep_lines",
           "swept_axes"]


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

        from geometry_precompute.fileio import write_atomic  # deferred: 12 ms to import

        buf = io.BytesIO()
        fig.savefig(buf, dpi=110, bbox_inches="tight",
                    format=Path(path).suffix.lstrip(".").lower() or "png")
        write_atomic(path, buf.getvalue())
    return fig


def correlation_panels(u: np.ndarray, measures: dict, correlations: dict, path=None,
                       ax=None):
    """Fig. 6a: baseline u_scene against each measure, with a least-squares line and
    rho with its bootstrap CI in the title. ``ax``: one Axes per measure.

    :param u: (S,) baseline success per scene.
    :param measures: name -> (S,) values per scene (C_init, d, h).
    :param correlations: name -> :func:`sweeps.analysis.stats.pearson_ci`'s dict.
    :param path: where to save the figure (PNG unless the suffix says otherwise).

    Example::

        >>> from sweeps.analysis.plots import correlation_panels
        >>> from sweeps.analysis.stats import pearson_ci
        >>> u, c = [0.9, 0.8, 0.5, 0.3], [0.0, 0.1, 0.3, 0.5]
        >>> fig = correlation_panels(u, {"C_init": c}, {"C_init": pearson_ci(c, u)})
        >>> len(fig.axes)
        1
    """
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
    """Fig. 6b-d: per category and mode, the mean of ``metric`` with CI error bars.

    :param categories: category -> {"n_scenes": n, mode: {metric: {"mean": m, "ci":
        [lo, hi]}}} (``shacc reproduce``'s ``summary.json`` holds this shape; categories
        with no scenes are left out).
    :param metric: the key under each mode (``"u_scene"``, ``"C_final"``, ...).

    Example::

        >>> from sweeps.analysis.plots import category_bars
        >>> cats = {"cluttered": {"n_scenes": 6,
        ...                       "baseline": {"u_scene": {"mean": 0.5, "ci": [0.4, 0.6]}},
        ...                       "shacc": {"u_scene": {"mean": 0.8, "ci": [0.7, 0.9]}}}}
        >>> fig = category_bars(cats, "u_scene", ["baseline", "shacc"], ylabel="success")
    """
    names = [c for c in categories if categories[c]["n_scenes"] > 0]
    fig, (a,) = _figure(ax, 1, (min(1.6 * len(names) + 2, 9.0), 3.4))
    width = 0.8 / len(modes)
    for k, mode in enumerate(modes):
        means: list[float] = []
        errs: list[list[float]] = [[], []]
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
    a.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    a.grid(axis="y", alpha=0.3)
    if ax is None:
        fig.tight_layout()
    return _save(fig, path)


def robustness_lines(section: dict, modes: Sequence[str], path=None, ax=None):
    """The reproduction's robustness section: one panel per user parameter, each mode's
    mean success over scenes against the parameter's level (the perfect user first),
    with the scene-level CIs as error bars.

    :param section: parameter -> {"rows": [{"level": v, "modes": {mode: {"u_scene":
        {"mean": m, "ci": [lo, hi]}}}}, ...]} (``summary.json``'s ``robustness``).

    Example::

        >>> from sweeps.analysis.plots import robustness_lines
        >>> row = lambda v, u: {"level": v, "modes": {"shacc": {"u_scene": {
        ...     "mean": u, "ci": [u - 0.1, u + 0.1]}}}}
        >>> fig = robustness_lines({"user_noise": {"rows": [row(0.0, 0.9), row(0.2, 0.8)]}},
        ...                        ["shacc"])
    """
    params = list(section)
    fig, axes = _figure(ax, len(params), (3.2 * len(params) + 1.5, 3.2), sharey=True)
    for a, param in zip(axes, params, strict=True):
        rows = section[param]["rows"]
        xs = np.arange(len(rows))
        for k, mode in enumerate(modes):
            u = [r["modes"][mode]["u_scene"] for r in rows]
            m = np.array([np.nan if e["mean"] is None else e["mean"] for e in u])
            lo = np.array([e["ci"][0] if e["ci"] else np.nan for e in u])
            hi = np.array([e["ci"][1] if e["ci"] else np.nan for e in u])
            err = np.nan_to_num(np.vstack([m - lo, hi - m]).clip(min=0))
            a.errorbar(xs + (k - (len(modes) - 1) / 2) * 0.06, m, yerr=err, capsize=3,
                       marker="o", ms=3, label=mode, color=MODE_COLORS.get(mode))
        a.set_xticks(xs, [str(r["level"]) for r in rows])
        a.set_xlabel(param)
        a.grid(alpha=0.3)
    axes[0].set_ylabel("success u_scene (mean over scenes)")
    axes[-1].legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    if ax is None:
        fig.tight_layout()
    return _save(fig, path)


def success_fields(outcome: np.ndarray, grid: tuple[int, int], y_range, z_range,
                   task_names: Sequence[str], modes: Sequence[str], path=None,
                   title: str | None = None, ax=None):
    """Fig. 7: per task (columns) and mode (rows), the outcome of the rollout from each
    start of the grid. ``outcome`` is (modes, starts, tasks) with starts y-major.
    ``ax``: modes x tasks Axes (row by row).

    :param outcome: (M, N, T) outcome codes (``shacc_jax.OUTCOMES``), N = ny * nz.
    :param grid: (ny, nz), the start grid; ``y_range``, ``z_range``: its extent (m).

    Example::

        >>> import numpy as np
        >>> from sweeps.analysis.plots import success_fields
        >>> outcome = np.zeros((2, 6 * 6, 3), int)         # every rollout a success
        >>> fig = success_fields(outcome, (6, 6), (-0.4, 0.4), (0.05, 0.4),
        ...                      ["a", "b", "c"], ["baseline", "shacc"])
        >>> len(fig.axes)
        6
    """
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


SPACE_STYLE: dict[str, dict[str, Any]] = {  # how a top view and its legend draw each kind of space
    "init": {"color": "#d62728", "lw": 1.0, "ls": "-", "label": "initial space"},
    "shrinking": {"color": "#1f77b4", "lw": 1.3, "ls": "-", "label": "after Shrinking"},
    "optimized": {"color": "#9467bd", "lw": 1.5, "ls": "--", "label": "optimized"},
}


def _place_labels(ax, items, avoid=(), fontsize: float = 7.0) -> list:
    """Write each ``(text, (x, y), color)`` near its point without covering another
    label, a box of ``avoid`` (display coordinates) or leaving the axes: the first of
    rings of candidate positions around the point that is free (else the least
    covered), joined to the point by a thin line. Returns the Annotations."""

    def text_box(ann):  # the text alone, without its leader line, where it now is
        ann.update_positions(renderer)
        return Text.get_window_extent(ann, renderer)

    fig = ax.figure
    renderer = fig.canvas.get_renderer()
    ax.apply_aspect()
    frame = ax.get_window_extent(renderer)
    placed = [Bbox(b) for b in avoid]
    out = []
    angles = np.deg2rad(np.arange(0, 360, 22.5))
    for text, xy, color in items:
        ann = ax.annotate(text, xy, xytext=xy, fontsize=fontsize, color=color,
                          ha="center", va="center", zorder=5,
                          bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none",
                                "alpha": 0.8},
                          arrowprops={"arrowstyle": "-", "lw": 0.6, "color": color})
        anchor = ax.transData.transform(xy)
        best, best_cost = None, np.inf
        for radius in (22, 34, 48, 64, 84, 110):
            for th in angles:
                at = anchor + radius * np.array([np.cos(th), np.sin(th)])
                ann.xyann = tuple(ax.transData.inverted().transform(at))
                box = text_box(ann).expanded(1.05, 1.15)
                cost = sum(_overlap(box, q) for q in placed)
                if not frame.contains(box.x0, box.y0) or not frame.contains(box.x1, box.y1):
                    cost += 1e6
                if cost < best_cost:
                    best, best_cost = at, cost
                if cost == 0:
                    break
            if best_cost == 0:
                break
        ann.xyann = tuple(ax.transData.inverted().transform(best))
        placed.append(text_box(ann))
        out.append(ann)
    return out


def _overlap(a, b) -> float:
    w = min(a.x1, b.x1) - max(a.x0, b.x0)
    h = min(a.y1, b.y1) - max(a.y0, b.y0)
    return w * h if w > 0 and h > 0 else 0.0


def scene_top_view(result, ax=None, path=None, show_clusters: bool = True, *,
                   labels: bool = True, legend: bool = True, start_plane: bool = True,
                   optimized=None, rollout=None, success: dict | None = None):
    """Top-down view (the paper's Fig. 5a): objects (their ids), each task's initial
    space (red), its space after Shrinking (blue) and, given ``optimized`` (Shapes, task
    order), the optimized mode's (purple, dashed); every task's id beside its space,
    with its meta-skill cluster (``K0``, ...) when it has one; the start plane; a legend.
    ``rollout``: ``(start xyz, end xyz, outcome name, label)`` drawn as a line from the
    start to where the rollout ended. ``success``: mode -> success rate, in the title.
    Labels are placed so that none covers another (:func:`_place_labels`).

    :param result: a ``geometry_precompute.PrecomputeResult``.

    Example::

        >>> from geometry_precompute import load_scene, precompute, shipped_scene_paths
        >>> r = precompute(load_scene(shipped_scene_paths()[8]))   # mug behind two
        >>> fig = scene_top_view(r, success={"baseline": 0.61, "shacc": 0.94})
        >>> fig.axes[0].get_xlabel()
        'x (m)'
    """

    from geometry_precompute.bodies import object_body, object_solid  # deferred: 88 ms to import
    from geometry_precompute.starts import start_plane as plane_of  # deferred: 126 ms to import

    own = ax is None
    if own:
        fig, ax = plt.subplots(figsize=(6.4, 4.8))
    else:
        fig = ax.figure
    cluster_of = {i: k for k, c in enumerate(result.meta_clusters()) for i in c}
    kinds = [("init", result.shapes_init), ("shrinking", result.shapes_opt)]
    if optimized is not None:
        kinds.append(("optimized", optimized))
    extent = []
    for kind, shapes in kinds:
        st = SPACE_STYLE[kind]
        for shape in shapes:
            ring = _outline_xy(shape)
            extent.append(ring)
            if kind == "init":
                ax.fill(ring[:, 0], ring[:, 1], color=st["color"], alpha=0.10, lw=0)
            ax.plot(ring[:, 0], ring[:, 1], color=st["color"], lw=st["lw"], ls=st["ls"])
    for o in result.scene.objects:
        if o.mesh is not None:  # a mesh's footprint: the hull of its vertices seen from above
            pts = np.asarray(object_solid(o).vertices)[:, :2]
            ring = pts[ConvexHull(pts).vertices]
            ring = np.vstack([ring, ring[:1]])
        else:
            ring = _outline_xy(object_body(o))
        extent.append(ring)
        ax.fill(ring[:, 0], ring[:, 1], color="k", alpha=0.6, zorder=3)
    handles: list[Artist] = [Patch(fc=SPACE_STYLE["init"]["color"], alpha=0.35,
                     ec=SPACE_STYLE["init"]["color"], label=SPACE_STYLE["init"]["label"])]
    handles += [Line2D([], [], color=SPACE_STYLE[k]["color"], lw=SPACE_STYLE[k]["lw"],
                       ls=SPACE_STYLE[k]["ls"], label=SPACE_STYLE[k]["label"])
                for k, _ in kinds[1:]]
    handles.append(Patch(fc="k", alpha=0.6, label="object"))
    if start_plane:
        x0, (y0, y1), (z0, z1) = plane_of(result.scene, result.settings)
        ax.plot([x0, x0], [y0, y1], color="0.35", lw=3, solid_capstyle="butt")
        extent.append(np.array([[x0, y0], [x0, y1]]))
        handles.append(Line2D([], [], color="0.35", lw=3,
                              label=f"start plane (x {x0:.2f} m, z {z0:.2f}-{z1:.2f} m)"))
    if rollout is not None:
        p0, p1, outcome, text = rollout
        color = OUTCOME_COLORS[_outcome_index(outcome)]
        ax.plot([p0[0], p1[0]], [p0[1], p1[1]], color=color, lw=2, zorder=4)
        ax.plot([p0[0]], [p0[1]], "o", color=color, ms=4, zorder=4)
        ax.plot([p1[0]], [p1[1]], "X", color=color, ms=7, zorder=4)
        extent.append(np.array([p0[:2], p1[:2]]))
        handles.append(Line2D([], [], color=color, lw=2, marker="X", label=text))
    if show_clusters and cluster_of:
        handles.append(Line2D([], [], ls="none", label="K0, K1, ...: meta-skill clusters"))
    pts = np.vstack(extent)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = 0.08 * max(hi - lo) + 0.02
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal", adjustable="box")
    title = f"{result.scene.name}\nC_init {result.C_init:.2f} -> C_final {result.C_final:.2f}"
    if success:
        title += "\nsuccess: " + ", ".join(f"{m} {v:.2f}" for m, v in success.items())
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(alpha=0.3)
    if legend:
        ax.legend(handles=handles, fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0),
                  borderaxespad=0.0, frameon=False)
    if own:
        fig.tight_layout()
    # Object ids on the objects, then task ids beside their spaces, none covering another.
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]  # Agg's
    ax.apply_aspect()
    avoid = []
    for o in result.scene.objects:
        t = ax.text(o.position[0], o.position[1], o.id, fontsize=7, color="w",
                    ha="center", va="center", zorder=6)
        avoid.append(t.get_window_extent(renderer))
    if labels:
        items = []
        for i, (task, shape) in enumerate(zip(result.scene.tasks, result.shapes_init,
                                              strict=True)):
            k = cluster_of.get(i) if show_clusters else None
            items.append((task.id + (f" (K{k})" if k is not None else ""),
                          _label_anchor(result, task, shape), SPACE_STYLE["init"]["color"]
                          if k is None else "#1f3f77"))
        _place_labels(ax, items, avoid)
    elif show_clusters:
        for i, k in cluster_of.items():
            ax.annotate(f"K{k}", result.shapes_opt[i].center[:2], fontsize=7, color="blue",
                        xytext=(6, 6), textcoords="offset points")
    _save(fig, path)
    return fig


def _label_anchor(result, task, shape) -> np.ndarray:
    """Where a task's label points: its space's footprint point farthest from the
    other objects' centroid side, i.e. the rim of its space on the side away from the
    scene's centre (two tasks of one object get different anchors when their spaces
    differ), or the space's centre."""
    ring = _outline_xy(shape)[:-1]
    centre = np.mean([o.position[:2] for o in result.scene.objects], axis=0)
    own = np.asarray(shape.center[:2])
    away = own - centre
    if np.linalg.norm(away) < 1e-6:
        return own
    away /= np.linalg.norm(away)
    return ring[np.argmax((ring - own) @ away)]


def _outcome_index(name: str) -> int:
    from geometry_precompute.schema import OUTCOMES  # deferred: 63 ms to import

    return OUTCOMES.index(name)


def space_shadows_yz(shapes, sections: int = 32) -> list[np.ndarray]:
    """Each space's outline seen from the start plane (its projection onto y-z): the
    convex hull of its mesh vertices, as closed polylines.

    :param shapes: task spaces (``PrecomputeResult.shapes_init`` or ``shapes_opt``).
    :returns: one (k, 2) array of (y, z) in m per space, its first point repeated last.

    Example::

        >>> from geometry_precompute import load_scene, precompute, shipped_scene_paths
        >>> r = precompute(load_scene(shipped_scene_paths()[8]))   # mug behind two
        >>> rings = space_shadows_yz(r.shapes_init)
        >>> len(rings) == len(r.spaces), rings[0].shape[1]
        (True, 2)
    """
    from geometry_precompute.meshes import shape_trimesh  # deferred: 75 ms to import

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
    (modes + 1) x tasks Axes (row by row).

    :param outcome: (M, N, T) outcome codes; ``delta_r``: (N, T) ShaCC's delta_R (rad).
    :param result: the scene's ``PrecomputeResult`` (its spaces are drawn).

    Example::

        >>> import numpy as np
        >>> from geometry_precompute import load_scene, precompute, shipped_scene_paths
        >>> r = precompute(load_scene(shipped_scene_paths()[8]))   # mug behind two
        >>> T = len(r.spaces)
        >>> fig = success_fields_with_spaces(np.zeros((1, 16, T), int), np.zeros((16, T)),
        ...                                  (4, 4), (-0.4, 0.4), (0.05, 0.4), r, ["shacc"])
    """
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
    ``ax``: one Axes per scene.

    :param results: ``PrecomputeResult``s, drawn ``columns`` to a row.

    Example::

        >>> from geometry_precompute import load_scene, precompute, shipped_scene_paths
        >>> results = [precompute(load_scene(p)) for p in shipped_scene_paths()[:2]]
        >>> fig = scene_gallery(results, columns=2)
    """
    if ax is None:
        rows = -(-len(results) // columns)
        fig, grid = plt.subplots(rows, columns, figsize=(3.3 * columns, 3.4 * rows),
                                 squeeze=False)
        axes = list(grid.ravel())
    else:
        fig, axes = _figure(ax, len(results))
    for a, r in zip(axes, results, strict=False):
        scene_top_view(r, ax=a, labels=False, legend=False, start_plane=False)
    for a in axes[len(results):]:
        a.axis("off")
    if ax is None:
        fig.tight_layout()
    return _save(fig, path)


def swept_axes(scenes_df, exclude: Sequence[str] = ()) -> list[str]:
    """The settings a sweep's scenes table varies (``set.NAME`` columns with more than
    one value), by name.

    :param scenes_df: a sweep's ``scenes`` table as a pandas DataFrame.
    :param exclude: setting names to leave out.

    Example::

        >>> import pandas as pd
        >>> df = pd.DataFrame({"set.v_max": [0.5, 1.0], "set.dt": [0.02, 0.02]})
        >>> swept_axes(df)
        ['v_max']
    """
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
    the mean over scenes with a 95 % bootstrap CI over scenes (``sweeps.analysis.stats``).
    ``axis`` is a setting name (the table's column ``set.<axis>``).

    The other settings the sweep varies are never pooled silently: with ``others =
    "lines"`` each combination of their values is a line of its own (colour per mode,
    line style per combination); with ``"marginalise"`` one line per mode averages each
    scene over the other settings first and resamples the scenes as clusters, which
    the title says. Both give scene-level intervals.

    :param scenes_df: a sweep's ``scenes`` table (``scene_index``, ``set.<axis>`` and
        ``<mode>.<metric>`` columns), one row per scene and point.

    Example::

        >>> import pandas as pd
        >>> df = pd.DataFrame({"scene_index": [0, 1, 2, 0, 1, 2],
        ...                    "set.v_max": [0.5, 0.5, 0.5, 1.0, 1.0, 1.0],
        ...                    "shacc.success": [0.9, 0.8, 0.7, 0.8, 0.6, 0.7]})
        >>> fig = sweep_lines(df, "v_max", "success", ["shacc"], n_resamples=200)
        >>> fig.axes[0].get_xlabel()
        'v_max'
    """
    from sweeps.analysis.stats import group_means  # deferred: 1.9 s to import

    col = f"set.{axis}"
    df = scenes_df.copy()
    other = swept_axes(df, exclude=[axis])
    df["_x"] = df[col].map(lambda v: float(v) if _is_number(v) else _label(v))
    df["_combo"] = df[[f"set.{o}" for o in other]].apply(
        lambda r: ", ".join(f"{o}={_label(v)}" for o, v in zip(other, r, strict=True)), axis=1) \
        if other and others == "lines" else ""
    fig, (a,) = _figure(ax, 1, (6.4, 3.6))
    styles = ["-", "--", ":", "-."]
    combos = sorted(df["_combo"].unique())
    # The modes' points are set a little apart along x (a fiftieth of the smallest gap
    # between values), so that modes with equal means stay visible side by side.
    numeric = _numeric_column(df["_x"])
    values = np.unique(df["_x"].to_numpy(float)) if numeric else np.zeros(1)
    gap = float(np.diff(values).min()) if len(values) > 1 else 1.0
    for k_mode, mode in enumerate(modes):
        shift = (k_mode - (len(modes) - 1) / 2) * gap / 50
        for k, combo in enumerate(combos):
            g = df[df["_combo"] == combo]
            pts = group_means(g, ["_x"], f"{mode}.{metric}", n_resamples, seed,
                              marginalise=other if others == "marginalise" else None)
            xs = np.array([p["_x"] for p in pts], float) + shift if numeric else \
                np.array([p["_x"] for p in pts], object)
            ms = np.array([np.nan if p["mean"] is None else p["mean"] for p in pts])
            lo = np.array([m if p["ci"] is None else p["ci"][0]
                           for p, m in zip(pts, ms, strict=True)])
            hi = np.array([m if p["ci"] is None else p["ci"][1]
                           for p, m in zip(pts, ms, strict=True)])
            label = mode if not combo else f"{mode}, {combo}"
            a.errorbar(xs, ms, yerr=[ms - lo, hi - ms], marker=MODE_MARKERS.get(mode, "o"),
                       ms=5, mfc="none" if k_mode % 2 else None, capsize=3, label=label,
                       color=MODE_COLORS.get(mode), ls=styles[k % len(styles)])
    a.set_xlabel(axis)
    a.set_ylabel(metric)
    if other and others == "marginalise":
        a.set_title(f"mean over {', '.join(other)} (scenes resampled as clusters)",
                    fontsize=8)
    # The legend beside the axes, never over the data.
    a.legend(fontsize=7 if len(combos) > 1 else 8, loc="upper left",
             bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    a.grid(alpha=0.3)
    if ax is None:
        fig.tight_layout()
    return _save(fig, path)


def _numeric_column(column) -> bool:
    """Whether every value of a column of setting values is a number."""
    return all(isinstance(v, (int, float, np.integer, np.floating)) for v in column)


def sweep_heatmap(scenes_df, axis_x: str, axis_y: str, metric: str, mode: str, path=None,
                  ax=None, scale: tuple[float, float] | None = (0.0, 1.0),
                  minus: str | None = None):
    """Mean ``metric`` of ``mode`` over scenes at each point of a two-axis sweep (each
    cell one point: its own scenes). Other swept settings must be fixed first (a
    table with repeated scenes in a cell is refused).

    The colour scale is fixed (``scale``, 0 to 1 by default: success rates), so that
    two pictures compare and a small difference is not drawn as the whole range;
    ``None`` spans the data. With ``minus`` (another mode) each cell is the mean over
    scenes of the paired difference ``mode - minus``, on a diverging scale centred on
    0 (red: ``mode`` worse, blue: better) and symmetric around it. The colour bar's
    limits are the image's (``fig.axes[0].images[0].get_clim()``).

    :param scenes_df: a sweep's ``scenes`` table; ``axis_x``, ``axis_y``: setting names.

    Example::

        >>> import pandas as pd
        >>> df = pd.DataFrame({"scene_index": [0, 0, 0, 0],
        ...                    "set.v_max": [0.5, 1.0, 0.5, 1.0],
        ...                    "set.dt": [0.01, 0.01, 0.02, 0.02],
        ...                    "shacc.success": [0.9, 0.8, 0.8, 0.7]})
        >>> fig = sweep_heatmap(df, "v_max", "dt", "success", "shacc")
        >>> fig.axes[0].get_title(), fig.axes[0].images[0].get_clim()
        ('shacc: success', (0.0, 1.0))
    """
    df = scenes_df.copy()
    for a_ in (axis_x, axis_y):
        df[a_] = df[f"set.{a_}"].map(lambda v: float(v) if _is_number(v) else _label(v))
    if df.duplicated([axis_x, axis_y, "scene_index"]).any():
        rest = ", ".join(swept_axes(scenes_df, [axis_x, axis_y]))
        raise ValueError(f"cells of {axis_x} x {axis_y} repeat scenes: select one value of "
                         f"the other swept settings ({rest}) first")
    value = df[f"{mode}.{metric}"]
    if minus is not None:
        value = value - df[f"{minus}.{metric}"]
    table = df.assign(_v=value).pivot_table(index=axis_y, columns=axis_x, values="_v",
                                            aggfunc="mean")
    grid = table.to_numpy(float)
    if minus is not None:  # symmetric around 0, in steps of 0.05 (at least +-0.05)
        reach = float(np.nanmax(np.abs(grid))) if np.isfinite(grid).any() else 0.0
        limit = max(0.05, float(np.ceil(reach / 0.05 - 1e-9)) * 0.05)
        vmin, vmax, cmap = -limit, limit, "RdBu"
    elif scale is not None:
        (vmin, vmax), cmap = scale, "viridis"
    else:
        vmin, vmax, cmap = float(np.nanmin(grid)), float(np.nanmax(grid)), "viridis"
    fig, (a,) = _figure(ax, 1, (5.6, 4.0))
    im = a.imshow(grid, origin="lower", cmap=cmap, vmin=vmin, vmax=vmax, aspect="auto")
    a.set_xticks(range(table.shape[1]), [_label(v) for v in table.columns])
    a.set_yticks(range(table.shape[0]), [_label(v) for v in table.index])
    for (i, j), v in np.ndenumerate(grid):
        r, g_, b, _ = im.cmap(im.norm(v))  # dark text on light cells, light on dark
        light = 0.299 * r + 0.587 * g_ + 0.114 * b > 0.55
        a.text(j, i, f"{v:+.3f}" if minus else f"{v:.3f}", ha="center", va="center",
               color="#222" if light else "w", fontsize=8)
    a.set_xlabel(axis_x)
    a.set_ylabel(axis_y)
    a.set_title(f"{mode} - {minus}: {metric}" if minus else f"{mode}: {metric}")
    fig.colorbar(im, ax=a)
    if ax is None:
        fig.tight_layout()
    return _save(fig, path)


def assistance_bars(shares: dict, kinds: Sequence[str], path=None, ax=None):
    """Per mode, the share of the approaches' steps under each kind of assistance, as
    one stacked horizontal bar (a row per mode; the shares of a mode sum to 1).

    :param shares: mode -> {kind: share}; ``kinds``: the order of the stack.

    Example::

        >>> fig = assistance_bars({"baseline": {"none": 0.7, "scene": 0.0},
        ...                        "shacc": {"none": 0.5, "scene": 0.2}},
        ...                       ["none", "scene"])
    """
    modes = list(shares)
    fig, (a,) = _figure(ax, 1, (6.4, 0.5 * len(modes) + 1.4))
    colors = ["#d9d9d9", "#2ca02c", "#1f77b4", "#d62728", "#9467bd", "#8c564b"]
    left = np.zeros(len(modes))
    for k, kind in enumerate(kinds):
        v = np.array([float(shares[m].get(kind) or 0.0) for m in modes])
        a.barh(range(len(modes)), v, left=left, color=colors[k % len(colors)], label=kind,
               edgecolor="white")
        left += v
    a.set_yticks(range(len(modes)), modes)
    a.invert_yaxis()
    a.set_xlim(0, 1)
    a.set_xlabel("share of the approaches' steps")
    a.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0,
             title="assistance", title_fontsize=8)
    if ax is None:
        fig.tight_layout()
    return _save(fig, path)


def _is_number(v) -> bool:
    try:
        float(v)
    except (TypeError, ValueError):
        return False
    return True
