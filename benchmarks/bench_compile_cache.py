"""Wall time of `shacc evaluate SCENE` with an empty and with a warm compilation cache.

    python benchmarks/bench_compile_cache.py [SCENE] [--repeat 3]

Each repeat uses a fresh cache folder: run 1 compiles and stores the programs, run 2
loads them. Prints both wall times (the whole command, imports included) and their
ratio; asserts nothing (SPEC: targets are checked in benchmarks, never in tests).
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
    subprocess.run(cmd, env=env, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", nargs="?", default=str(DEFAULT_SCENE))
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    cmd = [sys.executable, "-m", "sweeps.cli", "evaluate", args.scene]
    for _ in range(args.repeat):
        with tempfile.TemporaryDirectory() as cache:
            env = {**os.environ, "SHACC_COMPILE_CACHE": cache}
            cold, warm = wall(cmd, env), wall(cmd, env)
            n = len(os.listdir(cache))
        print(f"empty cache {cold:.2f} s, warm cache {warm:.2f} s, ratio {warm / cold:.2f} "
              f"({n} programs stored)", flush=True)


if __name__ == "__main__":
    main()
