"""Templates as data: the built-in file against the Python templates it replaced, bit for
bit; a template written only as data, end to end; template files' one-line errors, and a
property test of the loader."""

from __future__ import annotations

import copy
import json
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
import reference_templates as ref
import tomli_w
from hypothesis import HealthCheck, given, settings

from geometry_precompute import (
    InputError,
    load_scene,
    precompute,
    random_scene,
    scene_from_dict,
    shipped_scene_paths,
)
from geometry_precompute.generate import check_generator
from geometry_precompute.template_files import builtin, parse_file
from geometry_precompute.templates import resolve_tasks

ROOT = Path(__file__).parents[1]
KITCHEN_TEMPLATES = ROOT / "sweeps" / "configs" / "kitchen_templates.toml"
DOC = tomllib.loads(KITCHEN_TEMPLATES.read_text())


def _bits(v) -> bytes:
    return np.asarray(v, dtype=np.float64).tobytes()


def _scenes_for_bit_for_bit():
    scenes = [load_scene(p) for p in shipped_scene_paths()]
    scenes += [load_scene(p) for p in sorted((ROOT / "geometry_precompute" / "scenes" /
                                              "extra").glob("*.toml"))]
    scenes += [random_scene(seed=s) for s in range(80)]
    scenes += [random_scene(seed=s, preset="paper", kind="gaussian") for s in range(40)]
    gen = check_generator({"objects": [
        {"kind": "mug", "radius": [0.03, 0.06], "templates": {"side_grasp": 1, "top_grasp": 1}},
        {"kind": "cup", "templates": {"handle_grasp": 2, "top_grasp": 1, "side_grasp": 1}},
        {"kind": "box", "half_extents": [[0.02, 0.05], [0.05, 0.1], [0.05, 0.15]],
         "templates": {"drawer_pull": 1}}]}, "<test>")
    scenes += [random_scene(seed=s, generator=gen) for s in range(40)]
    return scenes


def test_the_builtin_file_gives_the_former_templates_bit_for_bit():
    """Every task space of the shipped scenes and of random scenes of the hidden scenes'
    style (and of a generator that uses all four templates, yawed boxes and cups): the
    same bits as the Python templates (tests/reference_templates.py) in the shape at
    three parameter vectors, bounds, fixed dimensions, orientation space and aim point.
    Everything downstream reads only these numbers, so every mode's results are
    unchanged."""
    n = 0
    for scene in _scenes_for_bit_for_bit():
        s = scene.settings()
        for task, new in zip(scene.tasks, resolve_tasks(scene, s), strict=True):
            old = ref.resolve_task(scene, task, s)
            assert new.param_names == old.param_names
            assert _bits(new.q_min) == _bits(old.q_min) and _bits(new.q_init) == _bits(old.q_init)
            assert {k: new.fixed[k] for k in old.fixed} == old.fixed
            for q in (old.q_init, old.q_min, (old.q_init + old.q_min) / 2):
                a, b = old.shape(q), new.shape(q)
                assert a.kind == b.kind, task
                for f in ("center", "quat", "dims"):
                    assert _bits(getattr(a, f)) == _bits(getattr(b, f)), (scene.name, task, f)
            assert old.orientation.kind == new.orientation.kind
            assert _bits(old.orientation.quat) == _bits(new.orientation.quat)
            assert _bits(old.orientation.axis_xy) == _bits(new.orientation.axis_xy)
            assert _bits(old.aim_point) == _bits(new.aim_point)
            assert _bits(old.pose_quat) == _bits(new.pose_quat)
            n += 1
    assert n > 1000
    assert list(builtin()) == ["side_grasp", "handle_grasp", "top_grasp", "drawer_pull"]


def _scene(tmp_path: Path, templates_doc: dict | None = None, extra_tasks=()) -> Path:
    """A board, two mugs and a cup, with the kitchen's two data-only templates."""
    (tmp_path / "mine.toml").write_text(tomli_w.dumps(templates_doc or DOC))
    doc = {"name": "board", "templates": ["mine.toml"],
           "objects": [
               {"id": "board", "kind": "box", "position": [0.0, 0.0, 0.0],
                "half_extents": [0.14, 0.09, 0.01], "yaw": 0.3},
               {"id": "mug", "kind": "mug", "position": [0.0, 0.2, 0.0]},
               {"id": "mug2", "kind": "mug", "position": [0.12, 0.2, 0.0]}],
           "tasks": [{"id": "place", "object": "board", "template": "above_board"},
                     {"id": "angled", "object": "mug", "template": "angled_top",
                      "bounds": {"half_angle_deg": [10, 20]}},
                     {"id": "side", "object": "mug2", "template": "side_grasp"},
                     *extra_tasks]}
    path = tmp_path / "scene.toml"
    path.write_text(tomli_w.dumps(doc))
    return path


def test_a_template_written_as_data_shapes_its_space(tmp_path):
    """The tilted cone and the box over a board land where their files say, in the
    object's frame (yawed board), and Shrinking moves only what their parameters name."""
    scene = load_scene(_scene(tmp_path))
    assert scene.templates.files == (str((tmp_path / "mine.toml").resolve()),)
    place, angled, _ = resolve_tasks(scene, scene.settings())
    sh = place.shape()
    c, s = np.cos(0.3), np.sin(0.3)
    np.testing.assert_allclose(sh.center, (0.0, 0.0, 0.02 + 0.1), atol=1e-15)
    np.testing.assert_allclose(sh.dims, (0.14, 0.09, 0.1))
    np.testing.assert_allclose(sh.rotation[:, 0], (c, s, 0.0), atol=1e-12)  # the board's x
    low = place.shape(place.q_min)
    np.testing.assert_allclose(low.center[2] - low.dims[2], 0.02)  # the board's surface stays
    assert place.aim_point == pytest.approx((0.0, 0.0, 0.02))
    cone = angled.shape()
    assert cone.kind == "cone" and cone.dims[:2] == pytest.approx((0.25, np.radians(20)))
    assert angled.q_min.tolist() == pytest.approx([0.08, np.radians(10)])  # from _deg
    np.testing.assert_allclose(cone.center, (0.0, 0.2, 0.13))
    np.testing.assert_allclose(cone.rotation[:, 2], (0.5, 0.0, np.sqrt(3) / 2), atol=1e-12)
    assert angled.orientation.kind == "fixed"


def test_a_template_written_as_data_end_to_end(tmp_path):
    """Precompute, every mode with the optimized one (as one batch), the pictures and the
    MJCF; the scene's cache key follows the template file's content."""
    import mujoco

    from geometry_precompute.cache import scene_key
    from geometry_precompute.mjcf import scene_to_mjcf
    from sweeps.analysis.render import optimized_shapes, render_array, top_view_array
    from sweeps.pipeline import evaluate_results

    path = _scene(tmp_path)
    scene = load_scene(path)
    s = scene.settings(overrides={"start_grid": (3, 3), "optimize_population": 8,
                                  "optimize_generations": 3, "optimize_starts": 16})
    result = precompute(scene, s)
    assert result.C_init > result.C_final  # the box over the board and the cones overlap
    modes = ("baseline", "shrinking", "shacc", "optimized")
    ev = evaluate_results([result], modes)
    rates = dict(zip(modes, np.asarray(ev.evaluation.metrics.u_scene[0]).tolist(), strict=True))
    assert rates["shrinking"] > rates["baseline"], rates
    q = np.asarray(ev.search.q[0, :3, :2])
    for t, sp in enumerate(result.spaces):  # the search stays within every data bound
        n = len(sp.param_names)
        assert np.all(q[t, :n] >= sp.q_min - 1e-9) and np.all(q[t, :n] <= sp.q_init + 1e-9)
    opt = optimized_shapes(ev)
    assert [sh.kind for sh in opt] == ["box", "cone", "cylinder"]
    picture = render_array(result, 160, 120, "both")
    assert picture.shape[:2] == (120, 160) and picture.std() > 0
    top = top_view_array(result, 160, 120, optimized=opt, success=rates)
    assert top.shape[:2] == (120, 160)
    model = mujoco.MjModel.from_xml_string(scene_to_mjcf(result))
    assert model.ngeom > 0
    key = scene_key(scene, s)
    changed = copy.deepcopy(DOC)
    changed["templates"]["above_board"]["params"]["height"]["init"] = 0.25
    assert scene_key(load_scene(_scene(tmp_path, changed)), s) != key


def test_templates_lists_builtin_file_and_scene_tasks(tmp_path):
    path = _scene(tmp_path)
    r = subprocess.run([sys.executable, "-m", "sweeps", "templates", str(path), "--json"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    names = [t["name"] for t in out["templates"]]
    assert names == ["side_grasp", "handle_grasp", "top_grasp", "drawer_pull", "angled_top",
                     "above_board"]
    assert out["templates"][0]["params"]["radius"]["min"] == \
        "object.radius + settings.side_grasp.radius_margin"
    tasks = {t["task"]: t for t in out["tasks"]}
    assert tasks["side"]["bounds"]["radius"] == pytest.approx([0.095, 0.2])
    assert tasks["place"]["bounds"]["height"] == [0.04, 0.2]
    r = subprocess.run([sys.executable, "-m", "sweeps", "templates", "--file",
                        str(KITCHEN_TEMPLATES)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "angled_top" in r.stdout and "shrinks half_angle [rad]" \
        in r.stdout, r.stderr


def _with(path: tuple, value, delete: bool = False) -> dict:
    doc = copy.deepcopy(DOC)
    parent = doc
    for k in path[:-1]:
        parent = parent[k]
    if delete:
        del parent[path[-1]]
    else:
        parent[path[-1]] = value
    return doc


T = ("templates", "angled_top")
B = ("templates", "above_board")
BAD_FILES = [
    (_with((*T, "shape"), "sphere"), "templates.angled_top.shape", "unknown shape kind"),
    (_with((*T, "fits"), ["chair"]), "templates.angled_top.fits", "object kinds"),
    (_with((*T, "center"), [0, 0]), "templates.angled_top.center", "list of 3"),
    (_with((*T, "dims"), ["length", "half_angle", 1]), "templates.angled_top.dims",
     "list of 2"),
    (_with((*B, "dims", 2), "height * height"), "templates.above_board.dims[2]",
     "not affine"),
    (_with((*T, "dims", 1), "sin(half_angle)"), "templates.angled_top.dims[1]", "not affine"),
    (_with((*B, "center", 2), "1 / height"), "templates.above_board.center[2]", "not affine"),
    (_with((*T, "center", 2), "object.height ** 2"), "templates.angled_top.center[2]",
     "operator Pow"),
    (_with((*T, "center", 2), "__import__('os')"), "templates.angled_top.center[2]",
     "may be called"),
    (_with((*T, "center", 2), "object.mass"), "templates.angled_top.center[2]",
     "unknown measure"),
    (_with((*T, "center", 2), "object.half_z"), "templates.angled_top.center[2]",
     "a box's measure"),
    (_with((*T, "center", 2), "settings.v_max"), "templates.angled_top.center[2]",
     "not a geometry setting"),
    (_with((*T, "center", 2), "length +"), "templates.angled_top.center[2]",
     "not an expression"),
    (_with((*T, "params", "length", "min"), "length"), "templates.angled_top.params.length.min",
     "unknown name"),
    (_with((*T, "params", "length", "unit"), "deg"), "templates.angled_top.params.length.unit",
     "must be one of"),
    (_with((*T, "params", "length"), None, delete=True), "templates.angled_top.dims[0]",
     "unknown name 'length'"),
    (_with((*T, "params", "extra"), {"min": 0.1, "init": 0.2}),
     "templates.angled_top.params", "at most 2"),
    (_with((*T, "rotation"), [0, 0, 0]), "templates.angled_top.rotation", "zero vector"),
    (_with((*T, "orientation"), "towards"), "templates.angled_top.orientation",
     "point_to_axis"),
    (_with((*B, "aim"), None, delete=True), "templates.above_board.aim", "required"),
    (_with((*T, "colour"), "red"), "templates.angled_top.colour", "unknown field"),
    (_with(("templates", "Bad-Name"), {}), "templates.'Bad-Name'", "lower-case"),
    (_with(("extra",), 1), "extra", "unknown field"),
]


@pytest.mark.parametrize("doc, fld, rule", BAD_FILES, ids=[f for _, f, _ in BAD_FILES])
def test_a_bad_template_file_is_one_line_naming_file_and_field(tmp_path, doc, fld, rule):
    path = _scene(tmp_path, doc)
    with pytest.raises(InputError) as e:
        load_scene(path)
    assert e.value.source == str(tmp_path / "mine.toml") or \
        e.value.source == str((tmp_path / "mine.toml").resolve())
    assert e.value.field == fld and rule in e.value.rule, str(e.value)
    assert "\n" not in str(e.value)


def test_scene_level_template_errors(tmp_path):
    path = _scene(tmp_path)
    doc = tomllib.loads(path.read_text())
    with pytest.raises(InputError, match=r"templates\[0\]: no template file"):
        scene_from_dict({**doc, "templates": ["nowhere.toml"]}, str(path))
    with pytest.raises(InputError, match="already defined by the built-in file"):
        load_scene(_scene(tmp_path, {"templates": {"side_grasp": DOC["templates"][
            "angled_top"]}}))
    _scene(tmp_path)
    bad = copy.deepcopy(doc)
    bad["tasks"][1]["object"] = "board"
    with pytest.raises(InputError, match=r"tasks\[angled\]\.template: angled_top does not fit a "
                       "box"):
        scene_from_dict(bad, str(path))
    bad = copy.deepcopy(doc)
    bad["tasks"][1]["bounds"] = {"half_angle": [0.2, 1.7]}
    with pytest.raises(InputError, match=r"tasks\[angled\]\.bounds\.half_angle"):
        scene_from_dict(bad, str(path))
    # Arithmetic that fails for one object: a one-line error naming the task.
    zero = _with((*B, "dims", 0), "object.half_x / (object.half_y - 0.09)")
    with pytest.raises(InputError, match=r"tasks\[place\]\.template: above_board's space "
                       "cannot be evaluated.*division by zero"):
        precompute(load_scene(_scene(tmp_path, zero)))
    neg = _with((*B, "params", "height", "min"), -0.1)
    with pytest.raises(InputError, match=r"box half_z of -0\.05 .*must be > 0"):
        precompute(load_scene(_scene(tmp_path, neg)))


@settings(max_examples=150, suppress_health_check=[HealthCheck.too_slow,
                                                    HealthCheck.function_scoped_fixture])
@given(__import__("test_loaders_property").mutated(DOC))
def test_mutated_template_file_is_templates_or_one_line_error(tmp_path, doc):
    """Whatever a template file holds: its templates, or one line naming the file; and a
    scene using accepted templates precomputes or gives one line naming the scene."""
    from test_loaders_property import one_line_error

    try:
        parse_file(doc, "mine.toml")
    except InputError as e:
        one_line_error(e, "mine.toml")
        return
    try:
        text = tomli_w.dumps(doc)
    except (TypeError, ValueError, RecursionError):
        return
    (tmp_path / "mine.toml").write_text(text)
    scene_doc = tomllib.loads(_scene(tmp_path, DOC).read_text())
    (tmp_path / "mine.toml").write_text(text)
    try:
        precompute(scene_from_dict(scene_doc, str(tmp_path / "scene.toml")))
    except InputError as e:
        one_line_error(e)


def test_a_sweep_of_scene_files_hashes_their_templates_by_content(tmp_path):
    """A sweep over scene files that name template files: the same hash from a copy in
    another folder, another hash when a template changes."""
    from sweeps.config import parse_config

    hashes = []
    for where in ("a", "b"):
        folder = tmp_path / where / "scenes"
        folder.mkdir(parents=True)
        _scene(folder)
        hashes.append(parse_config({"source": {"kind": "files", "path": "scenes"}},
                                   "cfg.toml", tmp_path / where).hash())
    assert hashes[0] == hashes[1]
    changed = copy.deepcopy(DOC)
    changed["templates"]["angled_top"]["params"]["length"]["init"] = 0.24
    _scene(tmp_path / "b" / "scenes", changed)
    assert parse_config({"source": {"kind": "files", "path": "scenes"}}, "cfg.toml",
                        tmp_path / "b").hash() != hashes[0]


def test_precomputed_scenes_pickle_with_plain_pickle(tmp_path):
    """A precomputed scene whose spaces were built (the templates' functions compiled and
    cached) pickles with the standard library's pickle, as a process pool sends it, and
    comes back with the same shapes, for a built-in and a data-only template."""
    import pickle

    result = precompute(load_scene(_scene(tmp_path)))
    assert all(sp.shape().dims for sp in result.spaces)  # builds and caches them
    back = pickle.loads(pickle.dumps(result))
    for a, b in zip(result.spaces, back.spaces, strict=True):
        for q in (a.q_init, a.q_min):
            assert a.shape(q) == b.shape(q)


def test_a_fixed_dimension_of_a_template_that_has_none_is_named_so(tmp_path):
    """A template without fixed dimensions: ``[tasks.fixed]`` takes no field, and the
    rule says so instead of listing none ("allowed: []")."""
    path = _scene(tmp_path, extra_tasks=[{"id": "f", "object": "mug", "template": "angled_top",
                                          "fixed": {"height": 0.2}}])
    with pytest.raises(InputError, match=r"tasks\[f\]\.fixed\.height: unknown field "
                       r"\(this table takes no fields\)"):
        load_scene(path)
