"""``shacc compare A B``: paired differences of two runs of the same scenes
(``sweeps.analysis.compare``), and the ``--fail-if`` gate for CI."""

from __future__ import annotations

import json

from sweeps.analysis.compare import REGRESSION, compare, failures, parse_fail_if
from sweeps.output import clean_json, human_output, write_output


def print_table(result: dict) -> None:
    print(f"A: {result['a']}\nB: {result['b']}")
    head = (f"{'point':>5} {'mode':<10} {'metric':<13} {'A':>8} {'B':>8} "
            f"{'B - A [95 % CI]':>28} {'scenes':>6}")
    print(head)
    print("-" * len(head))
    for r in result["rows"]:
        def f(v):
            return "n/a" if v is None else f"{v:.4f}"
        ci = "" if not r["ci"] else f" [{r['ci'][0]:+.4f}, {r['ci'][1]:+.4f}]"
        diff = "n/a" if r["diff"] is None else f"{r['diff']:+.4f}{ci}"
        print(f"{r['point']:>5} {r['mode']:<10} {r['metric']:<13} {f(r['a']):>8} {f(r['b']):>8} "
              f"{diff:>28} {r['n_scenes']:>6}")
    changed = result["tasks_changed"]
    if changed:
        print(f"\ntasks whose success changed: {len(changed)}; the largest:")
        for t in changed[:8]:
            print(f"  point {t['point']} {t['mode']:<10} {t['scene']} / {t['task']}: "
                  f"{t['a']:.3f} -> {t['b']:.3f} ({t['diff']:+.3f})")


def cmd_compare(args) -> int:
    rules = [parse_fail_if(r) for r in args.fail_if]
    result = compare(args.a, args.b, args.bootstrap, args.seed)
    failed = failures(result, rules)
    result["fail_if"] = args.fail_if
    result["failed"] = failed
    with human_output(args.json):
        print_table(result)
        for line in failed:
            print(f"FAILED: {line}")
    if args.json:
        write_output(args.json, (json.dumps(clean_json(result), indent=1) + "\n").encode())
    return REGRESSION if failed else 0
