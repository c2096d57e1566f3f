"""Search variants on a bake of random scenes (benchmarks/bench_optimize.py bake): the
mean objective each reaches on the search starts, and CPU against GPU agreement.

    python benchmarks/tune_search.py --bake search.npz --scenes 1000 --compare 64
"""

from __future__ import annotations

import argparse
import json
import time

import jax
import numpy as np
from bench_optimize import _load

from shacc_jax import optimize as opt

VARIANTS = [("shrinking", 0.2), ("shrinking", 0.35), ("center", 0.3), ("center", 0.5)]


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--bake", required=True)
    p.add_argument("--scenes", type=int, default=1000)
    p.add_argument("--compare", type=int, default=0)
    args = p.parse_args()
    baked = _load(args.bake, args.scenes)
    for mean0, sigma in VARIANTS:
        opt.MEAN0, opt.SIGMA0 = mean0, sigma
        jax.clear_caches()  # MEAN0 and SIGMA0 are traced in as constants
        found = opt.search(baked)
        t0 = time.perf_counter()
        found = opt.search(baked)
        row = {"mean0": mean0, "sigma0": sigma, "scenes": args.scenes,
               "search_s": round(time.perf_counter() - t0, 3),
               "objective": float(found.objective.mean()),
               "shrinking": float(found.objective_shrunk.mean())}
        if args.compare:
            small = _load(args.bake, args.compare)
            gpu = opt.search(small)
            with jax.default_device(jax.devices("cpu")[0]):
                cpu = opt.search(small)
            steps = 1.0 / (small.opt_start_mask.sum(1) * small.task_mask.sum(1))
            d = np.abs(cpu.objective - gpu.objective)
            row.update({"compared": args.compare,
                        "same_objective": int(np.sum(d <= 0.5 * steps)),
                        "same_parameters": int(np.sum(np.all(cpu.q == gpu.q, axis=(1, 2)))),
                        "max_objective_difference": float(d.max())})
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    from shacc_jax import configure_runtime

    configure_runtime()  # as the commands do, before anything starts JAX
    main()
