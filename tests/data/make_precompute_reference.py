"""Writes ``precompute_reference.json``: the precompute's answers on the shipped
scenes, the extra scenes and 200 random scenes of the generator, recorded from the
mesh-boolean implementation (issue 15) so that faster code can be held to them.

    python tests/data/make_precompute_reference.py

Per scene: clusters, Shrinking's parameters (repr-exact floats), iterations and the
pairs still intersecting; C_init and C_final from booleans at 32 sections (the old
default) and at 128 sections (the reference that C is compared with). Run it only
against the boolean implementation: regenerating it from the code under test would
test nothing.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from geometry_precompute import (
    extra_scene_paths,
    load_scene,
    precompute,
    random_scene,
    shipped_scene_paths,
)
from geometry_precompute.clutteredness import clutteredness

RANDOM = 200
OUT = Path(__file__).with_name("precompute_reference.json")


def scenes():
    for p in shipped_scene_paths() + extra_scene_paths():
        yield f"file:{Path(p).name}", load_scene(p)
    for i in range(RANDOM):
        kind = "uniform" if i % 2 == 0 else "gaussian"
        yield f"random:{kind}:{2000 + i}", random_scene(2000 + i, kind, 2, 12)


def record(scene) -> dict:
    r = precompute(scene, scene.settings())
    return {
        "clusters": r.clusters,
        "q_opt": [[float(v) for v in q] for q in r.q_opt],
        "iterations": r.iterations,
        "still_intersecting": [list(p) for p in r.still_intersecting],
        "C_init_32": clutteredness(r.shapes_init, 32, method="boolean"),
        "C_final_32": clutteredness(r.shapes_opt, 32, method="boolean"),
        "C_init_128": clutteredness(r.shapes_init, 128, method="boolean"),
        "C_final_128": clutteredness(r.shapes_opt, 128, method="boolean"),
    }


def main() -> None:
    data = {}
    for key, sc in scenes():
        data[key] = record(sc)
        print(key, file=sys.stderr)
    OUT.write_text(json.dumps(data, indent=0, sort_keys=True) + "\n")


if __name__ == "__main__":
    main()
