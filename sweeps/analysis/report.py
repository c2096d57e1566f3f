"""``shacc report DIR|FILE``: one self-contained HTML page of a sweep folder or of an
``evaluate --json`` file, figures embedded, for a browser, a lab notebook or a paper's
supplement.

For a sweep: per point and mode the mean success and delta_R over scenes with 95 %
bootstrap CIs over scenes; the paired differences between modes (ShaCC and Shrinking
against the baseline, the optimized mode against Shrinking) per point; the tasks by
template and object kind; every swept setting against success (the other settings
never pooled: a line per combination, or averaged within each scene and said so when
there are many); a heat map over the first two swept settings; and the provenance (the
command, the versions, the devices). For an evaluate file: a row per scene and mode,
a row per task, the paired mode differences over the scenes, and the provenance.

Intervals use ``REPORT_RESAMPLES`` bootstrap resamples (the page says so). The page
loads nothing from outside; a small script only counts the figures that decoded, into
``data-figures-loaded`` on its body, for the browser test.
"""

from __future__ import annotations

import base64
import html
import io
import json
from pathlib import Path
from typing import Any

import numpy as np

from sweeps.analysis.stats import group_means, mean_ci, paired_diff_ci

REPORT_RESAMPLES = 2000
PAIRS = (("baseline", "shrinking"), ("baseline", "shacc"), ("shrinking", "shacc"),
         ("shrinking", "optimized"))

STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1100px;
       color: #222; line-height: 1.4; }
h1 { font-size: 1.6em; } h2 { font-size: 1.25em; margin-top: 1.8em; }
table { border-collapse: collapse; margin: 0.6em 0; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }
th { background: #f2f2f2; } td.l, th.l { text-align: left; }
figure { margin: 1em 0; } figure img { max-width: 100%; border: 1px solid #eee; }
.note { color: #555; font-size: 0.9em; }
pre { background: #f6f6f6; padding: 0.6em; overflow-x: auto; font-size: 0.85em; }
"""

SCRIPT = """
window.addEventListener("load", function () {
  var imgs = Array.prototype.slice.call(document.images);
  var ok = imgs.filter(function (i) { return i.complete && i.naturalWidth > 0; });
  document.body.dataset.figuresLoaded = String(ok.length);
  document.body.dataset.figures = String(imgs.length);
});
"""


def _e(v) -> str:
    return html.escape(str(v))


def _fmt(v, digits: int = 3) -> str:
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "n/a"
    return f"{v:.{digits}f}"


def _ci(e: dict, digits: int = 3, signed: bool = False) -> str:
    if e is None or e.get("mean") is None:
        return "n/a"
    f = f"{{:{'+' if signed else ''}.{digits}f}}"
    text = f.format(e["mean"])
    if e.get("ci"):
        text += " [" + ", ".join(f.format(v) for v in e["ci"]) + "]"
    return text


def _table(head: list[str], rows: list[list], left: int = 1, cls: str = "") -> str:
    out = [f'<table class="{cls}"><tr>' + "".join(
        f'<th class="{"l" if i < left else ""}">{_e(h)}</th>' for i, h in enumerate(head))
        + "</tr>"]
    for r in rows:
        out.append("<tr>" + "".join(f'<td class="{"l" if i < left else ""}">{_e(c)}</td>'
                                    for i, c in enumerate(r)) + "</tr>")
    return "\n".join(out) + "</table>"


def _figure(fig, caption: str) -> str:
    import matplotlib.pyplot as plt  # deferred: 1.2 s to import

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    plt.close(fig)
    data = base64.b64encode(buf.getvalue()).decode()
    return (f'<figure><img alt="{_e(caption)}" src="data:image/png;base64,{data}">'
            f"<figcaption>{_e(caption)}</figcaption></figure>")


def _page(title: str, body: list[str]) -> str:
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{_e(title)}</title><style>{STYLE}</style></head><body>"
            f"<h1>{_e(title)}</h1>\n" + "\n".join(body)
            + f"<script>{SCRIPT}</script></body></html>\n")


def _provenance_section(prov) -> str:
    return ("<h2>Provenance</h2><pre>" + _e(json.dumps(prov, indent=1, default=str))
            + "</pre>")


def _paired_rows(frame, modes, by_point: bool, n_boot: int) -> list[list]:
    rows = []
    points = sorted(frame["point"].unique()) if by_point else [None]
    for p in points:
        g = frame if p is None else frame[frame["point"] == p]
        for a, b in PAIRS:
            if a not in modes or b not in modes:
                continue
            for metric, digits in (("success", 3), ("delta_R_mean", 3)):
                d = paired_diff_ci(g[f"{a}.{metric}"].to_numpy(float),
                                   g[f"{b}.{metric}"].to_numpy(float), n_boot)
                rows.append(([] if p is None else [p]) + [f"{b} - {a}", metric,
                                                          _ci(d, digits, True), d["n"]])
    return rows


def sweep_report(folder: Path, n_boot: int = REPORT_RESAMPLES) -> str:
    import pandas as pd  # deferred: 1.0 s to import

    from sweeps.analysis import plots  # deferred: 1.4 s to import
    from sweeps.analysis.compare import read_scenes_table  # deferred: 8 ms to import

    scenes = read_scenes_table(folder)
    config = {}
    try:
        config = json.loads((folder / "config.json").read_text())
    except (OSError, ValueError):
        pass
    modes = [c.split(".")[0] for c in scenes.columns if c.endswith(".success")]
    axes = plots.swept_axes(scenes)
    n_points = scenes["point"].nunique()
    body = [f'<p class="note">{len(scenes)} scene rows, {n_points} '
            f'point{"s" if n_points != 1 else ""}, '
            f"modes {', '.join(modes)}. Every interval is a 95 % percentile bootstrap over "
            f"scenes ({n_boot} resamples); a difference of two modes is paired (per-scene "
            "differences resampled).</p>"]
    # Per point and mode.
    rows = []
    point_cols = [c for c in scenes.columns if c.startswith("set.")]
    first = scenes.drop_duplicates("point").set_index("point")
    # The same success intervals, drawn below when there are few points.
    bars: dict[str, dict[str, Any]] = {}
    for p, g in scenes.groupby("point", sort=True):
        label = ", ".join(f"{c[4:]}={plots._label(first.loc[p, c])}" for c in point_cols
                          if c[4:] in axes) or "-"
        bars[f"point {p}"] = {"n_scenes": len(g)}
        for mode in modes:
            success = group_means(g, ["point"], f"{mode}.success", n_boot)[0]
            bars[f"point {p}"][mode] = {"success": success}
            rows.append([p, label, mode, _ci(success),
                         _ci(group_means(g, ["point"], f"{mode}.delta_R_mean", n_boot)[0]),
                         len(g)])
    body += ["<h2>Success and delta_R per point and mode</h2>",
             _table(["point", "settings", "mode", "success [95 % CI]",
                     "delta_R (rad) [95 % CI]", "scenes"], rows, left=3, cls="modes")]
    if n_points <= 8:
        body.append(_figure(plots.category_bars(bars, "success", modes, ylabel="mean success"),
                            "mean success per point and mode (95 % CI over scenes)"))
    body += ["<h2>Paired differences between modes</h2>",
             _table(["point", "difference", "metric", "mean [95 % CI]", "scenes"],
                    _paired_rows(scenes, modes, True, n_boot), left=3, cls="paired")]
    body += _how_long_sweep(scenes, modes, n_boot)
    body += _drawn_sweep(folder, modes, n_boot)
    # Tasks, by template and object kind (the scenes' own task ids differ).
    if (folder / "tasks").is_dir():
        tasks = pd.read_parquet(folder / "tasks")
        rows = []
        for (template, kind), g in tasks.groupby(["template", "object_kind"], sort=True):
            for mode in modes:
                per_scene = g.groupby(["point", "scene_index"])[f"{mode}.success"].mean()
                frame = per_scene.reset_index()
                e = group_means(frame.assign(all=0), ["all"], f"{mode}.success", n_boot,
                                marginalise=["point"] if frame["point"].nunique() > 1 else None)[0]
                rows.append([template, kind, mode, _ci(e), len(g)])
        body += ["<h2>Tasks by template</h2>", '<p class="note">Success of the tasks of one '
                 "template (averaged within each scene, scenes resampled; over all points)."
                 "</p>", _table(["template", "object", "mode", "success [95 % CI]", "tasks"],
                                rows, left=3, cls="tasks")]
    # Every axis, and a heat map over two.
    if axes:
        body.append("<h2>Swept settings</h2>")
        for axis in axes:
            others = plots.swept_axes(scenes, exclude=[axis])
            combos = scenes[[f"set.{o}" for o in others]].astype(str).drop_duplicates() \
                if others else []
            how = "lines" if len(combos) <= 4 else "marginalise"
            fig = plots.sweep_lines(scenes, axis, "success", modes, n_resamples=n_boot,
                                    others=how)
            if not others:
                caption = f"success against {axis}"
            elif how == "lines":
                caption = (f"success against {axis} (a line per combination of "
                           f"{', '.join(others)})")
            else:
                caption = (f"success against {axis} (averaged within each scene over "
                           f"{', '.join(others)})")
            body.append(_figure(fig, caption))
        if len(axes) >= 2:
            x, y = axes[:2]
            sel = scenes
            fixed = []
            for o in axes[2:]:
                v = sel[f"set.{o}"].map(plots._label).iloc[0]
                sel = sel[sel[f"set.{o}"].map(plots._label) == v]
                fixed.append(f"{o}={v}")
            mode = "shacc" if "shacc" in modes else modes[-1]
            fig = plots.sweep_heatmap(sel, x, y, "success", mode)
            body.append(_figure(fig, f"{mode} success over {x} and {y}"
                                + (f" ({', '.join(fixed)})" if fixed else "")))
    body.append(_provenance_section({"config": config.get("provenance"),
                                     "config_hash": config.get("hash"),
                                     "evaluated_on": _part_provenance(folder)}))
    name = (config.get("config") or {}).get("name") or folder.name
    return _page(f"Sweep {name}", body)


HOW_LONG_NOTE = ("the mean time to activation (s) and path length (m) of the successful "
                 "approaches, and the share of the approaches' steps under each kind of "
                 "assistance (none; scene: the meta skill; correct and wrong: assistance "
                 "towards the intended or another task)")


DRAWN_NOTE = ("The approaches binned by quartiles of each drawn user setting; per bin the "
              "mean over scenes of each scene's success in it, and the paired difference "
              "to the baseline (95 % CI over scenes).")


def _drawn_table(entry: dict, modes: list[str], lead: str = "") -> str:
    """One drawn parameter's bins (success per mode, difference to the baseline) and its
    sentence."""
    others = [m for m in modes if m != "baseline"]
    return _table(["bin"] + [f"{m} success" for m in modes]
                  + [f"{m} - baseline" for m in others],
                  [[r["level"]] + [_ci(r["modes"][m]["u_scene"]) for m in modes]
                   + [_ci(r["vs_baseline"][m], 3, True) for m in others]
                   for r in entry["rows"]], left=1, cls="drawn") + \
        f'<p>{_e(lead + entry["sentence"])}</p>'


def _how_long_sweep(scenes, modes: list[str], n_boot: int) -> list[str]:
    """Per point and mode: time, path and the assistance shares, each the mean over
    scenes with its CI (empty for a dataset written before these columns)."""
    from geometry_precompute.schema import ASSISTANCE  # deferred: 20 ms to import

    cols = ["time_mean", "path_length_mean"] + [f"assist_{k}" for k in ASSISTANCE]
    if not all(f"{m}.{c}" in scenes.columns for m in modes for c in cols):
        return []
    rows = []
    for p, g in scenes.groupby("point", sort=True):
        for mode in modes:
            rows.append([p, mode] + [_ci(group_means(g, ["point"], f"{mode}.{c}", n_boot)[0],
                                         2 if c == "time_mean" else 3) for c in cols])
    return ["<h2>How long, and how assisted</h2>",
            f'<p class="note">Per point and mode: {HOW_LONG_NOTE}; each the mean over '
            "scenes [95 % CI].</p>",
            _table(["point", "mode", "time (s)", "path (m)"]
                   + [f"assisted: {k}" for k in ASSISTANCE], rows, left=2, cls="time")]


def _drawn_sweep(folder: Path, modes: list[str], n_boot: int) -> list[str]:
    """Success against the drawn users of a sweep with a population: per point,
    :func:`sweeps.analysis.robustness.drawn` of its rollouts table."""
    import pyarrow.dataset as ds  # deferred: 0.2 s to import

    from geometry_precompute.population import POPULATED  # deferred: 20 ms to import
    from geometry_precompute.schema import OUTCOMES  # deferred: 20 ms to import
    from sweeps.analysis.robustness import drawn  # deferred: the pipeline's import

    if not (folder / "rollouts").is_dir() or "baseline" not in modes or len(modes) < 2:
        return []
    data = ds.dataset(folder / "rollouts", format="parquet")
    names = [n for n in POPULATED if n in data.schema.names]
    if not names:
        return []
    table = data.to_table(columns=["point", "scene_index", "mode", "start", "task",
                                   "outcome", *names]).to_pandas()
    code = {o: i for i, o in enumerate(OUTCOMES)}
    out: list[str] = []
    for p, g in table.groupby("point", sort=True):
        g = g[g["mode"].astype(str).isin(modes)]
        scene = g["scene_index"].to_numpy()
        si = np.unique(scene, return_inverse=True)[1]
        S, N, T = si.max() + 1, g["start"].max() + 1, g["task"].max() + 1
        mi = g["mode"].astype(str).map({m: i for i, m in enumerate(modes)}).to_numpy()
        n, t = g["start"].to_numpy(), g["task"].to_numpy()
        outcome = np.full((S, len(modes), N, T), -1, np.int8)
        outcome[si, mi, n, t] = g["outcome"].astype(str).map(code).to_numpy()
        user = np.zeros((S, len(modes), N, T, len(POPULATED)))
        for name in names:
            user[si, mi, n, t, POPULATED.index(name)] = g[name].to_numpy(float)
        mask = np.zeros((S, T), bool)
        mask[si, t] = True
        for entry in drawn(outcome, user, mask, modes, n_boot).values():
            out.append(_drawn_table(entry, modes, f"point {p}: "))
    if not out:
        return []
    return ["<h2>Success against the drawn users</h2>", f'<p class="note">{DRAWN_NOTE}</p>',
            *out]


def _part_provenance(folder: Path) -> list:
    import pyarrow.parquet as pq  # deferred: 100 ms to import

    seen = []
    for part in sorted((folder / "scenes").glob("part-*.parquet"))[:50]:
        meta = pq.read_schema(part).metadata or {}
        prov = meta.get(b"shacc.provenance")
        if prov:
            p = json.loads(prov)
            if p not in seen:
                seen.append(p)
    return seen


def _drawn_json(lines: list[dict], modes: list[str], n_boot: int) -> dict:
    """:func:`sweeps.analysis.robustness.drawn` of the scenes of an ``evaluate --json``
    file that drew their users from a population (tasks padded to the longest scene)."""
    from geometry_precompute.population import POPULATED  # deferred: 20 ms to import
    from geometry_precompute.schema import OUTCOMES  # deferred: 20 ms to import
    from sweeps.analysis.robustness import drawn  # deferred: the pipeline's import

    with_users = [d for d in lines if d.get("users") and all(m in d["modes"] for m in modes)]
    if not with_users or "baseline" not in modes or len(modes) < 2:
        return {}
    names = list(with_users[0]["users"])
    shapes = [np.shape(d["modes"][modes[0]]["outcome"]) for d in with_users]
    N, T = max(n for n, _ in shapes), max(t for _, t in shapes)
    S, M = len(with_users), len(modes)
    code = {o: i for i, o in enumerate(OUTCOMES)}
    outcome = np.full((S, M, N, T), -1, np.int8)
    user = np.zeros((S, M, N, T, len(POPULATED)), float)
    mask = np.zeros((S, T), bool)
    for s, (d, (n, t)) in enumerate(zip(with_users, shapes, strict=True)):
        mask[s, :t] = True
        for m, mode in enumerate(modes):
            outcome[s, m, :n, :t] = [[code[o] for o in row] for row in d["modes"][mode]["outcome"]]
        for name in names:
            if name in POPULATED:
                user[s, :, :n, :t, POPULATED.index(name)] = np.asarray(d["users"][name], float)
    return drawn(outcome, user, mask, modes, n_boot)


def evaluate_report(path: Path, n_boot: int = REPORT_RESAMPLES) -> str:
    import pandas as pd  # deferred: 1.0 s to import

    from geometry_precompute.schema import ASSISTANCE  # deferred: 20 ms to import
    from sweeps.analysis.compare import json_rows, read_evaluate_json  # deferred: 8 ms to import

    lines = read_evaluate_json(path)
    scenes_rows, task_rows = json_rows(lines)
    frame = pd.DataFrame(scenes_rows)
    modes = list(dict.fromkeys(frame["mode"]))
    wide = frame.pivot_table(index="key", columns="mode", values=["success", "delta_R_mean"],
                             aggfunc="first")
    wide.columns = [f"{m}.{v}" for v, m in wide.columns]
    wide = wide.reset_index().assign(point=0)
    body = [f'<p class="note">{len(lines)} scenes, modes {", ".join(modes)}.</p>',
            "<h2>Per scene</h2>",
            _table(["scene", "C_init", "C_final"]
                   + [f"{m} {what}" for m in modes for what in ("success", "delta_R (rad)")],
                   [[d["scene"], _fmt(d["clutteredness"]["init"]),
                     _fmt(d["clutteredness"]["final"])]
                    + [_fmt(d["modes"].get(m, {}).get(k)) for m in modes
                       for k in ("success_rate", "delta_R_mean")] for d in lines],
                   left=1, cls="modes")]
    per_scene = [[d["scene"], m, _fmt(e.get("time_to_activation_mean"), 2),
                  _fmt(e.get("path_length_mean"))]
                 + [_fmt((e.get("assistance") or {}).get(k)) for k in ASSISTANCE]
                 for d in lines for m, e in d["modes"].items()]
    if len(lines) > 1:  # each measure's mean over the scenes, with its interval
        for m in modes:
            es = [d["modes"][m] for d in lines if m in d["modes"]]
            values = [[e.get("time_to_activation_mean") for e in es],
                      [e.get("path_length_mean") for e in es]] + \
                     [[(e.get("assistance") or {}).get(k) for e in es] for k in ASSISTANCE]
            per_scene.append(["all scenes", m] + [
                _ci(mean_ci(np.array(v, dtype=float), n_boot), 2 if i == 0 else 3)
                for i, v in enumerate(values)])
    body += ["<h2>How long, and how assisted</h2>",
             f'<p class="note">Per scene and mode: {HOW_LONG_NOTE}; over all scenes, '
             "the mean over scenes [95 % CI].</p>",
             _table(["scene", "mode", "time (s)", "path (m)"]
                    + [f"assisted: {k}" for k in ASSISTANCE], per_scene, left=2, cls="time")]
    drawn_section = _drawn_json(lines, modes, n_boot)
    if drawn_section:
        body += ["<h2>Success against the drawn users</h2>", f'<p class="note">{DRAWN_NOTE}</p>']
        body += [_drawn_table(entry, modes) for entry in drawn_section.values()]
    if task_rows:
        body += ["<h2>Per task</h2>", _table(
            ["scene", "task", "template", "object"] + [f"{m} success" for m in modes],
            [[d["scene"], t["id"], t["template"], t.get("object_kind", "")]
             + [_fmt(t["modes"].get(m, {}).get("success_rate")) for m in modes]
             for d in lines for t in d.get("tasks_detail", [])],
            left=4, cls="tasks")]
    if len(lines) > 1:
        body += ["<h2>Paired differences between modes, over the scenes</h2>",
                 _table(["difference", "metric", "mean [95 % CI]", "scenes"],
                        _paired_rows(wide, modes, False, n_boot), left=2, cls="paired")]
        from sweeps.analysis import plots  # deferred: 1.4 s to import

        means = {"all scenes": {"n_scenes": len(lines), **{
            m: {"success": mean_ci(wide[f"{m}.success"].dropna().to_numpy(float), n_boot)}
            for m in modes}}}
        fig = plots.category_bars(means, "success", modes, ylabel="mean success")
        body.append(_figure(fig, "mean success per mode (95 % CI over scenes)"))
    body.append(_provenance_section({d["scene"]: d.get("provenance") for d in lines[:1]}))
    return _page(f"Evaluation {path.name}", body)
