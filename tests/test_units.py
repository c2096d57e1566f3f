"""Values that are legal but look like a unit mistake warn, naming the field and the
value probably meant; the _deg spellings convert on load; shipped scenes warn of
nothing."""

from __future__ import annotations

import math
import warnings

import pytest

from geometry_precompute import load_scene, shipped_scene_paths
from geometry_precompute.errors import InputError, SceneWarning
from geometry_precompute.loading import scene_from_dict


def scene(obj=None, task=None, settings=None) -> dict:
    o = {"id": "c", "kind": "cup", "position": [0.1, 0.0, 0.0], **(obj or {})}
    t = {"id": "t", "object": "c", "template": "handle_grasp", **(task or {})}
    return {"name": "u", "objects": [o], "tasks": [t], "settings": settings or {}}


def messages(data) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        s = scene_from_dict(data, "u.toml")
        s.settings()
    return [str(w.message) for w in caught if issubclass(w.category, SceneWarning)]


def test_a_yaw_in_degrees_warns_with_the_radians_meant():
    (m,) = messages(scene({"yaw": 180}))
    assert "objects[c].yaw" in m and "3.1416" in m and "yaw_deg" in m
    assert messages(scene({"yaw": 3.0})) == []


def test_yaw_deg_is_converted_and_exclusive():
    a = scene_from_dict(scene({"yaw_deg": 90}), "u.toml").objects[0].yaw
    assert a == pytest.approx(math.pi / 2)
    with pytest.raises(InputError, match=r"objects\[c\]\.yaw_deg.*not both"):
        scene_from_dict(scene({"yaw": 1.0, "yaw_deg": 90}), "u.toml")


def test_half_angle_in_degrees_is_refused_with_the_spelling_that_works():
    with pytest.raises(InputError, match=r"bounds\.half_angle: .*half_angle_deg = \[10, 30\]"):
        scene_from_dict(scene(task={"bounds": {"half_angle": [10, 30]}}), "u.toml")
    deg = scene_from_dict(scene(task={"bounds": {"half_angle_deg": [10, 30]}}), "u.toml")
    assert deg.tasks[0].bounds["half_angle"] == pytest.approx(
        (math.radians(10), math.radians(30)))
    with pytest.raises(InputError, match="half_angle_deg"):
        scene_from_dict(scene(task={"bounds": {"half_angle_deg": [10, 95]}}), "u.toml")


def test_centimetres_warn():
    (m,) = messages(scene({"radius": 4.0}))
    assert "objects[c].radius" in m and "0.04 m" in m
    (m,) = messages(scene({"position": [45.0, 10.0, 0.0]}))
    assert "objects[c].position" in m and "[0.45, 0.1, 0.0]" in m


def test_settings_in_the_wrong_unit_warn_once():
    got = messages(scene(settings={"omega_max": 171.0}))
    assert len(got) == 1 and "omega_max" in got[0] and "2.9845" in got[0]
    got = messages(scene(settings={"handle_grasp.length_init": 3.0}))
    assert len(got) == 1 and "handle_grasp.length_init" in got[0] and "0.03 m" in got[0]
    assert messages(scene(settings={"omega_max": 3.0})) == []


def test_shipped_scenes_warn_of_nothing():
    with warnings.catch_warnings():
        warnings.simplefilter("error", SceneWarning)
        for p in shipped_scene_paths():
            load_scene(p).settings()
