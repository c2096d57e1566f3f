"""The quantitative claims of the paper's Fig. 6 text, each set beside our number, its
95 % confidence interval over scenes, and whether it holds.

``check(scenes, correlation)`` takes ``reproduce``'s per-scene entries (category, C_init,
C_final, per mode u_scene and delta_R_mean) and its correlations, and returns one
entry per claim: the paper's words and number, ours, and a verdict by a stated rule
(``rule``), "holds", "does not hold" or "n/a". The rules read the paper's sentences as
a researcher would: a direction ("improves", "reduces") holds when the paired interval
over scenes excludes zero in that direction; "no significant improvement" when it
includes zero; a level ("about 30 %") when our mean is within 10 points of it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sweeps.analysis.stats import mean_ci, paired_diff_ci, relative_change_ci

HOLDS, FAILS, NA = "holds", "does not hold", "n/a"


def _pct(x, signed: bool = False) -> str:
    if x is None:
        return "n/a"
    return f"{100 * x:+.0f} %" if signed else f"{100 * x:.0f} %"


def _ci(e: dict, scale: float = 100, unit: str = " %", signed: bool = False) -> str:
    if e is None or e.get("mean") is None:
        return "n/a"
    f = "{:+.0f}" if signed else "{:.0f}"
    if scale != 100:
        f = "{:+.2f}" if signed else "{:.2f}"
    text = f.format(scale * e["mean"]) + unit
    if e.get("ci"):
        lo, hi = (scale * v for v in e["ci"])
        text += f" [{f.format(lo)}, {f.format(hi)}]"
    return text


def _verdict(ok) -> str:
    return NA if ok is None else HOLDS if ok else FAILS


def check(scenes: list[dict], correlation: dict, n_boot: int = 10_000,
          seed: int = 0) -> list[dict]:
    """The claims, in the order of the paper's text (module docstring)."""
    def pick(cats) -> list[dict]:
        return [s for s in scenes if s["category"] in cats or (
            "cinit_pos" in cats and s["C_init"] > 0) or "all" in cats]

    def arr(sel, mode, key):
        return np.array([np.nan if s[mode][key] is None else s[mode][key] for s in sel],
                        np.float64)

    def c_of(sel, mode):
        return np.array([s["C_init"] if mode == "baseline" else s["C_final"] for s in sel])

    out = []

    def claim(cid, text, paper, ours, ok, rule):
        out.append({"id": cid, "claim": text, "paper": paper, "ours": ours,
                    "holds": _verdict(ok), "rule": rule})

    manual = [s for s in scenes if s["set"] == "manual"]
    randoms = [s for s in scenes if s["set"] == "random"]
    if manual:
        u = arr(manual, "baseline", "u_scene")
        claim("manual_range", "baseline success of the manual scenes ranges widely",
              "44 % to 100 %", f"{_pct(u.min())} to {_pct(u.max())}",
              bool(u.min() <= 0.6 and u.max() >= 0.95), "lowest <= 60 % and highest >= 95 %")
    if randoms:
        u = arr(randoms, "baseline", "u_scene")
        e = mean_ci(u, n_boot, seed)
        ok = None if e["ci"] is None else e["ci"][0] <= 0.5 <= e["ci"][1]
        claim("random_mean", "the random scenes' mean baseline success",
              "50 % [14 %, 96 %]", _ci(e) + f" (scenes {_pct(u.min())} to {_pct(u.max())})",
              ok, "50 % lies in our interval")
    rho = correlation.get("C", {})
    ok = None if not rho.get("ci") else rho["ci"][1] < 0
    claim("rho_C", "C correlates negatively with baseline success", "-0.53 [-0.72, -0.27]",
          "n/a" if rho.get("rho") is None else
          f"{rho['rho']:.2f} [{rho['ci'][0]:.2f}, {rho['ci'][1]:.2f}]" if rho.get("ci") else
          f"{rho['rho']:.2f}", ok, "our interval lies below zero")
    dh = [correlation.get(k, {}) for k in ("d", "h")]
    ok = None if not all(c.get("ci") for c in dh) else \
        all(c["ci"][0] <= 0 <= c["ci"][1] for c in dh)
    claim("rho_d_h", "d and h show no correlation (their intervals include zero)",
          "intervals include 0",
          ", ".join(f"{k} {c['rho']:.2f} [{c['ci'][0]:.2f}, {c['ci'][1]:.2f}]"
                    for k, c in zip("dh", dh, strict=True) if c.get("ci")) or "n/a",
          ok, "both intervals include zero")
    levels: dict[str, Any] = {}
    for cat in ("cluttered", "gaussian", "uncluttered", "uniform"):
        sel = pick([cat])
        levels[cat] = mean_ci([s["C_init"] for s in sel], n_boot, seed) if sel else None
    have = all(levels[c] and levels[c]["mean"] is not None for c in ("cluttered", "gaussian"))
    claim("c_init_cluttered", "C_init is about 30 % for cluttered and gaussian scenes",
          "about 30 %", "cluttered " + _ci(levels["cluttered"]) + ", gaussian "
          + _ci(levels["gaussian"]),
          None if not have else all(abs(levels[c]["mean"] - 0.30) <= 0.10
                                    for c in ("cluttered", "gaussian")),
          "both means within 10 points of 30 %")
    have = all(levels[c] and levels[c]["mean"] is not None for c in ("uncluttered", "uniform"))
    claim("c_init_sparse", "C_init is zero for uncluttered and at most 11 % for uniform scenes",
          "0 % and up to 11 %", "uncluttered " + _ci(levels["uncluttered"]) + ", uniform "
          + _ci(levels["uniform"]),
          None if not have else levels["uncluttered"]["mean"] == 0
          and levels["uniform"]["mean"] <= 0.11, "uncluttered 0 and uniform mean <= 11 %")
    uni = pick(["uniform"])
    if manual and uni:
        zero = float(np.mean([s["C_final"] < 0.01 for s in manual]))
        cu = mean_ci([s["C_final"] for s in uni], n_boot, seed)
        claim("shrink_to_zero", "Shrinking reduces C to about zero for most manual scenes "
              "and the uniform scenes", "zero but for manual scenes 10 and 11",
              f"{_pct(zero)} of manual scenes below 1 %, uniform C_final {_ci(cu)}",
              zero >= 0.5 and cu["mean"] <= 0.02, "half the manual scenes below 1 % and "
              "uniform mean C_final <= 2 %")
    for cid, cats, paper in (("c_gaussian", ["gaussian"], "30 % -> 7 % (-76 %)"),
                             ("c_cinit_pos", ["cinit_pos"], "23 % -> 4 % (-84 %)")):
        sel = pick(cats)
        if not sel:
            continue
        a, b = c_of(sel, "baseline"), c_of(sel, "shrinking")
        rel = relative_change_ci(a, b, n_boot, seed)
        which = "gaussian scenes" if cats == ["gaussian"] else "scenes with C_init > 0"
        claim(cid, f"Shrinking reduces C ({which})", paper,
              f"{_pct(a.mean())} -> {_pct(b.mean())} ({_ci(rel, signed=True)})",
              None if not rel["ci"] else rel["ci"][1] <= -0.5,
              "relative change at most -50 % across our interval")
    for cid, cats, text, paper in (
            ("u_all", ["all"], "Shrinking improves success (all scenes)",
             "57 % -> 77 % (+36 %)"),
            ("u_cluttered", ["cluttered", "gaussian"],
             "Shrinking improves success on the initially cluttered scenes (cluttered manual "
             "and gaussian)", "49 % -> 79 % (+61 %)"),
            ("u_cinit_pos", ["cinit_pos"], "Shrinking improves success (C_init > 0)",
             "52 % -> 75 % (+45 %)")):
        sel = pick(cats)
        if not sel:
            continue
        a, b = arr(sel, "baseline", "u_scene"), arr(sel, "shrinking", "u_scene")
        d = paired_diff_ci(a, b, n_boot, seed)
        rel = relative_change_ci(a, b, n_boot, seed)
        claim(cid, text, paper, f"{_pct(np.nanmean(a))} -> {_pct(np.nanmean(b))} "
              f"({_ci(rel, signed=True)}; paired difference {_ci(d, unit=' points', signed=True)})",
              None if not d["ci"] else d["ci"][0] > 0, "paired interval above zero")
    sparse = [pick(["uncluttered"]), uni]
    ds: list[Any] = [paired_diff_ci(arr(sel, "baseline", "u_scene"),
                                    arr(sel, "shrinking", "u_scene"), n_boot, seed)
                     if sel else None for sel in sparse]
    claim("u_sparse", "no significant change of success on uncluttered and uniform scenes",
          "no significant improvement",
          ", ".join(f"{name} {_ci(d, unit=' points', signed=True)}" for name, d in
                    zip(("uncluttered", "uniform"), ds, strict=True) if d) or "n/a",
          None if not all(d and d["ci"] for d in ds) else
          all(d["ci"][0] <= 0 <= d["ci"][1] for d in ds), "both paired intervals include 0")
    gap = max(abs(s["shacc"]["u_scene"] - s["shrinking"]["u_scene"]) for s in scenes)
    claim("shacc_equals_shrinking", "ShaCC's success equals Shrinking's", "the same",
          f"largest difference over scenes {100 * gap:.1f} points", gap == 0.0,
          "equal on every scene")
    for cid, cats, text, paper in (
            ("dr_cluttered", ["cluttered", "gaussian"],
             "Merging lowers delta_R on the cluttered scenes", "1.65 -> 0.65 rad (-61 %)"),
            ("dr_cinit_pos", ["cinit_pos"], "Merging lowers delta_R (C_init > 0)",
             "1.66 -> 0.52 rad (-69 %)")):
        sel = pick(cats)
        if not sel:
            continue
        a, b = arr(sel, "baseline", "delta_R_mean"), arr(sel, "shacc", "delta_R_mean")
        d = paired_diff_ci(a, b, n_boot, seed)
        rel = relative_change_ci(a, b, n_boot, seed)
        claim(cid, text, paper, f"{np.nanmean(a):.2f} -> {np.nanmean(b):.2f} rad "
              f"({_ci(rel, signed=True)}; paired {_ci(d, 1, ' rad', signed=True)})",
              None if not d["ci"] else d["ci"][1] < 0, "paired interval below zero")
    return out


def markdown(claims: list[dict]) -> str:
    rows = ["| claim of the paper's Fig. 6 text | paper | ours [95 % CI] | holds? |",
            "| --- | --- | --- | --- |"]
    rows += [f"| {c['claim']} | {c['paper']} | {c['ours']} | {c['holds']} |" for c in claims]
    return "\n".join(rows)
