"""``shacc export-mjcf SCENE OUT``: a scene as MJCF, with its task spaces as
visual-only geoms (``geometry_precompute.mjcf``)."""

from __future__ import annotations

import sys

from geometry_precompute.mjcf import scene_to_mjcf
from sweeps.app.inputs import load_and_precompute
from sweeps.output import check_output_file, write_atomic


def cmd_export(args) -> int:
    check_output_file(args.out, "OUT")
    r = load_and_precompute(args.scene, args.set)
    write_atomic(args.out, scene_to_mjcf(r).encode())
    print(f"wrote {args.out}", file=sys.stderr)
    return 0
