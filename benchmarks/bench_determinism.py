"""Are a rollout's bits independent of its batch on this device? (shacc_jax/determinism.py)

Evaluates random scenes whole, then the same start grid in pieces of several sizes and
the scenes in several sub-batches, and counts the Rollouts values that differ in any
bit. On a CPU the test suite checks this; this script is for the accelerator, which CI
does not have.

    python benchmarks/bench_determinism.py --scenes 200

Nothing here asserts; it prints one JSON line.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=200)
    ap.add_argument("--grid", type=int, nargs=2, default=[6, 6])
    args = ap.parse_args()

    import jax

    import shacc_jax
    from geometry_precompute import bake, precompute, random_scene

    results = [precompute(random_scene(i, ("uniform", "gaussian")[i % 2], 5, 10),
                          {"start_grid": args.grid}) for i in range(args.scenes)]
    baked = bake(results)

    def run(b):
        return shacc_jax.run(b).evaluation.rollouts

    whole = run(baked)
    N, S = baked.n_starts, baked.n_scenes
    differ = {}
    for size in (2, 5, 7, N // 2):
        bad = 0
        for a in range(0, N - 1, size):
            idx = np.arange(a, min(a + size, N))
            part = run(replace(baked, starts=baked.starts[:, idx],
                               start_index=baked.start_index[:, idx]))
            bad += sum(int(np.sum(np.take(getattr(whole, f), idx, axis=2).view(np.uint8)
                                  != getattr(part, f).view(np.uint8)))
                       for f in whole._fields)
        differ[f"starts in pieces of {size}"] = bad
    for cut in (2, S // 3, S // 2):
        bad = 0
        for lo in range(0, S, cut):
            part = run(bake(results[lo:lo + cut], baked.n_tasks,
                            max_objects=baked.obj_mask.shape[1]))
            bad += sum(int(np.sum(getattr(whole, f)[lo:lo + cut].view(np.uint8)
                                  != getattr(part, f).view(np.uint8)))
                       for f in whole._fields)
        differ[f"scenes in batches of {cut}"] = bad
    print(json.dumps({"device": str(jax.devices()[0]), "scenes": S, "starts": N,
                      "differing_bytes": differ}))


if __name__ == "__main__":
    from shacc_jax import configure_runtime

    configure_runtime()  # as the commands do, before anything starts JAX
    main()
