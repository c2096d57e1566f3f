"""The sweep's precompute work without the sweep: K processes at once, each running
``geometry_precompute.batch.precompute_batch`` (the precompute task a sweep's worker
runs: build the random scene, precompute, store in the cache, bake) on its share of the
e2e config's scenes, in batches as the sweep sends them. Prints, per K, the wall time,
the summed CPU seconds and the CPU milliseconds per scene.

If a scene costs as much per CPU-second here as inside a sweep at the same K, the
growth with K is the host's (shared cores, memory bandwidth, clock), not Dask's; if it
costs less here, the difference is what the sweep adds around the task.

    python benchmarks/bench_precompute_parallel.py --scenes 4000 --procs 1 16 32 60
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import tempfile
import time

for _v in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_v, "1")


def _work(args) -> tuple[float, float, int]:
    """One process's share: (its wall seconds, its CPU seconds, scenes done)."""
    seeds, batch, cache = args
    from geometry_precompute.batch import precompute_batch

    refs = [(s, "uniform" if s % 2 == 0 else "gaussian", 10, 10) for s in seeds]
    t0, c0 = time.perf_counter(), time.process_time()
    for i in range(0, len(refs), batch):
        precompute_batch(refs[i:i + batch], [{}], cache, 10, 10)
    return time.perf_counter() - t0, time.process_time() - c0, len(refs)


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--scenes", type=int, default=2000)
    p.add_argument("--procs", type=int, nargs="+", default=[1, 4])
    p.add_argument("--batch", type=int, default=16, help="scenes per precompute task")
    args = p.parse_args()
    ctx = mp.get_context("forkserver")
    ctx.set_forkserver_preload(["geometry_precompute.batch"])
    rows = []
    for k in args.procs:
        n = max(args.scenes, k) if k > 1 else min(args.scenes, 400)
        with tempfile.TemporaryDirectory() as cache:
            shares = [(list(range(i, n, k)), args.batch, cache) for i in range(k)]
            with ctx.Pool(k) as pool:
                pool.map(_work, [([0], 1, cache)] * k)  # every process warmed up
                t0 = time.perf_counter()
                got = pool.map(_work, shares)
                wall = time.perf_counter() - t0
        cpu = sum(g[1] for g in got)
        rows.append({"procs": k, "scenes": n, "wall_s": round(wall, 2),
                     "cpu_s": round(cpu, 1), "cpu_ms_per_scene": round(1000 * cpu / n, 2),
                     "scenes_per_s": round(n / wall, 1)})
        print(json.dumps(rows[-1]), flush=True)


if __name__ == "__main__":
    main()
