"""Scene files: round trip, and one test per rule of the scene format (reference/scenes)."""

from __future__ import annotations

import math
import warnings

import pytest
from conftest import write_scene

from geometry_precompute import (
    InputError,
    load_scene,
    save_scene,
    scene_from_dict,
    shipped_scene_paths,
)
from geometry_precompute.errors import SceneWarning
from geometry_precompute.scene import scene_to_dict

BASE = """
name = "t"
[[objects]]
id = "a"
kind = "mug"
position = [0.0, 0.0, 0.0]
[[objects]]
id = "b"
kind = "cup"
position = [0.3, 0.0, 0.0]
yaw = 3.1416
[[tasks]]
id = "ta"
object = "a"
template = "side_grasp"
[[tasks]]
id = "tb"
object = "b"
template = "handle_grasp"
"""


def base() -> dict:
    import tomllib

    return tomllib.loads(BASE)


def test_shipped_scenes_round_trip(tmp_path):
    paths = shipped_scene_paths()
    assert len(paths) >= 12
    for p in paths:
        scene = load_scene(p)
        out = tmp_path / p.name
        save_scene(scene, out)
        again = load_scene(out)
        assert scene_to_dict(again) == scene_to_dict(scene)
        assert again.objects == scene.objects and again.tasks == scene.tasks


def test_overrides_parse(tmp_path):
    text = BASE.replace('template = "side_grasp"', 'template = "side_grasp"\n'
                        '[tasks.bounds]\nradius = [0.1, 0.15]\n[tasks.fixed]\nheight = 0.2')
    text += '\n[settings]\nshrink_step = 0.1\n"side_grasp.radius_init" = 0.18\n'
    scene = load_scene(write_scene(tmp_path, text))
    assert scene.tasks[0].bounds == {"radius": (0.1, 0.15)}
    assert scene.tasks[0].fixed == {"height": 0.2}
    s = scene.settings()
    assert s["shrink_step"] == 0.1 and s["side_grasp.radius_init"] == 0.18


def _expect(data, field_part, rule_part, source="scene.toml"):
    with pytest.raises(InputError) as e:
        scene_from_dict(data, source)
    assert field_part in e.value.field, (e.value.field, str(e.value))
    assert rule_part in e.value.rule, e.value.rule
    assert str(e.value).startswith(source)


def test_unknown_top_field():
    d = base()
    d["colour"] = "red"
    _expect(d, "colour", "unknown field")


def test_unknown_object_field():
    d = base()
    d["objects"][0]["mass"] = 1.0
    _expect(d, "objects[0].mass", "unknown field")


def test_unknown_task_field():
    d = base()
    d["tasks"][0]["speed"] = 1.0
    _expect(d, "tasks[0].speed", "unknown field")


def test_unknown_bound_and_fixed():
    d = base()
    d["tasks"][0]["bounds"] = {"length": [0.1, 0.2]}
    _expect(d, "bounds.length", "unknown field")
    d = base()
    d["tasks"][1]["fixed"] = {"height": 0.2}
    _expect(d, "fixed.height", "unknown field (allowed: handle_offset)")
    d = base()
    d["objects"][0]["mass"] = 1.0
    _expect(d, "objects[0].mass", "unknown field (allowed: half_extents, height, id, ")


def test_unknown_setting():
    d = base()
    d["settings"] = {"warp_speed": 9}
    _expect(d, "settings.warp_speed", "unknown setting")


@pytest.mark.parametrize("where,key", [("top", "name"), ("objects", "id"), ("objects", "kind"),
                                       ("objects", "position"), ("tasks", "id"),
                                       ("tasks", "object"), ("tasks", "template")])
def test_missing_fields(where, key):
    d = base()
    if where == "top":
        del d[key]
    else:
        del d[where][0][key]
    _expect(d, key, "missing")


def test_box_needs_half_extents():
    d = base()
    d["objects"][0] = {"id": "a", "kind": "box", "position": [0, 0, 0]}
    d["tasks"][0]["template"] = "top_grasp"
    _expect(d, "half_extents", "missing")


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_nan_inf(value):
    d = base()
    d["objects"][0]["position"] = [0.0, value, 0.0]
    _expect(d, "position[1]", "finite")
    d = base()
    d["settings"] = {"v_max": value}
    _expect(d, "settings.v_max", "")


@pytest.mark.parametrize("key,value", [("radius", 0.0), ("radius", -0.01), ("height", -1.0)])
def test_nonpositive_sizes(key, value):
    d = base()
    d["objects"][0][key] = value
    _expect(d, key, "> 0")


def test_nonpositive_bound_and_fixed():
    d = base()
    d["tasks"][0]["bounds"] = {"radius": [0.0, 0.1]}
    _expect(d, "bounds.radius", "> 0")
    d = base()
    d["tasks"][0]["fixed"] = {"height": -0.1}
    _expect(d, "fixed.height", "> 0")


def test_min_above_init():
    d = base()
    d["tasks"][1]["bounds"] = {"length": [0.3, 0.2]}
    _expect(d, "bounds.length", "min 0.3 > init 0.2")


def test_template_min_above_init_for_object():
    d = base()
    d["objects"][0]["radius"] = 0.2  # min = 0.2 + 0.05 > init 0.2
    _expect(d, "tasks[ta].bounds.radius", "min")


def test_unknown_kind_and_template():
    d = base()
    d["objects"][0]["kind"] = "plate"
    _expect(d, "kind", "unknown object kind")
    d = base()
    d["tasks"][0]["template"] = "pour"
    _expect(d, "template", "unknown template")


def test_task_on_missing_object():
    d = base()
    d["tasks"][0]["object"] = "ghost"
    _expect(d, "tasks[ta].object", "no object")


def test_template_does_not_fit():
    d = base()
    d["tasks"][0]["template"] = "handle_grasp"  # a mug has no handle
    _expect(d, "template", "does not fit a mug")


def test_duplicate_ids():
    d = base()
    d["objects"][1]["id"] = "a"
    _expect(d, "objects[1].id", "duplicate")
    d = base()
    d["tasks"][1]["id"] = "ta"
    _expect(d, "tasks[1].id", "duplicate")


def test_interpenetrating_objects():
    """Checked where the geometry is built (precompute), not when the file is parsed."""
    from geometry_precompute import precompute

    d = base()
    d["objects"][1]["position"] = [0.05, 0.0, 0.0]  # bodies overlap by 3.5 cm
    scene = scene_from_dict(d, "scene.toml")
    with pytest.raises(InputError) as e:
        precompute(scene)
    assert "position" in e.value.field and "interpenetrates" in e.value.rule
    assert str(e.value).startswith("scene.toml")


def test_touching_objects_are_fine():
    from geometry_precompute import precompute

    d = base()
    d["objects"][1]["position"] = [0.085, 0.0, 0.0]  # 0.045 + 0.040: touching
    precompute(scene_from_dict(d))


def test_empty_scene():
    d = base()
    d["objects"] = []
    _expect(d, "objects", "empty scene")
    d = base()
    d["tasks"] = []
    _expect(d, "tasks", "empty scene")


def test_bad_toml_and_missing_file(tmp_path):
    with pytest.raises(InputError) as e:
        load_scene(write_scene(tmp_path, "name = [unclosed"))
    assert "not valid TOML" in str(e.value)
    with pytest.raises(InputError) as e:
        load_scene(tmp_path / "nope.toml")
    assert "no such file" in str(e.value)


def test_objects_without_tasks_and_several_tasks_per_object():
    d = base()
    d["objects"].append({"id": "spare", "kind": "mug", "position": [0.0, 0.5, 0.0]})
    d["tasks"].append({"id": "top-b", "object": "b", "template": "top_grasp"})
    scene = scene_from_dict(d)
    assert len(scene.objects) == 3 and len(scene.tasks) == 3


CM_SCENE = """name = "cm"
[[objects]]
id = "a"
kind = "mug"
position = [0, -45, 0]
radius = 4
height = 10
[[objects]]
id = "b"
kind = "mug"
position = [0, 0, 0]
radius = 4
height = 10
[[tasks]]
id = "ta"
object = "a"
template = "side_grasp"
"""


def test_a_scene_in_centimetres_is_warned_before_its_template_error(tmp_path):
    """The unit warnings come before the error they may explain, and the error names
    the unit as its likely cause."""
    path = write_scene(tmp_path, CM_SCENE)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        with pytest.raises(InputError) as e:
            load_scene(path)
    said = [str(w.message) for w in seen if issubclass(w.category, SceneWarning)]
    assert any("objects[a].radius: 4 m is large for a mug; centimetres? 4 cm is 0.04 m" in s
               for s in said), said
    assert "bounds.radius" in str(e.value) and "does not fit its object" in str(e.value)
    assert "the object's radius is 4 m: if the scene is in centimetres, that is 0.04 m" \
        in str(e.value)


@pytest.mark.parametrize("value,hint", [
    (40, "a unit slip? 40 cm is 0.4 m, 40 mm is 0.04 m"),
    (250, "a unit slip? 250 mm is 0.25 m"),
    (20000, None)])
def test_a_size_past_its_limit_names_the_unit_that_fits(tmp_path, value, hint):
    path = write_scene(tmp_path, CM_SCENE.replace("radius = 4\n", f"radius = {value}\n", 1))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(InputError, match=r"objects\[a\]\.radius: must be > 0 and at "
                           r"most 10 m") as e:
            load_scene(path)
    if hint:
        assert hint in str(e.value)
    else:
        assert "unit slip" not in str(e.value)


def test_bounds_a_hundred_times_apart_name_the_unit(tmp_path):
    text = CM_SCENE.replace("position = [0, -45, 0]", "position = [0, -0.45, 0]") \
        .replace("radius = 4\nheight = 10", "radius = 0.04\nheight = 0.1") \
        + "[tasks.bounds]\nradius = [5.0, 0.04]\n"
    with pytest.raises(InputError) as e:
        load_scene(write_scene(tmp_path, text))
    assert "min is 125 times init: a unit slip (100x, centimetres for metres)" in str(e.value)
