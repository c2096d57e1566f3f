"""What an evaluation worker's warm-up costs, step by step, in a fresh process:
importing JAX, starting the backend, the first device operation (where JAX reserves
its memory unless ``XLA_PYTHON_CLIENT_PREALLOCATE=false``), the modules the warm-up
needs, and the warm-up itself (one scene precomputed, padded to the sweep's chunk and
evaluated: the programs loaded from the compilation cache, or compiled).

    python benchmarks/bench_warm_up.py [CONFIG]     # default benchmarks/e2e_10k.toml

Run it twice with the same ``SHACC_COMPILE_CACHE``: the first compiles.
"""

from __future__ import annotations

import sys
import time

T = time.perf_counter()


def lap(what: str) -> None:
    global T
    t = time.perf_counter()
    print(f"{what}: {t - T:.3f} s", flush=True)
    T = t


def main() -> None:
    config = sys.argv[1] if len(sys.argv) > 1 else "benchmarks/e2e_10k.toml"
    import jax
    import jax.numpy as jnp

    lap("import jax")
    jax.devices()
    lap("backend")
    jnp.zeros(1).block_until_ready()
    lap("first device operation")
    from sweeps.distributed import evaluation_worker as ew

    lap("import sweeps.distributed.evaluation_worker")
    import scipy.spatial.transform  # noqa: F401  (the bake's start orientations)

    lap("import scipy.spatial.transform")
    from sweeps import pipeline  # noqa: F401

    lap("import sweeps.pipeline")
    from sweeps.config import load_config
    from sweeps.distributed.runner import _warm_up_job

    cfg = load_config(config)
    from sweeps.distributed.plan import plan

    job, ref = _warm_up_job(cfg, plan(cfg), cfg.scenes() if cfg.source["kind"] == "files"
                            else None)
    ew._setup()
    lap("config and compilation cache")
    result = ew.warm_up(job, ref)
    lap(f"warm-up ({result['compiled']} compiled, {result['loaded']} loaded)")


if __name__ == "__main__":
    from shacc_jax import configure_runtime

    configure_runtime()  # as the commands do, before anything starts JAX
    main()
