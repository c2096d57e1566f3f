"""``shacc settings``: every setting (reference/settings) with its default, type, unit,
valid range, stage and meaning, read from the one place they are declared
(``geometry_precompute.settings``)."""

from __future__ import annotations

import json

from geometry_precompute.settings import describe


def cmd_settings(args) -> int:
    rows = describe()
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    cols = ("name", "default", "type", "unit", "rule", "meaning")
    width = {c: max(len(c), *(len(r[c]) for r in rows)) for c in cols[:-1]}
    print("  ".join(c.ljust(width.get(c, 0)) for c in cols).rstrip())
    for r in rows:
        print("  ".join(r[c].ljust(width.get(c, 0)) for c in cols).rstrip())
    print("\nA setting goes in a scene's [settings], a sweep's [settings], [axes] or "
          "[[points]], or on the command line as --set NAME=VALUE. Dotted names may be "
          "written bare or quoted in TOML. The stage says what a change recomputes: "
          "precompute (the geometry), starts, rollout, optimize (the optimized mode's "
          "search), analysis.")
    return 0
