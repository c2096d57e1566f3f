"""Whether a CPU program pays for XLA's optimisations: each case lowered once, compiled at
level 0 (``program_cache.QUICK_OPTIONS``) and at XLA's default, and run twice each.

    python benchmarks/bench_levels.py [--cases closed-shipped closed-random ...]

Cases: the paper's three modes in closed form on the shipped scenes (four copies, 6 x 6
starts) and on 40 random 10-task scenes; a noisy user (stepped) on the shipped scenes
(two copies); the intent modes with baseline and shacc on the shipped scenes (one copy)
and on 4 random 10-task scenes; the optimized mode's search on two random 10-task
scenes with a small search (population 8, 3 generations, 16 search starts) and with the
default sizes, and on six 4-task scenes with the small search. Prints one JSON line per
case and level: its work (closed-form rollouts, or the search's activation rollouts), the
seconds of trace and lowering, of the compile, and of each run. The break-even work of a
case is where the compile time saved at level 0 equals the run time lost, which is what
``program_cache.QUICK_COMPILE_ROLLOUTS`` and ``runplan.LEVEL_COST`` stand for. Asserts
nothing; the caches are off.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace

SMALL_SEARCH = {"optimize_population": 8, "optimize_generations": 3, "optimize_starts": 16}


def _evaluation(results, modes):
    import shacc_jax
    from geometry_precompute import bake
    from shacc_jax.runplan import program_work

    g, p, layout = shacc_jax.inputs(bake(results), modes=modes)
    lowered = shacc_jax.evaluate.trace(g, p, layout).lower()
    return lowered, (g, p), program_work(g, p, layout)


def _search(results, T):
    import jax
    import numpy as np

    from geometry_precompute import bake
    from shacc_jax import optimize
    from shacc_jax.types import Geometry, Params, SearchProblem

    baked = bake(results, T)
    trees = [jax.tree.map(np.asarray, kind.from_bake(baked, np.float64))
             for kind in (Geometry, Params, SearchProblem)]
    pop, gens, cand = optimize.search_sizes(baked)
    n_val = int(np.max(trees[2].optimize_validation_starts))
    S = len(results)
    args = tuple(optimize.cut(t, np.arange(S), T) for t in trees)
    work = S * T * (pop * gens * trees[2].opt_starts.shape[1] + (cand + 2) * n_val)
    lowered = optimize._search.trace(*args, population=pop, generations=gens,
                                     candidates=cand, n_val=n_val).lower()
    return lowered, args, work


def _case(name):
    from geometry_precompute import (
        DEFAULTS,
        load_scene,
        precompute,
        random_scene,
        shipped_scene_paths,
    )

    shipped = [load_scene(p) for p in shipped_scene_paths()]

    def shipped_at(copies, **over):
        return [precompute(s, s.settings(DEFAULTS, {"start_grid": [6, 6], **over}))
                for s in shipped * copies]

    def randoms(n, T, over=None):
        out = [precompute(random_scene(seed, "uniform", T, T)) for seed in range(n)]
        return [replace(r, settings=r.settings.with_overrides(over or {})) for r in out]

    paper = ("baseline", "shrinking", "shacc")
    if name == "closed-shipped":
        return _evaluation(shipped_at(4), paper)
    if name == "closed-random":
        return _evaluation(randoms(40, 10), paper)
    if name == "noisy-shipped":
        return _evaluation(shipped_at(2, user_noise=0.2, user_tremor=0.01), paper)
    if name == "intent-shipped":  # reproduce's intent section's modes
        return _evaluation(shipped_at(1), ("baseline", "shacc", "blend", "ho", "shacc_ho"))
    if name == "intent-random":
        return _evaluation(randoms(4, 10), ("baseline", "shacc", "blend", "ho", "shacc_ho"))
    if name == "search-small-10":
        return _search(randoms(2, 10, SMALL_SEARCH), 10)
    if name == "search-default-10":
        return _search(randoms(2, 10), 10)
    if name == "search-small-4":
        return _search(randoms(6, 4, SMALL_SEARCH), 4)
    raise ValueError(name)


CASES = ("closed-shipped", "closed-random", "noisy-shipped", "intent-shipped", "intent-random",
         "search-small-10", "search-small-4", "search-default-10")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", nargs="+", choices=CASES, default=list(CASES))
    args = ap.parse_args()

    import jax

    jax.config.update("jax_enable_compilation_cache", False)
    from shacc_jax import program_cache

    for name in args.cases:
        with jax.enable_x64(name.startswith("search")):  # as the search runs
            t0 = time.perf_counter()
            lowered, call_args, work = _case(name)
            t1 = time.perf_counter()
            for level, options in (("0", program_cache.QUICK_OPTIONS), ("default", None)):
                t2 = time.perf_counter()
                compiled = lowered.compile(options)
                t3 = time.perf_counter()
                runs = []
                for _ in range(2):
                    t = time.perf_counter()
                    jax.block_until_ready(compiled(*call_args))
                    runs.append(round(time.perf_counter() - t, 3))
                print(json.dumps({"case": name, "level": level, "work": int(work),
                                  "precompute_trace_lower_s": round(t1 - t0, 2),
                                  "compile_s": round(t3 - t2, 2), "run_s": runs}), flush=True)
        jax.clear_caches()


if __name__ == "__main__":
    from shacc_jax import configure_runtime

    configure_runtime()
    main()
