"""The optimized mode's search from a cold process: 8 random scenes of 3, 5, 7 and 9
tasks (two each), so four search programs, one per task count, compiled and run.
Prints the seconds of the search (compilation included) and a digest of its answers,
to compare two trees or two machines.

    python benchmarks/bench_search_compile.py
"""

from __future__ import annotations

import json
import time

import numpy as np

from geometry_precompute import bake, precompute, random_scene
from shacc_jax import optimize


def main() -> None:
    t0 = time.perf_counter()
    scenes = [random_scene(seed, "uniform", n, n)
              for seed, n in zip(range(8), [3, 3, 5, 5, 7, 7, 9, 9], strict=True)]
    baked = bake([precompute(s) for s in scenes], 10)
    t1 = time.perf_counter()
    found = optimize.search(baked)
    t2 = time.perf_counter()
    print(json.dumps({"precompute_s": round(t1 - t0, 3), "search_s": round(t2 - t1, 3),
                      "q_sum": float(np.sum(found.q)), "objective": found.objective.tolist()}))


if __name__ == "__main__":
    main()
