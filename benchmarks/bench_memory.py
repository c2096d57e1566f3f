"""Memory one rollout needs during evaluation, for the memory model of ``shacc_jax/runplan.py``.

    python benchmarks/bench_memory.py --bake bake.npz --scenes 1000 [--collision]
        [--user NAME=VALUE ...]

(the bake from ``bench_rollouts.py bake``). Prints XLA's memory analysis of the
compiled program (temporaries, outputs, arguments) and, where the device reports it,
the peak device memory after one evaluation, each per rollout. Nothing here asserts a
size.
"""

from __future__ import annotations

import argparse
import json

import jax
from bench_rollouts import _load, user_setting

import shacc_jax


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bake", required=True)
    ap.add_argument("--scenes", type=int, default=1000)
    ap.add_argument("--collision", action="store_true")
    ap.add_argument("--user", type=user_setting, nargs="+", metavar="NAME=VALUE",
                    help="an imperfect simulated user in every scene (the stepped program), "
                    "e.g. user_noise=0.3 user_noise_tau=0.5")
    args = ap.parse_args()
    geometry, params, layout = _load(args.bake, args.scenes, args.collision, user=args.user)
    f = jax.jit(shacc_jax.evaluate, static_argnames="layout")
    m = f.lower(geometry, params, layout).compile().memory_analysis()
    S, N = geometry.starts.shape[:2]
    rollouts = S * N * geometry.task_mask.shape[1] * len(layout.modes)
    analysis = m.temp_size_in_bytes + m.output_size_in_bytes + m.argument_size_in_bytes
    jax.block_until_ready(f(geometry, params, layout))
    stats = jax.devices()[0].memory_stats() or {}
    peak = stats.get("peak_bytes_in_use")
    print(json.dumps({"device": str(jax.devices()[0]), "scenes": S, "rollouts": rollouts,
                      "collision": args.collision, "user": args.user,
                      "stepped": layout.stepped_users,
                      "analysis_bytes_per_rollout": round(analysis / rollouts, 1),
                      "peak_bytes_per_rollout":
                      None if peak is None else round(peak / rollouts, 1)}))


if __name__ == "__main__":
    from shacc_jax import configure_runtime

    configure_runtime()  # as the commands do, before anything starts JAX
    main()
