"""The ``shacc`` command line: a thin layer over the library.

Bad input (a scene file, a ``--set``) prints one line naming the file, the
field and the rule, and exits with status 2; nothing is written.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence

from geometry_precompute import InputError

from .evaluate_cmd import add_evaluate
from .output import precompute_json, write_json
from .pipeline import load_and_precompute
from .render import add_render
from .reproduce import add_reproduce
from .runner import add_sweep


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
    t0 = time.perf_counter()
    r = load_and_precompute(args.scene, args.set)
    wall = time.perf_counter() - t0
    print_precompute(r, wall)
    if args.json:
        write_json(args.json, precompute_json(r))
        print(f"wrote {args.json}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="shacc", description="ShaCC batch evaluator")
    sub = p.add_subparsers(dest="command", required=True)
    pre = sub.add_parser("precompute", help="C, clusters and Shrinking of one scene")
    pre.add_argument("scene", help="scene TOML file")
    pre.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                     help="override a setting (SPEC section 16 names)")
    pre.add_argument("--json", metavar="OUT.json", help="write SPEC section 12a's keys")
    pre.set_defaults(func=cmd_precompute)
    add_evaluate(sub)
    add_reproduce(sub)
    add_sweep(sub)
    add_render(sub)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
