"""``shacc report SOURCE``: one self-contained HTML page of a sweep folder or an
``evaluate --json`` file (``sweeps.analysis.report``)."""

from __future__ import annotations

import sys
from pathlib import Path

from geometry_precompute import InputError
from geometry_precompute.fileio import write_atomic
from sweeps.analysis.report import evaluate_report, sweep_report


def cmd_report(args) -> int:
    src = Path(args.source)
    if not src.exists():
        raise InputError(src, "<path>", "no such sweep folder or evaluate --json file")
    text = sweep_report(src) if src.is_dir() else evaluate_report(src)
    out = Path(args.out) if args.out else (src / "report.html" if src.is_dir()
                                           else src.with_suffix(".html"))
    write_atomic(out, text.encode())
    print(f"wrote {out}", file=sys.stderr)
    return 0
