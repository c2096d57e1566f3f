"""Scenes from MuJoCo (``shacc import-mjcf``): every shipped scene exported to MJCF and
imported again keeps its objects and tasks; mesh geoms become mesh files whose solid is
the original's; a hand-written MuJoCo scene of nested bodies imports by body and geom
names; bad input is one line and leaves nothing behind."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest
import tomli_w
import trimesh

from geometry_precompute import load_scene, precompute
from geometry_precompute.bodies import object_solid
from geometry_precompute.errors import SceneWarning
from geometry_precompute.mjcf import scene_to_mjcf
from sweeps.app.cli import main


def _mapping(scene) -> dict:
    return {"tasks": [{"id": t.id, "object": f"object:{t.object}", "template": t.template,
                       **({"bounds": {k: list(v) for k, v in t.bounds.items()}} if t.bounds
                          else {}), **({"fixed": dict(t.fixed)} if t.fixed else {})}
                      for t in scene.tasks],
            "obstacles": [f"object:{o.id}" for o in scene.objects]}


def _angle(a: float, b: float) -> float:
    return abs((a - b + math.pi) % (2 * math.pi) - math.pi)


def test_shipped_scenes_come_back_from_their_mjcf(shipped_results, tmp_path):
    """Export, import: the same objects (kind, position, yaw, sizes, to the MJCF's six
    significant digits) and tasks, for every shipped scene (mugs, cups whose handles
    point somewhere, boxes)."""
    for k, r in enumerate(shipped_results):
        xml = tmp_path / f"{k}.xml"
        xml.write_text(scene_to_mjcf(r))
        mapping = tmp_path / f"{k}-map.toml"
        mapping.write_text(tomli_w.dumps(_mapping(r.scene)))
        out = tmp_path / f"{k}-back.toml"
        assert main(["import-mjcf", str(xml), "--out", str(out), "--map", str(mapping)]) == 0
        back = load_scene(out)
        assert back.name == r.scene.name
        assert [(t.id, t.object, t.template, dict(t.bounds), dict(t.fixed)) for t in back.tasks] \
            == [(t.id, t.object, t.template, dict(t.bounds), dict(t.fixed)) for t in r.scene.tasks]
        for a, b in zip(r.scene.objects, back.objects, strict=True):
            assert (a.id, a.kind) == (b.id, b.kind)
            np.testing.assert_allclose(b.position, a.position, atol=2e-6)
            assert b.body_radius == pytest.approx(a.body_radius, rel=2e-6)
            assert b.body_height == pytest.approx(a.body_height, rel=2e-6)
            if a.kind != "mug":  # a mug's yaw changes nothing
                assert _angle(a.yaw, b.yaw) < 1e-5, (r.scene.name, a.id)


def test_a_mesh_object_comes_back_as_the_same_solid(tmp_path):
    """A mesh object exported (its solid's vertices inline) and imported: the STL file
    written beside the scene holds the same solid, placed where it was (MuJoCo moves a
    mesh's frame to its centre of mass; the import puts the origin there)."""
    import mujoco

    src = Path(mujoco.__file__).parent / "mjx" / "test_data" / "barkour_v0" / "assets"
    scene = {"name": "one-mesh", "objects": [
        {"id": "handle", "kind": "mesh", "mesh": str(src / "handle.stl"),
         "position": [0.1, 0.2, 0.0], "yaw": 0.7}],
        "tasks": [{"id": "top", "object": "handle", "template": "top_grasp"}]}
    (tmp_path / "s.toml").write_text(tomli_w.dumps(scene))
    r = precompute(s := load_scene(tmp_path / "s.toml"), s.settings())
    (tmp_path / "s.xml").write_text(scene_to_mjcf(r))
    out = tmp_path / "back" / "s.toml"
    out.parent.mkdir()
    assert main(["import-mjcf", str(tmp_path / "s.xml"), "--out", str(out),
                 "--task", "top=object:handle:top_grasp"]) == 0
    assert (out.parent / "handle.stl").is_file()
    back = load_scene(out).objects[0]
    a, b = object_solid(s.objects[0]), object_solid(back)
    assert b.volume == pytest.approx(a.volume, rel=1e-5)
    np.testing.assert_allclose(b.bounds, a.bounds, atol=1e-6)


SCENE_XML = """
<mujoco model="kitchen">
  <asset>
    <mesh name="gem" file="{mesh}" scale="0.002 0.002 0.002"/>
  </asset>
  <worldbody>
    <geom name="floor" type="plane" size="2 2 0.1"/>
    <body name="shelf" pos="0.1 0 0">
      <body name="mug_body" pos="0 0.2 0.05" euler="0 0 30">
        <geom name="mug_geom" type="cylinder" size="0.04 0.05"/>
      </body>
      <body name="crate" pos="0 -0.2 0.03" euler="0 0 45">
        <geom type="box" size="0.05 0.04 0.03"/>
        <geom type="box" size="0.01 0.01 0.01" contype="0" conaffinity="0"/>
      </body>
      <body name="two" pos="0.3 0 0.03">
        <geom type="box" size="0.02 0.02 0.02"/>
        <geom type="box" pos="0 0 0.05" size="0.02 0.02 0.02"/>
      </body>
    </body>
    <body name="ball" pos="-0.3 0 0.05"><geom type="sphere" size="0.05"/></body>
    <body name="leaning" pos="-0.3 0.3 0.05" euler="20 0 0">
      <geom type="cylinder" size="0.04 0.05"/>
    </body>
    <body name="gem_body" pos="0.4 0.3 0.1" euler="10 20 30">
      <geom name="gem_geom" type="mesh" mesh="gem"/>
    </body>
  </worldbody>
</mujoco>
"""


@pytest.fixture()
def kitchen(tmp_path) -> Path:
    import mujoco

    mesh = Path(mujoco.__file__).parent / "mjx" / "test_data" / "meshes" / "dodecahedron.stl"
    xml = tmp_path / "kitchen.xml"
    xml.write_text(SCENE_XML.format(mesh=mesh))
    return xml


def test_a_mujoco_scene_of_nested_bodies_imports_by_name(kitchen, tmp_path):
    """Bodies inside bodies, Euler angles in degrees, a geom that does not collide beside
    the one that does, a mesh turned every way and scaled: the objects stand where
    MuJoCo puts them, with the kinds and templates the mapping asks for."""
    mapping = tmp_path / "map.toml"
    mapping.write_text(tomli_w.dumps({
        "name": "my-kitchen",
        "tasks": [{"id": "cup-handle", "object": "mug_body", "template": "handle_grasp"},
                  {"id": "crate-top", "object": "crate", "template": "top_grasp"},
                  {"id": "gem-side", "object": "gem_geom", "template": "side_grasp",
                   "bounds": {"radius": [0.1, 0.2]}}]}))
    out = tmp_path / "kitchen.toml"
    assert main(["import-mjcf", str(kitchen), "--out", str(out), "--map", str(mapping)]) == 0
    with warnings.catch_warnings():
        warnings.simplefilter("error", SceneWarning)
        scene = load_scene(out)
    assert scene.name == "my-kitchen"
    cup, crate, gem = scene.objects
    assert (cup.id, cup.kind, crate.kind, gem.kind) == ("mug_body", "cup", "box", "mesh")
    np.testing.assert_allclose(cup.position, [0.1, 0.2, 0.0], atol=1e-9)
    assert cup.yaw == pytest.approx(math.radians(30)) and cup.radius == pytest.approx(0.04)
    np.testing.assert_allclose(crate.position, [0.1, -0.2, 0.0], atol=1e-9)
    np.testing.assert_allclose(crate.half_extents, [0.05, 0.04, 0.03])
    assert crate.yaw == pytest.approx(math.radians(45))
    dodeca = trimesh.load(Path(kitchen.read_text().split('file="')[1].split('"')[0]))
    assert object_solid(gem).volume == pytest.approx(dodeca.volume * 0.002 ** 3, rel=1e-5)
    precompute(scene, scene.settings())


@pytest.mark.parametrize("args, message", [
    (["--task", "t=two:top_grasp"], "objects[two]: body 'two' has 2 collidable geoms"),
    (["--task", "t=ball:top_grasp"], "objects[ball]: geom 'ball' is a sphere"),
    (["--task", "t=leaning:side_grasp"], "objects[leaning]: geom 'leaning' is tilted 20"),
    (["--task", "t=nothing:side_grasp"], "no geom or body named 'nothing'"),
    (["--task", "t-side_grasp"], "--task: must be ID=OBJECT:TEMPLATE"),
    (["--task", "t=crate:drawer_pul"], "k.toml (from "),
    (["--task", "t=crate:drawer_pul"], "tasks[t].template: unknown template"),
    ([], "tasks: must be a non-empty list"),
])
def test_bad_imports_are_one_line_and_leave_nothing(kitchen, tmp_path, capsys, args, message):
    out = tmp_path / "out" / "k.toml"
    out.parent.mkdir()
    assert main(["import-mjcf", str(kitchen), "--out", str(out), *args]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1, err
    assert ".import-" not in err  # the draft's folder is never named
    assert list(out.parent.iterdir()) == []  # no scene, no mesh file, no work folder


def test_a_file_mujoco_cannot_load_is_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.xml"
    bad.write_text("<mujoco><worldbody><geom type='cylinder'/></worldbody>")
    assert main(["import-mjcf", str(bad), "--out", str(tmp_path / "x.toml"),
                 "--task", "t=a:side_grasp"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {bad}: <mjcf>: MuJoCo cannot load it: ") and \
        err.count("\n") == 1


def test_a_cylinder_asked_to_be_a_box_is_one_line(kitchen, tmp_path, capsys):
    mapping = tmp_path / "m.toml"
    mapping.write_text(tomli_w.dumps({"tasks": [{"id": "t", "object": "mug_body",
                                                 "template": "side_grasp"}],
                                      "objects": {"mug_body": {"kind": "box"}}}))
    assert main(["import-mjcf", str(kitchen), "--out", str(tmp_path / "k.toml"),
                 "--map", str(mapping)]) == 2
    assert f"{mapping}: objects.mug_body.kind: a cylinder is a mug or a cup, got 'box'" in \
        capsys.readouterr().err


def test_out_into_folders_that_do_not_exist(kitchen, tmp_path, capsys):
    """``--out`` into folders that do not exist makes them (as every output file of the
    command line does); below a file it is one line naming the path, and nothing is
    made; a failed import makes no folder."""
    task = ["--task", "t=crate:top_grasp"]
    out = tmp_path / "new" / "deeper" / "k.toml"
    assert main(["import-mjcf", str(kitchen), "--out", str(out), *task]) == 0
    assert load_scene(out).tasks[0].id == "t"
    (tmp_path / "afile").write_text("")
    below = tmp_path / "afile" / "sub" / "k.toml"
    capsys.readouterr()
    assert main(["import-mjcf", str(kitchen), "--out", str(below), *task]) == 2
    err = capsys.readouterr().err
    assert f"{below}: --out: {tmp_path / 'afile'} is a file, not a folder" in err
    failed = tmp_path / "never" / "k.toml"
    assert main(["import-mjcf", str(kitchen), "--out", str(failed),
                 "--task", "t=ball:top_grasp"]) == 2
    assert not (tmp_path / "never").exists()
