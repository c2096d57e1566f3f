"""Real assets as they come: a mesh file written Y-up, in centimetres, with its origin at
its centre, tilted, or with its vertices split at texture seams, placed by the scene's
keys, is the same object as the mesh written the plain way (the same solid, bounding
cylinder, C, clusters and rollouts); a wrong placement is said in one line; a
generator's folder takes the same keys, per file through ``meshes.toml``; and a sweep
says each of its scenes' warnings once, on one line."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import warnings
from pathlib import Path

import jsonschema
import numpy as np
import pytest
import tomli_w
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

import shacc_jax
from geometry_precompute import DEFAULTS, InputError, bake, load_scene, precompute
from geometry_precompute.bodies import object_solid
from geometry_precompute.errors import SceneWarning
from geometry_precompute.file_schema import LOADER_ONLY, scene_schema
from geometry_precompute.generate import check_generator, random_scene
from sweeps.app.cli import main

GRID = {"start_grid": [3, 3]}
YAW = 0.7  # the mesh object's yaw in every placement


def _mug() -> trimesh.Trimesh:
    """A mug with a handle (so that yaw and tilt show), its origin at the centre of its
    bounding box's lowest face, Z-up, in metres: the mesh written the plain way."""
    body = trimesh.creation.cylinder(0.04, 0.1, sections=48)
    body.apply_translation([0, 0, 0.05])
    handle = trimesh.creation.box([0.03, 0.012, 0.06])
    handle.apply_translation([0.05, 0, 0.05])
    mug = trimesh.boolean.union([body, handle], engine="manifold")
    lo, hi = mug.bounds
    mug.apply_translation([-(lo[0] + hi[0]) / 2, -(lo[1] + hi[1]) / 2, -lo[2]])
    assert mug.is_watertight
    return mug


def _split_seams(mesh: trimesh.Trimesh, path: Path) -> None:
    """An OBJ file whose every triangle has vertices and texture coordinates of its own,
    as a textured scan's are split at its seams (open as read, watertight once merged)."""
    lines = []
    for k, tri in enumerate(mesh.triangles):
        lines += [f"v {x:.12g} {y:.12g} {z:.12g}" for x, y, z in tri]
        lines += [f"vt {(k % 7) / 7:.4f} {(k % 5) / 5:.4f}"] * 3
    lines += [f"f {3 * k + 1}/{3 * k + 1} {3 * k + 2}/{3 * k + 2} {3 * k + 3}/{3 * k + 3}"
              for k in range(len(mesh.faces))]
    path.write_text("\n".join(lines) + "\n")


def _variants(folder: Path) -> dict[str, dict]:
    """Per placement, the mesh file written that way and the scene keys that place it
    where the plain one stands."""
    mug = _mug()
    v = np.asarray(mug.vertices, float)
    out: dict[str, dict] = {}

    def write(name: str, vertices: np.ndarray, suffix: str = ".ply") -> str:
        path = folder / f"{name}{suffix}"
        m = trimesh.Trimesh(vertices, mug.faces, process=False)
        if suffix == ".obj":
            _split_seams(m, path)
        else:
            path.write_bytes(trimesh.exchange.ply.export_ply(m, encoding="ascii"))
        return path.name

    out["plain"] = {"mesh": write("plain", v), "yaw": YAW}
    y_up = v @ np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]]).T  # Z-up -> Y-up
    out["y_up"] = {"mesh": write("y_up", y_up), "up": "y", "yaw": YAW}
    out["cm"] = {"mesh": write("cm", v * 100.0), "unit": "cm", "yaw": YAW}
    out["mm_scale"] = {"mesh": write("mm_scale", v * 1000.0), "scale": 0.001, "yaw": YAW}
    centre = v - (v.min(axis=0) + v.max(axis=0)) / 2
    out["centred"] = {"mesh": write("centred", centre), "origin": "base", "yaw": YAW}
    # Tilted in the file by T: placed by rpy = (roll, pitch, YAW) with Rz Ry Rx = Rz(YAW) T^-1.
    tilt = Rotation.from_euler("xyz", [0.4, -0.3, 0.0])  # extrinsic: Ry(-0.3) Rx(0.4)
    tilted = tilt.inv().apply(v)
    out["rpy"] = {"mesh": write("rpy", tilted), "rpy": [0.4, -0.3, YAW]}
    turn = Rotation.from_euler("xyz", [0.4, -0.3, YAW]).as_quat()  # x, y, z, w
    out["quat"] = {"mesh": write("quat", tilted), "quat": [turn[3], *turn[:3]]}
    out["seams"] = {"mesh": write("seams", v, ".obj"), "yaw": YAW}
    everything = (centre * 100.0) @ np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]]).T
    out["all"] = {"mesh": write("all", everything, ".obj"), "up": "y", "unit": "cm",
                  "origin": "base", "yaw": YAW}
    return out


def _scene(folder: Path, name: str, keys: dict, z: float = 0.0) -> Path:
    """The mesh mug between two mugs, close enough that their spaces overlap."""
    scene = {"name": name, "objects": [
        {"id": "m", "kind": "mesh", "position": [0.0, 0.0, z], **keys},
        {"id": "a", "kind": "mug", "position": [0.0, 0.13, 0.0]},
        {"id": "b", "kind": "mug", "position": [0.02, -0.13, 0.0]}],
        "tasks": [{"id": "side-m", "object": "m", "template": "side_grasp"},
                  {"id": "side-a", "object": "a", "template": "side_grasp"},
                  {"id": "side-b", "object": "b", "template": "side_grasp"}]}
    path = folder / f"{name}.toml"
    path.write_text(tomli_w.dumps(scene))
    return path


def test_every_placement_gives_the_same_object(tmp_path):
    """Y-up, centimetres, millimetres by scale, the origin at the centre, a tilt by rpy or
    quat, split seams and all at once: the same solid (vertex for vertex, to the files'
    rounding), bounding cylinder and base; the same C, clusters and Shrinking; the same
    outcome of every rollout in every mode. Read back from the file the scene is saved
    to, each is the same object again."""
    from geometry_precompute import save_scene

    scenes = {name: load_scene(_scene(tmp_path, name, keys))
              for name, keys in _variants(tmp_path).items()}
    plain = scenes["plain"].objects[0]
    want = np.asarray(object_solid(plain).vertices)
    for name, scene in scenes.items():
        o = scene.objects[0]
        assert not o.mesh.hull, name  # the seams merged: watertight
        got = np.asarray(object_solid(o).vertices)
        assert len(got) == len(want), name
        for a, b in ((got, want), (want, got)):  # every vertex has its twin
            assert cKDTree(b).query(a)[0].max() < 1e-7, name
        assert o.body_radius == pytest.approx(plain.body_radius, abs=1e-7), name
        assert o.body_height == pytest.approx(plain.body_height, abs=1e-7), name
        np.testing.assert_allclose(o.base, plain.base, atol=1e-7, err_msg=name)
        save_scene(scene, tmp_path / f"{name}-again.toml")
        again = load_scene(tmp_path / f"{name}-again.toml").objects[0]
        assert again.mesh.placement == o.mesh.placement and again.yaw == pytest.approx(o.yaw)
    results = {n: precompute(s, s.settings(DEFAULTS, GRID)) for n, s in scenes.items()}
    ref = results["plain"]
    assert ref.C_init > 0.05 and ref.meta_clusters()  # the spaces overlap
    for name, r in results.items():
        assert abs(r.C_init - ref.C_init) < 1e-6 and abs(r.C_final - ref.C_final) < 1e-6, name
        assert r.meta_clusters() == ref.meta_clusters(), name
        np.testing.assert_allclose(np.concatenate(r.q_opt), np.concatenate(ref.q_opt),
                                   atol=1e-6, err_msg=name)
    outcome = shacc_jax.run(bake(list(results.values()))).evaluation.rollouts.outcome
    for k in range(1, len(results)):
        assert np.array_equal(outcome[k], outcome[0]), list(results)[k]


def _lying(tmp_path: Path, **keys) -> Path:
    """A Y-up mug placed as if it were Z-up: it lies on its side, half below the table."""
    mug = _mug()
    v = np.asarray(mug.vertices) @ np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]]).T
    trimesh.Trimesh(v, mug.faces).export(tmp_path / "lying.stl")
    return _scene(tmp_path, "lying", {"mesh": "lying.stl", **keys})


def test_a_mesh_below_the_table_is_one_line_naming_the_likely_cause(tmp_path, capsys):
    with pytest.raises(InputError) as e:
        load_scene(_lying(tmp_path))
    message = str(e.value)
    assert e.value.field == "objects[m].position" and "lying.toml" in message
    assert "reaches 40.0 mm below the table" in message and 'up = "y"' in message
    assert "\n" not in message
    assert main(["evaluate", str(_lying(tmp_path))]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "below the table" in err
    load_scene(_lying(tmp_path, up="y"))  # said so, it stands


def test_a_floating_mesh_is_one_warning_line(tmp_path, capsys):
    (tmp_path / "plain.ply").write_bytes(
        trimesh.exchange.ply.export_ply(_mug(), encoding="ascii"))
    path = _scene(tmp_path, "floating", {"mesh": "plain.ply"}, z=0.012)
    with pytest.warns(SceneWarning, match=r"objects\[m\]\.position: the mesh 'plain.ply' "
                      r"floats 12\.0 mm above the table"):
        load_scene(path)
    with warnings.catch_warnings():
        warnings.simplefilter("error", SceneWarning)
        load_scene(_scene(tmp_path, "standing", {"mesh": "plain.ply"}))  # 0 mm: no warning


MESH_OBJECT = {"id": "m", "kind": "mesh", "position": [0.0, 0.0, 0.0], "mesh": "plain.ply"}


@pytest.mark.parametrize("keys, field, rule, loader_only", [
    ({"up": "x"}, "up", 'must be "z" or "y"', None),
    ({"unit": "inch"}, "unit", "must be one of m, cm, mm", None),
    ({"unit": "cm", "scale": 0.01}, "unit", "give unit or scale, not both", None),
    ({"origin": "top"}, "origin", 'must be "file"', None),
    ({"quat": [0.0, 0.0, 0.0, 0.0]}, "quat", "zero norm", "quat is not of zero norm"),
    ({"quat": [1.0, 0.0, 0.0]}, "quat", "must be a list of 4 numbers", None),
    ({"rpy": [0.0, 0.0, "x"]}, "rpy", "must be a list of 3 numbers", None),
    ({"rpy": [0.0, 0.0, 0.1], "yaw": 0.2}, "rpy", "give one orientation", None),
    ({"rpy": [0.0, 0.0, 0.1], "quat": [1.0, 0.0, 0.0, 0.0]}, "quat", "give one orientation",
     None),
    ({"scale": 0.0}, "scale", "must be > 0", None),
])
def test_bad_placement_keys_are_one_line_and_the_schema_agrees(tmp_path, keys, field, rule,
                                                               loader_only):
    (tmp_path / "plain.ply").write_bytes(
        trimesh.exchange.ply.export_ply(_mug(), encoding="ascii"))
    path = _scene(tmp_path, "bad", {k: v for k, v in MESH_OBJECT.items()
                                    if k not in ("id", "kind", "position")} | keys)
    with pytest.raises(InputError) as e:
        load_scene(path)
    assert e.value.field == f"objects[m].{field}" and rule in e.value.rule, str(e.value)
    assert "bad.toml" in str(e.value) and "\n" not in str(e.value)
    import tomllib

    valid = jsonschema.Draft202012Validator(scene_schema()).is_valid(
        tomllib.loads(path.read_text()))
    if loader_only is None:
        assert not valid, "the schema accepts what the loader refuses"
    else:
        assert any(loader_only in r for r in LOADER_ONLY["scene"])


def test_rpy_in_degrees_by_mistake_warns_and_placement_keys_are_for_meshes(tmp_path):
    (tmp_path / "plain.ply").write_bytes(
        trimesh.exchange.ply.export_ply(_mug(), encoding="ascii"))
    with pytest.warns(SceneWarning, match=r"objects\[m\]\.rpy: .* beyond 2 pi: rpy is in "
                      r"radians"):
        load_scene(_scene(tmp_path, "deg", {"mesh": "plain.ply", "rpy": [0.0, 0.0, 90.0]}))
    scene = {"name": "mug", "objects": [{"id": "a", "kind": "mug", "position": [0, 0, 0],
                                         "up": "y"}],
             "tasks": [{"id": "t", "object": "a", "template": "side_grasp"}]}
    (tmp_path / "mug.toml").write_text(tomli_w.dumps(scene))
    with pytest.raises(InputError, match=r"objects\[a\]\.up: not a field of a mug"):
        load_scene(tmp_path / "mug.toml")


MANIFEST = '["plain.stl"]\nup = "z"\n\n["scan.stl"]\nunit = "cm"\norigin = "base"\n'


def _folder(tmp_path: Path) -> Path:
    """A generator's folder of scans as they come: Y-up (the folder's key), one in
    centimetres with its origin at its centre (its line in meshes.toml), and one written
    the plain way (its line: Z-up)."""
    folder = tmp_path / "scans"
    folder.mkdir()
    mug = _mug()
    v = np.asarray(mug.vertices)
    centre = v - (v.min(axis=0) + v.max(axis=0)) / 2
    scan = (centre * 100.0) @ np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]]).T
    trimesh.Trimesh(scan, mug.faces).export(folder / "scan.stl")
    mug.export(folder / "plain.stl")
    (folder / "meshes.toml").write_text(MANIFEST)
    return folder


ENTRY = {"kind": "mesh", "folder": "scans", "up": "y"}


def test_a_generators_folder_takes_the_keys_per_folder_and_per_file(tmp_path):
    folder = _folder(tmp_path)
    gen = check_generator({"table": [0.6, 0.6], "objects": [ENTRY]}, "cfg.toml",
                          base_dir=tmp_path)
    heights = set()
    for seed in range(4):
        scene = random_scene(seed, "uniform", 3, 3, generator=gen)
        for o in scene.objects:
            assert o.base[2] == pytest.approx(0.0, abs=1e-6)  # standing on the table
            heights.add(round(o.body_height, 6))
    assert heights == {0.1}
    # The folder's keys alone leave the plain mug lying on its side, below the table.
    (folder / "meshes.toml").write_text('["scan.stl"]\nunit = "cm"\norigin = "base"\n')
    with pytest.raises(InputError) as e:
        check_generator({"objects": [ENTRY]}, "cfg.toml", base_dir=tmp_path)
    assert "cfg.toml" in str(e.value) and "objects[0]." in e.value.field
    assert "plain.stl" in e.value.rule and "below the table" in e.value.rule
    (folder / "meshes.toml").write_text('["nothing.stl"]\nup = "z"\n')
    with pytest.raises(InputError, match=r"meshes.toml: nothing.stl: no mesh file of that "
                       r"name beside it"):
        check_generator({"objects": [{"kind": "mesh", "folder": "scans"}]}, "cfg.toml",
                        base_dir=tmp_path)
    (folder / "meshes.toml").write_text('["plain.stl"]\nup = "q"\n')
    with pytest.raises(InputError, match=r"meshes.toml: plain.stl.up: must be \"z\" or"):
        check_generator({"objects": [{"kind": "mesh", "folder": "scans"}]}, "cfg.toml",
                        base_dir=tmp_path)


def test_a_sweep_says_each_scenes_warning_once_on_one_line(tmp_path):
    """A generator drawing an open mesh (its hull stands for it): the sweep's stderr has
    one ``warning:`` line per scene that drew it, none twice, and no Python warning
    form (a source line, ``SceneWarning``) from the workers."""
    folder = tmp_path / "open"
    folder.mkdir()
    box = trimesh.creation.box([0.06, 0.06, 0.08])
    box.apply_translation([0, 0, 0.04])
    open_box = trimesh.Trimesh(box.vertices, box.faces[:-1])  # a face missing
    open_box.export(folder / "crate.stl")
    config = tmp_path / "sweep.toml"
    config.write_text(tomli_w.dumps({
        "name": "open-meshes", "modes": ["baseline"], "chunk": 2,
        "source": {"kind": "random", "count": 3, "tasks": [2, 2], "seed": 1,
                   "generator": {"table": [0.8, 0.8], "objects": [
                       {"kind": "mesh", "folder": "open", "templates": {"top_grasp": 1}}]}},
        "settings": {"start_grid": [2, 2]}}))
    env = {**os.environ, "JAX_PLATFORMS": "cpu", "PYTHONUNBUFFERED": "1"}
    res = subprocess.run([sys.executable, "-m", "sweeps", "sweep", str(config), "--out",
                          str(tmp_path / "out"), "--cache", str(tmp_path / "cache"),
                          "--workers", "1", "--quiet"],
                         env=env, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    lines = [line for line in res.stderr.splitlines() if "not watertight" in line]
    assert all(line.startswith("warning: ") for line in lines), lines
    assert len(lines) == len(set(lines)) and "SceneWarning" not in res.stderr
    per_scene = [line for line in lines if line.startswith("warning: scene ")]
    assert len(per_scene) == 3, lines  # each scene once, its two crates one cause
    assert all("crate.stl' is not watertight" in line for line in per_scene)
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    assert summary["rollouts_this_run"] == 3 * 2 * 4, summary  # scenes x tasks x starts


def test_angles_decompose_exactly():
    """The yaw and tilt a quaternion is read as give back its rotation (scipy's)."""
    from geometry_precompute.mesh_objects import Placement, quat_matrix, yaw_and_tilt

    rng = np.random.default_rng(3)
    for q in [*Rotation.random(50, random_state=4).as_quat(),
              Rotation.from_euler("y", math.pi / 2).as_quat()]:
        wxyz = [q[3], *q[:3]]
        m = quat_matrix(wxyz)
        np.testing.assert_allclose(m, Rotation.from_quat(q).as_matrix(), atol=1e-12)
        yaw, roll, pitch = yaw_and_tilt(m)
        back = Rotation.from_euler("z", yaw).as_matrix() @ Placement(
            roll=roll, pitch=pitch).matrix()
        np.testing.assert_allclose(back, m, atol=1e-9)
    assert rng is not None


_BOX = trimesh.creation.box([0.05, 0.08, 0.12])
_BOX.apply_translation([0.01, -0.02, 0.03])  # its origin off its centre


@pytest.fixture(scope="module")
def placed_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("placed")


@settings(max_examples=40, deadline=None)
@given(up=st.sampled_from(["z", "y"]), unit=st.sampled_from(["m", "cm", "mm"]),
       origin=st.sampled_from(["file", "base"]),
       rpy=st.lists(st.floats(-math.pi, math.pi), min_size=3, max_size=3))
def test_placed_measures_agree_with_scipy(placed_dir, up, unit, origin, rpy):
    """Any placement of a box written in any unit and up axis: the measures the
    templates read (radius about the origin's axis, height range) are those of the
    vertices turned by scipy's Rotation, and ``origin = "base"`` puts the lowest face's
    centre of the bounding box at the origin."""
    from geometry_precompute.mesh_objects import UNITS, load, parse_placement

    factor = UNITS[unit]
    v = np.asarray(_BOX.vertices) / factor
    if up == "y":
        v = v @ np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]]).T
    path = placed_dir / f"box-{up}-{unit}.ply"
    if not path.exists():
        path.write_bytes(trimesh.exchange.ply.export_ply(
            trimesh.Trimesh(v, _BOX.faces), encoding="ascii"))
    placement, yaw = parse_placement({"up": up, "unit": unit, "origin": origin, "rpy": rpy},
                                     None, "<test>", "o.")
    info = load(str(path), placement, "<test>", "o.")
    want = Rotation.from_euler("xyz", [rpy[0], rpy[1], 0.0]).apply(_BOX.vertices)
    if origin == "base":
        lo, hi = want.min(axis=0), want.max(axis=0)
        want = want - [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]]
        assert info.z_min == pytest.approx(0.0, abs=1e-9)
    assert yaw == rpy[2]
    assert info.radius == pytest.approx(np.hypot(want[:, 0], want[:, 1]).max(), abs=1e-7)
    assert info.z_min == pytest.approx(want[:, 2].min(), abs=1e-7)
    assert info.z_max == pytest.approx(want[:, 2].max(), abs=1e-7)



EXAMPLE = Path(__file__).parents[1] / "docs" / "examples" / "packaged_kitchen"
# Stand-ins of the packaged objects the worked example links (not in the repository):
# their radius or half extents and their height range about their origin (robosuite
# 1.5.2's files, unscaled), split at seams as the package's OBJ files are.
STAND_INS = {"milk": ("cylinder", 0.0221, (-0.0678, 0.0922)),
             "cereal": ("box", (0.05, 0.015), (-0.075, 0.075)),
             "can": ("cylinder", 0.025, (-0.0403, 0.0397)),
             "bread": ("box", (0.03, 0.025), (-0.0291, 0.0309)),
             "bottle": ("cylinder", 0.0276, (-0.0649, 0.0951)),
             "lemon": ("cylinder", 0.02, (-0.0199, 0.0201))}


def test_the_worked_examples_files_stand_and_import(tmp_path):
    """docs/examples/packaged_kitchen with stand-in meshes of the package's shapes: the
    scene stands on the first try (no error, no floating warning), and the MJCF scene
    imports with its pattern into six side grasps, each object on the table."""
    import shutil

    meshes = tmp_path / "objects" / "meshes"
    meshes.mkdir(parents=True)
    for name, (kind, across, (low, high)) in STAND_INS.items():
        m = (trimesh.creation.cylinder(across, high - low, sections=32) if kind == "cylinder"
             else trimesh.creation.box([2 * across[0], 2 * across[1], high - low]))
        m.apply_translation([0, 0, (low + high) / 2])
        _split_seams(m, meshes / f"{name}.obj")
    for f in ("kitchen.toml", "kitchen.xml", "map.toml"):
        shutil.copy(EXAMPLE / f, tmp_path / f)
    with warnings.catch_warnings():
        warnings.simplefilter("error", SceneWarning)
        scene = load_scene(tmp_path / "kitchen.toml")
    assert all(o.base[2] == pytest.approx(0.0, abs=1e-9) for o in scene.objects)
    assert not any(o.mesh.hull for o in scene.objects)  # the seams merged
    precompute(scene, scene.settings(DEFAULTS, GRID))
    out = tmp_path / "imported" / "kitchen.toml"
    assert main(["import-mjcf", str(tmp_path / "kitchen.xml"), "--map",
                 str(tmp_path / "map.toml"), "--out", str(out)]) == 0
    imported = load_scene(out)
    assert [t.id for t in imported.tasks] == [f"side-{n}_main" for n in STAND_INS]
    assert all(abs(o.base[2]) < 1e-3 for o in imported.objects)
