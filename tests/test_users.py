"""Simulated users beyond the perfect one (shacc_jax.stepping and its parts): the stepped
kernel against
the NumPy Automaton driven by the same random numbers, the perfect user stepped against
the closed form, the random numbers' distributions and their independence of the
batch, the mode and the device split."""

from __future__ import annotations

import math
from dataclasses import replace
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import programs
import pytest
from reference_automaton import OUTCOME_NAMES, User, rollout, turn_across
from scipy import stats
from scipy.spatial.transform import Rotation

import shacc_jax
from geometry_precompute import (
    DEFAULTS,
    InputError,
    bake,
    load_scene,
    precompute,
    shipped_scene_paths,
)
from geometry_precompute.population import POPULATED
from shacc_jax import runplan, stepping, streams, user_models

# A population: each rollout draws its own user (the reference is given the values the
# kernel reports it drew).
POPULATION = {"user_noise": {"uniform": [0.0, 0.4]}, "user_noise_tau": {"values": [0.0, 0.4]},
              "user_tremor": {"normal": [0.008, 0.004]},
              "user_tremor_hz": {"uniform": [2.0, 6.0]}, "user_switch": {"values": [0.0, 1.0]},
              "user_switch_at": {"uniform": [0.3, 0.7]}}
USERS = {
    "noise": {"user_noise": 0.3},
    "wander": {"user_noise": 0.3, "user_noise_tau": 0.5},
    "tremor": {"user_tremor": 0.01, "user_tremor_hz": 3.0},
    "modes": {"user_input": "modes", "user_mode_switch_s": 0.1},
    "switch": {"user_switch": 1.0, "user_switch_at": 0.6},
    "all": {"user_noise": 0.2, "user_noise_tau": 0.3, "user_tremor": 0.008,
            "user_input": "modes", "user_switch": 0.5},
    "object": {"user_aim": "object"},
    "object-noisy": {"user_aim": "object", "user_noise": 0.2, "user_switch": 1.0},
    "swept": {"activation_check": "swept"},
    # Every parameter at once, drawn per rollout, with the swept check or with collisions
    # (one program each: the fixed values take the same code as a population's draws).
    "swept-population": {"activation_check": "swept", "user_input": "modes", **POPULATION},
    "collision-population": {"collision": "on", **POPULATION},
}


def reference_user(overrides: dict, values, steps, once, n: int, t: int):
    """The NumPy Automaton's user of rollout (n, t): the user settings (``values``, in
    POPULATED's order) and the kernel's random numbers of that rollout."""
    return User(*values, steps.xi[n, t], once.tremor_axis[n, t],
                float(once.tremor_phase[n, t]), once.noise0[n, t], float(once.switch[n, t]),
                float(once.other[n, t]), overrides.get("user_input") == "modes",
                overrides.get("user_aim") == "object")


def _evaluate(baked, x64=False, **layout):
    with jax.enable_x64(x64):
        g, p, lay = shacc_jax.inputs(baked, dtype=np.float64 if x64 else np.float32)
        ev = programs.evaluate(g, p, replace(lay, **layout))
        return jax.tree.map(np.asarray, ev)


@pytest.fixture(scope="module")
def scenes(mesh_scenes):
    """Three shipped scenes (uncluttered and cluttered) and a random one with mesh
    objects (collision checks off unless a test turns them on), on a 2 x 3 start grid,
    precomputed once."""
    grid = {"start_grid": [2, 3]}
    paths = shipped_scene_paths()
    picked = [load_scene(paths[i]) for i in (0, 6, 9)]
    return [precompute(s, s.settings(DEFAULTS, grid)) for s in picked] + \
        mesh_scenes(1, (3, 4), 1, collision="off", **grid)


def _bake(results, overrides):
    return bake([replace(r, settings=r.settings.with_overrides(overrides)) for r in results])


def test_carrying_user_models_a_scene_does_not_use_changes_nothing(scenes):
    """A program that carries the joystick's state and the change of mind's (because
    some other scene of its batch needs them) gives a scene whose user has neither the
    same rollouts, bit for bit: batches that mix users (the reproduction's robustness
    section evaluates every level in one) answer as a batch per user would. (The two
    programs are those of the perfect user stepped and of the accelerators' scheme
    below: the same layouts, so the suite compiles them once.)"""
    baked = _bake(scenes, USERS["wander"])
    alone = _evaluate(baked, lanes_per_block=40)
    carried = _evaluate(baked, joystick=True, switching=True, lanes_per_block=40)
    for name in alone.rollouts._fields:
        a, b = getattr(alone.rollouts, name), getattr(carried.rollouts, name)
        assert np.array_equal(a, b, equal_nan=True), name


def test_the_perfect_user_stepped_is_the_closed_form(scenes):
    """A perfect user's lanes take the closed form's sample positions: stepping them
    changes no bit of a real task's outcome, activated task, step or meta steps, in any
    mode (a padded task's rollout is not stepped). The two programs compute a sample
    p0 + (k s) u each in its own fusion, which XLA may contract to a multiply-add in one
    and not the other: points and path lengths agree to float32 rounding (seen: one
    unit in the last place, after 138 steps, on the scene with meshes). The meta
    target is computed per lane instead of per block of samples, and the stepped turn
    is ``quaternion.turn_towards``, not the slerp: the orientation and delta_R agree to
    float32 rounding accumulated over a turn (seen: 7.3e-6 rad of delta_R, where the
    closed form is 8.4e-6 and the stepped turn 1.1e-6 from the float64 answer)."""
    baked = bake(scenes)
    closed = _evaluate(baked)
    stepped = _evaluate(baked, stepped_users=True, lanes_per_block=40)
    real = closed.rollouts.outcome != shacc_jax.types.INVALID
    assert real.sum() == 3 * 6 * sum(len(r.spaces) for r in scenes)
    for name in ("outcome", "activated", "step", "meta_steps"):
        a, b = getattr(closed.rollouts, name), getattr(stepped.rollouts, name)
        assert np.array_equal(a[real], b[real]), name
    for name in ("point", "path_length"):
        a, b = getattr(closed.rollouts, name), getattr(stepped.rollouts, name)
        np.testing.assert_array_max_ulp(a[real], b[real], maxulp=2)
    for name in ("delta_R", "orientation"):
        a, b = getattr(closed.rollouts, name), getattr(stepped.rollouts, name)
        np.testing.assert_allclose(a[real], b[real], atol=1e-5, rtol=0)


@partial(jax.jit, static_argnums=(2, 3, 4))
def _draw_all(seed, scene_key, N: int, T: int, n_steps: int):
    # One program for every scene and case (seed and scene key are arguments).
    return jax.vmap(jax.vmap(lambda n, t: streams.user_draws(seed, scene_key, t, n, n_steps,
                                                           np.float64), (None, 0)), (0, None))(
        jnp.arange(N, dtype=jnp.int32), jnp.arange(T, dtype=jnp.int32))


def _draws(baked, scene: int, n_steps: int):
    """Every rollout's random numbers of one scene, (N, T), from the kernel's stream."""
    steps, once = _draw_all(baked.user_seed[scene], baked.scene_key[scene], baked.n_starts,
                            baked.n_tasks, n_steps)
    return jax.tree.map(np.asarray, steps), jax.tree.map(np.asarray, once)


# Left out for the suite's time: "all" (every parameter at once, fixed), which the
# swept and collision populations cover, and "swept" alone, which "swept-population"
# covers with the same program (test_swept_activation_does_not_depend_on_the_speed
# checks the perfect user's swept rollouts).
@pytest.mark.parametrize("name", [n for n in USERS if n not in ("all", "swept")])
def test_stepped_users_agree_with_the_reference(scenes, name):
    """Each user parameter alone, and all together, a user aiming at the object (alone
    and noisy), and a population of users (each rollout's drawn values): every rollout
    of every mode equals the NumPy Automaton's, stepped literally with the same random
    numbers (float64)."""
    overrides = {"user_tremor_hz": 5.0, **USERS[name]}
    baked = _bake(scenes, overrides)
    with jax.enable_x64(True):
        # Blocks of 40 lanes: slots end and take new lanes many times.
        ev = _evaluate(baked, x64=True, lanes_per_block=40)
        assert shacc_jax.inputs(baked)[2].stepped_users
        checked = 0
        for s, r in enumerate(scenes):
            steps, once = _draws(baked, s, int(baked.max_steps[s]) + 1)
            for n in range(baked.n_starts):
                for t in range(len(r.spaces)):
                    drawn = ev.rollouts.user[s, :, n, t]  # (M, 4) where a population
                    if drawn.shape[-1]:
                        assert (drawn == drawn[0]).all()  # one user in every mode
                        values = [float(v) for v in drawn[0]]
                    else:
                        values = [overrides.get(k, DEFAULTS[k]) for k in POPULATED]
                    user = reference_user(overrides, values, steps, once, n, t)
                    for m, mode in enumerate(shacc_jax.MODES):
                        ref = rollout(baked, s, mode, n, t, user,
                                      swept=overrides.get("activation_check") == "swept")
                        ro = ev.rollouts
                        got = (OUTCOME_NAMES[ro.outcome[s, m, n, t]], int(ro.activated[s, m, n, t]),
                               int(ro.step[s, m, n, t]), int(ro.meta_steps[s, m, n, t]))
                        assert got == (ref.outcome, ref.activated, ref.step, ref.meta_steps), \
                            (s, mode, n, t)
                        np.testing.assert_allclose(ro.point[s, m, n, t], ref.point, atol=1e-7)
                        assert abs(ro.path_length[s, m, n, t] - ref.path_length) < 1e-7
                        dr, ref_dr = ro.delta_R[s, m, n, t], ref.delta_R
                        assert (np.isnan(dr) and np.isnan(ref_dr)) or abs(dr - ref_dr) < 1e-6
                        checked += 1
    assert checked == 3 * 6 * sum(len(r.spaces) for r in scenes)
    if "collision" in overrides:  # the scenes do make this user collide
        assert (ev.rollouts.outcome == shacc_jax.types.COLLISION).any()
    # The user changed something: not every rollout is the perfect user's.
    perfect = _evaluate(bake(scenes), x64=False)
    assert (perfect.rollouts.step != ev.rollouts.step).any() or \
        not np.allclose(perfect.rollouts.point, ev.rollouts.point, equal_nan=True)


@pytest.fixture(scope="module")
def mixed(scenes):
    """A batch that mixes perfect users with imperfect ones (every parameter, and aiming
    at the object with noise and a change of mind), and its stepped evaluation in the
    paper's three modes with the CPU's scheme."""
    users_per_scene = [{}, USERS["all"], {}, USERS["object-noisy"]]
    baked = bake([replace(r, settings=r.settings.with_overrides(o))
                  for r, o in zip(scenes, users_per_scene, strict=True)])
    return baked, _evaluate(baked, stepped_users=True, lanes_per_block=40)


def test_the_accelerators_stepping_gives_the_same_rollouts(mixed):
    """The accelerators step differently (several steps per loop iteration,
    stepping.STEPPING); run here on the CPU (Layout.stepping), with every lane checked in
    full each step, their rollouts equal the CPU's scheme (a share of lanes gathered and
    checked, one step per iteration) bit for bit, in every mode, on a batch that mixes
    perfect users with imperfect ones (the schemes differ in the loop, not in a step's
    check). Two steps per iteration stand for the accelerators' eight: the paper's
    modes run them as a loop of one traced step (``stepping.ROLLED``), the intent
    modes unrolled, each copy more to compile."""
    baked, ours = mixed
    theirs = _evaluate(baked, stepped_users=True, lanes_per_block=40, stepping=(1, 2))
    assert stepping.STEPPING["accelerator"] > 1 and stepping.STEPPING["cpu"] == 1
    for field in ours.rollouts._fields:
        a, b = getattr(ours.rollouts, field), getattr(theirs.rollouts, field)
        assert np.array_equal(a, b, equal_nan=True), field


def test_baseline_folded_into_shaccs_pass_steps_as_alone(mixed):
    """On a CPU (stepping.FOLD) baseline runs in shacc's pass, on a copy of each scene
    without clusters whose optimised spaces are its initial ones: its rollouts, and
    shacc's, equal those of programs where each mode has its pass to itself (no partner
    in the batch), bit for bit, on the mixed batch. (ho runs in shacc_ho's pass the same
    way; test_intent holds its every rollout to the NumPy Automaton's.)"""
    assert stepping.FOLD["cpu"] and "shacc" in stepping.FOLDS["baseline"]
    baked, ours = mixed
    for mode in ("baseline", "shacc"):
        alone = _evaluate(baked, stepped_users=True, lanes_per_block=40, modes=(mode,))
        i = shacc_jax.MODES.index(mode)
        for field in ours.rollouts._fields:
            a, b = getattr(ours.rollouts, field)[:, i], getattr(alone.rollouts, field)[:, 0]
            assert np.array_equal(a, b, equal_nan=True), (mode, field)


def test_swept_activation_does_not_depend_on_the_speed(scenes):
    """With activation_check = swept a rollout activates where its path first enters a
    space, whatever the step length: the perfect user's outcomes at v_max = 2 m/s (4 cm
    steps, as thick as a top grasp's disk) are those at the default 0.15 m/s. Checked
    at the steps, the fast user steps over spaces. At the default speed the two checks
    differ only where a step enters two spaces at once (the step position is in both,
    ambiguous; the segment entered one first) or passes through a space between two
    steps (activating earlier)."""
    def rollouts(**overrides):
        return _evaluate(_bake(scenes, overrides)).rollouts

    swept_slow = rollouts(activation_check="swept")
    swept_fast = rollouts(activation_check="swept", v_max=2.0)
    steps_slow, steps_fast = rollouts(), rollouts(v_max=2.0)
    real = steps_slow.outcome != shacc_jax.types.INVALID
    assert np.array_equal(swept_slow.outcome[real], swept_fast.outcome[real])
    assert np.array_equal(swept_slow.activated[real], swept_fast.activated[real])
    assert (steps_fast.outcome[real] != steps_slow.outcome[real]).sum() > 0  # stepped over
    differ = real & (swept_slow.outcome != steps_slow.outcome)
    assert differ.mean() < 0.05
    two_at_once = (steps_slow.outcome == shacc_jax.types.AMBIGUOUS) & \
        (swept_slow.step == steps_slow.step)
    earlier = swept_slow.step < steps_slow.step
    assert (two_at_once | earlier)[differ].all()


def test_the_wandering_hand_is_an_ornstein_uhlenbeck_process():
    """The kernel's stream drives w_{k+1} = a w_k + sqrt(1 - a^2) sigma xi_k: xi is
    N(0, 1) per component (Kolmogorov-Smirnov); the process started at N(0, sigma^2 I)
    stays there (stationary variance sigma^2 per component, within its sampling error)
    with lag-one autocorrelation a = exp(-dt / tau) (within four standard errors); a = 0
    (tau 0) is white noise. The kernel's turn is the reference's, and that is scipy's
    ``Rotation.from_rotvec(...).apply``."""
    sigma, dt = 0.3, 0.02
    draw = jax.vmap(lambda start: streams.user_draws(3, 99, 0, start, n_steps=400))
    steps, once = draw(np.arange(200, dtype=np.int32))
    xi, w0 = np.asarray(steps.xi, float), np.asarray(once.noise0, float)  # (R, n, 3), (R, 3)
    assert stats.kstest(xi.ravel(), stats.norm.cdf).pvalue > 1e-3
    assert stats.kstest(w0.ravel(), stats.norm.cdf).pvalue > 1e-3
    for tau in (0.0, 0.1, 0.5):
        a = math.exp(-dt / tau) if tau else 0.0
        w = np.empty((xi.shape[0], xi.shape[1] + 1, 3))
        w[:, 0] = sigma * w0
        for k in range(xi.shape[1]):
            w[:, k + 1] = a * w[:, k] + math.sqrt(1 - a * a) * sigma * xi[:, k]
        var = w.var()
        assert abs(var / sigma**2 - 1) < 4 * math.sqrt(2 / (w.size / (1 + 2 * a / (1 - a)))), tau
        x0, x1 = w[:, :-1].ravel(), w[:, 1:].ravel()
        rho = np.corrcoef(x0, x1)[0, 1]
        assert abs(rho - a) < 4 / math.sqrt(x0.size) * (1 + a), (tau, rho, a)
    u = np.array([0.3, -0.5, 0.81])
    u /= np.linalg.norm(u)
    ws = sigma * xi[0, :50]
    turned = np.asarray(jax.vmap(lambda v: user_models.turn_across(
        jnp.asarray(u, jnp.float32), v.astype(jnp.float32)))(jnp.asarray(ws)))
    ref = np.array([turn_across(u, v) for v in ws])
    np.testing.assert_allclose(turned, ref, atol=2e-6)
    # The reference's turn (Python floats) is scipy's, from no turn to several turns.
    scales = np.array([0.0, 1e-12, 1e-6, 1e-3, 0.1, 1.0, 3.0, 10.0])
    for v in (ws[:, None] / sigma * scales[:, None]).reshape(-1, 3):
        across = v - (v @ u) * u
        np.testing.assert_allclose(turn_across(u, v), Rotation.from_rotvec(across).apply(u),
                                   rtol=0, atol=1e-14)


def test_step_draws_are_jax_threefry():
    """The kernel's written-out threefry gives JAX's ``threefry_2x32`` words for the
    counters [k, k, 0, 1] under the rollout's step key (its key folded with 1), bit for
    bit, over many rollouts and steps: the draws equal those mapped from JAX's words as
    ``step_draws`` documents them."""
    from jax.extend.random import threefry_2x32

    rng = np.random.default_rng(5)
    seeds = rng.integers(0, 2**31, (4000, 4)).astype(np.int32)
    k = jnp.asarray(rng.integers(0, 2**31, 4000), jnp.int32)

    def theirs(seed, k):
        key = streams.rollout_key(*seed)
        step_key = jax.random.key_data(jax.random.fold_in(key, 1))
        kk = k.astype(jnp.uint32)
        words = threefry_2x32(step_key, jnp.stack([kk, kk, jnp.zeros_like(kk),
                                                    jnp.ones_like(kk)]))
        u = ((words[:3] >> 8).astype(jnp.float32) + 0.5) * (1.0 / (1 << 24))
        return jnp.sqrt(2.0) * jax.scipy.special.erfinv(2.0 * u - 1.0)

    def ours(seed, k):
        return streams.step_draws(streams.rollout_key(*seed), k, jnp.float32).xi

    seeds = jnp.asarray(seeds)
    np.testing.assert_array_equal(np.asarray(jax.vmap(ours)(seeds, k)),
                                  np.asarray(jax.vmap(theirs)(seeds, k)))


def test_a_change_of_mind_happens_with_its_probability():
    """Over many rollouts a change of mind happens (its uniform number below
    user_switch) with probability user_switch (binomial test), the first-headed task is
    each other task as often (chi-square), and the tremor axes are uniform on the
    sphere (their z uniform in [-1, 1])."""
    from reference_automaton import first_headed

    draw = jax.vmap(lambda start: streams.user_draws(3, 99, 0, start, n_steps=1))
    _, once = draw(np.arange(4000, dtype=np.int32))
    u = np.asarray(once.switch)
    for p in (0.05, 0.2, 0.5):
        k = int((u < p).sum())
        assert stats.binomtest(k, u.size, p).pvalue > 1e-3, (p, k, u.size)
    user = User(0, 0, 0, 5, 1.0, 0.5, 0.5, None, None, 0, None, 0.0, 0.0)
    firsts = [first_headed(replace(user, other_u=float(o)), 2, 5) for o in np.asarray(once.other)]
    counts = np.bincount(firsts, minlength=5)
    assert counts[2] == 0 and stats.chisquare(counts[[0, 1, 3, 4]]).pvalue > 1e-3
    axes = np.asarray(once.tremor_axis)
    np.testing.assert_allclose(np.linalg.norm(axes, axis=1), 1.0, atol=1e-6)
    assert stats.kstest(axes[:, 2], stats.uniform(-1, 2).cdf).pvalue > 1e-3


def test_a_rollouts_noise_does_not_depend_on_its_batch_or_mode(scenes):
    """The stream is keyed by (seed, scene, task, start): a scene alone, and inside a
    batch of seven, split into pieces by a small memory budget over two CPU devices,
    gives the same rollouts, drawn from a population of users; and on a scene whose
    spaces Shrinking leaves alone the baseline and shrinking modes (the same spaces, the
    same draws) agree rollout for rollout."""
    overrides = POPULATION
    alone = shacc_jax.run(_bake(scenes[1:2], overrides), shacc_jax.MODES).evaluation
    batch = _bake([*scenes, *scenes[:3]], overrides)  # seven scenes
    devices = jax.devices("cpu")[:2]
    per_start = (runplan.bytes_per_rollout(False, stepped=True)
                 * batch.n_scenes * batch.n_tasks * 3)
    plan = shacc_jax.plan(batch, shacc_jax.MODES, budget_bytes=4 * per_start, devices=devices)
    assert len(plan.pieces) > 1 and len(plan.devices) == 2
    inside = shacc_jax.execute(plan, batch)
    for name in ("outcome", "activated", "step", "meta_steps", "delta_R", "user"):
        a = np.asarray(getattr(alone.rollouts, name))[0]
        b = np.asarray(getattr(inside.rollouts, name))[1, :, :, : a.shape[2]]
        assert np.array_equal(a, b, equal_nan=True), name
    unshrunk = [i for i, r in enumerate(scenes) if r.C_init == 0]
    assert unshrunk
    ev = jax.tree.map(np.asarray, inside)
    for i in unshrunk:
        assert np.array_equal(ev.rollouts.outcome[i, 0], ev.rollouts.outcome[i, 1])
        assert np.array_equal(ev.rollouts.point[i, 0], ev.rollouts.point[i, 1])


@pytest.mark.slow
def test_the_perfect_user_stepped_with_collision_checks_is_the_closed_form(scenes):
    """With collision checks on (against primitives and, in the last scene, meshes), a
    perfect user's stepped lanes collide where, and only where, the closed form's lane
    pass finds a penetration: the same outcomes, steps and meta steps in every mode, and
    points and path lengths to float32 rounding (as without collision checks).

    Faster twin: tests/test_users.py::test_the_perfect_user_stepped_is_the_closed_form,
    tests/test_users.py::test_stepped_users_agree_with_the_reference (the perfect user
    stepped against the closed form without collision checks; stepped users with
    collision checks against the reference, rollout for rollout)."""
    baked = _bake(scenes, {"collision": "on"})
    assert baked.obj_hull.shape[2] > 0
    closed = _evaluate(baked)
    stepped = _evaluate(baked, stepped_users=True, lanes_per_block=40)
    real = closed.rollouts.outcome != shacc_jax.types.INVALID
    assert (closed.rollouts.outcome == shacc_jax.types.COLLISION).any()
    assert (closed.rollouts.outcome[-1] == shacc_jax.types.COLLISION).any()
    for name in ("outcome", "activated", "step", "meta_steps"):
        a, b = getattr(closed.rollouts, name), getattr(stepped.rollouts, name)
        assert np.array_equal(a[real], b[real]), name
    for name in ("point", "path_length"):
        a, b = getattr(closed.rollouts, name), getattr(stepped.rollouts, name)
        np.testing.assert_array_max_ulp(a[real], b[real], maxulp=2)


def test_user_settings_have_ranges():
    for name, bad in (("user_noise", 10.0), ("user_noise_tau", -1.0), ("user_tremor", 1.0),
                      ("user_tremor_hz", 0.0), ("user_noise", -0.1), ("user_aim", "gaze"),
                      ("user_switch", 1.5), ("user_switch_at", 1.0), ("user_switch_at", 0.0),
                      ("user_input", "2d"), ("user_mode_switch_s", -0.5),
                      ("activation_check", "both")):
        with pytest.raises(InputError, match=name):
            DEFAULTS.with_overrides({name: bad})
    # Imperfect users are checked for collisions; the swept check is not.
    DEFAULTS.with_overrides({"collision": "on", "user_switch": 0.5, "user_aim": "object",
                             "user_input": "modes"})
    with pytest.raises(InputError, match=r"activation_check.*collision"):
        DEFAULTS.with_overrides({"collision": "on", "activation_check": "swept"})
