"""`shacc schema scene|sweep`: the JSON Schemas agree with the loaders. Every shipped
scene and config validates; every bad input the loader rejects, the schema rejects
too, unless it breaks a rule the schema lists as checked by the loader only."""

from __future__ import annotations

import copy
import json
import tomllib
from pathlib import Path

import jsonschema
import pytest

from geometry_precompute import shipped_scene_paths
from geometry_precompute.errors import InputError
from geometry_precompute.file_schema import LOADER_ONLY, scene_schema
from geometry_precompute.loading import scene_from_dict
from sweeps.app.cli import main
from sweeps.app.schema_cmd import LOADER_ONLY as SWEEP_LOADER_ONLY
from sweeps.app.schema_cmd import sweep_schema
from sweeps.config import parse_config

ROOT = Path(__file__).resolve().parents[1]
SCENE = jsonschema.Draft202012Validator(scene_schema())
SWEEP = jsonschema.Draft202012Validator(sweep_schema())


def test_the_schemas_are_valid_and_printed(capsys):
    jsonschema.Draft202012Validator.check_schema(scene_schema())
    jsonschema.Draft202012Validator.check_schema(sweep_schema())
    assert main(["schema", "scene"]) == 0
    assert json.loads(capsys.readouterr().out) == scene_schema()
    assert main(["schema", "sweep"]) == 0
    assert json.loads(capsys.readouterr().out)["title"] == "ShaCC sweep config"


@pytest.mark.parametrize("path", shipped_scene_paths(), ids=lambda p: p.stem)
def test_every_shipped_scene_validates(path):
    SCENE.validate(tomllib.loads(path.read_text()))


def _is_template_file(path: Path) -> bool:
    return set(tomllib.loads(path.read_text())) == {"templates"}


CONFIGS = sorted((ROOT / "sweeps/configs").glob("*.toml")) \
    + sorted((ROOT / "benchmarks").glob("*.toml"))
TEMPLATE_FILES = [ROOT / "geometry_precompute/builtin_templates.toml",
                  *[p for p in CONFIGS if _is_template_file(p)]]


@pytest.mark.parametrize("path", [p for p in CONFIGS if not _is_template_file(p)],
                         ids=lambda p: p.stem)
def test_every_shipped_config_validates(path):
    SWEEP.validate(tomllib.loads(path.read_text()))


def test_template_files_validate_and_bad_ones_are_refused_by_both(capsys):
    """The built-in and the shipped template files validate; every bad template file the
    loader refuses, the schema refuses too, unless its rule is listed as loader-only."""
    from test_template_files import BAD_FILES

    from geometry_precompute.file_schema import TEMPLATE_LOADER_ONLY, templates_schema
    from geometry_precompute.template_files import parse_file

    schema = templates_schema()
    jsonschema.Draft202012Validator.check_schema(schema)
    assert main(["schema", "templates"]) == 0
    assert json.loads(capsys.readouterr().out) == schema
    validator = jsonschema.Draft202012Validator(schema)
    assert len(TEMPLATE_FILES) >= 2
    for path in TEMPLATE_FILES:
        validator.validate(tomllib.loads(path.read_text()))
    # A bad file's rule, and the words of the loader-only rule that covers it.
    loader_only = {"not affine": "affine", "operator Pow": "expressions use",
                   "may be called": "expressions use", "unknown measure": "object.<measure>",
                   "a box's measure": "object.half_x", "not a geometry setting":
                   "settings.<geometry setting>", "not an expression": "expressions use",
                   "unknown name": "expressions use", "zero vector": "zero vector",
                   "required": "aim is given"}
    listed_rules = " ".join(TEMPLATE_LOADER_ONLY)
    refused_by_schema_only_if_listed = 0
    for doc, fld, rule in BAD_FILES:
        with pytest.raises(InputError):
            parse_file(doc, "mine.toml")
        if validator.is_valid(doc):
            words = [w for k, w in loader_only.items() if k in rule]
            assert words and words[0] in listed_rules, (fld, rule, "the schema accepts it")
            refused_by_schema_only_if_listed += 1
    assert refused_by_schema_only_if_listed < len(BAD_FILES)


BASE = {
    "name": "s",
    "objects": [{"id": "a", "kind": "cup", "position": [0.0, 0.0, 0.0], "yaw": 1.0},
                {"id": "b", "kind": "box", "position": [0.3, 0.0, 0.0],
                 "half_extents": [0.1, 0.1, 0.1]}],
    "tasks": [{"id": "t", "object": "a", "template": "handle_grasp"},
              {"id": "u", "object": "b", "template": "drawer_pull"}],
    "settings": {"dt": 0.02},
}


def _set(data, path, value):
    *head, last = path
    for k in head:
        data = data[k]
    if value is KeyError:
        del data[last]
    else:
        data[last] = value


# (where, value, a rule the schema cannot state or None). KeyError deletes the field.
BAD_SCENES = [
    (("name",), KeyError, None),
    (("name",), "", None),
    (("name",), 3, None),
    (("colour",), "red", None),
    (("objects",), [], None),
    (("tasks",), [], None),
    (("objects", 0, "kind"), "plate", None),
    (("objects", 0, "position"), [0.0, 0.0], None),
    (("objects", 0, "position"), [0.0, 0.0, 1e9], None),
    (("objects", 0, "position"), [0.0, "x", 0.0], None),
    (("objects", 0, "radius"), -0.04, None),
    (("objects", 0, "radius"), 0.0, None),
    (("objects", 0, "yaw"), 5000.0, None),
    (("objects", 0, "half_extents"), [0.1, 0.1, 0.1], None),
    (("objects", 1, "half_extents"), KeyError, None),
    (("objects", 1, "radius"), 0.1, None),
    (("objects", 0, "id"), "b", "object ids are unique"),
    (("objects", 0, "yaw_deg"), 30.0, "not both given"),
    (("tasks", 0, "template"), "wave", None),
    (("tasks", 0, "object"), "nope", "a task's object exists"),
    (("tasks", 0, "template"), "drawer_pull", "template fits that object's kind"),
    (("tasks", 0, "bounds"), {"radius": [0.1, 0.2]}, None),
    (("tasks", 0, "bounds"), {"length": [0.3, 0.1]}, "min <= init"),
    (("tasks", 0, "bounds"), {"half_angle": [10, 30]}, None),
    (("tasks", 0, "bounds"), {"half_angle_deg": [10, 95]}, None),
    (("tasks", 0, "fixed"), {"height": 0.1}, None),
    (("tasks", 1, "id"), "t", "task ids"),
    (("settings", "dt"), 0.0, None),
    (("settings", "max_steps"), 600.5, None),
    (("settings", "dt"), "fast", None),
    (("settings", "warp"), 9, None),
    (("settings", "ambiguity"), "random", None),
    (("settings", "start_grid"), [6], None),
    (("settings", "start_grid"), [65536, 65536], "n_y * n_z"),
    (("settings", "start_z_range"), [0.3, 0.02], "low <= high"),
    (("settings", "side_grasp"), {"radius_init": -1.0}, None),
    (("settings", "side_grasp"), {"radius_size": 0.2}, None),
]


@pytest.mark.parametrize("where,value,loader_only", BAD_SCENES,
                         ids=[".".join(map(str, w)) + f"={v!r}"[:30] for w, v, _ in BAD_SCENES])
def test_what_the_scene_loader_rejects_the_schema_rejects(where, value, loader_only):
    data = copy.deepcopy(BASE)
    _set(data, where, value)
    with pytest.raises(InputError):
        scene_from_dict(data, "s.toml").settings()
    schema_rejects = not SCENE.is_valid(data)
    if loader_only is None:
        assert schema_rejects, "the schema accepts what the loader rejects"
    else:
        assert any(loader_only in rule for rule in LOADER_ONLY["scene"])


def test_the_base_scene_is_valid_for_both():
    scene_from_dict(copy.deepcopy(BASE), "s.toml")
    SCENE.validate(BASE)


CONFIG = {"name": "c", "source": {"kind": "random", "count": 4, "tasks": [5, 8]},
          "axes": {"v_max": [0.1, 0.2]}, "settings": {"start_grid": [2, 2]}}

BAD_CONFIGS = [
    (("source",), KeyError, None),
    (("source", "kind"), "scans", None),
    (("source", "count"), 0, None),
    (("source", "colour"), 1, None),
    (("source", "tasks"), [8, 5], "min <= max"),
    (("source", "preset"), "huge", None),
    (("modes",), ["baseline", "baseline"], None),
    (("modes",), ["fast"], None),
    (("chunk",), 0, None),
    (("axes", "v_max"), [], None),
    (("axes", "v_max"), [0.1, -1.0], None),
    (("axes", "warp"), [1], None),
    (("settings", "dt"), -1.0, None),
    (("points",), [{"dt": 0.0}], None),
    (("scheduler",), "  ", None),
]


@pytest.mark.parametrize("where,value,loader_only", BAD_CONFIGS,
                         ids=[".".join(map(str, w)) + f"={v!r}"[:30] for w, v, _ in BAD_CONFIGS])
def test_what_the_config_loader_rejects_the_schema_rejects(where, value, loader_only, tmp_path):
    data = copy.deepcopy(CONFIG)
    _set(data, where, value)
    with pytest.raises(InputError):
        parse_config(data, "c.toml", tmp_path)
    if loader_only is None:
        assert not SWEEP.is_valid(data), "the schema accepts what the loader rejects"
    else:
        assert any(loader_only in rule for rule in SWEEP_LOADER_ONLY)


def test_the_base_config_is_valid_for_both(tmp_path):
    parse_config(copy.deepcopy(CONFIG), "c.toml", tmp_path)
    SWEEP.validate(CONFIG)
