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
    written beside the scene holds the same solid, placed where it was, with the same
    origin (MuJoCo moves a mesh's frame to its centre of mass; the import takes the
    geom's frame as the file wrote it)."""
    import mujoco

    src = Path(mujoco.__file__).parent / "mjx" / "test_data" / "barkour_v0" / "assets"
    scene = {"name": "one-mesh", "objects": [
        {"id": "handle", "kind": "mesh", "mesh": str(src / "handle.stl"),
         "position": [0.1, 0.2, 0.0], "yaw": 0.7, "origin": "base"}],
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
    np.testing.assert_allclose(back.position, s.objects[0].position, atol=1e-9)
    assert back.body_radius == pytest.approx(s.objects[0].body_radius, rel=1e-5)
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
    <body name="gem_body" pos="0.4 0.3 0.0196" euler="10 20 30">
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
    (["--task", "t=ball:top_grasp", "--max-tilt", "50"], "--max-tilt: must be in [0, 45]"),
    (["--task", "t=nothing*:top_grasp"], "tasks[0].object: no body matches the pattern"),
    (["--task", "t=ball:top_grasp"], "objects[ball]: geom 'ball' is a sphere"),
    (["--task", "t=leaning:side_grasp"], "objects[leaning]: geom 'leaning' is tilted 20 "
                                         "degrees, more than --max-tilt (1)"),
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


PACKAGE_XML = """
<mujoco model="package">
  <asset>
    <mesh name="mug_visual" file="mug.stl"/>
    <mesh name="mug_collision" file="mug.stl"/>
    <mesh name="jar_visual" file="jar.stl"/>
  </asset>
  <default>
    <default class="visual"><geom type="mesh" contype="0" conaffinity="0" group="2"/></default>
  </default>
  <worldbody>
    <geom name="table" type="plane" size="1 1 0.1"/>
    <body name="mug_1" pos="0.15 0 0" euler="0 0 40">
      <geom class="visual" mesh="mug_visual"/>
      <geom type="mesh" mesh="mug_collision"/>
    </body>
    <body name="mug_2" pos="-0.15 0 0">
      <geom class="visual" mesh="mug_visual"/>
      <geom type="mesh" mesh="mug_collision"/>
    </body>
    <body name="caddy" pos="0 0.25 0">
      <geom class="visual" mesh="jar_visual"/>
      <geom type="box" size="0.06 0.04 0.005" pos="0 0 0.005"/>
      <geom type="box" size="0.005 0.04 0.04" pos="0.055 0 0.045"/>
      <geom type="mesh" mesh="jar_visual" pos="-0.02 0 0.01"/>
    </body>
    <body name="jar" pos="0 -0.25 0"><geom class="visual" mesh="jar_visual"/></body>
    <body name="crate" pos="0.3 0.25 0.04" euler="0.2 0 17">
      <geom type="box" size="0.03 0.03 0.04"/>
    </body>
  </worldbody>
</mujoco>
"""


def _package(folder: Path) -> Path:
    """An object package as robot-learning packages ship them: a mug mesh whose centre of
    mass is off its origin (the handle), a jar, in an MJCF file with visual-only geoms
    of a class, unnamed geoms, a body of several geoms and a crate tilted 0.2 degrees."""
    body = trimesh.creation.cylinder(0.04, 0.1, sections=48)
    body.apply_translation([0, 0, 0.05])
    handle = trimesh.creation.box([0.03, 0.012, 0.06])
    handle.apply_translation([0.05, 0, 0.05])
    mug = trimesh.boolean.union([body, handle], engine="manifold")
    assert mug.is_watertight
    mug.export(folder / "mug.stl")
    jar = trimesh.creation.cylinder(0.03, 0.1, sections=48)
    jar.apply_translation([0, 0, 0.05])
    jar.export(folder / "jar.stl")
    xml = folder / "package.xml"
    xml.write_text(PACKAGE_XML)
    return xml


def test_object_files_as_packages_ship_them(tmp_path, capsys):
    """Unnamed geoms through their body, a glob over bodies, a body of three geoms as one
    object (the union's volume against the parts' exact ones), a visual-only body, a
    0.2-degree tilt levelled with one warning line, mesh objects at their geom frame
    (not their centre of mass); the scene reads back, and MuJoCo loads its MJCF."""
    import mujoco

    from geometry_precompute.mjcf import scene_to_mjcf

    xml = _package(tmp_path)
    mapping = tmp_path / "map.toml"
    mapping.write_text(tomli_w.dumps({"tasks": [
        {"id": "side", "object": "mug_*", "template": "side_grasp"},
        {"id": "caddy-top", "object": "caddy", "template": "top_grasp"},
        {"id": "jar-side", "object": "jar", "template": "side_grasp"},
        {"id": "crate-top", "object": "crate", "template": "top_grasp"}]}))
    out = tmp_path / "scene" / "kitchen.toml"
    assert main(["import-mjcf", str(xml), "--out", str(out), "--map", str(mapping)]) == 0
    err = capsys.readouterr().err
    assert err.count("warning:") == 1 and "geom 'crate' is tilted 0.2 degrees" in err \
        and "levelled" in err, err
    scene = load_scene(out)
    assert [t.id for t in scene.tasks] == ["side-mug_1", "side-mug_2", "caddy-top",
                                           "jar-side", "crate-top"]
    mug1, mug2, caddy, jar, crate = scene.objects
    assert (mug1.kind, caddy.kind, jar.kind, crate.kind) == ("mesh", "mesh", "mesh", "box")
    # At the geom frame: the mug's axis, not its centre of mass (off it by the handle).
    np.testing.assert_allclose(mug1.position, [0.15, 0.0, 0.0], atol=1e-7)
    np.testing.assert_allclose(mug2.position, [-0.15, 0.0, 0.0], atol=1e-7)
    file_mug = trimesh.load(tmp_path / "mug.stl")
    reach = float(np.hypot(file_mug.vertices[:, 0], file_mug.vertices[:, 1]).max())
    assert mug1.body_radius == pytest.approx(reach, abs=1e-6)
    assert mug1.body_height == pytest.approx(0.1, abs=1e-6)
    assert object_solid(mug1).volume == pytest.approx(file_mug.volume, rel=1e-5)
    # The visual-only body stands for its visual mesh.
    assert object_solid(jar).volume == pytest.approx(trimesh.load(tmp_path / "jar.stl").volume,
                                                     rel=1e-5)
    # The union: floor + wall - their overlap + the jar standing on the floor.
    jar_volume = trimesh.load(tmp_path / "jar.stl").volume
    expected = 0.12 * 0.08 * 0.01 + 0.01 * 0.08 * 0.08 - 0.01 * 0.08 * 0.005 + jar_volume
    assert object_solid(caddy).volume == pytest.approx(expected, rel=1e-4)
    np.testing.assert_allclose(caddy.position, [0.0, 0.25, 0.0], atol=1e-7)
    assert caddy.base[2] == pytest.approx(0.0, abs=1e-6)
    # Levelled: base on the table, its yaw kept.
    np.testing.assert_allclose(crate.position, [0.3, 0.25, 0.0], atol=1e-4)
    assert crate.yaw == pytest.approx(math.radians(17), abs=1e-4)
    r = precompute(scene, scene.settings())
    model = mujoco.MjModel.from_xml_string(scene_to_mjcf(r, spaces="none"))
    assert model.ngeom >= len(scene.objects)


def test_a_small_tilt_beyond_max_tilt_is_refused(tmp_path, capsys):
    xml = _package(tmp_path)
    assert main(["import-mjcf", str(xml), "--out", str(tmp_path / "k.toml"),
                 "--task", "t=crate:top_grasp", "--max-tilt", "0.1"]) == 2
    err = capsys.readouterr().err
    assert "geom 'crate' is tilted 0.2 degrees, more than --max-tilt (0.1)" in err
    assert err.count("\n") == 1


OBJECT_XML = """
<mujoco model="carton">
  <asset><mesh name="carton_mesh" file="carton.stl" scale="0.9 0.9 0.9"/></asset>
  <worldbody>
    <body>
      <body name="object">
        <geom pos="0 0 0" mesh="carton_mesh" type="mesh" group="0"/>
        <geom pos="0 0 0" mesh="carton_mesh" type="mesh" contype="0" conaffinity="0"
              group="1"/>
      </body>
      <site pos="0 0 -0.072" name="bottom_site"/>
    </body>
  </worldbody>
</mujoco>
"""


def test_an_object_file_centred_on_its_origin_stands_with_stand(tmp_path, capsys):
    """An object file as packages ship one (a body named 'object', its unnamed mesh geom
    centred on the origin, a visual copy beside it): as placed it reaches below the table,
    a one-line error naming the cause; with ``--stand`` it stands on the table, its grasp
    axis through the mesh's origin."""
    carton = trimesh.creation.box([0.06, 0.06, 0.16])  # centred on its origin
    carton.export(tmp_path / "carton.stl")
    xml = tmp_path / "carton.xml"
    xml.write_text(OBJECT_XML)
    out = tmp_path / "scene" / "carton.toml"
    args = ["import-mjcf", str(xml), "--out", str(out), "--task", "side=object:side_grasp"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "objects[object].position: the mesh 'object.stl' reaches 72.0 mm below the table" \
        in err and 'origin = "base"' in err and err.count("\n") == 1, err
    assert not out.parent.exists()
    (tmp_path / "scene").mkdir()
    xml.write_text(OBJECT_XML.replace('<body>', '<body pos="0 0 0.2">', 1))
    assert main(args) == 0  # floating: said in one line, naming the scene written
    err = capsys.readouterr().err
    assert err.startswith(f"warning: {out}: objects[object].position: the mesh 'object.stl' "
                          "floats 128.0 mm above the table") and ".import-" not in err, err
    assert main([*args, "--stand"]) == 0
    obj = load_scene(out).objects[0]
    np.testing.assert_allclose(obj.position, [0.0, 0.0, 0.072], atol=1e-6)
    assert obj.base[2] == pytest.approx(0.0, abs=1e-6)
    assert obj.body_height == pytest.approx(0.144, abs=1e-6)
