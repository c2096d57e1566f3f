"""``shacc precompute SCENE.toml``: C, clusters and Shrinking of one scene, printed,
and with ``--json`` the one-scene JSON's precompute keys."""

from __future__ import annotations

import time

from sweeps.app.inputs import load_and_precompute
from sweeps.output import announce, check_output_file, human_output, precompute_json, write_json


def _fmt_params(space, q) -> str:
    parts = []
    for name, lo, hi, v in zip(space.param_names, space.q_min, space.q_init, q, strict=True):
        parts.append(f"{name} [{lo:.4g}, {hi:.4g}] -> {v:.4g}")
    return "; ".join(parts)


def print_precompute(r, wall: float) -> None:
    ids = r.task_ids
    print(f"scene: {r.scene.name}  ({r.scene.source})")
    if r.scene.description:
        print(f"  {r.scene.description}")
    print(f"tasks ({len(ids)}):")
    w = max(len(i) for i in ids)
    for k, (sp, q) in enumerate(zip(r.spaces, r.q_opt, strict=True)):
        print(f"  {k:2d} {ids[k]:<{w}}  {sp.template:<12} on {sp.obj.id} ({sp.obj.kind})  "
              f"{_fmt_params(sp, q)}")
    print(f"C_init   {r.C_init:.4f}")
    print(f"C_final  {r.C_final:.4f}")
    meta = r.meta_clusters()
    print("clusters: " + ("none" if not meta else
                          "  ".join("[" + ", ".join(ids[i] for i in c) + "]" for c in meta)))
    still = ", ".join(f"{ids[i]}~{ids[j]}" for i, j in r.still_intersecting) or "none"
    print(f"shrinking: {r.iterations} iterations; still intersecting at bounds: {still}")
    print(f"d = {r.d:.4f} m   h = {r.h:.4f} ({r.settings['entropy_variant']})")
    sec = r.seconds
    parts = ", ".join(f"{k} {1e3 * v:.2f}" for k, v in sec.items() if k != "total")
    print(f"time: {1e3 * sec['total']:.2f} ms ({parts}); with loading {1e3 * wall:.1f} ms")


def cmd_precompute(args) -> int:
    if args.json and args.json != "-":
        check_output_file(args.json, "--json")
    t0 = time.perf_counter()
    r = load_and_precompute(args.scene, args.set)
    wall = time.perf_counter() - t0
    with human_output(args.json):
        print_precompute(r, wall)
    if args.json:
        write_json(args.json, precompute_json(r))
        announce(args.json)
    return 0
