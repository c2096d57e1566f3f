"""``shacc evaluate SCENE.toml [MORE.toml | FOLDER ...]``: scenes end to end in one
batch (one compilation), a readable summary and, with ``--json``, the
one-scene JSON object (reference/outputs) per scene.

``--json OUT`` writes JSON Lines: a one-scene JSON object (reference/outputs) per line, in
the order evaluated. For one scene that file is also a plain JSON document.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

import shacc_jax
from geometry_precompute import InputError
from geometry_precompute.baking import bake
from geometry_precompute.loading import scene_files as folder_scene_files
from geometry_precompute.settings import describe_user
from shacc_jax.types import ASSISTANCE, OUTCOMES
from sweeps.app.inputs import load_and_precompute
from sweeps.output import announce, check_output_file, clean_json, human_output, write_output
from sweeps.pipeline import evaluate_results, scene_json, tasks_json


def scene_files(args: list[str]) -> list[Path]:
    """Scene arguments as files: a folder stands for its ``*.toml`` scene files, sorted
    (less the template files beside them)."""
    out: list[Path] = []
    for a in args:
        p = Path(a)
        if p.is_dir():
            found = folder_scene_files(p)
            if not found:
                raise InputError(p, "<folder>", "holds no *.toml scene files")
            out += found
        else:
            out.append(p)
    return out


def _outcome_columns(results) -> int:
    # The collision column only where collision checking is on for some scene.
    return 5 if any(r.settings["collision"] != "off" for r in results) else 4


def print_summary(ev, s: int = 0) -> None:
    """One scene in detail: tasks, C, clusters, and a row per mode."""
    r = ev.results[s]
    ids = r.task_ids
    me = ev.evaluation.metrics
    meta = r.meta_clusters()
    print(f"scene: {r.scene.name}  ({r.scene.source})")
    if r.scene.description:
        print(f"  {r.scene.description}")
    print(f"tasks: {', '.join(ids)}")
    print(f"C_init {r.C_init:.4f}   C_final {r.C_final:.4f}   Shrinking passes {r.iterations}")
    print("clusters: " + ("none" if not meta else
                          "  ".join("[" + ", ".join(ids[i] for i in c) + "]" for c in meta)))
    n_starts = ev.baked.n_starts
    print(f"user: {describe_user(r.settings)}")
    print(f"rollouts per mode: {int(me.n_rollouts[s, 0])} ({n_starts} starts x {len(ids)} tasks)")
    print_table(ev, [s], with_scene=False)
    print_how_long(ev, [s], with_scene=False)


def print_table(ev, scenes: list[int], with_scene: bool = True) -> None:
    """A row per (scene, mode): success rate, outcome counts, mean delta_R."""
    me = ev.evaluation.metrics
    k = _outcome_columns([ev.results[s] for s in scenes])
    w = max([5] + [len(ev.results[s].scene.name) for s in scenes]) if with_scene else 0
    head = (f"{'scene':<{w}} " if with_scene else "") + f"{'mode':<10} {'rate':>8} " + \
        " ".join(f"{o:>9}" for o in OUTCOMES[:k]) + f" {'mean dR (rad)':>14}"
    print(head)
    print("-" * len(head))
    for s in scenes:
        name = ev.results[s].scene.name
        for m, mode in enumerate(ev.modes):
            counts = " ".join(f"{int(c):>9}" for c in me.outcome_counts[s, m, :k])
            dr = me.delta_R_mean[s, m]
            dr_txt = "n/a" if dr != dr else f"{dr:.3f}"
            lead = f"{name:<{w}} " if with_scene else ""
            print(f"{lead}{mode:<10} {me.u_scene[s, m]:>8.3f} {counts} {dr_txt:>14}")


def print_how_long(ev, scenes: list[int], with_scene: bool = True) -> None:
    """A row per (scene, mode): the mean time to activation and path length of the
    successes, and the fractions of the steps under each kind of assistance."""
    me = ev.evaluation.metrics
    w = max([5] + [len(ev.results[s].scene.name) for s in scenes]) if with_scene else 0
    head = (f"{'scene':<{w}} " if with_scene else "") + f"{'mode':<10} {'time (s)':>9} " \
        f"{'path (m)':>9}  assisted: " + " ".join(f"{k:>7}" for k in ASSISTANCE)
    print()
    print(head)
    print("-" * len(head))

    def f(v, fmt):
        return "n/a" if v != v else format(v, fmt)

    for s in scenes:
        lead = f"{ev.results[s].scene.name:<{w}} " if with_scene else ""
        for m, mode in enumerate(ev.modes):
            parts = " ".join(f"{f(v, '.3f'):>7}" for v in me.assist_fraction[s, m])
            print(f"{lead}{mode:<10} {f(me.time_mean[s, m], '.2f'):>9} "
                  f"{f(me.path_length_mean[s, m], '.3f'):>9}            {parts}")
    if len(scenes) > 1:
        from sweeps.analysis.stats import format_ci, mean_ci  # deferred: scipy, 0.3 s

        print(f"mean over the {len(scenes)} scenes [95 % CI]:")
        for m, mode in enumerate(ev.modes):
            def ci(a, digits):
                return format_ci(mean_ci(np.asarray(a)[scenes], 2000), digits)
            share = ", ".join(f"{k} {ci(me.assist_fraction[:, m, i], 3)}"
                              for i, k in enumerate(ASSISTANCE))
            print(f"  {mode}: time {ci(me.time_mean[:, m], 2)} s, path "
                  f"{ci(me.path_length_mean[:, m], 3)} m; assisted: {share}")


def print_drawn(ev) -> None:
    """With a population of users and a baseline to hold against: per drawn parameter,
    the advantage of ShaCC over the baseline from its lowest to its highest quartile."""
    user = ev.evaluation.rollouts.user
    if user is None or not user.shape[-1] or "baseline" not in ev.modes:
        return
    from sweeps.analysis.robustness import drawn  # deferred: scipy.stats, about 1 s

    found = drawn(np.asarray(ev.evaluation.rollouts.outcome), np.asarray(user),
                  np.asarray(ev.baked.task_mask), list(ev.modes))
    if found:
        print("\nsuccess against the drawn users (rollouts binned by quartiles of each value; "
              "CIs over scenes):")
        for entry in found.values():
            print(f"  {entry['sentence']}")


def print_tasks(ev, s: int, with_scene: bool = False) -> None:
    """Scene ``s`` per task: per mode its success rate and outcome counts."""

    r = ev.results[s]
    k = _outcome_columns([r])
    detail = tasks_json(ev, s)
    w = max(len("task"), *(len(t["id"]) for t in detail))
    print(f"\nper task{f' ({r.scene.name})' if with_scene else ''}:")
    head = f"{'task':<{w}} {'template':<12} {'mode':<10} {'rate':>7} " + \
        " ".join(f"{o:>9}" for o in OUTCOMES[:k])
    print(head)
    print("-" * len(head))
    for t in detail:
        for i, (mode, e) in enumerate(t["modes"].items()):
            lead = f"{t['id']:<{w}} {t['template']:<12} " if i == 0 else " " * (w + 14)
            counts = " ".join(f"{e['outcome_counts'][o]:>9}" for o in OUTCOMES[:k])
            print(f"{lead}{mode:<10} {e['success_rate']:>7.3f} {counts}")


def print_plan(results, modes) -> int:
    """``shacc evaluate --plan``: the RunPlan of the batch, nothing evaluated."""

    baked = bake(results)
    plain = [m for m in modes if m != "optimized"]
    if plain:
        print(shacc_jax.plan(baked, plain).describe())
    if "optimized" in modes:
        if plain:
            print()
        print("optimized: the search first (its own starts), then the shacc mode on the "
              "spaces it found:")
        print(shacc_jax.plan(baked, ["shacc"]).describe())
    return 0


def cmd_evaluate(args) -> int:
    if len(set(args.modes)) != len(args.modes):
        raise InputError("<arguments>", "--modes", f"each mode once, got {args.modes}")
    if args.json and args.json != "-":
        check_output_file(args.json, "--json")
    paths = scene_files(args.scene)
    t0 = time.perf_counter()
    results = [load_and_precompute(p, args.set) for p in paths]
    t1 = time.perf_counter()
    if args.plan:
        return print_plan(results, args.modes)
    ev = evaluate_results(results, args.modes)
    with human_output(args.json):
        if len(results) == 1:
            print_summary(ev)
        else:
            print(f"{len(results)} scenes, {ev.baked.n_starts} starts each, evaluated as "
                  "one batch")
            users = {describe_user(r.settings) for r in results}
            print("user: " + (users.pop() if len(users) == 1 else "per scene, as its "
                              "settings say"))
            print_table(ev, list(range(len(results))))
            print_how_long(ev, list(range(len(results))))
        print_drawn(ev)
        if len(results) <= 10:
            for s in range(len(results)):
                print_tasks(ev, s, with_scene=len(results) > 1)
        else:
            print("per-task rates: in --json (tasks_detail), for batches of more than 10")
        print(f"time: precompute {1e3 * (t1 - t0):.1f} ms, evaluation (with compilation) "
              f"{ev.seconds['evaluate']:.2f} s")
    if args.json:
        lines = [json.dumps(clean_json(scene_json(ev, s))) for s in range(len(results))]
        write_output(args.json, ("\n".join(lines) + "\n").encode())
        announce(args.json)
    return 0
