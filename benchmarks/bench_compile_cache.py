"""Wall time of an evaluation with an empty and with a warm compilation cache.

    python benchmarks/bench_compile_cache.py [SCENE] [--repeat 3]
    python benchmarks/bench_compile_cache.py --bake BAKE.npz --scenes 1000

The first form times `shacc evaluate SCENE`; the second (no geometry libraries needed,
for the accelerator machine) evaluates a bake of ``bench_rollouts.py bake`` with
``shacc_jax.run`` in a new process, the cache on as the command line
turns it on, and once more with it off, and checks that the outcomes agree. Each
repeat uses a fresh cache folder: run 1 compiles and stores the programs, run 2 loads
them. Prints the wall times (whole process, imports included) and their ratio;
asserts nothing (performance targets are checked in benchmarks, never in tests).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_SCENE = ROOT / "geometry_precompute" / "scenes" / "09_mug_behind_two.toml"


def wall(cmd: list[str], env: dict) -> float:
    t = time.perf_counter()
    subprocess.run(cmd, env=env, check=True, stdout=subprocess.DEVNULL, cwd=ROOT)
    return time.perf_counter() - t


BAKE_CHILD = """
import hashlib, sys, time
import jax, numpy as np
sys.path.insert(0, {bench!r})
from bench_rollouts import _load_bake
from sweeps import compile_cache
import shacc_jax
compile_cache.enable()
baked = _load_bake({bake!r}, {n})
t = time.perf_counter()
ev = shacc_jax.run(baked).evaluation
print("evaluate", round(time.perf_counter() - t, 3), jax.devices()[0].device_kind,
      hashlib.sha256(np.asarray(ev.rollouts.outcome).tobytes()).hexdigest()[:16])
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", nargs="?", default=str(DEFAULT_SCENE))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--bake", help="a bake from bench_rollouts.py bake (accelerator form)")
    ap.add_argument("--scenes", type=int, default=1000)
    args = ap.parse_args()
    cmd = [sys.executable, "-m", "sweeps", "evaluate", args.scene]
    if args.bake:
        code = BAKE_CHILD.format(bench=str(ROOT / "benchmarks"), bake=args.bake, n=args.scenes)
        cmd = [sys.executable, "-c", code]
        out = subprocess.run(cmd, env={**os.environ, "SHACC_COMPILE_CACHE": "off"},
                             check=True, capture_output=True, text=True, cwd=ROOT).stdout
        print("cache off:", out.strip().splitlines()[-1], flush=True)
    for _ in range(args.repeat):
        with tempfile.TemporaryDirectory() as cache:
            env = {**os.environ, "SHACC_COMPILE_CACHE": cache}
            cold, warm = wall(cmd, env), wall(cmd, env)
            if args.bake:
                last = subprocess.run(cmd, env=env, check=True, capture_output=True,
                                      text=True, cwd=ROOT).stdout.strip().splitlines()[-1]
                print("cache warm, third run:", last, flush=True)
            n = len(os.listdir(cache))
        print(f"empty cache {cold:.2f} s, warm cache {warm:.2f} s, ratio {warm / cold:.2f} "
              f"({n} programs stored)", flush=True)


if __name__ == "__main__":
    from shacc_jax import configure_runtime

    configure_runtime()  # as the commands do, before anything starts JAX
    main()
