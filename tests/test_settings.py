"""Settings: one place for defaults, validation, and the documented precedence."""

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
             "drawer_pull.depth_min", "optimize_starts", "optimize_seed",
             "optimize_population", "optimize_generations", "optimize_validation_starts",
             "optimize_validation_seed", "optimize_candidates", "optimize_selection",
             "user_noise", "user_noise_tau", "user_tremor", "user_tremor_hz", "user_input",
             "user_mode_switch_s", "user_switch", "user_switch_at", "user_aim",
             "activation_check", "intent_beta", "blend_threshold", "ho_gain"}
    assert set(SPECS) == names
    assert DEFAULTS["dt"] == 0.02 and DEFAULTS["start_grid"] == (6, 6)
    assert (DEFAULTS["optimize_starts"], DEFAULTS["optimize_seed"],
            DEFAULTS["optimize_population"], DEFAULTS["optimize_generations"]) == (64, 1, 64, 30)
    assert DEFAULTS["handle_grasp.half_angle_init"] == pytest.approx(0.5236, abs=1e-4)


@pytest.mark.parametrize("name,value,rule", [
    ("dt", 0.0, "(0, 10]"), ("dt", math.nan, "finite"), ("shrink_step", 1.5, "[0.001, 1]"),
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


DOTTED = sorted(n for n in SPECS if "." in n)
SCENE_HEAD = ('name = "dotted"\n[[objects]]\nid = "m"\nkind = "mug"\nposition = [0, 0, 0]\n'
              '[[tasks]]\nid = "g"\nobject = "m"\ntemplate = "side_grasp"\n')


def _value(name):
    return round(SPECS[name].default * 0.9, 6)  # valid for every dotted setting


@pytest.mark.parametrize("name", DOTTED)
def test_dotted_setting_bare_and_quoted_mean_the_same(tmp_path, name):
    """`a.b = v` (a nested TOML table) and `"a.b" = v` name one setting."""
    from geometry_precompute import load_scene

    v = _value(name)
    bare = tmp_path / "bare.toml"
    bare.write_text(SCENE_HEAD + f"[settings]\n{name} = {v}\n")
    quoted = tmp_path / "quoted.toml"
    quoted.write_text(SCENE_HEAD + f'[settings]\n"{name}" = {v}\n')
    s_bare, s_quoted = load_scene(bare).settings(), load_scene(quoted).settings()
    assert s_bare[name] == s_quoted[name] == pytest.approx(v)
    assert s_bare == s_quoted and s_bare[name] != SPECS[name].default


@pytest.mark.parametrize("form", ["bare", "quoted", "table"])
def test_dotted_settings_in_sweep_config_axes_points_and_settings(tmp_path, form):
    from sweeps.config import load_config

    key = {"bare": "side_grasp.radius_init", "quoted": '"side_grasp.radius_init"'}
    if form == "table":
        body = ("[settings.top_grasp]\noffset = 0.12\n[axes.side_grasp]\n"
                "radius_init = [0.15, 0.2]\n[[points]]\n[points.handle_grasp]\n"
                "length_init = 0.25\n")
    else:
        k = key[form]
        body = (f'[settings]\n{k.replace("side_grasp.radius_init", "top_grasp.offset")} = 0.12\n'
                f"[axes]\n{k} = [0.15, 0.2]\n[[points]]\n"
                f'{k.replace("side_grasp.radius_init", "handle_grasp.length_init")} = 0.25\n')
    (tmp_path / "scenes").mkdir()
    (tmp_path / "scenes" / "a.toml").write_text(SCENE_HEAD)
    cfg_path = tmp_path / "s.toml"
    cfg_path.write_text('name = "d"\n[source]\nkind = "files"\npath = "scenes"\n' + body)
    cfg = load_config(cfg_path)
    assert cfg.points == [
        {"top_grasp.offset": 0.12, "side_grasp.radius_init": 0.15},
        {"top_grasp.offset": 0.12, "side_grasp.radius_init": 0.2},
        {"top_grasp.offset": 0.12, "handle_grasp.length_init": 0.25},
    ]


def test_unknown_name_inside_a_nested_table_names_the_full_dotted_name(tmp_path):
    from geometry_precompute import load_scene

    p = tmp_path / "s.toml"
    p.write_text(SCENE_HEAD + "[settings]\nside_grasp.radius_inti = 0.18\n")
    with pytest.raises(InputError) as e:
        load_scene(p)
    assert str(e.value) == f"{p}: settings.side_grasp.radius_inti: unknown setting; " \
        "did you mean side_grasp.radius_init? (`shacc settings` lists them)"


def test_both_forms_of_one_name_is_an_error(tmp_path):
    from geometry_precompute import load_scene

    p = tmp_path / "s.toml"
    p.write_text(SCENE_HEAD + '[settings]\n"v_max" = 0.2\nside_grasp.radius_init = 0.18\n'
                 '"side_grasp.radius_init" = 0.19\n')
    with pytest.raises(InputError, match=r"settings\.side_grasp\.radius_init: given twice"):
        load_scene(p)


def test_overrides_from_python_take_nested_tables_too():
    s = DEFAULTS.with_overrides({"side_grasp": {"radius_init": 0.17}, "v_max": 0.2})
    assert s["side_grasp.radius_init"] == 0.17 and s["v_max"] == 0.2


def test_the_old_collision_value_is_read_as_on_with_a_warning():
    """collision = "mjx", its name before the checks became closed forms, is "on" with a
    one-line warning; the JSON Schema accepts both, and nothing else."""
    import warnings

    from jsonschema import Draft202012Validator

    from geometry_precompute.errors import SceneWarning
    from geometry_precompute.file_schema import settings_schema

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        s = DEFAULTS.with_overrides({"collision": "mjx"}, "old.toml")
    assert s["collision"] == "on"
    said = [str(w.message) for w in caught if issubclass(w.category, SceneWarning)]
    assert said == ['old.toml: collision: "mjx" is the old name of "on" (the checks are exact '
                    'closed forms, not MJX\'s); write collision = "on"']
    schema = Draft202012Validator(settings_schema())
    assert all(schema.is_valid({"collision": v}) for v in ("off", "on", "mjx"))
    assert not schema.is_valid({"collision": "yes"})


def test_each_setting_is_declared_once_and_reaches_the_bake(shipped_results):
    """A setting's declaration (settings.SPECS) carries its bake encoding: every Params
    field but the populations' comes from exactly one declaration, every declaration
    with an encoding reaches its field, and what the bake writes there is the
    declaration's encoding of the scene's value; every setting the rollouts read
    (stage rollout) has one. A Params field without a declaration, or a declaration
    that reaches no field, fails here."""
    import dataclasses

    from geometry_precompute import bake, schema
    from shacc_jax.types import Params

    declared = {s.param.field: s for s in SPECS.values() if s.param is not None}
    populations = ("user_dist", "user_dist_args", "user_dist_values")
    assert len(declared) == sum(s.param is not None for s in SPECS.values())  # one each
    assert set(Params._fields) == set(declared) | set(populations)
    assert schema.names(schema.PARAMS) == Params._fields
    assert all(s.param is not None for s in SPECS.values() if s.stage == "rollout")
    for f in schema.PARAMS:
        if f.name in declared:
            assert f.dtype == declared[f.name].param.dtype, f.name
    # What the bake writes: a batch whose settings differ from the defaults in each
    # encoded setting, read back field by field.
    # (collision checks and the swept check exclude each other: two batches).
    r = shipped_results[0]
    for over in ({"v_max": 0.3, "ambiguity": "nearest", "seed": 7, "collision": "on",
                  "user_aim": "object", "gripper.opening": 0.12, "max_steps": 321,
                  "user_tremor": 0.004},
                 {"activation_check": "swept", "dt": 0.01, "user_noise": 0.2}):
        b = bake([dataclasses.replace(r, settings=r.settings.with_overrides(over))])
        for field, spec in declared.items():
            value = over.get(spec.name, DEFAULTS[spec.name])
            assert getattr(b, field)[0] == spec.param.encode(value), (field, value)


def test_every_number_has_a_unit_where_it_has_one():
    """Lengths, angles, times and rates declare their unit, which `shacc settings`
    shows; counts, probabilities and choices have none."""
    from geometry_precompute.settings import describe

    units = {s.name: s.unit for s in SPECS.values()}
    assert units["v_max"] == "m/s" and units["dt"] == "s" and units["user_noise"] == "rad"
    assert units["side_grasp.radius_init"] == "m" and units["user_switch"] == ""
    assert units["max_steps"] == "" and units["ambiguity"] == ""
    assert {r["name"]: r["unit"] for r in describe()} == units
