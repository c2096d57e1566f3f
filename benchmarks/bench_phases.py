"""Where a program's compile time goes: trace, lower and XLA's compile, per user.

    python benchmarks/bench_phases.py [--users perfect every intent] [--level 0]

Three shipped scenes (01, 07 and 10, an uncluttered and two cluttered ones) on a 2 x 3
start grid, the programs the test suite and a first answer compile most: the paper's
three modes with the perfect user (closed form), with every user setting on (stepped),
and the intent modes with every user setting. Each is traced
(``shacc_jax.evaluate.trace``), lowered and compiled in this process with the
compilation caches off, at XLA's level ``--level`` (0: what the command line uses for
small batches, ``program_cache.QUICK_OPTIONS``; -1: XLA's default). Prints one JSON
line per program: its equations and the seconds of each phase. Run it twice on each
tree to compare, alternating (a tree from ``git archive REV`` on ``PYTHONPATH`` goes
first on the path). Asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace

EVERY_USER = {"user_noise": 0.2, "user_noise_tau": 0.5, "user_tremor": 0.01,
              "user_input": "modes", "user_switch": 0.3}
USERS = {"perfect": ({}, ("baseline", "shrinking", "shacc")),
         "every": (EVERY_USER, ("baseline", "shrinking", "shacc")),
         "intent": (EVERY_USER, ("baseline", "shacc", "blend", "ho", "shacc_ho"))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--users", nargs="+", choices=sorted(USERS), default=list(USERS))
    ap.add_argument("--level", type=int, default=0)
    args = ap.parse_args()

    import jax

    jax.config.update("jax_enable_compilation_cache", False)
    import shacc_jax
    from geometry_precompute import DEFAULTS, bake, load_scene, precompute, shipped_scene_paths

    paths = shipped_scene_paths()
    grid = {"start_grid": [2, 3]}
    scenes = [load_scene(paths[i]) for i in (0, 6, 9)]
    results = [precompute(s, s.settings(DEFAULTS, grid)) for s in scenes]
    options = {} if args.level < 0 else {"xla_backend_optimization_level": args.level}
    for name in args.users:
        user, modes = USERS[name]
        baked = bake([replace(r, settings=r.settings.with_overrides(user)) for r in results])
        g, p, layout = shacc_jax.inputs(baked, modes=modes)
        t0 = time.perf_counter()
        traced = shacc_jax.evaluate.trace(g, p, layout)
        t1 = time.perf_counter()
        lowered = traced.lower()
        t2 = time.perf_counter()
        lowered.compile(options)
        t3 = time.perf_counter()
        print(json.dumps({"users": name, "modes": modes, "stepped": layout.stepped_users,
                          "equations": len(traced.jaxpr.eqns), "trace_s": round(t1 - t0, 2),
                          "lower_s": round(t2 - t1, 2), "compile_s": round(t3 - t2, 2)}),
              flush=True)
        jax.clear_caches()


if __name__ == "__main__":
    main()
