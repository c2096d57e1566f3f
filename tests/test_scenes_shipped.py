"""The shipped manual scenes (reference/scenes) and the random generator."""

from __future__ import annotations

import numpy as np
import pytest

from geometry_precompute import load_scene, random_scene, shipped_scene_paths
from geometry_precompute.bodies import object_body
from geometry_precompute.intersect import SpaceSet


def test_manual_set(shipped_results):
    assert len(shipped_results) >= 12
    for r in shipped_results:
        assert len(r.scene.tasks) == 3 and r.scene.description
    c = [r.C_init for r in shipped_results]
    assert min(c) == 0.0 and max(c) >= 0.4
    templates = {t.template for r in shipped_results for t in r.scene.tasks}
    assert {"side_grasp", "handle_grasp"} <= templates


def test_names_unique():
    names = [load_scene(p).name for p in shipped_scene_paths()]
    assert len(set(names)) == len(names)


@pytest.mark.parametrize("kind", ["uniform", "gaussian"])
def test_random_scenes(kind):
    for seed in range(15):
        s = random_scene(seed, kind)
        assert 5 <= len(s.tasks) <= 10 and len(s.objects) == len(s.tasks)
        bodies = SpaceSet([object_body(o) for o in s.objects])
        for i in range(len(s.objects)):
            for j in range(i + 1, len(s.objects)):
                assert bodies.signed_distance(i, j) >= 0.01 - 1e-9
        if kind == "uniform":
            xy = np.array([o.position[:2] for o in s.objects])
            assert np.all(np.abs(xy) <= 0.3)
    assert random_scene(7, kind) == random_scene(7, kind)
    assert random_scene(7, kind) != random_scene(8, kind)


def test_random_scene_is_valid_input():
    from geometry_precompute import scene_from_dict
    from geometry_precompute.scene import scene_to_dict

    s = random_scene(4, "gaussian")
    again = scene_from_dict(scene_to_dict(s), "<roundtrip>")
    assert again.objects == s.objects and again.tasks == s.tasks
