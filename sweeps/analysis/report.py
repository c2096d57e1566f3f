"""``shacc report DIR|FILE``: one self-contained HTML page of a sweep folder or of an
``evaluate --json`` file, figures embedded, for a lab meeting, a lab notebook or a
paper's supplement.

The page reads top down as a talk would: a headline (one sentence per comparison that
matters: ShaCC and Shrinking against the baseline, the optimized mode against
Shrinking, each a paired difference of success over scenes with its 95 % interval and
what it says), then the figures (success per point and mode; the share of steps under
each assistance; every swept setting against success, the other settings never pooled:
a line per combination, or averaged within each scene and said so when there are many;
over the first two swept settings a heat map of ShaCC's success on a fixed 0-1 scale
and one of its difference to the baseline on a diverging scale centred on 0), then the
tables (per point and mode; the paired differences; time, path and assistance; the
drawn users when the run drew them; the tasks by template), long ones folded, and the
provenance (the command, the versions, the devices) last.

Every figure is at least ``FIGURE_WIDTH`` pixels wide, its legend outside the axes; the
modes' lines carry markers and are set a little apart so that equal ones stay visible.
Intervals use ``REPORT_RESAMPLES`` bootstrap resamples (the page says so). The page is
rendered from the Jinja2 template ``templates/report.html`` and loads nothing from
outside; a small script counts the figures that decoded and the narrowest one's width,
into ``data-figures-loaded`` and ``data-narrowest-figure`` on its body, for the browser
test.
"""

from __future__ import annotations

import base64
import io
import json
from pathlib import Path
from typing import Any

import numpy as np

from sweeps.analysis.stats import group_means, mean_ci, paired_diff_ci

REPORT_RESAMPLES = 2000
PAIRS = (("baseline", "shrinking"), ("baseline", "shacc"), ("shrinking", "shacc"),
         ("shrinking", "optimized"), ("baseline", "blend"), ("baseline", "ho"),
         ("shacc", "shacc_ho"), ("ho", "shacc_ho"))
# The comparisons the headline states (new against old), in this order: the paper's,
# then intent inference against the baseline and ShaCC combined with it against each
# part.
HEADLINE_PAIRS = (("baseline", "shacc"), ("baseline", "shrinking"), ("shrinking", "optimized"),
                  ("baseline", "blend"), ("baseline", "ho"), ("shacc", "shacc_ho"),
                  ("ho", "shacc_ho"))
MODE_NAMES = {"baseline": "the baseline", "shrinking": "Shrinking", "shacc": "ShaCC",
              "optimized": "the optimized mode", "blend": "blending",
              "ho": "hindsight optimization", "shacc_ho": "ShaCC with hindsight optimization"}
FIGURE_WIDTH = 760  # px: the narrowest a figure is embedded (its natural width)
PAGE_WIDTH = 1000  # px: the text column
FOLD_ROWS = 12  # tables longer than this are folded (<details>)
INTERVALS = ("Every interval is a 95 % percentile bootstrap over scenes ({n} resamples); "
             "a difference of two modes is paired (the per-scene differences are "
             "resampled).")


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


def _table(head: list[str], rows: list[list], left: int = 1, cls: str = "",
           sentence: str = "") -> dict:
    return {"head": head, "rows": [[str(c) for c in r] for r in rows], "left": left,
            "cls": cls, "sentence": sentence}


def _section(title: str, tables: list[dict], note: str = "") -> dict:
    return {"title": title, "note": note, "tables": tables}


def _png_width(png: bytes) -> int:
    return int.from_bytes(png[16:20], "big")  # the IHDR chunk's width


def _figure(fig, caption: str) -> dict:
    """The figure as an embedded PNG at least ``FIGURE_WIDTH`` pixels wide (made wider
    and saved again when its tight bounding box came out narrower), with its colour
    scale when it is a heat map."""
    import matplotlib.pyplot as plt  # deferred: 1.2 s to import

    scale = cmap = None
    if fig.axes and fig.axes[0].images:
        image = fig.axes[0].images[0]
        scale = tuple(float(v) for v in image.get_clim())
        cmap = image.get_cmap().name
    for _ in range(3):
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=100, bbox_inches="tight")
        png = buf.getvalue()
        if _png_width(png) >= FIGURE_WIDTH:
            break
        # Wider, not enlarged: the text keeps its size and the axes get the room.
        w, h = fig.get_size_inches()
        fig.set_size_inches(w * FIGURE_WIDTH / _png_width(png) * 1.03, h)
        fig.tight_layout()
    plt.close(fig)
    return {"data": base64.b64encode(png).decode(), "caption": caption,
            "width": _png_width(png), "scale": scale, "cmap": cmap}


def _page(title: str, summary: str, headline: list[str], figures: list[dict],
          sections: list[dict], provenance: Any, n_boot: int) -> str:
    import jinja2  # deferred: 40 ms to import

    env = jinja2.Environment(loader=jinja2.PackageLoader("sweeps.analysis", "templates"),
                             autoescape=True, keep_trailing_newline=True)
    return env.get_template("report.html").render(
        title=title, summary=summary, headline=headline, figures=figures,
        sections=sections, provenance=json.dumps(provenance, indent=1, default=str),
        intervals=INTERVALS.format(n=n_boot), fold_rows=FOLD_ROWS,
        figure_width=FIGURE_WIDTH, page_width=PAGE_WIDTH,
        no_headline="Only one mode was evaluated: there is no comparison to state.")


def headline_sentences(per_scene: dict[str, np.ndarray], modes: list[str], n_boot: int,
              over: str = "") -> list[str]:
    """One sentence per comparison that matters: the paired difference of success over
    scenes, its interval and what it says; first the modes' own success.

    :param per_scene: mode -> (S,) success per scene (averaged over points first).
    :param over: how the scenes' values were made (", averaged over 4 points")."""
    n = len(next(iter(per_scene.values())))
    lines = ["Success over " + (f"{n} scenes" if n != 1 else "one scene") + over + ": "
             + ", ".join(f"{MODE_NAMES.get(m, m)} {_ci(mean_ci(per_scene[m], n_boot))}"
                         for m in modes) + "."]
    for a, b in HEADLINE_PAIRS:
        if a not in modes or b not in modes:
            continue
        d = paired_diff_ci(per_scene[a], per_scene[b], n_boot)
        name_b = MODE_NAMES.get(b, b)
        name_b = name_b[0].upper() + name_b[1:]
        if not d.get("ci"):
            lines.append(f"{name_b} against {MODE_NAMES[a]}: success {_ci(d, 3, True)} "
                         f"(paired; {'one scene' if d['n'] == 1 else 'no scene with both'}: no "
                         "interval, so no verdict).")
            continue
        if d["ci"][0] > 0:
            verdict = f"better than {MODE_NAMES[a]}"
        elif d["ci"][1] < 0:
            verdict = f"worse than {MODE_NAMES[a]}"
        else:
            verdict = f"not told apart from {MODE_NAMES[a]} with {d['n']} scenes"
        lines.append(f"{name_b} against {MODE_NAMES[a]}: success {_ci(d, 3, True)} "
                     f"(paired, over {d['n']} scenes{over}): {verdict}.")
    return lines if len(modes) > 1 else []


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


def _assistance_figure(shares: dict, kinds) -> dict:
    from sweeps.analysis import plots  # deferred: 1.4 s to import

    return _figure(plots.assistance_bars(shares, kinds),
                   "share of the approaches' steps under each kind of assistance, per mode "
                   "(mean over scenes; none: unassisted; scene: the meta skill; correct "
                   "and wrong: towards the intended or another task)")


def sweep_report(folder: Path, n_boot: int = REPORT_RESAMPLES) -> str:
    import pandas as pd  # deferred: 1.0 s to import

    from geometry_precompute.schema import ASSISTANCE  # deferred: 20 ms to import
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
    n_scenes = scenes["scene_index"].nunique()
    summary = (f"{n_scenes} scenes at {n_points} point{'s' if n_points != 1 else ''} "
               f"({len(scenes)} scene rows); modes {', '.join(modes)}"
               + (f"; swept: {', '.join(axes)}" if axes else "") + ".")
    per_scene = {m: scenes.groupby("scene_index")[f"{m}.success"].mean().to_numpy(float)
                 for m in modes}
    headline = headline_sentences(per_scene, modes, n_boot,
                         f", averaged over {n_points} points" if n_points > 1 else "")
    figures: list[dict] = []
    # Per point and mode.
    rows = []
    point_cols = [c for c in scenes.columns if c.startswith("set.")]
    first = scenes.drop_duplicates("point").set_index("point")
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
    if n_points <= 8:
        figures.append(_figure(plots.category_bars(bars, "success", modes,
                                                   ylabel="mean success"),
                               "mean success per point and mode (95 % CI over scenes)"))
    assist_cols = [f"{m}.assist_{k}" for m in modes for k in ASSISTANCE]
    if all(c in scenes.columns for c in assist_cols):
        figures.append(_assistance_figure(
            {m: {k: float(scenes[f"{m}.assist_{k}"].mean()) for k in ASSISTANCE}
             for m in modes}, ASSISTANCE))
    sections = [_section("Success and delta_R per point and mode", [_table(
        ["point", "settings", "mode", "success [95 % CI]", "delta_R (rad) [95 % CI]",
         "scenes"], rows, left=3, cls="modes")]),
        _section("Paired differences between modes", [_table(
            ["point", "difference", "metric", "mean [95 % CI]", "scenes"],
            _paired_rows(scenes, modes, True, n_boot), left=3, cls="paired")])]
    sections += _how_long_sweep(scenes, modes, n_boot)
    sections += _drawn_sweep(folder, modes, n_boot)
    # Tasks, by template and object kind (the scenes' own task ids differ).
    if (folder / "tasks").is_dir():
        tasks = pd.read_parquet(folder / "tasks")
        rows = []
        for (template, kind), g in tasks.groupby(["template", "object_kind"], sort=True):
            for mode in modes:
                frame = g.groupby(["point", "scene_index"])[f"{mode}.success"].mean() \
                    .reset_index()
                e = group_means(frame.assign(all=0), ["all"], f"{mode}.success", n_boot,
                                marginalise=["point"] if frame["point"].nunique() > 1 else None)[0]
                rows.append([template, kind, mode, _ci(e), len(g)])
        sections.append(_section(
            "Tasks by template", [_table(["template", "object", "mode", "success [95 % CI]",
                                          "tasks"], rows, left=3, cls="tasks")],
            "Success of the tasks of one template (averaged within each scene, scenes "
            "resampled; over all points)."))
    # Every axis, and heat maps over two.
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
            caption = f"success against {axis} (a line per combination of {', '.join(others)})"
        else:
            caption = (f"success against {axis} (averaged within each scene over "
                       f"{', '.join(others)})")
        figures.append(_figure(fig, caption + "; mean over scenes with 95 % CI, the modes "
                               "set slightly apart along x so that equal ones stay visible"))
    if len(axes) >= 2:
        x, y = axes[:2]
        sel = scenes
        fixed = []
        for o in axes[2:]:
            v = sel[f"set.{o}"].map(plots._label).iloc[0]
            sel = sel[sel[f"set.{o}"].map(plots._label) == v]
            fixed.append(f"{o}={v}")
        mode = "shacc" if "shacc" in modes else modes[-1]
        where = f" ({', '.join(fixed)})" if fixed else ""
        figures.append(_figure(plots.sweep_heatmap(sel, x, y, "success", mode),
                               f"{mode} success over {x} and {y}{where}, on a fixed 0-1 "
                               "scale"))
        if "baseline" in modes and mode != "baseline":
            figures.append(_figure(
                plots.sweep_heatmap(sel, x, y, "success", mode, minus="baseline"),
                f"{mode} - baseline success over {x} and {y}{where} (the mean paired "
                "difference; blue: better than the baseline, red: worse; centred on 0)"))
    provenance = {"config": config.get("provenance"), "config_hash": config.get("hash"),
                  "evaluated_on": _part_provenance(folder)}
    name = (config.get("config") or {}).get("name") or folder.name
    return _page(f"Sweep {name}", summary, headline, figures, sections, provenance, n_boot)


HOW_LONG_NOTE = ("the mean time to activation (s) and path length (m) of the successful "
                 "approaches, and the share of the approaches' steps under each kind of "
                 "assistance (none; scene: the meta skill; correct and wrong: assistance "
                 "towards the intended or another task)")


DRAWN_NOTE = ("The approaches binned by quartiles of each drawn user setting; per bin the "
              "mean over scenes of each scene's success in it, and the paired difference "
              "to the baseline (95 % CI over scenes).")


def _drawn_table(entry: dict, modes: list[str], lead: str = "") -> dict:
    """One drawn parameter's bins (success per mode, difference to the baseline) and its
    sentence."""
    others = [m for m in modes if m != "baseline"]
    return _table(["bin"] + [f"{m} success" for m in modes]
                  + [f"{m} - baseline" for m in others],
                  [[r["level"]] + [_ci(r["modes"][m]["u_scene"]) for m in modes]
                   + [_ci(r["vs_baseline"][m], 3, True) for m in others]
                   for r in entry["rows"]], left=1, cls="drawn",
                  sentence=lead + entry["sentence"])


def _how_long_sweep(scenes, modes: list[str], n_boot: int) -> list[dict]:
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
    return [_section("How long, and how assisted", [_table(
        ["point", "mode", "time (s)", "path (m)"] + [f"assisted: {k}" for k in ASSISTANCE],
        rows, left=2, cls="time")],
        f"Per point and mode: {HOW_LONG_NOTE}; each the mean over scenes [95 % CI].")]


def _drawn_sweep(folder: Path, modes: list[str], n_boot: int) -> list[dict]:
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
    out: list[dict] = []
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
    return [_section("Success against the drawn users", out, DRAWN_NOTE)]


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
    from sweeps.analysis import plots  # deferred: 1.4 s to import
    from sweeps.analysis.compare import json_rows, read_evaluate_json  # deferred: 8 ms to import

    lines = read_evaluate_json(path)
    scenes_rows, task_rows = json_rows(lines)
    frame = pd.DataFrame(scenes_rows)
    modes = list(dict.fromkeys(frame["mode"]))
    wide = frame.pivot_table(index="key", columns="mode", values=["success", "delta_R_mean"],
                             aggfunc="first")
    wide.columns = [f"{m}.{v}" for v, m in wide.columns]
    wide = wide.reset_index().assign(point=0)
    summary = f"{len(lines)} scene{'s' if len(lines) != 1 else ''}; modes {', '.join(modes)}."
    complete = wide.dropna(subset=[f"{m}.success" for m in modes])
    headline = headline_sentences({m: complete[f"{m}.success"].to_numpy(float) for m in modes},
                         modes, n_boot)
    means = {"all scenes": {"n_scenes": len(lines), **{
        m: {"success": mean_ci(wide[f"{m}.success"].dropna().to_numpy(float), n_boot)}
        for m in modes}}}
    figures = [_figure(plots.category_bars(means, "success", modes, ylabel="mean success"),
                       "mean success per mode (95 % CI over scenes)")]
    shares = {m: {k: np.mean([float((d["modes"][m].get("assistance") or {}).get(k) or 0.0)
                              for d in lines if m in d["modes"]]) for k in ASSISTANCE}
              for m in modes}
    if any(d["modes"][m].get("assistance") for d in lines for m in d["modes"]):
        figures.append(_assistance_figure(shares, ASSISTANCE))
    sections = [_section("Per scene", [_table(
        ["scene", "C_init", "C_final"]
        + [f"{m} {what}" for m in modes for what in ("success", "delta_R (rad)")],
        [[d["scene"], _fmt(d["clutteredness"]["init"]), _fmt(d["clutteredness"]["final"])]
         + [_fmt(d["modes"].get(m, {}).get(k)) for m in modes
            for k in ("success_rate", "delta_R_mean")] for d in lines],
        left=1, cls="modes")])]
    if len(lines) > 1:
        sections.append(_section("Paired differences between modes, over the scenes", [
            _table(["difference", "metric", "mean [95 % CI]", "scenes"],
                   _paired_rows(wide, modes, False, n_boot), left=2, cls="paired")]))
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
    sections.append(_section("How long, and how assisted", [_table(
        ["scene", "mode", "time (s)", "path (m)"] + [f"assisted: {k}" for k in ASSISTANCE],
        per_scene, left=2, cls="time")],
        f"Per scene and mode: {HOW_LONG_NOTE}; over all scenes, the mean over scenes "
        "[95 % CI]."))
    drawn_section = _drawn_json(lines, modes, n_boot)
    if drawn_section:
        sections.append(_section("Success against the drawn users",
                                 [_drawn_table(entry, modes) for entry in
                                  drawn_section.values()], DRAWN_NOTE))
    if task_rows:
        sections.append(_section("Per task", [_table(
            ["scene", "task", "template", "object"] + [f"{m} success" for m in modes],
            [[d["scene"], t["id"], t["template"], t.get("object_kind", "")]
             + [_fmt(t["modes"].get(m, {}).get("success_rate")) for m in modes]
             for d in lines for t in d.get("tasks_detail", [])],
            left=4, cls="tasks")]))
    provenance = {d["scene"]: d.get("provenance") for d in lines[:1]}
    return _page(f"Evaluation {path.name}", summary, headline, figures, sections,
                 provenance, n_boot)
