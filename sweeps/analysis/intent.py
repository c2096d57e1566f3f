"""ShaCC and intent inference: the reproduction's section on the paper's open question
(reference/model, "Intent inference").

The paper's random scenes are evaluated in the baseline, ShaCC, blending, hindsight
optimization and ShaCC with hindsight optimization, by the perfect user and by two
imperfect ones (a change of mind in every approach, the case where inference is wrong
first; a wandering hand), all in one batch. Per user and mode: the mean over scenes of
success, of delta_R and of the four fractions of time under each kind of assistance,
with scene-level bootstrap CIs; and two sentences per comparison (the report's headline
pairs), one on success and one on delta_R, saying whether the newer mode is better,
worse or not told apart.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from geometry_precompute import PrecomputeResult
from shacc_jax.types import ASSISTANCE
from sweeps.analysis.report import HEADLINE_PAIRS, MODE_NAMES, headline_sentences
from sweeps.analysis.robustness import PERFECT
from sweeps.analysis.stats import format_ci, mean_ci, paired_diff_ci
from sweeps.pipeline import evaluate_results

MODES = ("baseline", "shacc", "blend", "ho", "shacc_ho")
# The users, each named as the sentences say it.
USERS: dict[str, dict[str, Any]] = {
    "the perfect user": {},
    "a change of mind in every approach": {"user_switch": 1.0},
    "a wandering hand (0.3 rad, 0.5 s)": {"user_noise": 0.3, "user_noise_tau": 0.5},
}
# The user of the figure (the paper's Fig. 9b): a change of mind is where an inferred
# goal is wrong first.
FIGURE_USER = "a change of mind in every approach"


def run(results: Sequence[PrecomputeResult], n_boot: int, seed: int,
        progress: Callable[[str], None] | None = None,
        budget_bytes: int | None = None) -> dict:
    """The section's numbers (``summary.json``'s ``intent``): {"modes": [...], "users":
    {user: {"settings": {...}, "modes": {mode: {"u_scene", "delta_R", "assist": {kind:
    ci}}}, "sentences": [...]}}, "n_scenes": S}. ``budget_bytes``: the evaluation's memory
    budget (``evaluate_results``)."""
    batch = [replace(r, settings=r.settings.with_overrides({**PERFECT, **over}))
             for over in USERS.values() for r in results]
    if progress:
        progress(f"intent inference: {len(results)} scenes x {len(USERS)} users in "
                 f"{', '.join(MODES)} (one batch)...")
    ev = evaluate_results(batch, MODES, max_tasks=max(len(r.spaces) for r in results),
                          budget_bytes=budget_bytes)
    me = ev.evaluation.metrics
    S = len(results)
    out: dict[str, Any] = {"modes": list(MODES), "n_scenes": S, "users": {}}
    for k, (name, over) in enumerate(USERS.items()):
        part = slice(k * S, (k + 1) * S)
        u = np.asarray(me.u_scene[part], float)
        dr = np.asarray(me.delta_R_mean[part], float)
        share = np.asarray(me.assist_fraction[part], float)
        modes = {}
        for m, mode in enumerate(MODES):
            modes[mode] = {"u_scene": mean_ci(u[:, m], n_boot, seed),
                           "delta_R": mean_ci(dr[:, m], n_boot, seed),
                           "assist": {kind: mean_ci(share[:, m, j], n_boot, seed)
                                      for j, kind in enumerate(ASSISTANCE)}}
        said = headline_sentences({mode: u[:, m] for m, mode in enumerate(MODES)},
                                  list(MODES), n_boot, over=f", {name}")
        said += [_delta_r_sentence(dr[:, MODES.index(a)], dr[:, MODES.index(b)], a, b,
                                   name, n_boot, seed) for a, b in HEADLINE_PAIRS
                 if a in MODES and b in MODES]
        out["users"][name] = {"settings": over, "modes": modes, "sentences": said[1:]}
    return out


def _delta_r_sentence(old: np.ndarray, new: np.ndarray, a: str, b: str, user: str,
                      n_boot: int, seed: int) -> str:
    """One sentence on the orientation at activation: the paired difference of the
    scenes' mean delta_R (scenes where both modes have a success), and what it says."""
    d = paired_diff_ci(old, new, n_boot, seed)
    name_b = MODE_NAMES[b][0].upper() + MODE_NAMES[b][1:]
    text = f"{name_b} against {MODE_NAMES[a]}: delta_R {format_ci(d, 3)} rad"
    if not d.get("ci"):
        return f"{text} (paired; fewer than two scenes with successes in both, {user})."
    verdict = ("lower" if d["ci"][1] < 0 else "higher" if d["ci"][0] > 0 else
               f"not told apart with {d['n']} scenes")
    return f"{text} (paired, over {d['n']} scenes, {user}): {verdict}."


def markdown(section: dict) -> list[str]:
    """The report's lines: per user a table (mode, success, delta_R, the four fractions)
    and its sentences."""
    lines: list[str] = []
    for name, entry in section["users"].items():
        lines += [f"**{name[0].upper() + name[1:]}** ({section['n_scenes']} scenes):", "",
                  "| mode | success | delta_R (rad) | "
                  + " | ".join(f"{k} (share)" for k in ASSISTANCE) + " |",
                  "|" + " --- |" * (3 + len(ASSISTANCE))]
        for mode in section["modes"]:
            e = entry["modes"][mode]
            lines.append(f"| {mode} | {format_ci(e['u_scene'], 3)} | "
                         f"{format_ci(e['delta_R'], 3)} | "
                         + " | ".join(format_ci(e["assist"][k], 3) for k in ASSISTANCE)
                         + " |")
        lines += ["", *[f"- {s}" for s in entry["sentences"]], ""]
    return lines


def shares(section: dict, user: str = FIGURE_USER) -> dict:
    """mode -> {kind: mean share} of one user, for ``plots.assistance_bars``."""
    entry = section["users"][user]["modes"]
    return {MODE_NAMES.get(m, m): {k: entry[m]["assist"][k]["mean"] for k in ASSISTANCE}
            for m in section["modes"]}
