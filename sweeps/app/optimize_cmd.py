"""``shacc optimize SCENE.toml [--json OUT]``: the optimized mode's search for one scene.

Prints, per task, the parameters of Shrinking and of the search (with their bounds),
the success rates of every mode on the scene's usual start grid (held out: the search
never saw those starts), the search's objective on its own starts, and its
convergence (the best objective after each generation). ``--json`` writes the
one-scene JSON object (reference/outputs) with ``modes.optimized`` and an ``optimize`` block.
"""

from __future__ import annotations

import json
import time

from geometry_precompute.schema import PAPER_MODES
from shacc_jax.optimize import winner_name
from sweeps.app.evaluate_cmd import print_table
from sweeps.app.inputs import load_and_precompute
from sweeps.output import announce, check_output_file, clean_json, human_output, write_output
from sweeps.pipeline import evaluate_results, optimized_params, scene_json


def _convergence(history) -> str:
    """The best objective per generation, each new best marked with its generation."""
    marks, last = [], None
    for g, v in enumerate(history):
        if last is None or v > last:
            marks.append(f"{g}: {v:.3f}")
            last = v
    return "  ".join(marks)


def cmd_optimize(args) -> int:
    if args.json and args.json != "-":
        check_output_file(args.json, "--json")
    t0 = time.perf_counter()
    result = load_and_precompute(args.scene, args.set)
    t1 = time.perf_counter()
    ev = evaluate_results([result], PAPER_MODES)
    s = result.settings
    found = ev.searched()
    with human_output(args.json):
        print(f"scene: {result.scene.name}  ({result.scene.source})")
        print(f"C_init {result.C_init:.4f}   C_final {result.C_final:.4f}   Shrinking passes "
              f"{result.iterations}")
        print(f"search: CMA-ES (evosax), population {s['optimize_population']}, "
              f"{s['optimize_generations']} generations, {s['optimize_starts']} search starts "
              f"(seed {s['optimize_seed']})")
        best = optimized_params(ev, 0)
        rows = [("task", "parameter", "min", "init", "shrinking", "optimized")]
        for sp, q in zip(result.spaces, result.q_opt, strict=True):
            for k, name in enumerate(sp.param_names):
                rows.append((sp.task.id, name, f"{sp.q_min[k]:.4f}", f"{sp.q_init[k]:.4f}",
                             f"{q[k]:.4f}", f"{best[sp.task.id][name]:.4f}"))
        widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
        for i, row in enumerate(rows):
            print("  ".join(c.ljust(w) if j < 2 else c.rjust(w)
                            for j, (c, w) in enumerate(zip(row, widths, strict=True))))
            if i == 0:
                print("  ".join("-" * w for w in widths))
        me = ev.evaluation.metrics.u_scene[0]
        grid = dict(zip(ev.modes, me, strict=True))
        success = [("success on", "starts", "initial", "shrinking", "optimized"),
                ("search (what it maximised)", str(s["optimize_starts"]),
                 f"{found.objective_init[0]:.3f}", f"{found.objective_shrunk[0]:.3f}",
                 f"{found.objective[0]:.3f}"),
                ("validation (what chose)", str(s["optimize_validation_starts"]),
                 f"{found.validation_init[0]:.3f}", f"{found.validation_shrunk[0]:.3f}",
                 f"{found.validation[0]:.3f}"),
                ("held out (the grid)", str(ev.baked.n_starts),
                 f"{grid['baseline']:.3f}" if "baseline" in grid else "-",
                 f"{grid['shrinking']:.3f}" if "shrinking" in grid else "-",
                 f"{grid['optimized']:.3f}")]
        widths = [max(len(r[i]) for r in success) for i in range(len(success[0]))]
        print()
        for i, line in enumerate(success):
            print("  ".join(c.ljust(w) if j == 0 else c.rjust(w)
                            for j, (c, w) in enumerate(zip(line, widths, strict=True))))
            if i == 0:
                print("  ".join("-" * w for w in widths))
        print(f"chosen: {winner_name(int(found.winner[0]), s['optimize_candidates'])} "
              f"(selection {s['optimize_selection']}; estimated C of its spaces "
              f"{found.clutteredness[0]:.4f})")
        print(f"convergence (generation: best so far): {_convergence(found.history[0])}")
        print(f"\nheld out: the scene's {ev.baked.n_starts} grid starts (seed {s['seed']})")
        print_table(ev, [0], with_scene=False)
        print(f"time: precompute {1e3 * (t1 - t0):.1f} ms, search and evaluation (with "
              f"compilation) {ev.seconds['evaluate']:.2f} s")
    if args.json:
        write_output(args.json, (json.dumps(clean_json(scene_json(ev, 0))) + "\n").encode())
        announce(args.json)
    return 0
