"""Does the optimized mode lose to Shrinking on starts it did not see? (reference/model)

For random scenes (half ``uniform``, half ``gaussian``, 5 to 10 tasks) and the shipped
manual scenes, the optimized mode is run twice, with ``optimize_selection = search``
(the earlier objective: ties to larger spaces, the search's best on its own starts)
and ``validation`` (ties to lower C, then larger spaces; the final choice on the
validation starts, ties to Shrinking), and both are scored on the scene's usual start
grid, which neither search saw. Per selection it reports the share of scenes whose
held-out success is below Shrinking's by more than one rollout, the mean held-out gain
over Shrinking with a scene-level percentile-bootstrap CI (scipy), how often each
candidate won, and the time of the search and evaluation.

    python benchmarks/bench_optimize_heldout.py --scenes 1000 --workers 16 --out held.json

Nothing here asserts anything; the numbers go to benchmarks/RESULTS.md.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace

import numpy as np


def _precompute(item):
    from geometry_precompute import load_scene, precompute, random_scene

    kind, ref, overrides = item
    scene = load_scene(ref) if kind == "manual" else random_scene(ref[0], ref[1], 5, 10)
    return precompute(scene, scene.settings(overrides=overrides))


def _summary(name, u_shr, u_opt, one, chosen, seconds, n_boot, seed) -> dict:
    from sweeps.analysis.stats import mean_ci

    gain = u_opt - u_shr
    lost = gain < -one - 1e-12
    return {"selection": name, "scenes": len(gain),
            "share_below_shrinking_by_more_than_one_rollout": float(lost.mean()),
            "n_below": int(lost.sum()),
            "worst_pp": float(100 * gain.min()),
            "mean_gain_pp": {k: (None if v is None else
                                 (100 * np.asarray(v)).tolist()) for k, v in
                             mean_ci(gain, n_boot, seed).items() if k in ("mean", "ci")},
            "chosen": {k: int(v) for k, v in zip(*np.unique(chosen, return_counts=True),
                                                 strict=True)},
            "seconds": round(seconds, 2)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=1000, help="random scenes")
    ap.add_argument("--seed", type=int, default=0, help="first random scene's seed")
    ap.add_argument("--workers", type=int, default=os.cpu_count())
    ap.add_argument("--no-manual", action="store_true", help="random scenes only")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    ap.add_argument("--bootstrap", type=int, default=10_000)
    ap.add_argument("--out", help="JSON file")
    args = ap.parse_args()

    import jax

    from geometry_precompute import bake, shipped_scene_paths
    from shacc_jax import run
    from shacc_jax.optimize import winner_name
    from sweeps import compile_cache
    from sweeps.app.inputs import parse_sets

    compile_cache.enable()
    sets = parse_sets(args.set)
    items = [("random", (args.seed + i, ("uniform", "gaussian")[i % 2]), sets)
             for i in range(args.scenes)]
    if not args.no_manual:
        items += [("manual", str(p), sets) for p in shipped_scene_paths()]
    out = {"device": str(jax.devices()[0]), "scenes": len(items), "settings": args.set,
           "selections": []}
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.workers, mp_context=multiprocessing.get_context("spawn")) \
            as pool:
        precomputed = list(pool.map(_precompute, items, chunksize=8))
    out["precompute_s"] = round(time.perf_counter() - t0, 2)
    for selection in ("search", "validation"):  # a setting of the search only
        results = [replace(r, settings=r.settings.with_overrides(
            {"optimize_selection": selection})) for r in precomputed]
        t1 = time.perf_counter()
        baked = bake(results)
        ev, found = run(baked, ("shrinking", "optimized"))
        t2 = time.perf_counter()
        u = ev.metrics.u_scene
        one = 1.0 / ev.metrics.n_rollouts[:, 0]
        chosen = np.array([winner_name(w, r.settings["optimize_candidates"])
                           .split(" #")[0] for w, r in zip(found.winner, results, strict=True)])
        manual = np.array([k == "manual" for k, _, _ in items])
        uniform = np.array([k == "random" and r[1] == "uniform" for k, r, _ in items])
        entry = {"search_and_evaluation_s": round(t2 - t1, 2)}
        for part, keep in (("all", np.ones(len(items), bool)), ("manual", manual),
                           ("uniform", uniform), ("gaussian", ~manual & ~uniform)):
            if keep.any():
                entry[part] = _summary(selection, u[keep, 0], u[keep, 1], one[keep],
                                       chosen[keep], t2 - t1, args.bootstrap, 0)
        entry["mean_search_gain_pp"] = float(100 * np.mean(found.objective
                                                           - found.objective_shrunk))
        out["selections"].append({selection: entry})
        print(json.dumps({selection: entry}), flush=True)
    if args.out:
        with open(args.out, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    from shacc_jax import configure_runtime

    configure_runtime()  # as the commands do, before anything starts JAX
    main()
