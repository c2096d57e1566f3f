"""``shacc compare A B``: paired differences of two runs of the same scenes
(``sweeps.analysis.compare``), and the ``--fail-if`` gate for CI."""

from __future__ import annotations

import json

from sweeps.analysis.compare import REGRESSION, compare, gate, parse_fail_if, verdict_line
from sweeps.output import clean_json, human_output, write_output


def print_table(result: dict) -> None:
    print(f"A: {result['a']}\nB: {result['b']}")
    head = (f"{'point':>5} {'mode':<10} {'metric':<16} {'A':>8} {'B':>8} "
            f"{'B - A [95 % CI]':>28} {'scenes':>6}")
    print(head)
    print("-" * len(head))
    for r in result["rows"]:
        def f(v):
            return "n/a" if v is None else f"{v:.4f}"
        ci = "" if not r["ci"] else f" [{r['ci'][0]:+.4f}, {r['ci'][1]:+.4f}]"
        diff = "n/a" if r["diff"] is None else f"{r['diff']:+.4f}{ci}"
        print(f"{r['point']:>5} {r['mode']:<10} {r['metric']:<16} {f(r['a']):>8} {f(r['b']):>8} "
              f"{diff:>28} {r['n_scenes']:>6}")
    changed = result["tasks_changed"]
    if changed:
        print(f"\ntasks whose success changed: {len(changed)}; the largest:")
        for t in changed[:8]:
            print(f"  point {t['point']} {t['mode']:<10} {t['scene']} / {t['task']}: "
                  f"{t['a']:.3f} -> {t['b']:.3f} ({t['diff']:+.3f})")


def print_verdicts(verdicts: list[dict]) -> None:
    if not verdicts:
        print("\nno gate (--fail-if or --fail-if-shown): nothing decided")
        return
    print()
    for v in verdicts:
        print(verdict_line(v))
        moved = [x for x in v["worst_scenes"] if x["diff"] * (1 if v["margin"] < 0 else -1) < 0]
        if moved and not v["passed"]:
            print("  moved most against it: " + "; ".join(
                f"{x['scene']} {x['a']:.4f} -> {x['b']:.4f}" for x in moved))


def cmd_compare(args) -> int:
    rules = [parse_fail_if(r) for r in args.fail_if]
    shown = [parse_fail_if(r, "--fail-if-shown") for r in args.fail_if_shown]
    result = compare(args.a, args.b, args.bootstrap, args.seed)
    verdicts = gate(result, rules, shown)
    if (rules or shown) and not verdicts:
        from geometry_precompute import InputError  # deferred: only on this error

        raise InputError("<arguments>", "--fail-if", "no mode of the two runs matches "
                         f"{', '.join(args.fail_if + args.fail_if_shown)}")
    result["fail_if"] = args.fail_if
    result["fail_if_shown"] = args.fail_if_shown
    result["verdicts"] = verdicts
    result["passed"] = all(v["passed"] for v in verdicts)
    with human_output(args.json):
        print_table(result)
        print_verdicts(verdicts)
    if args.json:
        write_output(args.json, (json.dumps(clean_json(result), indent=1) + "\n").encode())
    return 0 if result["passed"] else REGRESSION
