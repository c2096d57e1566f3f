"""The configured random generator (geometry_precompute.generate.check_generator): its
table and one-line errors, scenes of the kinds, sizes, meshes and templates asked for at
the weights asked for, the same on every call, and the example kitchen config."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

import shacc_jax
from geometry_precompute import InputError, bake, precompute, random_scene
from geometry_precompute.generate import check_generator
from sweeps.config import load_config, parse_config

CONFIGS = Path(__file__).parents[1] / "sweeps" / "configs"


@pytest.fixture()
def meshes(tmp_path) -> Path:
    folder = tmp_path / "meshes"
    folder.mkdir()
    for name, r in (("small", 0.03), ("large", 0.06)):
        m = trimesh.creation.cylinder(radius=r, height=0.1, sections=32)
        m.apply_translation([0.0, 0.0, 0.05])
        m.export(folder / f"{name}.stl")
    return folder


def _table(folder: Path) -> dict:
    return {"table": [1.0, 0.8], "objects": [
        {"kind": "mug", "weight": 2, "radius": [0.03, 0.05],
         "templates": {"side_grasp": 3, "top_grasp": 1}},
        {"kind": "box", "weight": 1, "half_extents": [[0.05, 0.06], [0.05, 0.06], 0.04],
         "templates": {"top_grasp": 1, "drawer_pull": 1}},
        {"kind": "mesh", "weight": 1, "folder": str(folder)}]}


def test_scenes_follow_the_table(meshes):
    """Over many scenes: each entry comes up at its weight and each template at its
    weight within its entry (chi-square), sizes stay in their ranges, every mesh file
    is used, positions stay on the table; the same seed gives the same scene."""
    spec = check_generator(_table(meshes), "cfg.toml")
    scenes = [random_scene(s, "uniform", 5, 8, generator=spec) for s in range(150)]
    assert random_scene(3, "uniform", 5, 8, generator=spec) == scenes[3]
    objects = [o for sc in scenes for o in sc.objects]
    kinds = Counter(o.kind for o in objects)
    assert stats.chisquare([kinds["mug"], kinds["box"], kinds["mesh"]],
                           np.array([2, 1, 1]) / 4 * len(objects)).pvalue > 1e-3
    templates = Counter(t.template for sc in scenes for t in sc.tasks
                        if sc.object(t.object).kind == "mug")
    assert stats.chisquare([templates["side_grasp"], templates["top_grasp"]],
                           np.array([3, 1]) / 4 * kinds["mug"]).pvalue > 1e-3
    assert all(0.03 <= o.radius <= 0.05 for o in objects if o.kind == "mug")
    assert all(0.05 <= o.half_extents[0] <= 0.06 and o.half_extents[2] == 0.04
               for o in objects if o.kind == "box")
    assert {round(o.body_radius, 3) for o in objects if o.kind == "mesh"} == {0.03, 0.06}
    assert all(abs(o.position[0]) <= 0.5 and abs(o.position[1]) <= 0.4 for o in objects)


def test_generated_scenes_precompute_and_evaluate(meshes):
    spec = check_generator(_table(meshes), "cfg.toml")
    results = [precompute(sc) for sc in
               (random_scene(s, "gaussian", 6, 6, generator=spec) for s in range(2))]
    assert any(r.C_init > 0 for r in results)
    run = shacc_jax.run(bake(results))
    assert (run.evaluation.metrics.n_rollouts == 36 * 6).all()


@pytest.mark.parametrize("table, field, rule", [
    ({"objects": []}, "source.generator.objects", "non-empty list"),
    ({"objects": [{"kind": "plate"}]}, "source.generator.objects[0].kind", "must be one of"),
    ({"objects": [{"kind": "mug", "radius": [0.05, 0.03]}]},
     "source.generator.objects[0].radius", "low <= high"),
    ({"objects": [{"kind": "mug", "half_extents": [1, 1, 1]}]},
     "source.generator.objects[0].half_extents", "not a field of a mug entry"),
    ({"objects": [{"kind": "cup", "templates": {"drawer_pull": 1}}]},
     "source.generator.objects[0].templates.drawer_pull", "does not fit a cup"),
    ({"objects": [{"kind": "mesh", "folder": "nowhere"}]},
     "source.generator.objects[0].folder", "no mesh files"),
    ({"objects": [{"kind": "mug", "weight": 0}]}, "source.generator.objects[0].weight",
     "must be a number in (0"),
    ({"table": [0.5]}, "source.generator.table", "[x, y] extents"),
    ({"tilt": 1}, "source.generator.tilt", "unknown field"),
])
def test_bad_generator_tables_are_one_line(tmp_path, table, field, rule):
    data = {"source": {"kind": "random", "count": 2, "generator": table}}
    with pytest.raises(InputError) as e:
        parse_config(data, "cfg.toml", tmp_path)
    assert str(e.value).startswith(f"cfg.toml: {field}: ") and rule in str(e.value), e.value


def test_a_template_that_cannot_fit_a_generated_object_stops_the_sweep_early(meshes, tmp_path):
    table = _table(meshes)
    table["objects"][1]["half_extents"] = [[0.2, 0.2], [0.2, 0.2], 0.04]  # top grasp too small
    with pytest.raises(InputError, match=r"point 0: .*bounds.radius of the random "
                                         r"generator's objects: min 0.3028 > init 0.15"):
        parse_config({"source": {"kind": "random", "count": 2, "generator": table}},
                     "cfg.toml", tmp_path)


def test_the_kitchen_config_and_its_hash(tmp_path):
    """The example config loads; its hash names the mesh files by content, not by where
    the repository lies (a copy of the config and its meshes elsewhere has the same)."""
    import shutil

    cfg = load_config(CONFIGS / "kitchen.toml")
    assert cfg.n_scenes() == 40
    kinds = {o.kind for i in range(8) for o in random_scene(*cfg.random_ref(i)).objects}
    assert kinds == {"mesh", "mug", "cup", "box"}
    shutil.copytree(CONFIGS / "kitchen_meshes", tmp_path / "kitchen_meshes")
    shutil.copy(CONFIGS / "kitchen.toml", tmp_path / "kitchen.toml")
    shutil.copy(CONFIGS / "kitchen_templates.toml", tmp_path / "kitchen_templates.toml")
    assert load_config(tmp_path / "kitchen.toml").hash() == cfg.hash()
    mine = tmp_path / "kitchen_templates.toml"  # a template's definition is in the hash
    mine.write_text(mine.read_text().replace("init = 0.25", "init = 0.24"))
    assert load_config(tmp_path / "kitchen.toml").hash() != cfg.hash()
    shutil.copy(CONFIGS / "kitchen_templates.toml", mine)
    (tmp_path / "kitchen_meshes" / "jar.stl").write_bytes(
        (tmp_path / "kitchen_meshes" / "bowl.stl").read_bytes())
    assert load_config(tmp_path / "kitchen.toml").hash() != cfg.hash()


values = st.recursive(st.none() | st.booleans() | st.integers(-5, 5) | st.floats(-1, 1)
                      | st.text(max_size=6),
                      lambda inner: st.lists(inner, max_size=3)
                      | st.dictionaries(st.text(max_size=8), inner, max_size=3), max_leaves=8)
fields = st.sampled_from(["kind", "weight", "radius", "height", "half_extents", "folder",
                          "scale", "templates", "other"])


@settings(max_examples=150, deadline=None)
@given(top=st.dictionaries(st.sampled_from(["table", "sigma", "gap", "objects", "x"]), values,
                           max_size=3),
       entry=st.dictionaries(fields, values | st.sampled_from(["mug", "cup", "box", "mesh"]),
                             max_size=4))
def test_any_generator_table_is_read_or_refused_in_one_line(top, entry):
    """Whatever a [source.generator] table holds: a checked table, or a one-line
    InputError naming a field of source.generator (never another exception)."""
    for table in (top, {**top, "objects": [entry]}):
        try:
            check_generator(table, "cfg.toml")
        except InputError as e:
            assert str(e).startswith("cfg.toml: source.generator") and "\n" not in str(e)
