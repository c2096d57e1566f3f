"""The jitted evaluation against the plain NumPy Automaton, rollout by rollout, on
every shipped manual scene in all three modes (float32 and float64), and the
properties the modes must have."""

from __future__ import annotations

from dataclasses import replace

import jax
import numpy as np
import programs
import pytest
from reference_automaton import OUTCOME_NAMES, rollout
from scipy.spatial.transform import Rotation

import shacc_jax
from geometry_precompute import bake, extra_scene_paths, load_scene, precompute
from shacc_jax import program_cache
from shacc_jax.types import INVALID, SUCCESS, Geometry


def run(baked, modes=shacc_jax.MODES, x64=False, meta=None, **layout):
    """The public evaluate; with ``meta`` the meta-target formula is forced ("general":
    the Markley average even where the closed form for horizontal frames applies);
    other keywords replace Layout fields (block sizes)."""
    with jax.enable_x64(x64):
        g, p, lay = shacc_jax.inputs(baked, modes, np.float64 if x64 else np.float32)
        if meta is not None:
            layout["meta_formula"] = meta
        ev = programs.evaluate(g, p, replace(lay, **layout))
        return jax.tree.map(np.asarray, ev)


def reference_table(baked, n_tasks, modes=shacc_jax.MODES):
    table = {}
    for s in range(baked.n_scenes):
        for m, mode in enumerate(modes):
            for n in range(baked.n_starts):
                for t in range(n_tasks[s]):
                    table[s, m, n, t] = rollout(baked, s, mode, n, t)
    return table


@pytest.fixture(scope="module")
def reference(shipped_bake, shipped_results):
    return reference_table(shipped_bake, [len(r.spaces) for r in shipped_results])


def compare(ev, table, dr_tol):
    ro = ev.rollouts
    mismatches = []
    for (s, m, n, t), ref in table.items():
        got = (OUTCOME_NAMES[ro.outcome[s, m, n, t]], int(ro.activated[s, m, n, t]),
               int(ro.step[s, m, n, t]), int(ro.meta_steps[s, m, n, t]))
        exp = (ref.outcome, ref.activated, ref.step, ref.meta_steps)
        dr, ref_dr = ro.delta_R[s, m, n, t], ref.delta_R
        same_dr = (np.isnan(dr) and np.isnan(ref_dr)) or abs(dr - ref_dr) <= dr_tol
        if got != exp or not same_dr:
            mismatches.append(((s, m, n, t), got, exp, dr, ref_dr))
        else:
            np.testing.assert_allclose(ro.point[s, m, n, t], ref.point, atol=1e-5)
            assert abs(ro.path_length[s, m, n, t] - ref.path_length) < 1e-5
            q = np.asarray(ro.orientation[s, m, n, t], float)
            angle = 2 * np.arccos(min(abs(q @ ref.quat) / np.linalg.norm(q), 1.0))
            assert angle <= max(dr_tol, 2e-3), (q, ref.quat)  # the same R (q or -q)
    assert not mismatches, mismatches[:10]
    return len(table)


def test_agrees_with_reference_float32(shipped_bake, reference):
    assert compare(run(shipped_bake), reference, dr_tol=5e-3) == 12 * 3 * 36 * 3


def test_agrees_with_reference_float64(shipped_bake, reference):
    compare(run(shipped_bake, x64=True), reference, dr_tol=1e-6)


def test_markley_path_agrees_with_reference(shipped_bake, reference):
    """Every shipped scene's clusters have horizontal approach frames only, so evaluate
    takes the closed form; the general Markley path, forced, agrees as well (in float64
    it is checked to 1e-6 on the tray scene, test_top_grasp_cluster_and_mixed_batch)."""
    assert shipped_bake.layout().meta_formula == "yaw"
    compare(run(shipped_bake, meta="general"), reference, dr_tol=5e-3)


def test_top_grasp_cluster_and_mixed_batch(shipped_results):
    """The extra tray scene clusters a top grasp with two side grasps (the Markley
    path). Batched with two shipped scenes (the closed form), each lane takes its own
    path: the same rollouts as separate runs, and the reference's in both precisions."""
    tray = precompute(load_scene(extra_scene_paths()[0]))
    assert tray.meta_clusters() == [[0, 1, 2]]
    assert bake([tray]).layout().meta_formula == "general"
    mixed = bake([shipped_results[8], tray, shipped_results[2]])
    assert mixed.layout().meta_formula == "both"
    # The reference for the tray's rollouts (the shipped scenes' are checked above).
    table = reference_table(mixed, [0, 3, 0])
    together = run(mixed)
    compare(together, table, dr_tol=5e-3)
    compare(run(mixed, x64=True), table, dr_tol=1e-6)
    assert together.rollouts.meta_steps[1, 2].sum() > 0  # the tray's cluster is tracked
    # Separately: the tray alone, and the two shipped scenes together.
    for rows, part in (([1], bake([tray])), ([0, 2], bake([shipped_results[8],
                                                            shipped_results[2]]))):
        alone = run(part)
        for a, b in zip(jax.tree.leaves(alone), jax.tree.leaves(together), strict=True):
            if a.dtype.kind == "f":
                np.testing.assert_allclose(a, b[rows], atol=1e-6)
            else:
                np.testing.assert_array_equal(a, b[rows])


@pytest.mark.parametrize("overrides", [
    {"max_steps": 120},                              # timeouts
    {"ambiguity": "nearest"},
    {"v_max": 0.4, "omega_max": 1.0},
    {"start_orientation": "forward", "start_grid": [3, 2]},
])
def test_settings_variants_against_reference(shipped_results, overrides):
    picks = [shipped_results[i] for i in (2, 8, 10)]  # cluttered: tight row, behind, mixed
    rs = [precompute(r.scene, r.settings.with_overrides(overrides)) for r in picks]
    b = bake(rs)
    table = reference_table(b, [3, 3, 3])
    ev = run(b)
    compare(ev, table, dr_tol=5e-3)
    if "max_steps" in overrides:
        assert (ev.rollouts.outcome == 3).any()


def test_shrinking_and_shacc_same_outcomes(shipped_bake, reference):
    ev = run(shipped_bake)
    ro = ev.rollouts
    np.testing.assert_array_equal(ro.outcome[:, 1], ro.outcome[:, 2])
    np.testing.assert_array_equal(ro.activated[:, 1], ro.activated[:, 2])
    # The reference, run mode by mode, agrees (Merging changes orientation, not paths).
    for (s, m, n, t), ref in reference.items():
        if m == 1:
            assert reference[s, 2, n, t].outcome == ref.outcome


def test_same_start_orientations_in_every_mode(shipped_bake, shipped_results):
    """delta_R of every success equals the angle between the baked start orientation
    and the target's orientation at activation, in baseline and shrinking; shacc
    equals shrinking where no rotation happened (no meta steps)."""
    ev = run(shipped_bake)
    ro = ev.rollouts
    b = shipped_bake
    for s, r in enumerate(shipped_results):
        for m in (0, 1, 2):
            for n in range(b.n_starts):
                r0 = Rotation.from_quat(np.r_[b.starts[s, n, 4:], b.starts[s, n, 3]])
                for t in range(len(r.spaces)):
                    if ro.outcome[s, m, n, t] != SUCCESS or ro.meta_steps[s, m, n, t] > 0:
                        continue
                    p = ro.point[s, m, n, t]
                    from reference_automaton import angle_between, task_rotation
                    ori = (int(b.orient_kind[s, t]), b.orient_quat[s, t], b.orient_axis[s, t])
                    expected = angle_between(r0, task_rotation(*ori, p))
                    assert abs(ro.delta_R[s, m, n, t] - expected) < 2e-3


def test_merging_lowers_delta_r_on_cluttered_scenes(shipped_bake, shipped_results):
    ev = run(shipped_bake)
    cluttered = [i for i, r in enumerate(shipped_results) if r.C_init > 0]
    dr = ev.metrics.delta_R_mean[cluttered]
    assert np.nanmean(dr[:, 2]) < np.nanmean(dr[:, 1])
    assert np.nanmean(dr[:, 2]) < np.nanmean(dr[:, 0])


def test_padding_changes_nothing(shipped_results):
    # float64, so that a difference cannot hide in rounding (in float32 a different
    # reduction order over 3 or 7 tasks changes delta_R by up to ~1e-3 rad).
    b3 = bake(shipped_results[:4])
    b7 = bake(shipped_results[:4], max_tasks=7)
    e3, e7 = run(b3, x64=True), run(b7, x64=True)
    for f in ("outcome", "activated", "step", "meta_steps"):
        np.testing.assert_array_equal(getattr(e7.rollouts, f)[..., :3],
                                      getattr(e3.rollouts, f))
    np.testing.assert_allclose(e7.rollouts.delta_R[..., :3], e3.rollouts.delta_R, atol=1e-9)
    assert (e7.rollouts.outcome[..., 3:] == INVALID).all()
    assert (e7.rollouts.activated < 3).all()  # a padded task never activates
    np.testing.assert_allclose(e7.metrics.u_scene, e3.metrics.u_scene)


def test_metrics_follow_rollouts(shipped_bake):
    ev = run(shipped_bake)
    ro, me = ev.rollouts, ev.metrics
    success = ro.outcome == SUCCESS
    np.testing.assert_allclose(me.u_scene, success.mean(axis=(2, 3)), rtol=1e-6)
    assert (me.outcome_counts.sum(-1) == me.n_rollouts).all()
    for s in range(ro.outcome.shape[0]):
        for m in range(3):
            d = ro.delta_R[s, m][success[s, m]]
            assert me.delta_R_mean[s, m] == pytest.approx(d.mean(), rel=1e-5)


def test_settings_are_leaves_no_recompile(shipped_results, count_compiles):
    rs = shipped_results[:2]
    b = bake(rs)
    with count_compiles("evaluate") as first:
        run(b)
    with count_compiles("evaluate") as later:
        for overrides in ({"v_max": 0.25}, {"dt": 0.01, "omega_max": 1.5},
                          {"activation_tol": 1e-3, "ambiguity": "nearest", "max_steps": 300}):
            run(bake([precompute(r.scene, r.settings.with_overrides(overrides)) for r in rs]))
    assert len(first) <= 1 and later == []  # (the first may be cached by an earlier test)


def test_montecarlo_clutteredness_agrees_with_mesh(shipped_results, shipped_bake):
    g = Geometry.from_bake(shipped_bake)
    key = jax.random.PRNGKey(0)
    for s, r in enumerate(shipped_results):
        for which, c_mesh in (("init", r.C_init), ("opt", r.C_final)):
            k = jax.random.fold_in(key, 2 * s + (which == "opt"))
            spaces = shacc_jax.Spaces(g.kind[s], getattr(g, f"center_{which}")[s],
                                      getattr(g, f"quat_{which}")[s],
                                      getattr(g, f"dims_{which}")[s])
            c = float(shacc_jax.clutteredness_mc(spaces, g.task_mask[s], k, 1 << 16))
            assert abs(c - c_mesh) < 0.01, (r.scene.name, which, c, c_mesh)


def test_points_axis_equals_one_call_per_point(shipped_results):
    """Params with a leading axis of sweep points: one call gives, per point, what a
    call with that point's settings gives (the lanes of all points share one lane
    sort; each rollout depends only on its own scene and settings)."""
    b = bake(shipped_results[7:9])
    g, p, layout = shacc_jax.inputs(b)
    points = jax.tree.map(lambda a: np.stack([np.asarray(a)] * 3), p)
    points = points._replace(
        v_max=points.v_max * np.array([[1.0], [0.5], [2.0]], points.v_max.dtype),
        ambiguity_nearest=np.array([[False] * 2, [True] * 2, [False, True]]),
        omega_max=points.omega_max * np.array([[1.0], [1.0], [0.3]], points.omega_max.dtype))
    together = jax.tree.map(np.asarray, programs.evaluate(g, points, layout))
    assert together.rollouts.outcome.shape == (3, 2, 3, b.n_starts, b.n_tasks)
    for i in range(3):
        alone = programs.evaluate(g, jax.tree.map(lambda a, i=i: a[i], points), layout)
        for x, y in zip(jax.tree.leaves(alone), jax.tree.leaves(together), strict=True):
            x, y = np.asarray(x), y[i]
            if x.dtype.kind == "f":
                np.testing.assert_allclose(x, y, rtol=1e-6, atol=1e-6, equal_nan=True)
            else:
                np.testing.assert_array_equal(x, y)
    # The settings changed something: half the speed takes more steps to the same spaces.
    assert together.rollouts.step[1].sum() > together.rollouts.step[0].sum()


def test_evaluate_is_traceable(shipped_results):
    """No host reads of array values inside: evaluate runs under an outer jit and lowers
    ahead of time, with the same results."""
    g, p, layout = shacc_jax.inputs(bake(shipped_results[:2]), ("baseline", "shacc"))
    direct = programs.evaluate(g, p, layout)
    quick = program_cache.QUICK_OPTIONS  # a small program, compiled as the commands would
    wrapped = jax.jit(lambda g, p: shacc_jax.evaluate(g, p, layout).metrics.u_scene,
                      compiler_options=quick)(g, p)
    np.testing.assert_array_equal(np.asarray(wrapped), np.asarray(direct.metrics.u_scene))
    compiled = shacc_jax.evaluate.lower(g, p, layout).compile(quick)
    np.testing.assert_array_equal(np.asarray(compiled(g, p).rollouts.outcome),
                                  np.asarray(direct.rollouts.outcome))
    with pytest.raises(ValueError, match="n_tasks"):
        shacc_jax.evaluate(g, p, replace(layout, n_tasks=layout.n_tasks + 1))
