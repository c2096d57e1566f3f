"""Robustness to imperfect simulated users (reference/model, "Simulated users"), two
ways: the reproduction's section (:func:`run`, the paper's experiment again at fixed
levels of each user parameter) and, for any run whose users are drawn from a population
(``evaluate``, ``report`` of a sweep), success against each drawn parameter
(:func:`drawn`, binned).

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

# The levels each parameter is evaluated at (besides the perfect user, level 0), and
# what else that parameter's levels set (the wandering hand's correlation time needs a
# hand that wanders: user_noise at 0.3 rad).
LEVELS: dict[str, list[Any]] = {
    "user_noise": [0.1, 0.2, 0.4],
    "user_noise_tau": [0.2, 0.5, 1.0],
    "user_tremor": [0.005, 0.01, 0.02],
    "user_input": ["modes"],
    "user_switch": [0.25, 0.5, 1.0],
    "user_aim": ["object"],
}
QUICK_LEVELS: dict[str, list[Any]] = {
    "user_noise_tau": [0.5], "user_tremor": [0.01],
    "user_input": ["modes"], "user_switch": [1.0], "user_aim": ["object"]}
WITH: dict[str, dict[str, Any]] = {"user_noise_tau": {"user_noise": 0.3}}
PERFECT: dict[str, Any] = {"user_noise": 0.0, "user_noise_tau": 0.0, "user_tremor": 0.0,
                           "user_input": "3d", "user_switch": 0.0, "user_aim": "space",
                           "user_switch_at": 0.5, "user_mode_switch_s": 0.5,
                           "user_tremor_hz": 5.0}
WHAT = {"user_noise": "direction noise (rad)",
        "user_noise_tau": "a wandering hand's correlation time (s, at 0.3 rad)",
        "user_tremor": "tremor amplitude (m, at 5 Hz)",
        "user_input": "the input device (a 3-D command or a two-mode joystick)",
        "user_switch": "a change of mind's probability (turning half-way)",
        "user_aim": "aim (at the task's space or at the object)",
        "user_switch_at": "where a change of mind turns (of the way to the first task)",
        "user_mode_switch_s": "a joystick's time to switch mode (s)",
        "user_tremor_hz": "tremor frequency (Hz)"}
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
    reference = (f"at {rows[0]['level']}" if param in WITH else "for the perfect user")
    parts = []
    for mode, name in (("shacc", "ShaCC's"), ("optimized", "the optimized mode's")):
        if mode not in last["vs_baseline"]:
            continue
        v = verdict(rows, mode)
        said = {"none": "is not there to begin with", "holds": "holds",
                "shrinks": "shrinks", "reverses": "reverses"}[v]
        parts.append(f"{name} advantage {said} ({_pp(rows[0]['vs_baseline'][mode])} "
                     f"{reference}, {_pp(last['vs_baseline'][mode])} at {last['level']})")
    return f"{_upper(WHAT[param])}: " + "; ".join(parts) + "."


def run(results: list[PrecomputeResult], found: Search, modes: Sequence[str],
        perfect_u: np.ndarray, perfect_delta_r: np.ndarray, n_boot: int, seed: int,
        quick: bool = False, progress=None, budget_bytes: int | None = None) -> dict:
    """The robustness section: per parameter {"rows": [...], "verdict": {mode: ...},
    "sentence": ...}; rows[0] is the perfect user (``perfect_u``, ``perfect_delta_r``:
    the main evaluation's per-scene metrics (S, M)), or for a parameter in WITH that
    parameter's perfect value beside the WITH settings. ``budget_bytes``: the
    evaluation's memory budget (``evaluate_results``)."""
    levels = QUICK_LEVELS if quick else LEVELS
    max_tasks = max(len(r.spaces) for r in results)
    # Every (parameter, level) evaluated, as copies of the scenes in one batch: one
    # program serves them all (the layout carries every user model some copy needs;
    # each copy's settings are data), where a batch per level compiled a program each
    # (the first evaluation of the quick reproduction spent most of its time there).
    # A scene's rollouts do not depend on the batch it is in (docs/DECISIONS.md).
    cases = [(param, value) for param, values in levels.items()
             for value in ([PERFECT[param]] if param in WITH else []) + list(values)]
    if progress is not None:
        progress(f"  {len(cases)} users x {len(results)} scenes in one batch: "
                 + ", ".join(f"{p} = {v}" for p, v in cases))
    users = [replace(r, settings=r.settings.with_overrides({**WITH.get(param, {}),
                                                            param: value}))
             for param, value in cases for r in results]
    tiled = None if found is None else Search(*[
        np.concatenate([np.asarray(f)] * len(cases)) for f in found])
    me = evaluate_results(users, modes, max_tasks=max_tasks, found=tiled,
                          budget_bytes=budget_bytes).evaluation.metrics
    S = len(results)
    u_all = np.asarray(me.u_scene).reshape(len(cases), S, -1)
    dr_all = np.asarray(me.delta_R_mean).reshape(len(cases), S, -1)
    out: dict[str, Any] = {}
    for param in levels:
        # A parameter that only means something beside another (WITH) starts from that
        # other alone, so that its first row is what its levels are compared with.
        rows = [] if param in WITH else [
            level_row(PERFECT[param], perfect_u, perfect_delta_r, modes, n_boot, seed)]
        for c, (name, value) in enumerate(cases):
            if name == param:
                rows.append(level_row(value, u_all[c], dr_all[c], modes, n_boot, seed))
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


def drawn(outcome: np.ndarray, user: np.ndarray, task_mask: np.ndarray,
          modes: Sequence[str], n_boot: int = 2000, seed: int = 0, bins: int = 4) -> dict:
    """Success against each drawn user parameter of a run with a population of users:
    per parameter that varies, the rollouts binned by its drawn value (``bins`` bins
    between quantiles); per bin and mode the mean over scenes of each scene's success
    among its rollouts in the bin, and each mode's paired difference to the baseline,
    scene by scene (scenes without a rollout in the bin left out), with scene-level
    CIs; and the sentence :func:`sentence` says of the lowest bin against the highest.

    :param outcome: (S, M, N, T) outcome codes; ``user``: (S, M, N, T, U) the drawn
        values (the same in every mode), U = len(POPULATED); ``task_mask``: (S, T).
    :returns: {parameter: {"rows": [...], "verdict": {...}, "sentence": ...}}, rows as
        :func:`level_row`'s with the bin "[low, high]" as the level.
    """
    from geometry_precompute.population import POPULATED
    from geometry_precompute.schema import SUCCESS

    outcome = np.asarray(outcome)
    values = np.asarray(user, float)[:, 0]  # (S, N, T, U): one user in every mode
    real = np.broadcast_to(np.asarray(task_mask, bool)[:, None, :], values.shape[:3])
    out: dict[str, Any] = {}
    for i, name in enumerate(POPULATED):
        v = values[..., i]
        spread = v[real]
        if spread.size == 0 or np.ptp(spread) <= 0:
            continue  # not drawn (or drawn to one value)
        edges = np.unique(np.quantile(spread, np.linspace(0, 1, bins + 1)))
        if edges.size < 2:
            continue
        rows = []
        for b in range(edges.size - 1):
            lo, hi = edges[b], edges[b + 1]
            inside = real & (v >= lo) & ((v < hi) if b < edges.size - 2 else (v <= hi))
            n = inside.sum(axis=(1, 2))
            with np.errstate(invalid="ignore", divide="ignore"):
                u = np.stack([np.where(n > 0, ((outcome[:, m] == SUCCESS) & inside)
                                       .sum(axis=(1, 2)) / np.maximum(n, 1), np.nan)
                              for m in range(len(modes))], axis=1)
            row = level_row(f"[{lo:.3g}, {hi:.3g}]", u, np.full_like(u, np.nan), modes,
                            n_boot, seed)
            rows.append(row)
        entry = {"rows": rows,
                 "verdict": {m: verdict(rows, m) for m in modes if m != "baseline"},
                 "sentence": drawn_sentence(name, rows)}
        out[name] = entry
    return out


def drawn_sentence(param: str, rows: list[dict]) -> str:
    """One sentence: ShaCC's (and the optimized mode's) advantage over the baseline,
    from the lowest bin of a drawn parameter to the highest; a verdict only where there
    are scenes enough for CIs."""
    first, last = rows[0], rows[-1]
    parts = []
    for mode, name in (("shacc", "ShaCC's"), ("optimized", "the optimized mode's")):
        if mode not in last["vs_baseline"]:
            continue
        with_ci = all(r["vs_baseline"][mode]["ci"] is not None for r in rows)
        said = {"none": "is not there in the lowest bin", "holds": "holds",
                "shrinks": "shrinks", "reverses": "reverses"}[verdict(rows, mode)] \
            if with_ci else "goes"
        parts.append(f"{name} advantage {said} ({_pp(first['vs_baseline'][mode])} at "
                     f"{first['level']}, {_pp(last['vs_baseline'][mode])} at {last['level']})")
    if not parts:
        return f"{_upper(WHAT.get(param, param))}, as drawn: no mode to hold against the baseline."
    return f"{_upper(WHAT.get(param, param))}, as drawn: " + "; ".join(parts) + "."
