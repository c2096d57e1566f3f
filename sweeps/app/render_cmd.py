"""``shacc render SCENE --out PNG``: MuJoCo's picture of a scene beside the top-down
view of its spaces, optionally with one rollout's path (``sweeps.analysis.render``)."""

from __future__ import annotations

import sys
from pathlib import Path

from geometry_precompute import InputError
from sweeps.analysis.render import render_scene
from sweeps.app.inputs import load_and_precompute
from sweeps.output import check_output_file


def cmd_render(args) -> int:
    check_output_file(args.out, "--out")
    r = load_and_precompute(args.scene, args.set)
    spec = None
    if args.path:
        try:
            spec = (int(args.path[0]), args.path[1])
        except ValueError:
            raise InputError("<--path>", "START", f"must be a whole number, got "
                             f"{args.path[0]!r}") from None
    path = render_scene(r, Path(args.out), args.width, args.height, args.mode, spec)
    if path is not None:
        print(path.description)
    print(f"wrote {args.out}", file=sys.stderr)
    return 0
