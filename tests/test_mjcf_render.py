"""MJCF export and the rendered picture (reference/mujoco)."""

from __future__ import annotations

import matplotlib.image as mpimg
import mujoco
import numpy as np
import pytest

from geometry_precompute.bodies import object_body
from geometry_precompute.mjcf import scene_to_mjcf
from sweeps.app.cli import main


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

    from sweeps.analysis.render import render_array, rollout_path
    from sweeps.pipeline import evaluate_results

    r = shipped_results[9]  # three mugs in a cluster: the meta skill turns the gripper
    ev = evaluate_results([r], ("shacc",))
    ro = ev.evaluation.rollouts
    n, t = np.argwhere(ro.meta_steps[0, 0] > 5)[0]
    path = rollout_path(ev, "shacc", int(n), r.task_ids[t])
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


def test_render_path_takes_task_ids_and_prints_the_outcome(tmp_path, capsys,
                                                          shipped_results):
    """``--path START TASK`` names the task by id (or index) and prints the rollout's
    outcome, which is the evaluation's; a wrong id lists the scene's tasks."""
    from geometry_precompute import shipped_scene_paths
    from geometry_precompute.schema import OUTCOMES
    from sweeps.pipeline import evaluate_results

    scene = shipped_scene_paths()[11]  # cabinet, mug and cup
    r = shipped_results[11]
    ev = evaluate_results([r], ("baseline",))
    ro = ev.evaluation.rollouts
    out = tmp_path / "scene.png"
    for start in (0, 7):
        for t, task in enumerate(r.task_ids):
            want = OUTCOMES[int(ro.outcome[0, 0, start, t])]
            assert main(["render", str(scene), "--out", str(out), "--mode", "baseline",
                         "--width", "320", "--height", "200", "--path", str(start),
                         task]) == 0
            line = capsys.readouterr().out.splitlines()[0]
            assert line.startswith(f"start {start} -> task {task} (baseline): {want} ")
    assert main(["render", str(scene), "--out", str(tmp_path / "x.png"), "--path", "0",
                 "grasp-nothing"]) == 2
    err = capsys.readouterr().err
    assert "grasp-nothing" in err and all(t in err for t in r.task_ids)
    assert not (tmp_path / "x.png").exists()


def test_top_view_labels_every_task_and_none_covers_another(shipped_results):
    """The most crowded shipped scenes: every task id is written once, with its cluster;
    no two labels (task or object) overlap, and all lie inside the axes; the legend
    names every kind of space drawn, and the start plane."""
    import matplotlib.pyplot as plt
    from matplotlib.text import Annotation, Text

    from sweeps.analysis.plots import scene_top_view

    for r in (shipped_results[9], shipped_results[2], shipped_results[11]):
        fig, ax = plt.subplots(figsize=(6.4, 4.8))
        fig.subplots_adjust(right=0.6)
        scene_top_view(r, ax=ax, optimized=r.shapes_init, success={"baseline": 0.5})
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        labels = [t for t in ax.texts if isinstance(t, Annotation)]
        objects = [t for t in ax.texts if not isinstance(t, Annotation)]
        clusters = {i: k for k, c in enumerate(r.meta_clusters()) for i in c}
        want = [tid + (f" (K{clusters[i]})" if i in clusters else "")
                for i, tid in enumerate(r.task_ids)]
        assert [t.get_text() for t in labels] == want
        assert sorted(t.get_text() for t in objects) == sorted(o.id for o in r.scene.objects)
        boxes = [Text.get_window_extent(t, renderer) for t in labels + objects]  # no leader
        frame = ax.get_window_extent(renderer)
        for i, a in enumerate(boxes[:len(labels)]):
            assert frame.x0 <= a.x0 and a.x1 <= frame.x1 and frame.y0 <= a.y0 <= a.y1 <= frame.y1
            for b in boxes[i + 1:]:
                assert not a.overlaps(b), (r.scene.name, a, b)
        legend = [t.get_text() for t in ax.get_legend().get_texts()]
        assert legend[:4] == ["initial space", "after Shrinking", "optimized", "object"]
        assert any(t.startswith("start plane (x ") for t in legend)
        assert "success: baseline 0.50" in ax.get_title()
        plt.close(fig)


def test_render_optimized_mode_draws_its_own_spaces(tmp_path):
    """``--mode optimized`` searches, draws the optimized spaces (not Shrinking's),
    within the template's bounds, and its success is in the title. A short search
    (8 generations) keeps it quick; both runs share one compiled program."""
    from geometry_precompute import load_scene, precompute, shipped_scene_paths
    from sweeps.analysis.render import optimized_shapes
    from sweeps.pipeline import evaluate_results

    scene = shipped_scene_paths()[11]  # cabinet, mug and cup: the search beats Shrinking
    short = {"optimize_generations": 8}
    r = precompute(load_scene(scene), short)
    ev = evaluate_results([r], ("shrinking", "optimized"))
    opt = optimized_shapes(ev)
    assert len(opt) == len(r.task_ids)
    assert any(not np.allclose(a.dims, b.dims) for a, b in zip(opt, r.shapes_opt,
                                                                strict=True))
    for t, sp in enumerate(r.spaces):
        q = ev.search.q[0, t, :len(sp.param_names)]
        assert np.all(q >= sp.q_min - 1e-9) and np.all(q <= sp.q_init + 1e-9)
    out = tmp_path / "opt.png"
    assert main(["render", str(scene), "--out", str(out), "--mode", "optimized",
                 "--set", "optimize_generations=8", "--width", "400", "--height", "240"]) == 0
    assert mpimg.imread(out).shape[:2] == (240, 400)
