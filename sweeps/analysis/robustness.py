"""The reproduction's robustness section: the paper's experiment again with imperfect
simulated users (reference/model, "Simulated users").

For each user parameter, at several levels, the same scenes are evaluated in every mode
(the optimized mode keeps the spaces its search found for the perfect user: the
question is how spaces tuned for one user serve another). Per level and mode: the mean
over scenes of the success rate u_scene and of delta_R, with scene-level bootstrap CIs
(a scene is the unit that is resampled, never a rollout); and the paired difference of
each mode's u_scene to the baseline's, scene by scene. One sentence per parameter then
says whether ShaCC's advantage over the baseline, and the optimized mode's, holds,
shrinks or reverses (:func:`verdict`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from geometry_precompute import PrecomputeResult
from shacc_jax.types import Search
from sweeps.analysis.stats import format_ci, mean_ci, paired_diff_ci
from sweeps.pipeline import evaluate_results

# The levels each parameter is evaluated at (besides the perfect user, level 0).
LEVELS: dict[str, list[Any]] = {
    "user_noise": [0.1, 0.2, 0.4],
    "user_lag": [0.25, 0.5],
    "user_tremor": [0.005, 0.01, 0.02],
    "user_aim": ["object"],
}
QUICK_LEVELS: dict[str, list[Any]] = {
    "user_noise": [0.3], "user_lag": [0.5], "user_tremor": [0.01], "user_aim": ["object"]}
PERFECT: dict[str, Any] = {"user_noise": 0.0, "user_lag": 0.0, "user_tremor": 0.0,
                           "user_aim": "space"}
WHAT = {"user_noise": "direction noise (rad)", "user_lag": "lag (probability a step)",
        "user_tremor": "tremor amplitude (m, at 5 Hz)",
        "user_aim": "aim (at the task's space or at the object)"}
# The advantage "holds" where, at every level, its CI lies above zero and its mean is at
# least this share of the perfect user's.
HOLDS_SHARE = 0.75


def level_row(level, u_scene: np.ndarray, delta_r: np.ndarray, modes: Sequence[str],
              n_boot: int, seed: int) -> dict:
    """One level's statistics from per-scene metrics (S, M): per mode the mean u_scene
    and delta_R (rad) with bootstrap CIs over scenes, and per mode but the baseline the
    paired difference of u_scene to the baseline's."""
    row: dict[str, Any] = {"level": level, "modes": {}, "vs_baseline": {}}
    base = modes.index("baseline")
    for m, mode in enumerate(modes):
        row["modes"][mode] = {"u_scene": mean_ci(u_scene[:, m], n_boot, seed),
                              "delta_R": mean_ci(delta_r[:, m], n_boot, seed)}
        if m != base:
            row["vs_baseline"][mode] = paired_diff_ci(u_scene[:, base], u_scene[:, m],
                                                      n_boot, seed)
    return row


def verdict(rows: list[dict], mode: str) -> str:
    """``reverses`` where at some level the mode's paired difference to the baseline has
    its CI below zero; else ``holds`` where at every level its CI lies above zero and
    its mean is at least HOLDS_SHARE of the perfect user's (rows[0]); else ``shrinks``;
    ``none`` where the perfect user shows no advantage to hold (its CI not above
    zero)."""
    diffs = [r["vs_baseline"][mode] for r in rows]
    if any(d["ci"] is not None and d["ci"][1] < 0 for d in diffs):
        return "reverses"
    first = diffs[0]
    if first["ci"] is None or first["ci"][0] <= 0:
        return "none"
    holds = all(d["ci"] is not None and d["ci"][0] > 0
                and d["mean"] >= HOLDS_SHARE * first["mean"] for d in diffs[1:])
    return "holds" if holds else "shrinks"


def _pp(d: dict) -> str:
    if d["mean"] is None:
        return "n/a"
    ci = "" if d["ci"] is None else f" [{100 * d['ci'][0]:+.1f}, {100 * d['ci'][1]:+.1f}]"
    return f"{100 * d['mean']:+.1f} pp{ci}"


def sentence(param: str, rows: list[dict]) -> str:
    """One sentence: what happens to ShaCC's and the optimized mode's advantage over the
    baseline from the perfect user to the parameter's last level."""
    last = rows[-1]
    parts = []
    for mode, name in (("shacc", "ShaCC's"), ("optimized", "the optimized mode's")):
        if mode not in last["vs_baseline"]:
            continue
        v = verdict(rows, mode)
        said = {"none": "is not there to begin with", "holds": "holds",
                "shrinks": "shrinks", "reverses": "reverses"}[v]
        parts.append(f"{name} advantage {said} ({_pp(rows[0]['vs_baseline'][mode])} for "
                     f"the perfect user, {_pp(last['vs_baseline'][mode])} at "
                     f"{last['level']})")
    return f"{_upper(WHAT[param])}: " + "; ".join(parts) + "."


def run(results: list[PrecomputeResult], found: Search, modes: Sequence[str],
        perfect_u: np.ndarray, perfect_delta_r: np.ndarray, n_boot: int, seed: int,
        quick: bool = False, progress=None) -> dict:
    """The robustness section: per parameter {"rows": [...], "verdict": {mode: ...},
    "sentence": ...}; rows[0] is the perfect user (``perfect_u``, ``perfect_delta_r``:
    the main evaluation's per-scene metrics (S, M))."""
    levels = QUICK_LEVELS if quick else LEVELS
    max_tasks = max(len(r.spaces) for r in results)
    out: dict[str, Any] = {}
    for param, values in levels.items():
        rows = [level_row(PERFECT[param], perfect_u, perfect_delta_r, modes, n_boot, seed)]
        for value in values:
            if progress is not None:
                progress(f"  {param} = {value}")
            user = [replace(r, settings=r.settings.with_overrides({param: value}))
                    for r in results]
            me = evaluate_results(user, modes, max_tasks=max_tasks,
                                  found=found).evaluation.metrics
            rows.append(level_row(value, np.asarray(me.u_scene), np.asarray(me.delta_R_mean),
                                  modes, n_boot, seed))
        out[param] = {"rows": rows,
                      "verdict": {m: verdict(rows, m) for m in modes if m != "baseline"},
                      "sentence": sentence(param, rows)}
    return out


def markdown(section: dict, modes: Sequence[str]) -> str:
    """The report's tables: per parameter, per level, each mode's success (and ShaCC's
    delta_R), and the paired differences to the baseline, then the sentence."""
    lines = []
    others = [m for m in modes if m != "baseline"]
    for param, entry in section.items():
        lines += [f"### {_upper(WHAT[param])}: `{param}`", "",
                  "| level | " + " | ".join(f"u {m}" for m in modes) + " | delta_R shacc (rad) | "
                  + " | ".join(f"{m} - baseline" for m in others) + " |",
                  "| --- " * (2 + len(modes) + len(others)) + "|"]
        for r in entry["rows"]:
            u = [r["modes"][m]["u_scene"] for m in modes]
            dr = r["modes"]["shacc"]["delta_R"] if "shacc" in modes else {"mean": None}
            lines.append(f"| {r['level']} | " + " | ".join(format_ci(x) for x in u) + f" | "
                         f"{format_ci(dr, 3)} | "
                         + " | ".join(_pp(r["vs_baseline"][m]) for m in others) + " |")
        lines += ["", entry["sentence"], ""]
    return "\n".join(lines)


def _upper(text: str) -> str:
    return text[:1].upper() + text[1:]
