"""Where the time goes for one sweep chunk after its precompute: the join of the precompute
tasks' bakes (a CPU worker's task in a sweep, untimed here), the evaluation worker's
part, then the tables (a CPU worker's task); then a profile of the evaluation worker's
part.

    python benchmarks/bench_chunk.py [--scenes 1024] [--workers 16] [--repeat 3]

The chunk's scenes are precomputed and baked on a local Dask cluster (as in a sweep),
then ``evaluation_worker.evaluate_chunk`` runs in this process, on its default device.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import tempfile
import time


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", type=int, default=1024)
    ap.add_argument("--workers", type=int, default=16)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    from geometry_precompute.batch import precompute_batch
    from sweeps import compile_cache
    from sweeps.config import parse_config
    from sweeps.distributed.cluster import connect
    from sweeps.distributed.evaluation_worker import (
        ChunkJob,
        encode_chunk,
        evaluate_chunk,
        join_chunk,
    )
    from sweeps.distributed.plan import plan, precompute_batches, shapes

    compile_cache.enable()
    cfg = parse_config({"name": "chunk", "chunk": args.scenes, "source": {
        "kind": "random", "count": args.scenes, "tasks": [10, 10], "seed": 0}},
        "<bench>", tempfile.gettempdir())
    chunk, shp = plan(cfg)[0], shapes(cfg)
    t = time.perf_counter()
    with connect(None, args.workers) as pool, tempfile.TemporaryDirectory() as cache:
        futures = [pool.client.submit(precompute_batch, [cfg.random_ref(i) for i in part],
                                      [{}], cache, shp.tasks, shp.objects,
                                      resources=pool.precompute)
                   for part in precompute_batches(chunk.scenes, args.workers)]
        batches = pool.client.gather(futures)
    print(f"precompute of {args.scenes} scenes on {args.workers} workers: "
          f"{time.perf_counter() - t:.2f} s (cluster start included)")
    job = ChunkJob(chunk, ({},), cfg.modes, shp, ())
    for k in range(args.repeat):
        joined = join_chunk(job, *batches)  # on a CPU worker in a sweep
        t = time.perf_counter()
        arrays = evaluate_chunk(job, joined)
        t1 = time.perf_counter()
        res = encode_chunk(job, arrays)  # on a CPU worker in a sweep
        print(f"chunk {k}: evaluation worker {t1 - t:.3f} s, "
              f"tables {time.perf_counter() - t1:.3f} s "
              f"{ {k: round(v, 3) for k, v in res.seconds.items()} } "
              f"compiled {res.compiled} loaded {res.loaded}, {res.n_rollouts} rollouts")
    prof = cProfile.Profile()
    prof.enable()
    evaluate_chunk(job, joined)
    prof.disable()
    out = io.StringIO()
    pstats.Stats(prof, stream=out).sort_stats("cumulative").print_stats(35)
    print(out.getvalue())


if __name__ == "__main__":
    from shacc_jax import configure_runtime

    configure_runtime()  # as the commands do, before anything starts JAX
    main()
