"""``shacc evaluate SCENE.toml``: one scene end to end, a readable summary and,
with ``--json``, SPEC section 12a's object."""

from __future__ import annotations

import time

import shacc_jax
from shacc_jax.types import OUTCOMES

from .output import write_json
from .pipeline import evaluate_results, load_and_precompute, scene_json


def print_summary(ev, s: int = 0) -> None:
    r = ev.results[s]
    ids = r.task_ids
    me = ev.evaluation.metrics
    meta = r.meta_clusters()
    print(f"scene: {r.scene.name}  ({r.scene.source})")
    if r.scene.description:
        print(f"  {r.scene.description}")
    print(f"tasks: {', '.join(ids)}")
    print(f"C_init {r.C_init:.4f}   C_final {r.C_final:.4f}   Shrinking passes {r.iterations}")
    print("clusters: " + ("none" if not meta else
                          "  ".join("[" + ", ".join(ids[i] for i in c) + "]" for c in meta)))
    n_starts = ev.baked.n_starts
    print(f"rollouts per mode: {int(me.n_rollouts[s, 0])} ({n_starts} starts x {len(ids)} tasks)")
    # The collision column only where collision checking is on.
    k = 5 if r.settings["collision"] != "off" else 4
    head = f"{'mode':<10} {'rate':>8} " + " ".join(f"{o:>9}" for o in OUTCOMES[:k]) + \
        f" {'mean dR (rad)':>14}"
    print(head)
    print("-" * len(head))
    for m, mode in enumerate(ev.modes):
        counts = " ".join(f"{int(c):>9}" for c in me.outcome_counts[s, m, :k])
        dr = me.delta_R_mean[s, m]
        dr_txt = "n/a" if dr != dr else f"{dr:.3f}"
        print(f"{mode:<10} {me.u_scene[s, m]:>8.3f} {counts} {dr_txt:>14}")


def cmd_evaluate(args) -> int:
    t0 = time.perf_counter()
    r = load_and_precompute(args.scene, args.set)
    t1 = time.perf_counter()
    ev = evaluate_results([r], args.modes)
    print_summary(ev)
    print(f"time: precompute {1e3 * (t1 - t0):.1f} ms, evaluation (with compilation) "
          f"{ev.seconds['evaluate']:.2f} s")
    if args.json:
        write_json(args.json, scene_json(ev, 0))
        print(f"wrote {args.json}")
    return 0


def add_evaluate(sub) -> None:
    p = sub.add_parser("evaluate", help="evaluate one scene in every mode (SPEC 12a)")
    p.add_argument("scene", help="scene TOML file")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="override a setting (SPEC section 16 names)")
    p.add_argument("--modes", nargs="+", default=list(shacc_jax.MODES),
                   choices=list(shacc_jax.MODES))
    p.add_argument("--json", metavar="OUT.json", help="write SPEC section 12a's JSON")
    p.set_defaults(func=cmd_evaluate)
