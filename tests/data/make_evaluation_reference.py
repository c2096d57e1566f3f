"""Writes ``evaluation_reference.npz``: every rollout of the shipped scenes, the extra
scene and 16 random scenes of the generator in the three modes (with collisions off,
and the shipped scenes again with them on), recorded before the evaluation's host side
was rebuilt around one plan (issue 37), so that the rebuilt code can be held to the
same answers bit for bit.

    JAX_PLATFORMS=cpu python tests/data/make_evaluation_reference.py

Run it only against a commit whose answers are the reference: regenerating it from the
code under test would test nothing.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np

OUT = Path(__file__).with_name("evaluation_reference.npz")
RANDOM = 16
FIELDS = ("outcome", "activated", "step", "meta_steps", "point", "path_length", "delta_R",
          "orientation")


def batches():
    """(name, precomputed scenes) of each recorded batch, the same every time."""
    from geometry_precompute import (
        extra_scene_paths,
        load_scene,
        precompute,
        random_scene,
        shipped_scene_paths,
    )

    files = [load_scene(p) for p in shipped_scene_paths() + extra_scene_paths()]
    yield "files", [precompute(s) for s in files]
    yield "files_collision", [precompute(s, {"collision": "on"}) for s in files[:12]]
    yield "random", [precompute(random_scene(3000 + i, "uniform" if i % 2 else "gaussian",
                                             2, 12, "paper")) for i in range(RANDOM)]


def main() -> None:
    from sweeps.pipeline import evaluate_results

    arrays = {}
    for name, results in batches():
        ev = evaluate_results(results, ("baseline", "shrinking", "shacc"))
        for f in FIELDS:
            arrays[f"{name}/{f}"] = np.asarray(getattr(ev.evaluation.rollouts, f))
        arrays[f"{name}/u_scene"] = np.asarray(ev.evaluation.metrics.u_scene)
        arrays[f"{name}/delta_R_mean"] = np.asarray(ev.evaluation.metrics.delta_R_mean)
    commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                            cwd=Path(__file__).parent).stdout.strip()
    np.savez_compressed(OUT, commit=np.array(commit), **arrays)
    print(f"wrote {OUT} ({OUT.stat().st_size} bytes) from {commit}")


if __name__ == "__main__":
    main()
