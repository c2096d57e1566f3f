"""``shacc compare A B``: did a change of template, setting or code change the results?

A and B are two ``evaluate --json`` outputs (JSON Lines, one scene per line) or two
sweep folders, of the same scenes (and, for sweeps, the same points). For every mode
(per sweep point for sweeps) and every metric (success, delta_R_mean) it reports the
mean over scenes of A and of B and their paired difference B - A with a 95 % bootstrap
CI over scenes (``sweeps.analysis.stats.paired_diff_ci``); per task, the tasks whose success
changed most. ``--fail-if METRIC:MARGIN`` (``success:-0.02``, ``shacc.success:-0.05``,
``delta_R_mean:+0.1``) makes the command exit with status 3 when the difference is past
the margin with confidence: the whole interval below a negative margin, or above a
positive one. That is the check a CI job runs after changing a template.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from geometry_precompute import InputError
from geometry_precompute.fileio import read_bytes_limited
from sweeps.analysis.stats import paired_diff_ci

METRICS = ("success", "delta_R_mean")
REGRESSION = 3  # the exit status of a --fail-if that is met


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
            scenes.append({"key": name, "point": 0, "mode": mode,
                           "success": m.get("success_rate"),
                           "delta_R_mean": m.get("delta_R_mean")})
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
                           "mode": mode, "success": r[f"{mode}.success"],
                           "delta_R_mean": r[f"{mode}.delta_R_mean"]})
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
            rows.append({"point": point, "mode": mode, "metric": metric,
                         "a": None if np.all(np.isnan(va)) else float(np.nanmean(va)),
                         "b": None if np.all(np.isnan(vb)) else float(np.nanmean(vb)),
                         "diff": d["mean"], "ci": d["ci"], "n_scenes": d["n"]})
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


def parse_fail_if(text: str) -> tuple[str | None, str, float]:
    """``[MODE.]METRIC:MARGIN`` as (mode or None for every mode, metric, margin)."""
    try:
        name, margin = text.rsplit(":", 1)
        value = float(margin)
    except ValueError:
        raise InputError("<arguments>", "--fail-if", f"must be [MODE.]METRIC:MARGIN such as "
                         f"success:-0.02, got {text!r}") from None
    mode, _, metric = name.rpartition(".")
    if metric not in METRICS or not np.isfinite(value) or value == 0:
        raise InputError("<arguments>", "--fail-if", f"METRIC must be one of "
                         f"{', '.join(METRICS)} and MARGIN a non-zero number, got {text!r}")
    return mode or None, metric, value


def failures(result: dict, rules: list[tuple[str | None, str, float]]) -> list[str]:
    """The rows past a --fail-if margin with confidence (module docstring)."""
    out = []
    for mode, metric, margin in rules:
        for r in result["rows"]:
            if r["metric"] != metric or (mode and r["mode"] != mode) or not r["ci"]:
                continue
            lo, hi = r["ci"]
            if (margin < 0 and hi < margin) or (margin > 0 and lo > margin):
                out.append(f"point {r['point']} {r['mode']} {metric}: B - A = {r['diff']:+.4f} "
                           f"[{lo:+.4f}, {hi:+.4f}], past {margin:+g}")
    return out
