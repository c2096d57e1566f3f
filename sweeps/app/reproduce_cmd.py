"""``shacc reproduce``: the paper's simulation experiment (sections VI-VII) in one
command: the shipped manual set and a random set, in the paper's three modes and the
``optimized`` mode (reference/model), with Fig. 6 as numbers, tables and plots, Fig. 7's
success fields, and how much success Shrinking leaves on the table: per category, the
mean over scenes of u_scene(optimized) - u_scene(shrinking) on the held-out grid, with
its bootstrap CI.

Categories (reference/statistics, experiments): ``uncluttered`` (manual, C_init = 0),
``cluttered`` (manual, C_init > 0), ``uniform``, ``gaussian`` (random sets),
``all``, and ``cinit_pos`` (every scene with C_init > 0). Per category and mode
the means of u_scene, delta_R (the scene means over successes; scenes without a
success are left out) and C_final (C_init for baseline, which does not shrink),
each with a 95 % percentile-bootstrap CI over scenes. C_final of ``optimized`` is C
of the spaces the search found (the same booleans as C_final).
"""

from __future__ import annotations

import contextlib
import importlib.metadata as md
import logging
import os
import platform
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import matplotlib.pyplot as plt
import numpy as np
from tqdm import tqdm

import shacc_jax
from geometry_precompute import (
    DEFAULTS,
    InputError,
    PrecomputeResult,
    precompute,
    shipped_scene_paths,
)
from geometry_precompute.batch import precompute_scene
from geometry_precompute.clutteredness import clutteredness
from geometry_precompute.schema import ASSISTANCE, PAPER_MODES
from shacc_jax.optimize import winner_name
from shacc_jax.program_cache import LOG as PROGRAMS
from shacc_jax.types import Search
from sweeps.analysis import claims, intent, plots, robustness
from sweeps.analysis.stats import format_ci, mean_ci, partial_corr_ci, pearson_ci
from sweeps.app.inputs import parse_sets
from sweeps.distributed.cluster import connect
from sweeps.output import check_output_dir, check_output_file, write_atomic, write_json
from sweeps.pipeline import evaluate_results

MODES = PAPER_MODES  # the paper's four; intent inference has its own section
CATEGORIES = ("uncluttered", "cluttered", "uniform", "gaussian", "all", "cinit_pos",
              "cluttered_gaussian")
README_BEGIN = "<!-- reproduce:begin (written by shacc reproduce --readme) -->"
README_END = "<!-- reproduce:end -->"


def _software() -> dict:
    out: dict[str, str | None] = {"python": platform.python_version()}
    for name in ("jax", "jaxlib", "numpy", "scipy", "trimesh", "manifold3d", "coal", "shacc"):
        try:
            out[name] = md.version(name)
        except md.PackageNotFoundError:
            out[name] = None
    return out


def _ratio(a, b):
    return None if a in (None, 0) or b is None else (b - a) / a


_BEGUN = time.perf_counter()


def _log(*parts) -> None:
    """Progress lines go to stderr (stdout is kept for results), each with the seconds
    since the command began, so that a slow stage shows where it is."""
    # One write per line: the last stages log from their threads at once.
    line = " ".join([f"[{time.perf_counter() - _BEGUN:6.1f} s]", *map(str, parts)])
    sys.stderr.write(line + "\n")
    sys.stderr.flush()


class _ProgramLines(logging.Handler):
    """Each program's preparation (``shacc_jax.program_cache.LOG``) as a progress line,
    named after the stage whose thread prepared it."""

    def emit(self, record: logging.LogRecord) -> None:
        thread = threading.current_thread().name
        stage = thread.removeprefix("reproduce ") + ": " if thread.startswith("reproduce ") \
            else ""
        _log(f"  {stage}{record.getMessage()}")


@contextlib.contextmanager
def _programs_told():
    """Progress lines for the programs prepared within (compiling is most of the
    command's time: without them a stage would be silent for a minute)."""
    handler, level = _ProgramLines(logging.INFO), PROGRAMS.level
    PROGRAMS.addHandler(handler)
    PROGRAMS.setLevel(logging.INFO)
    try:
        yield
    finally:
        PROGRAMS.removeHandler(handler)
        PROGRAMS.setLevel(level)


def side_by_side(stages: dict[str, Callable[[int], Any]], share: int | None = None
                 ) -> dict[str, tuple[Any, float]]:
    """Run independent stages at once and wait for them (:class:`Beside`):
    ``{name: (result, seconds)}``."""
    return Beside(stages, share).join()


class Beside:
    """Independent stages started at once, one thread each, every one given ``share``
    bytes of memory (default an equal share of ``shacc_jax.budget()``); :meth:`join`
    waits for them and raises the first stage's error (in ``stages``' order) once all
    have ended.

    The stages are mostly compilation: JAX traces under the GIL, but XLA compiles and
    runs without it, so stages overlap on a machine with a free core (docs/DECISIONS.md,
    "The reproduction's last stages side by side"). Progress lines come from each as it
    goes. Ctrl-C still ends the command at once (``sweeps.distributed.interrupt``)."""

    def __init__(self, stages: dict[str, Callable[[int], Any]], share: int | None = None):
        self.stages = stages
        self.share = share or max(1, shacc_jax.budget() // max(1, len(stages)))
        self.done: dict[str, tuple[Any, float]] = {}
        self.failed: dict[str, BaseException] = {}
        self.threads = [threading.Thread(target=self._work, args=item, daemon=True,
                                         name=f"reproduce {item[0]}")
                        for item in stages.items()]
        for t in self.threads:
            t.start()

    def _work(self, name: str, stage: Callable[[int], Any]) -> None:
        t0 = time.perf_counter()
        try:
            self.done[name] = (stage(self.share), time.perf_counter() - t0)
            _log(f"  {name}: done in {self.done[name][1]:.1f} s")
        except BaseException as e:  # raised in the joining thread
            self.failed[name] = e

    def wait(self) -> None:
        for t in self.threads:
            t.join()

    def join(self) -> dict[str, tuple[Any, float]]:
        self.wait()
        for name in self.stages:
            if name in self.failed:
                raise self.failed[name]
        return self.done


def _optimized_clutteredness(r: PrecomputeResult, q: np.ndarray) -> float:
    """C of the spaces at the search's parameters q (T, P): section 5's booleans."""

    shapes = [sp.shape(q[t, :len(sp.param_names)]) for t, sp in enumerate(r.spaces)]
    return clutteredness(shapes, r.settings["mesh_sections"])


def _precompute(items: list, workers: int | None) -> list[PrecomputeResult]:
    """The scenes' precompute, in order, on the local cluster's precompute workers (the
    sweep's cluster, without evaluation workers: this process evaluates)."""
    from distributed import as_completed  # deferred: 1.7 s to import


    with connect(workers=workers, evaluate=False) as pool:
        futures = pool.client.map(precompute_scene, items, resources=pool.precompute,
                                  pure=False)
        for f in tqdm(as_completed(futures), total=len(items), desc="precompute",
                      unit="scene", file=sys.stderr, disable=None):
            if f.status == "error":
                f.result()  # the scene's own error (a bad file: one line), at once
        return [f.result() for f in futures]


def run(out: Path, n_random: int = 20, seed: int = 0, quick: bool = False,
        field_grid: int = 64, overrides: dict | None = None, workers: int | None = None,
        readme: Path | None = None, preset: str = "paper") -> dict:
    global _BEGUN
    t_start = _BEGUN = time.perf_counter()
    settings = DEFAULTS.with_overrides(overrides or {}, "<--set>")
    if quick:
        settings = settings.with_overrides({"bootstrap_resamples": 200})
    n_boot = settings["bootstrap_resamples"]

    manual = shipped_scene_paths()
    # The generator's ``paper`` preset by default: its C_init matches the paper's random
    # scenes (geometry_precompute/generate.py); ``compact`` is the earlier geometry.
    randoms = [(seed + i, "uniform" if i % 2 == 0 else "gaussian", preset)
               for i in range(n_random)]
    items: list[tuple[str, Path | tuple[int, str, str], dict]] = [
        ("manual", p, dict(overrides or {})) for p in manual]
    items += [("random", r, dict(overrides or {})) for r in randoms]
    _log(f"reproduce: {len(manual)} manual + {n_random} random scenes ({preset} preset), modes "
          f"{', '.join(MODES)}")
    results = _precompute(items, workers)
    t_pre = time.perf_counter()
    # The intent section needs only the random scenes: it starts now, beside the
    # main evaluation and the later stages (a third of the memory budget each), and
    # fills the cores they leave free.
    # The budget is read once: read again while a stage runs, it would count that
    # stage's memory as taken.
    budget = shacc_jax.budget()
    share = max(1, budget // 3)
    early: dict[str, Callable[[int], Any]] = {}
    if n_random:  # the paper's open question, on its random scenes
        early["intent"] = lambda budget_bytes: intent.run(
            results[len(manual):], n_boot, seed, progress=_log, budget_bytes=budget_bytes)
    beside = Beside(early, share)
    try:
        counts = sorted({len(r.spaces) for r in results})
        _log(f"evaluating all rollouts: the paper's modes, then the optimized mode's search (one "
             f"program per task count, {', '.join(map(str, counts))}, compiled side by side)...")
        ev = evaluate_results(results, MODES, max_tasks=max(len(r.spaces) for r in results),
                              budget_bytes=max(1, budget - share * len(early)))
        me = ev.evaluation.metrics
        n_rollouts = int(me.n_rollouts.sum())
        t_eval = time.perf_counter()
        _log(f"  {n_rollouts} rollouts in {ev.seconds['evaluate']:.1f} s")

        scenes = []
        found = ev.searched()
        for i, r in enumerate(results):
            is_manual = i < len(manual)
            cat = ("uncluttered" if r.C_init == 0 else "cluttered") if is_manual else randoms[
                i - len(manual)][1]
            entry: dict[str, Any] = {
                     "name": r.scene.name, "set": "manual" if is_manual else "random",
                     "category": cat, "n_tasks": len(r.spaces), "C_init": r.C_init,
                     "C_final": r.C_final, "d": r.d, "h": r.h,
                     "C_optimized": _optimized_clutteredness(r, np.asarray(found.q[i])),
                     "search_objective": {k: float(getattr(found, f)[i]) for k, f in (
                         ("init", "objective_init"), ("shrinking", "objective_shrunk"),
                         ("optimized", "objective"))},
                     "validation": {k: float(getattr(found, f)[i]) for k, f in (
                         ("init", "validation_init"), ("shrinking", "validation_shrunk"),
                         ("optimized", "validation"))},
                     "chosen": winner_name(int(found.winner[i]), r.settings["optimize_candidates"]),
                     "rollouts_per_mode": int(me.n_rollouts[i, 0])}
            for m, mode in enumerate(MODES):
                dr = me.delta_R_mean[i, m]
                entry[mode] = {"u_scene": float(me.u_scene[i, m]),
                               "delta_R_mean": None if not np.isfinite(dr) else float(dr)}
            scenes.append(entry)

        _log("bootstrap confidence intervals...")
        u_base = np.array([s["baseline"]["u_scene"] for s in scenes])
        measures = {k: np.array([s[k] for s in scenes]) for k in ("C_init", "d", "h")}
        correlation = {("C" if k == "C_init" else k): pearson_ci(v, u_base, n_boot, seed)
                       for k, v in measures.items()}
        # The task count alone predicts failure too: C_init's correlation with it removed.
        n_tasks = np.array([s["n_tasks"] for s in scenes], float)
        partial = {"C_given_tasks": partial_corr_ci(measures["C_init"], u_base, n_tasks, n_boot,
                                                    seed),
                   "tasks": pearson_ci(n_tasks, u_base, n_boot, seed)}
        members = {
            "uncluttered": [s["category"] == "uncluttered" for s in scenes],
            "cluttered": [s["category"] == "cluttered" for s in scenes],
            "uniform": [s["category"] == "uniform" for s in scenes],
            "gaussian": [s["category"] == "gaussian" for s in scenes],
            "all": [True for _ in scenes],
            "cinit_pos": [s["C_init"] > 0 for s in scenes],
            "cluttered_gaussian": [s["category"] in ("cluttered", "gaussian") for s in scenes],
        }
        categories = {}
        for c in CATEGORIES:
            idx = [i for i, keep in enumerate(members[c]) if keep]
            entry = {"n_scenes": len(idx)}
            for mode in MODES:
                sel = [scenes[i] for i in idx]
                c_final = [s["C_init"] if mode == "baseline" else s["C_optimized"]
                           if mode == "optimized" else s["C_final"] for s in sel]
                dr = [np.nan if s[mode]["delta_R_mean"] is None else s[mode]["delta_R_mean"]
                      for s in sel]
                entry[mode] = {"u_scene": mean_ci([s[mode]["u_scene"] for s in sel], n_boot, seed),
                               "delta_R": mean_ci(dr, n_boot, seed),
                               "C_final": mean_ci(c_final, n_boot, seed)}
            # What Shrinking leaves on the table: held-out success, optimized - shrinking.
            entry["optimized_gain"] = mean_ci(
                [s["optimized"]["u_scene"] - s["shrinking"]["u_scene"] for s in sel], n_boot, seed)
            entry["search_gain"] = mean_ci(
                [s["search_objective"]["optimized"] - s["search_objective"]["shrinking"]
                 for s in sel], n_boot, seed)
            entry["optimized_losses"] = losses_to_shrinking(sel)
            categories[c] = entry
        t_stats = time.perf_counter()

        # The robustness and field stages need nothing of one another: they run side by
        # side (side_by_side), beside the intent section, each with its share of the memory
        # budget.
        stages: dict[str, Callable[[int], Any]] = {}
        if settings["collision"] == "off":
            def robust_stage(budget_bytes: int) -> dict:
                _log("robustness: the experiment with imperfect simulated users...")
                return robustness.run(
                    results, found, MODES, np.asarray(me.u_scene), np.asarray(me.delta_R_mean),
                    n_boot, seed, quick, progress=_log, budget_bytes=budget_bytes)
            stages["robustness"] = robust_stage

        field_idx = next(i for i, s in enumerate(scenes) if s["name"] == "mug-behind-two")
        fr = results[field_idx]

        def field_stage(budget_bytes: int):
            _log(f"success fields on a {field_grid} x {field_grid} start grid...")
            field_settings = fr.settings.with_overrides({"start_grid": [field_grid, field_grid]})
            # The optimized spaces of the tables (the search is not run again for the field).
            T = len(fr.spaces)
            field_search = Search._make(a[field_idx:field_idx + 1, :T] if a.ndim == 3
                                        else a[field_idx:field_idx + 1] for a in found)
            return evaluate_results([precompute(fr.scene, field_settings)],
                                    ("baseline", "shrinking", "shacc", "optimized"),
                                    found=field_search, budget_bytes=budget_bytes)
        stages["success fields"] = field_stage
        t_side = time.perf_counter()
        done = {**side_by_side(stages, share), **beside.join()}
        t_done = time.perf_counter()
        robust: dict[str, Any] = done["robustness"][0] if "robustness" in done else {}
        intent_section = done["intent"][0] if "intent" in done else {}
        field = done["success fields"][0]
        seconds = {name: t for name, (_, t) in done.items()}

        summary: dict[str, Any] = {
            "correlation": correlation,
            "categories": categories,
            "scenes": scenes,
            "settings": {**settings.to_dict(), "random_scenes": n_random, "seed": seed,
                         "preset": preset,
                         "quick": quick, "field_grid": field_grid, "field_scene": fr.scene.name,
                         "software": _software(), "device": str(shacc_jax_device())},
            "comparison": _comparison(correlation, categories),
            "partial_correlation": partial,
            "robustness": robust,
            "intent": intent_section,
            "claims": claims.check(scenes, correlation, n_boot, seed),
            "timing_s": {"precompute": t_pre - t_start, "evaluate": t_eval - t_pre,
                         "statistics": t_stats - t_eval,
                         # the last stages' wall time, and each one's own seconds
                         # (intent inference's from the main evaluation's start on)
                         "side_by_side": t_done - t_side,
                         "robustness": seconds.get("robustness", 0.0),
                         "intent": seconds.get("intent", 0.0),
                         "success_fields": seconds["success fields"]},
            "rollouts": n_rollouts,
        }
        _log("figures and report...")
        _figures(out, summary, scenes, measures, u_base, field, field_grid, fr)
        report = render_report(summary)
        write_atomic(out / "report.md", report.encode())
        summary["timing_s"]["total"] = time.perf_counter() - t_start
        write_json(out / "summary.json", summary)
        if readme is not None:
            update_readme(readme, out, summary)
        _log(f"wrote {out}/summary.json, report.md and figures in "
              f"{summary['timing_s']['total']:.1f} s")
        return summary
    finally:
        beside.wait()  # also where a later stage failed (its error is the one raised)


def shacc_jax_device():

    return jax.devices()[0]


def _comparison(corr: dict, cats: dict) -> dict:
    pos = cats["cinit_pos"]
    c0 = pos["baseline"]["C_final"]["mean"]
    c1 = pos["shrinking"]["C_final"]["mean"]
    u0 = pos["baseline"]["u_scene"]["mean"]
    u1 = pos["shrinking"]["u_scene"]["mean"]
    d0 = pos["baseline"]["delta_R"]["mean"]
    d1 = pos["shacc"]["delta_R"]["mean"]
    return {"rho_C": corr["C"], "C_change_cinit_pos": _ratio(c0, c1),
            "C_cinit_pos": [c0, c1], "success_cinit_pos": [u0, u1],
            "success_change_cinit_pos": _ratio(u0, u1), "delta_R_cinit_pos": [d0, d1],
            "delta_R_change_cinit_pos": _ratio(d0, d1)}


def _figures(out, summary, scenes, measures, u_base, field, grid, fr) -> None:
    named = {"d": measures["d"], "h": measures["h"], "C": measures["C_init"]}
    plots.correlation_panels(u_base, named, summary["correlation"], out / "fig6a_correlation.png")
    cats = summary["categories"]
    plots.category_bars(cats, "C_final", MODES, out / "fig6b_c_final.png", "C_final")
    plots.category_bars(cats, "u_scene", MODES, out / "fig6c_success.png", "u_scene")
    plots.category_bars(cats, "delta_R", MODES, out / "fig6d_delta_r.png", "delta_R (rad)")
    s = fr.settings
    y_c = float(np.mean([o.position[1] for o in fr.scene.objects]))
    w = s["start_y_halfwidth"]
    plots.success_fields(field.evaluation.rollouts.outcome[0, :, :, : len(fr.spaces)],
                         (grid, grid), (y_c - w, y_c + w), s["start_z_range"], fr.task_ids,
                         field.modes, out / "fig7_success_fields.png",
                         f"{fr.scene.name}: success fields ({grid} x {grid} starts)")
    plots.scene_top_view(fr, path=out / "scene_field.png")
    if summary["robustness"]:
        plots.robustness_lines(summary["robustness"], MODES, out / "robustness.png")
    if summary["intent"]:
        plots.assistance_bars(intent.shares(summary["intent"]), ASSISTANCE,
                              out / "intent_assistance.png")

    plt.close("all")


def _fmt_rho(c) -> str:
    if c.get("rho") is None:
        return "n/a"
    ci = c["ci"]
    return f"{c['rho']:.2f} [{ci[0]:.2f}, {ci[1]:.2f}]"


def _pct_abs(x) -> str:
    return "n/a" if x is None else f"{100 * x:.0f} %"


def _pct(x) -> str:
    return "n/a" if x is None else f"{100 * x:+.0f} %"


def tables_markdown(summary: dict) -> str:
    corr, cats = summary["correlation"], summary["categories"]
    lines = ["**(a) Pearson's rho between baseline u_scene and each measure** "
             "(95 % bootstrap CI)", "", "| measure | rho [95 % CI] |", "| --- | --- |"]
    for k in ("d", "h", "C"):
        lines.append(f"| {k} | {_fmt_rho(corr[k])} |")
    for metric, title, digits in (("C_final", "(b) C_final", 3),
                                  ("u_scene", "(c) success rate u_scene", 2),
                                  ("delta_R", "(d) delta_R at skill start (rad)", 2)):
        lines += ["", f"**{title}**, mean [95 % CI] per category", "",
                  "| category | n | " + " | ".join(MODES) + " |",
                  "| --- | --- | " + " | ".join("---" for _ in MODES) + " |"]
        for c in CATEGORIES:
            e = cats[c]
            cells = " | ".join(format_ci(e[m][metric], digits) for m in MODES)
            lines.append(f"| {c} | {e['n_scenes']} | {cells} |")
    return "\n".join(lines)


def comparison_markdown(summary: dict) -> str:
    cmp = summary["comparison"]
    rho = cmp["rho_C"]
    c0, c1 = cmp["C_cinit_pos"]
    u0, u1 = cmp["success_cinit_pos"]
    d0, d1 = cmp["delta_R_cinit_pos"]

    def num(x, d=2):
        return "n/a" if x is None else f"{x:.{d}f}"

    return "\n".join([
        "| quantity | paper | ours |", "| --- | --- | --- |",
        f"| rho(C, u_scene baseline) | -0.53 [-0.72, -0.27] | {_fmt_rho(rho)} |",
        f"| C, scenes with C_init > 0 (baseline -> Shrinking) | 23 % -> 4 % (-84 %) | "
        f"{num(100 * c0 if c0 is not None else None, 0)} % -> "
        f"{num(100 * c1 if c1 is not None else None, 0)} % "
        f"({_pct(cmp['C_change_cinit_pos'])}) |",
        f"| success, C_init > 0 (baseline -> Shrinking) | 52 % -> 75 % (+45 %) | "
        f"{num(100 * u0 if u0 is not None else None, 0)} % -> "
        f"{num(100 * u1 if u1 is not None else None, 0)} % "
        f"({_pct(cmp['success_change_cinit_pos'])}) |",
        f"| delta_R, C_init > 0 (baseline -> ShaCC) | 1.66 -> 0.52 rad (-69 %) | "
        f"{num(d0)} -> {num(d1)} rad ({_pct(cmp['delta_R_change_cinit_pos'])}) |",
    ])


def discussion(summary: dict) -> str:
    corr, cats, cmp = summary["correlation"], summary["categories"], summary["comparison"]
    rho_c = corr["C"]["rho"]
    others = [abs(corr[k]["rho"]) for k in ("d", "h") if corr[k]["rho"] is not None]
    stronger = rho_c is not None and rho_c < 0 and all(abs(rho_c) > o for o in others)
    u_unc = cats["uncluttered"]
    unc_drop = (u_unc["shrinking"]["u_scene"]["mean"] or 0) < (
        u_unc["baseline"]["u_scene"]["mean"] or 0) - 1e-9
    same = all(cats[c]["shrinking"]["u_scene"]["mean"] == cats[c]["shacc"]["u_scene"]["mean"]
               for c in CATEGORIES)
    parts = [
        f"C correlates {'negatively' if rho_c is not None and rho_c < 0 else 'not negatively'}"
        f" with baseline success (rho = {rho_c:.2f})" if rho_c is not None else
        "rho for C is undefined",
        "and more strongly than d and h" if stronger else "but not more strongly than d or h",
    ]
    text = [
        " ".join(parts) + ". Shrinking changes C on scenes with C_init > 0 by "
        f"{_pct(cmp['C_change_cinit_pos'])} and their success rate by "
        f"{_pct(cmp['success_change_cinit_pos'])}; on uncluttered manual scenes it "
        f"{'lowers' if unc_drop else 'does not lower'} success. ShaCC's success "
        f"{'equals' if same else 'differs from'} Shrinking's in every category, and Merging "
        f"changes delta_R on C_init > 0 scenes by {_pct(cmp['delta_R_change_cinit_pos'])} "
        "against the baseline.",
        "",
        optimized_sentence(cats),
        "",
        "Where and why the numbers differ from the paper's: our scenes with C_init > 0 are "
        f"more cluttered on average (C_init {_pct_abs(cmp['C_cinit_pos'][0])} against the "
        "paper's 23 %), which lowers baseline success and leaves Shrinking more to do. "
        "The scenes are not the paper's "
        "(its twelve manual scenes and twenty random ones are shown only as pictures; ours "
        "follow the same patterns with our own coordinates, and the random set comes from "
        "our seeded generator, half mugs with side grasps and half cups with handle grasps). "
        "The Automaton here follows the greedy step rule of docs/reference/model.md "
        "exactly, with starts on a grid 0.45 m in front of the scene and uniformly random "
        "start orientations; the "
        "paper's Automaton moves towards the closest valid pose of its task, and its start "
        "orientations are only called arbitrary. A uniformly random rotation is on average "
        "pi/2 + 2/pi = 2.21 rad from any fixed one, which is what our baseline delta_R "
        "shows where no meta skill acts; the paper's baseline averages 1.66 rad, so its "
        "start orientations were closer to the task orientations than uniform ones, and the "
        "relative change of delta_R is not comparable one to one. With a few dozen scenes "
        "the confidence intervals are wide, and the correlations move with the random set "
                "(`--seed`).",
    ]
    return "\n".join(text)


def partial_sentence(summary: dict) -> str:
    """C_init against baseline success with the task count controlled for."""
    p = summary["partial_correlation"]
    c, t = p["C_given_tasks"], p["tasks"]

    def r(e):
        if e.get("rho") is None:
            return "undefined"
        ci = e.get("ci")
        return f"{e['rho']:.2f}" + (f" [{ci[0]:.2f}, {ci[1]:.2f}]" if ci else "")

    return (f"The task count alone correlates with baseline success too (rho = {r(t)}); "
            f"controlling for it, C_init's partial correlation with baseline success is "
            f"{r(c)} (not a claim of the paper; a question a reader of it may ask).")


def losses_to_shrinking(scenes: list[dict]) -> dict:
    """How many scenes' held-out success under the optimized spaces is below Shrinking's
    by more than one rollout, the largest such loss, and how often the final choice
    was Shrinking's own sizes."""
    diff = [(s["optimized"]["u_scene"] - s["shrinking"]["u_scene"], 1.0 / s["rollouts_per_mode"])
            for s in scenes]
    lost = [d for d, one in diff if d < -one - 1e-12]
    return {"n_scenes": len(scenes), "n_below_by_more_than_one_rollout": len(lost),
            "worst": min(lost) if lost else None,
            "chose_shrinking": sum(s["chosen"] == "shrinking" for s in scenes)}


def optimized_sentence(cats: dict) -> str:
    """How much success Shrinking leaves on the table (reference/model)."""
    def pp(e) -> str:
        if e is None or e.get("mean") is None:
            return "n/a"
        ci = e.get("ci")
        rng = f" [{100 * ci[0]:+.1f}, {100 * ci[1]:+.1f}]" if ci else ""
        return f"{100 * e['mean']:+.1f}{rng}"

    pos, every = cats["cinit_pos"], cats["all"]
    return (
        "How far is Shrinking from the best sizes? The search (docs/reference/model.md) "
        "looks for "
        "the sizes of the same spaces, within the same bounds, that make the most rollouts "
        "succeed on its own starts; scored on the held-out start grid, the optimized spaces "
        f"change success against Shrinking's by {pp(pos['optimized_gain'])} percentage "
        f"points on scenes with C_init > 0 ({pos['n_scenes']} scenes) and "
        f"{pp(every['optimized_gain'])} on all {every['n_scenes']} (mean over scenes "
        f"[95 % bootstrap CI]); on the search's own starts the gain is "
        f"{pp(pos['search_gain'])} and {pp(every['search_gain'])}. The difference between "
        "the two is what the search fitted to its starts and did not carry over. "
        f"{losses_sentence(every['optimized_losses'])}")


def losses_sentence(loss: dict) -> str:
    n, k = loss["n_scenes"], loss["n_below_by_more_than_one_rollout"]
    worst = "" if loss["worst"] is None else \
        f" (at worst {100 * loss['worst']:+.1f} percentage points)"
    return (f"On {k} of {n} scenes the optimized spaces succeed less often than "
            f"Shrinking's by more than one rollout{worst}; the validation starts chose "
            f"Shrinking's own sizes on {loss['chose_shrinking']}.")


def render_report(summary: dict) -> str:
    s = summary["settings"]
    t = summary["timing_s"]
    return "\n".join([
        "# Reproduction of the paper's simulation experiment", "",
        f"Generated by `shacc reproduce` ({summary['rollouts']} rollouts, "
        f"{summary['categories']['all']['n_scenes']} scenes, seed {s['seed']}, "
        f"{s['bootstrap_resamples']} bootstrap resamples, device {s['device']}).", "",
        "## Fig. 6 as tables", "", tables_markdown(summary), "",
        "## Against the paper", "", claims.markdown(summary["claims"]), "",
        partial_sentence(summary), "",
        discussion(summary), "",
        "## Figures", "",
        "![Fig. 6a](fig6a_correlation.png)", "",
        "![Fig. 6b](fig6b_c_final.png) ![Fig. 6c](fig6c_success.png) "
        "![Fig. 6d](fig6d_delta_r.png)", "",
        "![Fig. 7](fig7_success_fields.png)", "",
        *robustness_section(summary),
        *intent_section(summary),
        f"Time: precompute {t['precompute']:.1f} s, evaluation {t['evaluate']:.1f} s, "
        f"statistics {t['statistics']:.1f} s, then side by side in "
        f"{t['side_by_side']:.1f} s: robustness {t['robustness']:.1f} s, "
        f"success fields {t['success_fields']:.1f} s; intent inference, beside them from "
        f"the evaluation on, {t['intent']:.1f} s.", "",
    ])


def robustness_section(summary: dict) -> list[str]:
    """The report's section on imperfect simulated users (empty where it was not run)."""
    if not summary["robustness"]:
        return ["## Beyond the perfect user", "",
                "Not run: collision checks are on, and they take the perfect user only.", ""]
    return ["## Beyond the perfect user", "",
            "The same scenes and modes with imperfect simulated users, one parameter at a "
            "time (the optimized mode keeps the spaces its search found for the perfect "
            "user). Success u_scene: the mean over scenes with a 95 % bootstrap CI over "
            "scenes; the differences to the baseline are paired scene by scene, in "
            "percentage points. An advantage *holds* where at every level its CI lies "
            f"above zero at no less than {robustness.HOLDS_SHARE:.0%} of the perfect "
            "user's; it *reverses* where some level's CI lies below zero; it *shrinks* "
            "otherwise.", "",
            robustness.markdown(summary["robustness"], MODES), "",
            "![Robustness](robustness.png)", ""]


def intent_section(summary: dict) -> list[str]:
    """The report's section on the paper's open question (empty without random
    scenes)."""
    if not summary["intent"]:
        return []
    return ["## ShaCC and intent inference", "",
            "The paper leaves open how ShaCC combines with assistance that infers the "
            "user's goal from the motion. On the random scenes, the baseline and ShaCC "
            "against blending (`blend`), hindsight optimization (`ho`) and ShaCC with "
            "hindsight optimization (`shacc_ho`), for three users. Means over scenes with "
            "95 % bootstrap CIs; the shares of time are the steps before activation under "
            "no assistance, the meta skill's (scene), assistance towards the intended "
            "task (correct) and towards another (wrong); the comparisons are paired scene "
            "by scene.", "",
            *intent.markdown(summary["intent"]),
            f"![Shares of time under each assistance, {intent.FIGURE_USER}]"
            "(intent_assistance.png)", ""]


def _readme_text(readme: Path) -> str:
    """The README to rewrite, checked before any work: readable text with the markers."""
    try:
        text = readme.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(readme, "--readme", f"cannot be read as text ({e})") from None
    if README_BEGIN not in text or README_END not in text:
        raise InputError(readme, "--readme", f"has no {README_BEGIN!r} ... {README_END!r} "
                         "markers to write between")
    return text


def update_readme(readme: Path, out: Path, summary: dict) -> None:
    text = _readme_text(readme)
    # Links relative to the README, wherever the two are.
    rel = Path(os.path.relpath(out.resolve(), readme.resolve().parent)).as_posix()
    body = "\n".join([
        README_BEGIN, "",
        f"From `shacc reproduce --out {rel} --readme {readme.name}` "
        f"({summary['rollouts']} rollouts on {summary['settings']['device']}, "
        f"{summary['timing_s']['total']:.0f} s):", "",
        tables_markdown(summary), "", claims.markdown(summary["claims"]), "",
        partial_sentence(summary), "",
        discussion(summary), "",
        f"![Fig. 6a]({rel}/fig6a_correlation.png)", "",
        f"![Fig. 6c]({rel}/fig6c_success.png) ![Fig. 6d]({rel}/fig6d_delta_r.png)", "",
        f"![Fig. 7]({rel}/fig7_success_fields.png)", "",
        *([f"With imperfect simulated users ({rel}/report.md, \"Beyond the perfect "
           "user\"):", "", *[f"- {e['sentence']}" for e in summary["robustness"].values()],
           "", f"![Robustness]({rel}/robustness.png)", ""] if summary["robustness"] else []),
        *([f"ShaCC and intent inference ({rel}/report.md, the section of that name):", "",
           *[f"- {line}" for entry in summary["intent"]["users"].values()
             for line in entry["sentences"]],
           "", f"![Shares of time under each assistance]({rel}/intent_assistance.png)", ""]
          if summary["intent"] else []),
        README_END])
    head, rest = text.split(README_BEGIN, 1)
    _, tail = rest.split(README_END, 1)
    write_atomic(readme, (head + body + tail).encode())


# What reproduce writes into its output folder; a folder holding anything else is refused.
REPRODUCE_FILES = ("fig*.png", "scene_field.png", "robustness.png", "intent_assistance.png",
                   "report.md",
                   "summary.json", ".*.tmp")


def cmd_reproduce(args) -> int:
    check_output_dir(args.out, "--out", REPRODUCE_FILES)
    if args.readme:
        check_output_file(args.readme, "--readme")
        _readme_text(Path(args.readme))
    n_random = args.random_scenes if args.random_scenes is not None else (4 if args.quick
                                                                           else 20)
    grid = args.field_grid if args.field_grid is not None else (16 if args.quick else 64)
    with _programs_told():
        summary = run(Path(args.out), n_random, args.seed, args.quick, grid,
                      parse_sets(args.set), args.workers,
                      Path(args.readme) if args.readme else None, args.preset)
    print(claims.markdown(summary["claims"]))
    print()
    print(partial_sentence(summary))
    return 0
