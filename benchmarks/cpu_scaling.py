"""Whether work slows down per core as a machine's cores fill: the same work in N
processes at once, each timing its own CPU time.

    python benchmarks/cpu_scaling.py [--n 1,4,8,12,16]

Three kinds of work: a pure-Python loop (the cores' speed), a NumPy loop over 16 MB
(memory bandwidth) and our precompute of 150 random 10-task scenes (ms per scene). If
the loop slows down as N grows, so does any CPU-bound code, ours included.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import time

SCENES = 150


def python_loop(_) -> float:
    c = time.process_time()
    s = 0
    for i in range(20_000_000):
        s += i & 7
    return time.process_time() - c


def numpy_loop(_) -> float:
    import numpy as np

    a = np.random.default_rng(0).random(2_000_000)
    c = time.process_time()
    for _ in range(60):
        a = np.sqrt(a * a + 1.0) - 0.5
    return time.process_time() - c


def precompute_ms(k: int) -> float:
    from geometry_precompute import DEFAULTS, precompute, random_scene

    scenes = [random_scene(1000 * k + i, "uniform", 10, 10) for i in range(SCENES)]
    settings = scenes[0].settings(DEFAULTS, {})
    precompute(scenes[0], settings)  # imports and first-call costs
    c = time.process_time()
    for s in scenes:
        precompute(s, settings)
    return (time.process_time() - c) / SCENES * 1e3


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", default="1,4,8,12,16")
    args = ap.parse_args()
    ctx = mp.get_context("spawn")
    for name, f in (("python loop, s", python_loop), ("numpy loop, s", numpy_loop),
                    ("precompute, ms/scene", precompute_ms)):
        for n in (int(x) for x in args.n.split(",")):
            with ctx.Pool(n) as pool:
                t = time.perf_counter()
                r = pool.map(f, range(n))
                wall = time.perf_counter() - t
            print(f"{name:>22} N={n:3d}: mean {sum(r) / n:.3f} max {max(r):.3f} "
                  f"(wall {wall:.1f} s)", flush=True)


if __name__ == "__main__":
    main()
