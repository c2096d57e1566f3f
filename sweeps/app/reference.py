"""The generated parts of the reference in ``docs/reference/``: the settings table and
the sweep dataset's columns, written from the definitions the code itself uses
(``geometry_precompute.settings`` and ``sweeps.analysis.tables.COLUMNS``), so the docs and the
code cannot disagree.

    python -m sweeps.app.reference            # rewrite the generated blocks
    python -m sweeps.app.reference --check    # exit 1 if a page is out of date (a test runs it)

A generated block sits between ``<!-- generated: NAME -->`` and ``<!-- end generated -->``.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Callable
from functools import partial
from pathlib import Path

from geometry_precompute.settings import describe
from sweeps.analysis.tables import COLUMNS

DOCS = Path(__file__).resolve().parents[2] / "docs" / "reference"


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|")


def settings_table() -> str:
    rows = ["| name | default | type | unit | rule | stage | meaning |",
            "| --- | --- | --- | --- | --- | --- | --- |"]
    for r in describe():
        rows.append("| " + " | ".join(_cell(x) for x in (
            f"`{r['name']}`", f"`{r['default']}`", r["type"], r["unit"], r["rule"],
            r["stage"], r["meaning"])) + " |")
    return "\n".join(rows)


def columns_table(table: str) -> str:
    rows = ["| column | type | unit | meaning |", "| --- | --- | --- | --- |"]
    for name, (kind, unit, doc) in COLUMNS[table].items():
        rows.append(f"| `{name}` | {_cell(kind)} | {_cell(unit)} | {_cell(doc)} |")
    return "\n".join(rows)


BLOCKS: dict[str, dict[str, Callable[[], str]]] = {
    "settings.md": {"settings": settings_table},
    "outputs.md": {f"columns-{t}": partial(columns_table, t) for t in COLUMNS},
}

_BLOCK = re.compile(r"(<!-- generated: (?P<name>[\w-]+) -->\n)(?:|.*?\n)(<!-- end generated -->)",
                    re.S)


def render(page: str, text: str) -> str:
    """``text`` with every generated block of ``page`` rewritten."""
    makers = BLOCKS[page]
    seen = set()

    def fill(m: re.Match) -> str:
        seen.add(m["name"])
        return m[1] + makers[m["name"]]() + "\n" + m[3]

    out = _BLOCK.sub(fill, text)
    missing = set(makers) - seen
    if missing:
        raise ValueError(f"docs/reference/{page} lacks the generated blocks {sorted(missing)}")
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--check", action="store_true", help="only check; exit 1 if stale")
    args = p.parse_args(argv)
    stale = []
    for page in BLOCKS:
        path = DOCS / page
        text = path.read_text(encoding="utf-8")
        new = render(page, text)
        if new != text:
            stale.append(page)
            if not args.check:
                path.write_text(new, encoding="utf-8")
    if args.check and stale:
        print(f"out of date: {', '.join(stale)} (run python -m sweeps.app.reference)",
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
