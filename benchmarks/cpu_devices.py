"""Stepped users' CPU throughput over N XLA CPU devices (reference/index).

Each device count runs in its own process (JAX fixes its CPU devices when it starts),
JAX_PLATFORMS=cpu, the compile cache off; each times ``shacc_jax.execute`` of a plan
over the N devices (first call, then the minimum of three), user 0.2 / 0.2 / 0.01:

    python benchmarks/cpu_devices.py --bake bake.npz --scenes 400 --devices 1 2 4 8 16

Nothing here asserts a speed.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time


def one(bake: str, scenes: int, devices: int) -> dict:
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import jax

    jax.config.update("jax_num_cpu_devices", devices)
    import bench_rollouts as br
    import numpy as np

    import shacc_jax

    raw = br._load_bake(bake, scenes, False, (0.2, 0.2, 0.01), False)
    p = shacc_jax.plan(raw, devices=jax.devices()[:devices])
    t = time.perf_counter()
    shacc_jax.execute(p, raw)
    first = time.perf_counter() - t
    times = []
    for _ in range(3):
        t = time.perf_counter()
        shacc_jax.execute(p, raw)
        times.append(time.perf_counter() - t)
    return {"scenes": scenes, "devices": devices, "cores": os.cpu_count(),
            "first_s": round(first, 2), "min_s": round(min(times), 3),
            "median_s": round(float(np.median(times)), 3),
            "rollouts_per_s": round(scenes * 1080 / min(times))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bake", required=True)
    ap.add_argument("--scenes", type=int, default=400)
    ap.add_argument("--devices", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--one", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        print(json.dumps(one(args.bake, args.scenes, args.one)), flush=True)
        return
    env = dict(os.environ, JAX_PLATFORMS="cpu", SHACC_COMPILE_CACHE="off")
    for n in args.devices:
        out = subprocess.run([sys.executable, __file__, "--bake", args.bake, "--scenes",
                              str(args.scenes), "--one", str(n)], env=env,
                             capture_output=True, text=True)
        lines = [line for line in out.stdout.splitlines() if line.startswith("{")]
        print(lines[-1] if lines else out.stderr[-2000:], flush=True)


if __name__ == "__main__":
    main()
