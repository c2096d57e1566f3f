"""Assistance that infers intent (the blend, ho and shacc_ho modes): the posterior against
its formula, the weighted Markley average against scipy, every rollout against the NumPy
Automaton with the same random numbers, and the limits where a mode must equal the
baseline. Two compiled programs in all: the suite's time is mostly compiling."""

from __future__ import annotations

from dataclasses import replace

import jax
import jax.numpy as jnp
import numpy as np
import programs
import pytest
from reference_automaton import OUTCOME_NAMES, rollout
from scipy.spatial.transform import Rotation
from test_users import _draws, reference_user

import shacc_jax
from geometry_precompute import DEFAULTS, bake, load_scene, precompute, shipped_scene_paths
from geometry_precompute.loading import scene_from_dict
from geometry_precompute.population import POPULATED
from shacc_jax import assistance
from shacc_jax import quaternion as quat
from shacc_jax.types import ASSISTANCE, INVALID

INTENT = shacc_jax.INTENT_MODES
# Every user parameter at once (the change of mind in half the approaches).
EVERY = {"user_noise": 0.2, "user_noise_tau": 0.3, "user_tremor": 0.008, "user_tremor_hz": 5.0,
         "user_input": "modes", "user_switch": 0.5}
GRID = {"start_grid": [2, 3]}


def _mugs(name: str, ys) -> dict:
    """A scene of mugs at (0, y) with a side grasp each."""
    objects = [{"id": f"mug{i}", "kind": "mug", "position": [0.0, y, 0.0]}
               for i, y in enumerate(ys)]
    tasks = [{"id": f"grasp{i}", "object": f"mug{i}", "template": "side_grasp"}
             for i in range(len(ys))]
    return {"name": name, "objects": objects, "tasks": tasks}


@pytest.fixture(scope="module")
def scenes():
    """Two shipped three-task scenes (uncluttered and cluttered), one mug alone and two
    mugs close together, on a 2 x 3 start grid."""
    paths = shipped_scene_paths()
    picked = [load_scene(paths[i]) for i in (0, 9)]
    picked += [scene_from_dict(_mugs("one-mug", [0.0])),
               scene_from_dict(_mugs("two-mugs", [-0.1, 0.1]))]
    return [precompute(s, s.settings(DEFAULTS, GRID)) for s in picked]


def _bake(results, overrides):
    return bake([replace(r, settings=r.settings.with_overrides(overrides)) for r in results])


def test_the_posterior_is_its_formula():
    """P(j) = exp(-(V_j - V0_j) / beta) / sum, over the real tasks; g* the largest (the
    lower index on a tie) and the confidence its lead over the second."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        T = int(rng.integers(1, 8))
        mask = np.arange(8) < T
        v, v0 = rng.uniform(0, 0.5, 8), rng.uniform(0, 0.5, 8)
        beta = float(rng.uniform(0.01, 0.2))
        got = np.asarray(assistance.posterior(jnp.asarray(v), jnp.asarray(v0),
                                              jnp.asarray(mask), jnp.asarray(beta)))
        e = np.exp(-(v[:T] - v0[:T]) / beta)
        np.testing.assert_allclose(got[:T], e / e.sum(), rtol=1e-5)
        assert (got[T:] == 0).all()
        best, conf = assistance.best_and_confidence(jnp.asarray(got), jnp.asarray(mask))
        order = np.sort(got[:T])[::-1]
        assert int(best) == int(np.argmax(got[:T]))
        np.testing.assert_allclose(float(conf), order[0] - (order[1] if T > 1 else 0.0),
                                   atol=1e-6)
    # A tie: the lower index, no lead.
    best, conf = assistance.best_and_confidence(jnp.array([0.5, 0.5, 0.0]),
                                                jnp.array([True, True, False]))
    assert (int(best), float(conf)) == (0, 0.0)


def test_the_weighted_average_is_scipys():
    """The ho mode's orientation target, the posterior-weighted Markley average, against
    scipy's Rotation.mean with the same weights."""
    rng = np.random.default_rng(5)
    for _ in range(20):
        n = int(rng.integers(2, 6))
        base = Rotation.random(random_state=rng)
        rots = base * Rotation.from_rotvec(rng.normal(0, 0.4, (n, 3)))
        w = rng.dirichlet(np.ones(n))
        q = np.roll(rots.as_quat(), 1, axis=1)  # w first
        got = np.asarray(quat.markley_average(jnp.asarray(q), jnp.asarray(w)))
        want = rots.mean(weights=w)
        angle = (Rotation.from_quat(np.roll(got, -1)).inv() * want).magnitude()
        assert angle < 1e-4


def test_the_yaw_average_is_the_markley_average():
    """Where every task is a horizontal approach frame (Layout.intent_yaw), ho's average
    orientation takes the closed form: the same rotation as the weighted Markley
    average of the tasks' orientations at p, for fixed and point-to-axis tasks."""
    from geometry_precompute.schema import is_horizontal_approach
    from shacc_jax.orientation import horizontal_approach_quat, task_orientation

    rng = np.random.default_rng(11)
    T = 5
    for _ in range(20):
        psi = rng.uniform(-np.pi, np.pi, T)
        q = np.stack([np.asarray(horizontal_approach_quat(jnp.cos(a), jnp.sin(a)))
                      for a in psi])
        assert all(is_horizontal_approach(v) for v in q.astype(np.float64))
        kind = rng.integers(0, 2, T).astype(np.int32)
        axis = rng.uniform(-0.3, 0.3, (T, 2))
        p = rng.uniform(-0.4, 0.4, 3)
        w = rng.dirichlet(np.ones(T))
        g = type("G", (), {"orient_kind": jnp.asarray(kind), "orient_quat": jnp.asarray(q),
                           "orient_axis": jnp.asarray(axis)})
        got = np.asarray(assistance.weighted_yaw_average(g, jnp.asarray(w), jnp.asarray(p)))
        qs = jax.vmap(task_orientation, in_axes=(0, 0, 0, None))(
            jnp.asarray(kind), jnp.asarray(q), jnp.asarray(axis), jnp.asarray(p))
        want = np.asarray(quat.markley_average(qs, jnp.asarray(w)))
        assert float(np.asarray(quat.angle(jnp.asarray(got), jnp.asarray(want)))) < 1e-3


def test_every_intent_rollout_agrees_with_the_reference(scenes):
    """Every rollout of blend, ho and shacc_ho, with the perfect user and with every
    imperfect-user parameter at once (each scene twice in one batch: one program; with the
    swept activation check and with collision checks on one scene each), equals
    the NumPy Automaton's, stepped literally with the kernel's random numbers (float64):
    outcome, activated task, steps, the steps under each kind of assistance; points and
    path lengths to 1e-7 m, delta_R to 1e-5 rad (the weighted average's eigenvector by
    repeated squaring against scipy's)."""
    perfect = list(scenes)
    every = [replace(r, settings=r.settings.with_overrides(EVERY)) for r in scenes]
    # The swept activation check on the two close mugs, collision checks on the mug
    # behind two, each with every user parameter.
    checks = [replace(scenes[3], settings=scenes[3].settings.with_overrides(
                  {**EVERY, "activation_check": "swept"})),
              replace(scenes[1], settings=scenes[1].settings.with_overrides(
                  {**EVERY, "collision": "on"}))]
    every += checks
    baked = bake(perfect + every)
    with jax.enable_x64(True):
        g, p, lay = shacc_jax.inputs(baked, modes=INTENT, dtype=np.float64)
        assert lay.stepped_users and lay.intent_yaw  # mugs: ho's average in closed form
        ev = jax.tree.map(np.asarray, programs.evaluate(g, p, replace(lay, lanes_per_block=40)))
        ro = ev.rollouts
        kinds = {"none": 0, "scene": 0, "correct": 0, "wrong": 0}
        for s in range(len(perfect) + len(every)):
            imperfect = s >= len(perfect)
            T = int(baked.task_mask[s].sum())
            steps, once = _draws(baked, s, int(baked.max_steps[s]) + 1)
            values = [EVERY.get(k, DEFAULTS[k]) for k in POPULATED]
            for n in range(baked.n_starts):
                for t in range(T):
                    user = reference_user(EVERY, values, steps, once, n, t) \
                        if imperfect else None
                    for m, mode in enumerate(INTENT):
                        ref = rollout(baked, s, mode, n, t, user,
                                      swept=bool(baked.activation_swept[s]))
                        got = (OUTCOME_NAMES[ro.outcome[s, m, n, t]], int(ro.activated[s, m, n, t]),
                               int(ro.step[s, m, n, t]), int(ro.meta_steps[s, m, n, t]),
                               tuple(int(a) for a in ro.assist[s, m, n, t]))
                        assert got == (ref.outcome, ref.activated, ref.step, ref.meta_steps,
                                       ref.assist), (s, mode, n, t)
                        np.testing.assert_allclose(ro.point[s, m, n, t], ref.point, atol=1e-7)
                        assert abs(ro.path_length[s, m, n, t] - ref.path_length) < 1e-7
                        dr, ref_dr = ro.delta_R[s, m, n, t], ref.delta_R
                        assert (np.isnan(dr) and np.isnan(ref_dr)) or abs(dr - ref_dr) < 1e-5
                        for k, c in zip(ASSISTANCE, ref.assist, strict=True):
                            kinds[k] += c
    # Every kind of assistance occurred, so each was compared; the checks did act.
    assert min(kinds.values()) > 0, kinds
    assert (ro.outcome[-1] == shacc_jax.types.COLLISION).any()


def test_the_limits_where_a_mode_is_the_baseline(scenes):
    """One program, five points of settings: with intent_beta very large the posterior
    is uniform and blend never assists (it equals the baseline rollout for rollout);
    with ho_gain 0 ho moves as the baseline does; at blend_threshold 1 blend assists
    only where it is certain: on the one-mug scene towards that mug from the first step,
    elsewhere never. With a change of mind on the two close mugs, blend assists towards
    the wrong mug for some steps; shacc never does (its assistance is the scene's)."""
    modes = ("baseline", "shacc", "blend", "ho")
    settings = [{}, {"intent_beta": 100.0}, {"ho_gain": 0.0}, {"blend_threshold": 1.0},
                {"user_switch": 1.0, "user_switch_at": 0.8}]
    points = [_bake(scenes, s) for s in settings]
    ev = shacc_jax.run(points[0], modes, points=points).evaluation
    ro = ev.rollouts
    base, shacc, blend, ho = range(4)
    real = ro.outcome[0, :, base] != INVALID  # (S, N, T)

    def same_path(point, a, b):
        for name in ("outcome", "activated", "step"):
            x, y = getattr(ro, name)[point, :, a], getattr(ro, name)[point, :, b]
            assert np.array_equal(x[real], y[real]), name
        np.testing.assert_allclose(ro.point[point, :, a][real], ro.point[point, :, b][real],
                                   atol=2e-5)

    # intent_beta large: blend never assists where there is a choice (a one-task
    # scene's posterior is certain at any beta), and equals the baseline.
    same_path(1, base, blend)
    n_tasks = np.array([len(r.spaces) for r in scenes])
    choice = real & (n_tasks > 1)[:, None, None]
    assert (ro.assist[1, :, blend][choice][:, 2:] == 0).all()
    np.testing.assert_allclose(ro.orientation[1, :, blend][choice],
                               ro.orientation[1, :, base][choice], atol=1e-6)
    # The default blend does assist, and ho always does.
    assert ro.assist[0, :, blend][real][:, 2:].sum() > 0
    # ho_gain 0: ho's positions are the baseline's (its orientation still turns).
    same_path(2, base, ho)
    # blend_threshold 1: certain only on the one-mug scene, from the first step.
    one = next(i for i, r in enumerate(scenes) if len(r.spaces) == 1)
    a = ro.assist[3, one, blend, :, 0]  # (N, 4)
    ended = ro.outcome[3, one, blend, :, 0] == shacc_jax.types.SUCCESS
    assert ended.all()
    assert np.array_equal(a[:, 2], ro.step[3, one, blend, :, 0] - 1)
    assert (a[:, 3] == 0).all()
    others = np.ones(len(scenes), bool)
    others[one] = False
    assert (ro.assist[3, others, blend][:, :, :, 2:] == 0).all()
    # A change of mind between two close mugs: blend is wrong for a while, shacc is not.
    two = next(i for i, r in enumerate(scenes) if r.scene.name == "two-mugs")
    assert ro.assist[4, two, blend, :, :2, 3].sum() > 0
    assert ro.assist[4, two, shacc, :, :2, 3].sum() == 0
    assert ro.assist[4, two, shacc, :, :2, 1].sum() > 0  # its meta skill does act


def test_the_plan_says_which_modes_are_stepped(scenes):
    """With perfect users the paper's modes keep the closed form and the intent modes are
    stepped, in one program; the plan says so (no compilation)."""
    baked = bake(scenes[:1])
    text = shacc_jax.plan(baked, ("baseline", "ho", "shacc_ho")).describe()
    assert "closed-form and stepped (ho, shacc_ho" in text
    assert "closed-form rollouts" in shacc_jax.plan(baked, ("baseline",)).describe()
    with pytest.raises(ValueError, match="distinct names"):
        shacc_jax.run(baked, ("baseline", "hindsight"))
