"""Time of the optimized mode's search (reference/model) and CPU/GPU agreement.

Two steps, so the accelerator machine needs only JAX, evosax and ``shacc_jax``:

    # on any machine with the project installed: precompute and bake random scenes
    python benchmarks/bench_optimize.py bake --scenes 1000 --out search.npz
    # where the timing happens
    python benchmarks/bench_optimize.py run --bake search.npz --per-call 250 1000
    # the same search on the CPU and on the default device (a GPU), seed for seed
    python benchmarks/bench_optimize.py compare --bake search.npz --scenes 64

``run`` reports the first call (compilation included) apart from a second, timed call,
for each scenes-per-call size. The search's sizes are the settings' defaults
(population 64, 30 generations, 64 search starts) unless the bake says otherwise.
Nothing here asserts a speed.
"""

from __future__ import annotations

import argparse
import json
import time
from types import SimpleNamespace

import numpy as np


def cmd_bake(args) -> None:
    from concurrent.futures import ProcessPoolExecutor

    from bench_rollouts import _precompute_one  # the same random 10-task scenes

    from geometry_precompute import bake

    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.workers) as pool:
        results = list(pool.map(_precompute_one, range(args.scenes), chunksize=16))
    b = bake(results)
    np.savez_compressed(args.out, **b.arrays())
    print(f"precomputed and baked {args.scenes} scenes in {time.perf_counter() - t0:.1f} s; "
          f"wrote {args.out}")


def _load(path: str, n: int | None = None) -> SimpleNamespace:
    data = dict(np.load(path))
    if n is not None:
        data = {k: v[:n] for k, v in data.items()}
    return SimpleNamespace(**data, labels={})


def _search(baked, per_call):
    from shacc_jax.optimize import search

    t0 = time.perf_counter()
    found = search(baked, per_call)
    return found, time.perf_counter() - t0


def cmd_run(args) -> None:
    import jax

    with jax.enable_x64(args.x64):
        _run(args)


def _run(args) -> None:
    import jax

    baked = _load(args.bake, args.scenes)
    S = baked.task_mask.shape[0]
    pop, gens = int(baked.optimize_population[0]), int(baked.optimize_generations[0])
    No, T = baked.opt_starts.shape[1], baked.task_mask.shape[1]
    for per in args.per_call:
        _, first = _search(baked, per)
        found, warm = _search(baked, per)
        rollouts = S * pop * gens * No * T
        print(json.dumps({
            "device": str(jax.devices()[0]), "x64": args.x64, "scenes": S, "per_call": per,
            "population": pop, "generations": gens, "search_starts": No, "tasks": T,
            "first_call_s": round(first, 3), "search_s": round(warm, 3),
            "scenes_per_s": round(S / warm, 1),
            "activation_rollouts_per_s": float(f"{rollouts / warm:.3g}"),
            "mean_objective": {"init": float(found.objective_init.mean()),
                               "shrinking": float(found.objective_shrunk.mean()),
                               "optimized": float(found.objective.mean())}}))


def cmd_compare(args) -> None:
    import jax

    with jax.enable_x64(args.x64):
        _compare(args)


def _compare(args) -> None:
    import jax

    baked = _load(args.bake, args.scenes)
    cpu = jax.devices("cpu")[0]
    with jax.default_device(cpu):
        on_cpu, _ = _search(baked, None)
    other, _ = _search(baked, None)
    smaller, _ = _search(baked, 16)  # the same scenes, 16 per call
    S = baked.task_mask.shape[0]
    steps = 1.0 / (baked.opt_start_mask.sum(1) * baked.task_mask.sum(1))
    d_obj = np.abs(on_cpu.objective - other.objective)
    print(json.dumps({
        "devices": [str(cpu), str(jax.devices()[0])], "x64": args.x64, "scenes": S,
        "same_objective": int(np.sum(d_obj <= 0.5 * steps)),
        "objective_within_one_outcome": int(np.sum(d_obj <= 1.5 * steps)),
        "max_objective_difference": float(d_obj.max()),
        "same_parameters_1e-4": int(np.sum(np.all(np.abs(on_cpu.q - other.q) <= 1e-4,
                                                  axis=(1, 2)))),
        "max_parameter_difference": float(np.abs(on_cpu.q - other.q).max()),
        "same_parameters_16_per_call": int(np.sum(np.all(smaller.q == other.q, axis=(1, 2)))),
        "max_objective_difference_16_per_call": float(np.abs(smaller.objective -
                                                             other.objective).max())}))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    b = sub.add_parser("bake")
    b.add_argument("--scenes", type=int, default=1000)
    b.add_argument("--workers", type=int, default=2)
    b.add_argument("--out", required=True)
    r = sub.add_parser("run")
    r.add_argument("--bake", required=True)
    r.add_argument("--scenes", type=int, default=None)
    r.add_argument("--per-call", type=int, nargs="+", default=[1000])
    c = sub.add_parser("compare")
    c.add_argument("--bake", required=True)
    c.add_argument("--scenes", type=int, default=64)
    for q in (r, c):
        q.add_argument("--x64", action="store_true", help="the whole search in float64")
    args = p.parse_args()
    {"bake": cmd_bake, "run": cmd_run, "compare": cmd_compare}[args.cmd](args)


if __name__ == "__main__":
    from shacc_jax import configure_runtime

    configure_runtime()  # as the commands do, before anything starts JAX
    main()
