"""Settings: one place for defaults, validation, and SPEC section 16's precedence."""

from __future__ import annotations

import math

import pytest

from geometry_precompute import DEFAULTS, SPECS, InputError, scene_from_dict
from geometry_precompute.settings import parse_cli_value


def test_every_spec_name_present():
    names = {"shrink_step", "shrink_max_iter", "dt", "v_max", "omega_max", "max_steps",
             "activation_tol", "ambiguity", "start_grid", "start_plane_offset",
             "start_y_halfwidth", "start_z_range", "start_orientation", "seed", "collision",
             "gripper.finger_length", "gripper.finger_radius", "gripper.opening",
             "gripper.palm_radius",
             "mesh_sections", "entropy_variant", "bootstrap_resamples",
             "side_grasp.radius_init", "side_grasp.radius_margin", "side_grasp.height_margin",
             "handle_grasp.length_init", "handle_grasp.length_min",
             "handle_grasp.half_angle_init", "handle_grasp.half_angle_min",
             "handle_grasp.handle_offset", "top_grasp.radius_init", "top_grasp.radius_margin",
             "top_grasp.offset", "top_grasp.thickness", "drawer_pull.depth_init",
             "drawer_pull.depth_min"}
    assert set(SPECS) == names
    assert DEFAULTS["dt"] == 0.02 and DEFAULTS["start_grid"] == (6, 6)
    assert DEFAULTS["handle_grasp.half_angle_init"] == pytest.approx(0.5236, abs=1e-4)


@pytest.mark.parametrize("name,value,rule", [
    ("dt", 0.0, "> 0"), ("dt", math.nan, "finite"), ("shrink_step", 1.5, "(0, 1]"),
    ("ambiguity", "random", "one of"), ("start_grid", [6], "two"), ("max_steps", 2.5, "integer"),
    ("start_z_range", [0.3, 0.1], "low <= high"), ("warp", 1, "unknown setting"),
])
def test_bad_values_rejected(name, value, rule):
    with pytest.raises(InputError) as e:
        DEFAULTS.with_overrides({name: value}, "cfg.toml")
    assert rule in str(e.value) and name in str(e.value) and "cfg.toml" in str(e.value)


def test_precedence():
    data = {"name": "p", "objects": [{"id": "m", "kind": "mug", "position": [0, 0, 0]}],
            "tasks": [{"id": "g", "object": "m", "template": "side_grasp",
                       "bounds": {"radius": [0.1, 0.12]}}],
            "settings": {"v_max": 0.2, "side_grasp.radius_init": 0.18}}
    scene = scene_from_dict(data)
    s = scene.settings()
    assert s["v_max"] == 0.2 and s["dt"] == 0.02           # scene over defaults
    s2 = scene.settings(overrides={"v_max": 0.3})
    assert s2["v_max"] == 0.3                               # --set over the scene
    from geometry_precompute.templates import resolve_tasks
    sp = resolve_tasks(scene, scene.settings(overrides={"side_grasp.radius_init": 0.25}))[0]
    assert sp.q_init.tolist() == [0.12]                     # the task's own bounds win


def test_cli_value_parsing():
    assert parse_cli_value("v_max", "0.2") == 0.2
    assert parse_cli_value("start_grid", "[8, 4]") == [8.0, 4.0]
    assert parse_cli_value("ambiguity", "nearest") == "nearest"
    with pytest.raises(InputError, match="unknown setting"):
        parse_cli_value("nope", "1")
    with pytest.raises(InputError, match="number"):
        parse_cli_value("dt", "fast")
