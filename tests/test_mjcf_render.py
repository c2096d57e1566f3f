"""MJCF export and the rendered picture (SPEC section 12b, first half of issue 7)."""

from __future__ import annotations

import matplotlib.image as mpimg
import mujoco
import numpy as np
import pytest

from geometry_precompute.bodies import object_body
from geometry_precompute.mjcf import scene_to_mjcf
from sweeps.cli import main


def test_every_shipped_scene_loads(shipped_results):
    for r in shipped_results:
        m = mujoco.MjModel.from_xml_string(scene_to_mjcf(r))
        n_obj, n_task = len(r.scene.objects), len(r.spaces)
        assert m.ngeom == 1 + n_obj + 2 * n_task
        assert m.nmesh == 2 * sum(s.kind == "cone" for s in r.shapes_init)
        for o in r.scene.objects:
            g = m.geom(f"object:{o.id}")
            np.testing.assert_allclose(g.pos, object_body(o).center, atol=1e-9)
            assert g.contype[0] == 1
        for t in r.task_ids:
            for w in ("init", "opt"):
                g = m.geom(f"space:{w}:{t}")
                assert g.contype[0] == 0 and g.conaffinity[0] == 0 and g.rgba[3] < 1


def test_spaces_match_the_precompute(shipped_results):
    r = shipped_results[1]  # handle cones: meshes
    m = mujoco.MjModel.from_xml_string(scene_to_mjcf(r, spaces="opt"))
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    for t, shape in zip(r.task_ids, r.shapes_opt, strict=True):
        # MuJoCo recentres a mesh at its centroid; a cone's centroid is 3/4 of the way
        # from the apex along its axis.
        axis = shape.rotation[:, 2]
        expected = np.asarray(shape.center) + 0.75 * shape.dims[0] * axis
        np.testing.assert_allclose(d.geom(f"space:opt:{t}").xpos, expected, atol=2e-3)


def test_export_command(tmp_path):
    from geometry_precompute import shipped_scene_paths

    out = tmp_path / "scene.xml"
    assert main(["export-mjcf", str(shipped_scene_paths()[0]), str(out)]) == 0
    assert mujoco.MjModel.from_xml_path(str(out)).ngeom == 10


@pytest.mark.parametrize("mode,path", [("shacc", None), ("baseline", ["3", "1"])])
def test_render_is_a_nonblank_picture_of_the_right_size(tmp_path, mode, path):
    from geometry_precompute import shipped_scene_paths

    out = tmp_path / "scene.png"
    args = ["render", str(shipped_scene_paths()[8]), "--out", str(out), "--mode", mode,
            "--width", "400", "--height", "240"]
    assert main(args + (["--path", *path] if path else [])) == 0
    img = mpimg.imread(out)
    assert img.shape[:2] == (240, 400)
    left, right = img[:, :200, :3], img[:, 200:, :3]
    assert left.std() > 0.05 and right.std() > 0.05  # both views drew something
    assert len(np.unique(left.reshape(-1, 3).round(2), axis=0)) > 50


def test_render_draws_the_gripper_at_the_end_pose(shipped_results):
    """``--path`` in shacc: the gripper's capsules are drawn at the start pose and at the
    end pose in the orientation the meta skill turned it to (the evaluation's
    ``orientation``, checked against the NumPy reference in test_automaton)."""
    from scipy.spatial.transform import Rotation

    from sweeps.pipeline import evaluate_results
    from sweeps.render import render_array, rollout_path

    r = shipped_results[9]  # three mugs in a cluster: the meta skill turns the gripper
    ro = evaluate_results([r], ("shacc",)).evaluation.rollouts
    n, t = np.argwhere(ro.meta_steps[0, 0] > 5)[0]
    path = rollout_path(r, "shacc", int(n), int(t))
    np.testing.assert_allclose(path.points[1], ro.point[0, 0, n, t], atol=1e-6)
    start, end = (Rotation.from_quat(np.roll(q, -1)) for q in path.quats)
    assert (start.inv() * end).magnitude() > 0.05  # it turned
    centres, mats, sizes = path.capsules[1]
    z = end.as_matrix()[:, 2]
    np.testing.assert_allclose(centres[2], path.points[1] - sizes[0, 1] * 2 * z, atol=1e-5)
    np.testing.assert_allclose(mats[0], end.as_matrix(), atol=1e-5)
    drawn = render_array(r, 320, 240, "both", path)
    bare = render_array(r, 320, 240, "both", path._replace(capsules=[]))
    changed = np.abs(drawn.astype(int) - bare.astype(int)).sum(axis=-1) > 30
    assert changed.sum() > 100  # the capsules cover a visible part of the picture
