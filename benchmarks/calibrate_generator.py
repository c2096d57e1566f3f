"""C_init of random scenes for candidate table areas and gaussian spreads: how the
``paper`` preset of the generator (geometry_precompute/generate.py) was chosen.

For each candidate (table half-width for ``uniform``, sigma for ``gaussian``),
precomputes N scenes of 5 to 10 tasks (seeds 0..N-1) and reports the mean C_init with a
95 % percentile-bootstrap CI over scenes, the share of scenes with C_init > 0, and the
quartiles. The paper reports uniform scenes with C_init of at most about 0.11 and
gaussian scenes about 0.30.

    python benchmarks/calibrate_generator.py --scenes 1000 --half 0.3 0.5 0.6 --sigma 0.1 0.15

Nothing here asserts; it prints one JSON line per candidate.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor

import numpy as np


def _c_init(item) -> tuple[float, int]:
    import geometry_precompute.generate as gen
    from geometry_precompute import precompute

    seed, kind, half, sigma = item
    gen.PRESETS["candidate"] = gen.Preset(half, sigma, "calibration candidate")
    r = precompute(gen.random_scene(seed, kind, 5, 10, "candidate"))
    return r.C_init, len(r.spaces)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=1000)
    ap.add_argument("--half", type=float, nargs="*", default=[], help="uniform: half widths, m")
    ap.add_argument("--sigma", type=float, nargs="*", default=[], help="gaussian: sigmas, m")
    ap.add_argument("--workers", type=int, default=os.cpu_count())
    args = ap.parse_args()
    from sweeps.analysis.stats import mean_ci

    jobs = [("uniform", h, 0.10) for h in args.half] + [("gaussian", 0.30, s)
                                                        for s in args.sigma]
    with ProcessPoolExecutor(args.workers, mp_context=multiprocessing.get_context("spawn")) \
            as pool:
        for kind, half, sigma in jobs:
            got = list(pool.map(_c_init, [(i, kind, half, sigma) for i in range(args.scenes)],
                                chunksize=16))
            c = np.array([g[0] for g in got])
            print(json.dumps({"kind": kind, "table_half": half, "sigma": sigma,
                              "scenes": args.scenes, "C_init": mean_ci(c, 2000, 0),
                              "share_positive": float(np.mean(c > 0)),
                              "quartiles": np.quantile(c, [0.25, 0.5, 0.75]).round(4).tolist(),
                              "mean_tasks": float(np.mean([g[1] for g in got]))}), flush=True)


if __name__ == "__main__":
    main()
