"""Collision checks against mesh objects: the exact segment-to-hull distance against a
slow reference, the gripper against CPU MuJoCo on poses near real and made meshes, and
what the bake carries (the rollouts against the NumPy Automaton with MuJoCo are in
test_collision.py, the stepped users' in test_users.py)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st
from reference_automaton import Collider
from scipy.spatial.transform import Rotation

import shacc_jax
from geometry_precompute import bake, precompute, scene_from_dict
from geometry_precompute.baking import concatenate
from geometry_precompute.batch import bake_batch
from geometry_precompute.mjcf import scene_to_mjcf
from geometry_precompute.schema import MESH
from shacc_jax import collision as col
from shacc_jax.hulls import Hulls, hull_distance
from shacc_jax.types import COLLISION, Geometry, Params

KITCHEN = "sweeps/configs/kitchen_meshes"


def _brute_distance(hull: trimesh.Trimesh, a, d, samples: int = 257) -> float:
    """The segment's distance to the hull by sampling it: 0 where a sample is inside,
    else the least distance of a sample to the hull's surface (trimesh). Never below the
    true distance, and above it by at most |d| / (2 (samples - 1))."""
    t = np.linspace(0.0, 1.0, samples)
    points = a + t[:, None] * d
    if (points @ hull.face_normals.T - (hull.face_normals * hull.triangles[:, 0]).sum(1)
            <= 0).all(axis=1).any():
        return 0.0
    return float(trimesh.proximity.ProximityQuery(hull).on_surface(points)[1].min())


_HULL_DISTANCE = jax.jit(jax.vmap(hull_distance, (None, None, 0, 0)))


@settings(max_examples=25)
@given(st.integers(0, 2**31 - 1), st.integers(4, 60))
def test_hull_distance_is_the_sampled_distance(seed, n_points):
    """Random convex hulls (of 4 to 60 random points) and 40 random segments each,
    inside, through, beside and far from them: the exact distance is never above the
    sampled one and below it by no more than the sampling's spacing."""
    rng = np.random.default_rng(seed)
    hull = trimesh.convex.convex_hull(rng.uniform(-0.05, 0.05, (n_points, 3))
                                      * rng.uniform(0.2, 1.0, 3))
    pad = np.arange(128) % len(hull.faces)  # one shape, one program (as the bake pads)
    tri = jnp.asarray(hull.triangles[pad], jnp.float32)
    normals = hull.face_normals[pad]
    plane = jnp.asarray(np.c_[normals, (normals * hull.triangles[pad, 0]).sum(1)],
                        jnp.float32)
    a = rng.uniform(-0.12, 0.12, (40, 3))
    d = rng.normal(size=(40, 3)) * rng.uniform(0.01, 0.15, (40, 1))
    got = np.asarray(_HULL_DISTANCE(
        tri, plane, jnp.asarray(a, jnp.float32), jnp.asarray(d, jnp.float32)))
    want = np.array([_brute_distance(hull, a[i], d[i]) for i in range(40)])
    slack = np.linalg.norm(d, axis=1) / 512 + 2e-6
    assert np.all(got <= want + 2e-6), np.max(got - want)
    assert np.all(got >= want - slack), np.min(got - want + slack)


def _scene():
    """The kitchen's kettle and bowl, and robot parts of mujoco-mjx's test data (a
    watertight CAD handle, a part that is not watertight, a thumb in millimetres), with
    a mug, collision checks on."""
    import mujoco

    assets = f"{mujoco.__file__.rsplit('/', 1)[0]}/mjx/test_data"
    return scene_from_dict({
        "name": "meshes", "settings": {"collision": "on"},
        "objects": [
            {"id": "kettle", "kind": "mesh", "mesh": f"{KITCHEN}/kettle.stl",
             "position": [0.0, 0.0, 0.0], "yaw": 0.5},
            {"id": "bowl", "kind": "mesh", "mesh": f"{KITCHEN}/bowl.stl",
             "position": [0.3, 0.0, 0.0]},
            {"id": "handle", "kind": "mesh", "position": [0.0, 0.35, 0.0], "yaw": -1.0,
             "origin": "base", "mesh": f"{assets}/barkour_v0/assets/handle.stl"},
            {"id": "part", "kind": "mesh", "position": [0.3, 0.35, 0.0], "origin": "base",
             "mesh": f"{assets}/barkour_v0/assets/abduction.stl"},
            {"id": "thumb", "kind": "mesh", "position": [-0.2, 0.2, 0.0118], "scale": 0.001,
             "mesh": f"{assets}/shadow_hand/assets/th_proximal.obj"},
            {"id": "mug", "kind": "mug", "position": [0.15, 0.2, 0.0]}],
        "tasks": [{"id": "t", "object": "bowl", "template": "top_grasp"}]}, "<meshes>")


@pytest.fixture(scope="module")
def meshes():
    import warnings

    from geometry_precompute.errors import SceneWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)  # the open part stands for its hull
        r = precompute(_scene())
    return r, bake([r])


def test_gripper_near_meshes_agrees_with_cpu_mujoco(meshes):
    """6 000 random gripper poses near the meshes, against CPU MuJoCo's
    ``mj_geomDistance`` on the scene's exported MJCF (MuJoCo collides with a mesh's
    convex hull): the same penetrations, none missed and none invented, and where
    MuJoCo finds the gripper clear by less than a centimetre the same distance to
    float32 rounding."""
    r, b = meshes
    assert (b.obj_kind[0] == MESH).sum() == 5 and b.obj_hull.shape[2] >= 318
    sc = Geometry.from_bake(b)
    objects = col.scene_objects(sc.obj_kind[0], sc.obj_center[0], sc.obj_quat[0],
                                sc.obj_size[0], sc.obj_mask[0])
    hulls = Hulls.of(sc)
    gripper = Params.from_bake(b).gripper()[0]
    rng = np.random.default_rng(5)
    n = 6000
    P = b.obj_center[0, rng.integers(0, 5, n)] + rng.normal(scale=0.06, size=(n, 3))
    R = Rotation.random(n, random_state=6)
    Q = jnp.asarray(np.roll(R.as_quat(), 1, axis=1), jnp.float32)
    exact = jax.jit(jax.vmap(lambda p, q: col.deepest(objects, p, q, gripper, hulls, 0,
                                                      jnp.inf)))
    decide = jax.jit(jax.vmap(lambda p, q: col.penetrates(objects, p, q, gripper, hulls, 0)))
    got = np.asarray(exact(jnp.asarray(P, jnp.float32), Q))
    pen = np.asarray(decide(jnp.asarray(P, jnp.float32), Q))
    ref = Collider(b, 0, scene_to_mjcf(r, spaces="none"))
    want = np.array([ref.deepest(P[i], R[i]) for i in range(n)])
    edge = np.abs(want + col.PENETRATION_EPS) < 1e-5  # on the decision's edge: rounding
    pen_want = want < -col.PENETRATION_EPS
    assert 0.2 < pen_want.mean() < 0.8
    assert np.array_equal(pen[~edge], pen_want[~edge])
    assert np.array_equal((got < -col.PENETRATION_EPS)[~edge], pen_want[~edge])
    close = (want > 0) & (want < 0.01)
    assert close.sum() > 200
    np.testing.assert_allclose(got[close], want[close], atol=1e-5)


def test_a_mesh_on_the_path_collides_only_with_collision_checks_on():
    """A kettle between the start plane and a mug: with collision checks on, rollouts end
    as collisions (the kettle is the only object they can touch on the way); with them
    off, the same scene has no object slots for meshes and no hull to carry."""
    scene = scene_from_dict({
        "name": "kettle-in-the-way",
        "settings": {"collision": "on", "start_orientation": "forward", "start_grid": [3, 3],
                     "start_y_halfwidth": 0.03, "start_z_range": [0.06, 0.1]},
        "objects": [{"id": "mug", "kind": "mug", "position": [0.35, 0.0, 0.0]},
                    {"id": "kettle", "kind": "mesh", "mesh": f"{KITCHEN}/kettle.stl",
                     "position": [0.1, 0.0, 0.0]}],
        "tasks": [{"id": "grasp", "object": "mug", "template": "side_grasp"}]}, "<kettle>")
    on = precompute(scene)
    out = shacc_jax.run(bake([on]), ("baseline",)).evaluation.rollouts.outcome
    assert (out == COLLISION).mean() > 0.5
    off = precompute(scene, on.settings.with_overrides({"collision": "off"}))
    b = bake([off])
    assert b.obj_hull.shape[2] == 0 and not b.obj_mask[0, 1]
    assert not (shacc_jax.run(b, ("baseline",)).evaluation.rollouts.outcome == COLLISION).any()


def test_hulls_are_padded_by_repetition_and_shared_by_a_sweeps_points(meshes):
    """Hull arrays: each object's triangles repeated to the batch's size F (a quarter
    octave at most above the largest hull), concatenated bakes padded the same way,
    primitive rows zero; a sweep's points that share one geometry all carry the hulls
    when any of them checks collisions."""
    _, b = meshes
    F = b.obj_hull.shape[2]
    sizes = [len(set(map(tuple, b.obj_hull[0, o].reshape(-1, 9)))) for o in range(6)]
    assert max(sizes) <= F <= 1.25 * max(sizes) and sizes[5] == 1  # the mug: zeros
    assert not b.obj_hull[0, 5].any()
    small = precompute(scene_from_dict({
        "name": "one", "settings": {"collision": "on"},
        "objects": [{"id": "bowl", "kind": "mesh", "mesh": f"{KITCHEN}/bowl.stl",
                     "position": [0.0, 0.0, 0.0]}],
        "tasks": [{"id": "t", "object": "bowl", "template": "top_grasp"}]}, "<one>"))
    joined = concatenate([bake([small], max_tasks=1, max_objects=6), b])
    assert joined.obj_hull.shape[2] == F
    assert set(map(tuple, joined.obj_hull[0, 0].reshape(-1, 9))) == \
        set(map(tuple, bake([small]).obj_hull[0, 0].reshape(-1, 9)))
    off = precompute(small.scene, small.settings.with_overrides({"collision": "off"}))
    batch = bake_batch([(off, False)], [{"collision": "off"}, {"collision": "on"}], 1, 1, 0.0)
    assert [k.obj_hull.shape[2] for k in batch.bakes] == [bake([small]).obj_hull.shape[2]] * 2
    assert [bool(k.collision[0]) for k in batch.bakes] == [False, True]


def test_check_collisions_compares_with_mujoco_and_mjx(tmp_path):
    """``shacc check-collisions``: on a scene of meshes and a mug, the check decides every
    pose as CPU MuJoCo does, and the report holds MJX's numbers beside it (stdout is the
    JSON alone, though importing MJX prints)."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).parents[1]
    scene = tmp_path / "kitchen.toml"
    scene.write_text(
        'name = "corner"\n'
        f'[[objects]]\nid = "kettle"\nkind = "mesh"\nmesh = "{root / KITCHEN}/kettle.stl"\n'
        'position = [0.0, 0.0, 0.0]\nyaw = 0.5\n'
        f'[[objects]]\nid = "bowl"\nkind = "mesh"\nmesh = "{root / KITCHEN}/bowl.stl"\n'
        'position = [0.3, 0.0, 0.0]\n'
        '[[objects]]\nid = "mug"\nkind = "mug"\nposition = [0.15, 0.2, 0.0]\n'
        '[[tasks]]\nid = "t"\nobject = "bowl"\ntemplate = "top_grasp"\n')
    res = subprocess.run([sys.executable, "-m", "sweeps", "check-collisions", str(scene),
                          "--poses", "600", "--json"], capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert out["poses"] == 600 and 100 < out["penetrating"] < 500
    assert out["shacc"]["agreement"] == 1.0 and out["shacc"]["invented"] == 0
    assert out["shacc"]["max_distance_error_within_1cm"] < 1e-5
    assert set(out["mjx"]) == {"agreement", "missed", "missed_deeper_than_1mm", "invented"}
    assert 0.5 < out["mjx"]["agreement"] <= 1.0
