"""``shacc compare A B``: did a change of template, setting or code change the results?

A and B are two ``evaluate --json`` outputs (JSON Lines, one scene per line) or two
sweep folders, of the same scenes (and, for sweeps, the same points). For every mode
(per sweep point for sweeps) and every metric (METRICS: success, delta_R_mean, the mean
time to activation and path length of the successes, and the shares of the steps under
each assistance; outputs written before a metric existed leave it empty) it reports the
mean over scenes of A and of B and their paired difference B - A with a 95 % bootstrap
CI over scenes (``sweeps.analysis.stats.paired_diff_ci``); per task, the tasks whose
success changed most; per gated metric, the scenes that moved most against it.

The gate, for CI (:func:`gate`):

- ``--fail-if METRIC:MARGIN`` is a non-inferiority test. A negative margin
  (``shacc.success:-0.02``) says "B may be worse than A by at most 0.02": the gate
  passes only when the interval's lower bound lies above -0.02, i.e. B is shown to be
  no worse than the margin. A positive margin (``delta_R_mean:+0.1``, a metric where
  less is better) passes only when the upper bound lies below it. An interval that
  reaches past the margin fails: the data do not show the change harmless.
- ``--fail-if-shown METRIC:MARGIN`` is the lenient reading: it fails only when the
  whole interval lies past the margin, i.e. the harm is shown. With few scenes the
  interval is wide and such a gate lets most regressions through.

Each rule gives a verdict per matching mode and point: PASS or FAIL, the estimate, the
interval, the margin, the number of scenes, and where the interval is too wide to
decide, about how many scenes would narrow it enough (the interval's half-width falls
as one over the square root of the scenes).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from geometry_precompute import InputError
from geometry_precompute.fileio import read_bytes_limited
from geometry_precompute.schema import ASSISTANCE as ASSIST
from sweeps.analysis.stats import paired_diff_ci

METRICS = ("success", "delta_R_mean", "time_mean", "path_length_mean",
           *(f"assist_{k}" for k in ASSIST))
# the key of each metric in an ``evaluate --json`` mode object
JSON_KEYS = {"success": "success_rate", "delta_R_mean": "delta_R_mean",
             "time_mean": "time_to_activation_mean", "path_length_mean": "path_length_mean"}
REGRESSION = 3  # the exit status of a gate that fails
WORST = 5  # scenes listed per gated row, the most moved against the rule first


def read_evaluate_json(path: Path) -> list[dict]:
    """The scene objects of an ``evaluate --json`` file (JSON Lines, one per scene), each
    checked to carry ``scene`` and ``modes``."""
    text = read_bytes_limited(path, "an evaluate --json file", 1 << 30).decode("utf-8",
                                                                              "replace")
    objects = []
    for n, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        try:
            d = json.loads(line)
            if not isinstance(d["scene"], str) or not isinstance(d["modes"], dict):
                raise TypeError
        except (ValueError, KeyError, TypeError):
            raise InputError(path, f"<line {n}>", "not an object written by `shacc evaluate "
                             "--json`") from None
        objects.append(d)
    if not objects:
        raise InputError(path, "<file>", "holds no scene")
    return objects


def json_rows(objects: list[dict]) -> tuple[list[dict], list[dict]]:
    """(scene rows, task rows) of the objects of an ``evaluate --json`` file."""
    scenes, tasks = [], []
    for d in objects:
        name = d["scene"]
        for mode, m in d["modes"].items():
            shares = m.get("assistance") or {}
            scenes.append({"key": name, "point": 0, "mode": mode,
                           **{k: m.get(j) for k, j in JSON_KEYS.items()},
                           **{f"assist_{k}": shares.get(k) for k in ASSIST}})
        for t in d.get("tasks_detail", []):
            for mode, m in t["modes"].items():
                tasks.append({"key": name, "point": 0, "task": t["id"], "mode": mode,
                              "success": m["success_rate"]})
    return scenes, tasks


def read_scenes_table(path: Path):
    """A sweep folder's scenes table as a DataFrame; anything else is an InputError."""
    import pandas as pd  # deferred: 871 ms to import

    try:
        return pd.read_parquet(path / "scenes")
    except Exception as e:  # pyarrow's errors have no common base
        raise InputError(path, "scenes/", f"not a sweep folder's scenes table ({e})") from None


def _load_sweep(path: Path) -> tuple[list[dict], list[dict]]:
    import pandas as pd  # deferred: 871 ms to import

    frame = read_scenes_table(path)
    modes = [c.split(".")[0] for c in frame.columns if c.endswith(".success")]
    scenes = []
    for r in frame.to_dict("records"):
        for mode in modes:
            scenes.append({"key": (r["scene_index"], r["scene"]), "point": int(r["point"]),
                           "mode": mode, **{k: r.get(f"{mode}.{k}") for k in METRICS}})
    tasks = []
    if (path / "tasks").is_dir():
        t = pd.read_parquet(path / "tasks")
        names = dict(zip(zip(frame.point, frame.scene_index, strict=True), frame.scene,
                         strict=True))
        for mode in modes:
            for p, s, task, v in zip(t.point, t.scene_index, t.task_id, t[f"{mode}.success"],
                                     strict=True):
                tasks.append({"key": (s, names[(p, s)]), "point": int(p), "task": task,
                              "mode": mode, "success": v})
    return scenes, tasks


def load(path: str | Path) -> tuple[list[dict], list[dict]]:
    path = Path(path)
    if path.is_dir():
        if not (path / "scenes").is_dir():
            raise InputError(path, "<folder>", "not a sweep folder (no scenes/ table)")
        return _load_sweep(path)
    return json_rows(read_evaluate_json(path))


def _index(rows: list[dict], keys: tuple[str, ...]) -> dict:
    return {tuple(r[k] for k in keys): r for r in rows}


def compare(a: str | Path, b: str | Path, n_boot: int = 10_000, seed: int = 0) -> dict:
    """The comparison of ``a`` and ``b`` (module docstring) as plain data."""
    (sa, ta), (sb, tb) = load(a), load(b)
    ia, ib = _index(sa, ("point", "mode", "key")), _index(sb, ("point", "mode", "key"))
    if ia.keys() != ib.keys():
        only = sorted(map(str, (ia.keys() ^ ib.keys())))[:3]
        raise InputError(f"{a} / {b}", "<scenes>", "the two hold different scenes, points or "
                         f"modes (e.g. {', '.join(only)}); compare runs of the same scenes")
    groups: dict[tuple, list] = {}
    for point, mode, key in ia:
        groups.setdefault((point, mode), []).append(key)
    from geometry_precompute.schema import ALL_MODES  # deferred: 20 ms to import

    rows = []
    order = {m: i for i, m in enumerate(ALL_MODES)}
    for (point, mode), keys in sorted(groups.items(), key=lambda g: (g[0][0],
                                                                      order.get(g[0][1], 9))):
        for metric in METRICS:
            va = np.array([np.nan if ia[(point, mode, k)][metric] is None
                           else ia[(point, mode, k)][metric] for k in keys], float)
            vb = np.array([np.nan if ib[(point, mode, k)][metric] is None
                           else ib[(point, mode, k)][metric] for k in keys], float)
            d = paired_diff_ci(va, vb, n_boot, seed)
            per_scene = [{"scene": str(k[-1] if isinstance(k, tuple) else k),
                          "a": float(x), "b": float(y), "diff": float(y - x)}
                         for k, x, y in zip(keys, va, vb, strict=True)
                         if np.isfinite(x) and np.isfinite(y)]
            rows.append({"point": point, "mode": mode, "metric": metric,
                         "a": None if np.all(np.isnan(va)) else float(np.nanmean(va)),
                         "b": None if np.all(np.isnan(vb)) else float(np.nanmean(vb)),
                         "diff": d["mean"], "ci": d["ci"], "n_scenes": d["n"],
                         "scenes": per_scene})
    tasks = []
    ja, jb = _index(ta, ("point", "mode", "key", "task")), _index(tb, ("point", "mode", "key",
                                                                        "task"))
    for k in sorted(ja.keys() & jb.keys(), key=str):
        change = jb[k]["success"] - ja[k]["success"]
        if change:
            tasks.append({"point": k[0], "mode": k[1], "scene": str(k[2]), "task": k[3],
                          "a": ja[k]["success"], "b": jb[k]["success"], "diff": change})
    tasks.sort(key=lambda t: -abs(t["diff"]))
    return {"a": str(a), "b": str(b), "rows": rows, "tasks_changed": tasks}


def parse_fail_if(text: str, option: str = "--fail-if") -> tuple[str | None, str, float]:
    """``[MODE.]METRIC:MARGIN`` as (mode or None for every mode, metric, margin)."""
    try:
        name, margin = text.rsplit(":", 1)
        value = float(margin)
    except ValueError:
        raise InputError("<arguments>", option, f"must be [MODE.]METRIC:MARGIN such as "
                         f"success:-0.02, got {text!r}") from None
    mode, _, metric = name.rpartition(".")
    if metric not in METRICS or not np.isfinite(value) or value == 0:
        raise InputError("<arguments>", option, f"METRIC must be one of "
                         f"{', '.join(METRICS)} and MARGIN a non-zero number, got {text!r}")
    return mode or None, metric, value


def _scenes_needed(n: int, diff: float, ci: list[float], margin: float) -> int | None:
    """About how many scenes would put the interval on the estimate's side of the
    margin (its half-width shrinking as 1 / sqrt(n)); None where the estimate itself is
    past the margin, so that more scenes would not pass it."""
    half = (ci[1] - ci[0]) / 2
    room = (diff - margin) if margin < 0 else (margin - diff)
    if room <= 0:
        return None
    return int(np.ceil(n * (half / room) ** 2))


def verdict(row: dict, mode_rule: str | None, metric: str, margin: float,
            shown: bool) -> dict:
    """One rule's verdict on one row of :func:`compare` (module docstring)."""
    lo_hi = row["ci"]
    out = {"rule": f"{(mode_rule + '.') if mode_rule else ''}{metric}:{margin:+g}",
           "reading": "shown" if shown else "non-inferiority", "point": row["point"],
           "mode": row["mode"], "metric": metric, "diff": row["diff"], "ci": lo_hi,
           "margin": margin, "n_scenes": row["n_scenes"], "needed": None}
    if row["diff"] is None or not lo_hi:
        out["passed"] = shown  # nothing shown; nothing shown harmless either
        out["why"] = f"no interval ({row['n_scenes']} scene(s) with a value; at least 2 needed)"
        return out
    lo, hi = lo_hi
    worse = lo if margin < 0 else hi  # the interval's end on the harmful side
    better = hi if margin < 0 else lo
    past = (lambda v: v < margin) if margin < 0 else (lambda v: v > margin)
    if shown:
        out["passed"] = not past(better)
        out["why"] = ("the whole interval lies past the margin" if not out["passed"] else
                      "the interval reaches the margin's good side: harm not shown")
    else:
        out["passed"] = not past(worse) and worse != margin
        out["why"] = ("the interval lies on the good side of the margin: no worse than it"
                      if out["passed"] else
                      "the interval reaches past the margin: not shown no worse than it")
    if not shown and not out["passed"]:
        out["needed"] = _scenes_needed(row["n_scenes"], row["diff"], lo_hi, margin)
    return out


def gate(result: dict, rules: list[tuple[str | None, str, float]],
         shown_rules: list[tuple[str | None, str, float]] | None = None) -> list[dict]:
    """Every verdict of the rules (``--fail-if``: non-inferiority) and ``shown_rules``
    (``--fail-if-shown``) on the rows of :func:`compare`, with each row's scenes that
    moved most against its rule."""
    out = []
    for shown, group in ((False, rules), (True, shown_rules or [])):
        for mode, metric, margin in group:
            for r in result["rows"]:
                if r["metric"] != metric or (mode and r["mode"] != mode):
                    continue
                v = verdict(r, mode, metric, margin, shown)
                sign = 1 if margin < 0 else -1  # harm is a drop (or a rise for +)
                v["worst_scenes"] = sorted(r["scenes"], key=lambda x: sign * x["diff"])[:WORST]
                out.append(v)
    return out


def verdict_line(v: dict) -> str:
    """``PASS`` or ``FAIL``, the rule, the estimate, interval, margin and scenes, why, and
    what would decide."""
    ci = "no interval" if not v["ci"] else f"[{v['ci'][0]:+.4f}, {v['ci'][1]:+.4f}]"
    est = "n/a" if v["diff"] is None else f"{v['diff']:+.4f}"
    line = (f"{'PASS' if v['passed'] else 'FAIL'} {v['rule']} ({v['reading']}) point "
            f"{v['point']} {v['mode']} {v['metric']}: B - A = {est} {ci}, margin "
            f"{v['margin']:+g}, {v['n_scenes']} scenes: {v['why']}")
    if v["ci"] and not v["passed"] and v["reading"] == "non-inferiority":
        line += ("; the estimate itself is past the margin" if v["needed"] is None else
                 f"; about {v['needed']} scenes would decide if the estimate held")
    return line
