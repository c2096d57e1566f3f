"""Mesh objects (geometry_precompute.mesh_objects): a cylinder mesh behaves as the mug
primitive of its size, real meshes no one on the team made (the meshes that ship with
mujoco-mjx, a required dependency: a CAD handle, a robot body part that is not
watertight, a hand part in millimetres) go through precompute, every mode, MJCF and the
top view, and bad meshes get one-line errors."""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import mujoco
import numpy as np
import pytest
import tomli_w
import trimesh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import shacc_jax
from geometry_precompute import (
    DEFAULTS,
    InputError,
    bake,
    load_scene,
    precompute,
    save_scene,
    shipped_scene_paths,
)
from geometry_precompute.errors import SceneWarning
from geometry_precompute.mjcf import scene_to_mjcf
from geometry_precompute.scene import scene_to_dict

MJX_MESHES = Path(mujoco.__file__).parent / "mjx" / "test_data"
GRID = {"start_grid": [2, 3]}


def _cylinder(path: Path, radius: float, height: float) -> None:
    """A cylinder mesh standing on its origin (fine sections: its discretisation)."""
    m = trimesh.creation.cylinder(radius=radius, height=height, sections=256)
    m.apply_translation([0.0, 0.0, height / 2])
    m.export(path)


def _as_meshes(scene_path: Path, folder: Path) -> Path:
    """The shipped scene with every mug replaced by a cylinder mesh of its size."""
    scene = load_scene(scene_path)
    data = scene_to_dict(scene)
    for raw, obj in zip(data["objects"], scene.objects, strict=True):
        if obj.kind == "mug":
            name = f"{obj.id}.stl"
            _cylinder(folder / name, obj.body_radius, obj.body_height)
            for key in ("radius", "height"):
                raw.pop(key, None)
            raw.update(kind="mesh", mesh=name)
    out = folder / "meshes.toml"
    out.write_text(tomli_w.dumps(data))
    return out


@pytest.mark.parametrize("index", [2, 9])  # a tight row and a cluster of mugs
def test_a_cylinder_mesh_is_the_mug_of_its_size(tmp_path, index):
    """Mugs replaced by cylinder meshes of the same radius and height: the same C
    (initial and shrunk), clusters and Shrinking parameters (to the file's rounding: an
    STL stores float32 vertices, and the mesh's radius is its vertices' largest distance
    from the axis), and the same outcome of every rollout in every mode."""
    path = shipped_scene_paths()[index]
    prims = load_scene(path)
    meshes = load_scene(_as_meshes(path, tmp_path))
    assert [o.kind for o in meshes.objects] == ["mesh"] * 3
    a, b = (precompute(s, s.settings(DEFAULTS, GRID)) for s in (prims, meshes))
    assert abs(a.C_init - b.C_init) < 1e-6 and abs(a.C_final - b.C_final) < 1e-6
    assert a.meta_clusters() == b.meta_clusters() and a.C_init > 0
    np.testing.assert_allclose(np.concatenate(a.q_opt), np.concatenate(b.q_opt), atol=1e-6)
    ev = [shacc_jax.run(bake([r])).evaluation for r in (a, b)]
    assert np.array_equal(ev[0].rollouts.outcome, ev[1].rollouts.outcome)


def _real_scene(folder: Path) -> Path:
    """A scene of three meshes from mujoco-mjx's test data and a mug primitive."""
    scene = {
        "name": "real-meshes",
        "objects": [
            {"id": "handle", "kind": "mesh", "position": [0.0, 0.2, 0.0], "origin": "base",
             "mesh": str(MJX_MESHES / "barkour_v0" / "assets" / "handle.stl")},
            {"id": "body", "kind": "mesh", "position": [0.05, -0.25, 0.0], "yaw": 0.4,
             "origin": "base", "mesh": str(MJX_MESHES / "barkour_v0" / "assets" / "body.stl")},
            {"id": "thumb", "kind": "mesh", "position": [0.0, 0.0, 0.0118], "unit": "mm",
             "mesh": str(MJX_MESHES / "shadow_hand" / "assets" / "th_proximal.obj")},
            {"id": "mug", "kind": "mug", "position": [-0.1, 0.05, 0.0]},
        ],
        "tasks": [
            {"id": "top-handle", "object": "handle", "template": "top_grasp"},
            # The body's bounding cylinder (radius 0.18 m) is wider than the side grasp's
            # default space: the task sizes its own.
            {"id": "side-body", "object": "body", "template": "side_grasp",
             "bounds": {"radius": [0.23, 0.3]}},
            {"id": "side-thumb", "object": "thumb", "template": "side_grasp"},
            {"id": "side-mug", "object": "mug", "template": "side_grasp"},
        ],
    }
    path = folder / "real.toml"
    path.write_text(tomli_w.dumps(scene))
    return path


def test_real_meshes_go_through_every_stage(tmp_path):
    """Real meshes: the one that is not watertight stands for its convex hull (a warning
    says so), the others are their own solids; precompute, the paper's modes, the MJCF (loaded
    by MuJoCo, each mesh object a mesh geom of its solid) and the top view work."""
    path = _real_scene(tmp_path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = load_scene(path)
    said = [str(w.message) for w in caught if issubclass(w.category, SceneWarning)]
    assert any("body.stl' is not watertight" in m and "convex hull" in m for m in said)
    save_scene(scene, tmp_path / "copy.toml")  # written with where each mesh is
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        assert load_scene(tmp_path / "copy.toml").objects == scene.objects
    info = {o.id: o.mesh for o in scene.objects}
    assert info["body"].hull and not info["handle"].hull and not info["thumb"].hull
    assert info["handle"].faces > 10_000  # a real CAD part, not convex
    thumb = trimesh.load(MJX_MESHES / "shadow_hand" / "assets" / "th_proximal.obj",
                         force="mesh")
    v = np.asarray(thumb.vertices) * 0.001
    assert scene.object("thumb").body_radius == pytest.approx(np.hypot(v[:, 0], v[:, 1]).max())
    assert scene.object("thumb").body_height == pytest.approx(np.ptp(v[:, 2]))
    r = precompute(scene, scene.settings(DEFAULTS, GRID))
    run = shacc_jax.run(bake([r]))
    assert run.evaluation.metrics.u_scene.shape == (1, 3)
    assert (run.evaluation.metrics.n_rollouts == 6 * 4).all()
    model = mujoco.MjModel.from_xml_string(scene_to_mjcf(r, spaces="none"))
    names = [model.geom(i).name for i in range(model.ngeom)]
    meshes = [n for i, n in enumerate(names) if model.geom_type[i] == mujoco.mjtGeom.mjGEOM_MESH]
    assert sorted(meshes) == ["object:body", "object:handle", "object:thumb"]
    from sweeps.analysis.plots import scene_top_view

    scene_top_view(r)


def test_mesh_objects_interpenetrate_by_their_solids(tmp_path):
    """A mug placed into a cylinder mesh is refused, a hair beside it is not; a mug
    standing in the hole of a ring mesh is not refused (the bounding bodies overlap, the
    solids do not: manifold3d's boolean), one that cuts the ring's wall is."""
    _cylinder(tmp_path / "c.stl", 0.045, 0.1)
    ring = trimesh.creation.annulus(r_min=0.06, r_max=0.08, height=0.1, sections=64)
    ring.apply_translation([0.0, 0.0, 0.05])
    ring.export(tmp_path / "ring.stl")

    def scene(mesh: str, x: float):
        return {"name": "pair", "objects": [
            {"id": "a", "kind": "mesh", "mesh": mesh, "position": [0.0, 0.0, 0.0]},
            {"id": "b", "kind": "mug", "position": [x, 0.0, 0.0]}],
            "tasks": [{"id": "t", "object": "a", "template": "top_grasp"}]}

    path = tmp_path / "pair.toml"
    for mesh, x, refused in (("c.stl", 0.06, "share"), ("c.stl", 0.0902, None),
                             ("ring.stl", 0.0, None), ("ring.stl", 0.03, "share")):
        path.write_text(tomli_w.dumps(scene(mesh, x)))
        s = load_scene(path)
        if refused is None:
            precompute(s, s.settings(DEFAULTS, GRID))
            continue
        with pytest.raises(InputError, match=rf"objects\[b\].position: interpenetrates "
                                             rf"object 'a' \(.*{refused}"):
            precompute(s, s.settings(DEFAULTS, GRID))


def _write(folder: Path, obj: dict, template: str = "top_grasp", **task) -> Path:
    path = folder / "s.toml"
    path.write_text(tomli_w.dumps({"name": "s", "objects": [{"id": "a", **obj}],
                                   "tasks": [{"id": "t", "object": "a", "template": template,
                                              **task}]}))
    return path


def test_bad_mesh_objects_get_one_line_errors(tmp_path):
    _cylinder(tmp_path / "c.stl", 0.04, 0.1)
    (tmp_path / "empty.obj").write_text("# no faces\n")
    trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]).export(tmp_path / "flat.stl")
    cases = [
        ({"kind": "mesh", "mesh": "nope.stl", "position": [0, 0, 0]}, "objects[a].mesh",
         "'nope.stl': cannot be read"),
        ({"kind": "mesh", "mesh": "c.txt", "position": [0, 0, 0]}, "objects[a].mesh",
         "not a mesh file this tool reads"),
        ({"kind": "mesh", "mesh": "empty.obj", "position": [0, 0, 0]}, "objects[a].mesh",
         "holds no triangles"),
        ({"kind": "mesh", "mesh": "flat.stl", "position": [0, 0, 0]}, "objects[a].mesh",
         "has no volume"),
        ({"kind": "mesh", "position": [0, 0, 0]}, "objects[a].mesh", "missing required"),
        ({"kind": "mesh", "mesh": "c.stl", "radius": 0.1, "position": [0, 0, 0]},
         "objects[a].radius", "not a field of a mesh"),
        ({"kind": "mesh", "mesh": "c.stl", "scale": 0, "position": [0, 0, 0]},
         "objects[a].scale", "must be > 0"),
        ({"kind": "mug", "mesh": "c.stl", "position": [0, 0, 0]}, "objects[a].mesh",
         "not a field of a mug"),
    ]
    for obj, field, rule in cases:
        path = _write(tmp_path, obj)
        with pytest.raises(InputError) as e:
            load_scene(path)
        assert str(e.value).startswith(f"{path}: {field}: ") and rule in str(e.value), e.value
    path = _write(tmp_path, {"kind": "mesh", "mesh": "c.stl", "position": [0, 0, 0]},
                  "handle_grasp")
    with pytest.raises(InputError, match=r"tasks\[t\].template: handle_grasp does not fit a mesh"):
        load_scene(path)


def test_a_mesh_in_millimetres_is_warned_about(tmp_path):
    """A mug written in millimetres: a warning names the likely scale before the
    template's error says the object is far too large for its space."""
    _cylinder(tmp_path / "c.stl", 40.0, 100.0)
    with pytest.warns(SceneWarning, match=r"objects\[a\].scale: .* scale = 0.001"), \
            pytest.raises(InputError, match=r"bounds.radius: min 40.02 > init 0.15"):
        load_scene(_write(tmp_path, {"kind": "mesh", "mesh": "c.stl", "position": [0, 0, 0]}))


@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.binary(max_size=400), suffix=st.sampled_from([".stl", ".obj", ".ply", ".glb"]))
def test_any_file_is_a_mesh_or_a_one_line_error(tmp_path, data, suffix):
    """Whatever bytes a mesh file holds, reading the scene gives a scene or a one-line
    InputError naming the field (never a traceback from trimesh)."""
    (tmp_path / f"m{suffix}").write_bytes(data)
    os.utime(tmp_path / f"m{suffix}")
    try:
        load_scene(_write(tmp_path, {"kind": "mesh", "mesh": f"m{suffix}",
                                     "position": [0, 0, 0]}))
    except InputError as e:
        assert "objects[a].mesh" in str(e) and "\n" not in str(e)


@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(radius=st.floats(0.01, 0.2), height=st.floats(0.01, 0.3), scale=st.floats(0.2, 5.0),
       lift=st.floats(-0.05, 0.05))
def test_a_mesh_is_measured_by_its_bounding_upright_cylinder(tmp_path, radius, height, scale,
                                                             lift):
    """A cylinder mesh of any size, scale and height above its origin: the object's
    radius, height and base are the scaled cylinder's (trimesh's vertices as reference)."""
    m = trimesh.creation.cylinder(radius=radius, height=height, sections=64)
    m.apply_translation([0.0, 0.0, height / 2 + lift])
    m.export(tmp_path / "c.stl")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        obj = load_scene(_write(tmp_path, {"kind": "mesh", "mesh": "c.stl", "scale": scale,
                                           "position": [0.1, 0.2, 0.3]},
                                bounds={"radius": [2.0, 2.5]})).objects[0]
    v = np.asarray(trimesh.load(tmp_path / "c.stl").vertices) * scale
    assert obj.body_radius == pytest.approx(np.hypot(v[:, 0], v[:, 1]).max(), rel=1e-9)
    assert obj.body_height == pytest.approx(height * scale, rel=1e-6)
    assert obj.base[2] == pytest.approx(0.3 + lift * scale, abs=1e-6)  # STL: float32
