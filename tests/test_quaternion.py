"""Quaternions, orientation spaces and the meta skill against scipy and the CPU frames."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from jax_layouts import meta_target, meta_target_yaw, meta_weights
from scipy.spatial.transform import Rotation

from geometry_precompute.frames import frame_from_approach as cpu_frame
from geometry_precompute.schema import is_horizontal_approach
from shacc_jax import quaternion as quat
from shacc_jax import trig
from shacc_jax.meta import yaw_directions
from shacc_jax.orientation import fixed_direction, frame_from_approach, task_orientation
from shacc_jax.shapes import prepare_all
from shacc_jax.types import Spaces


def wxyz(r: Rotation) -> np.ndarray:
    q = r.as_quat()
    return np.concatenate([q[..., 3:], q[..., :3]], axis=-1)


def angle_np(a, b) -> float:
    """Rotation angle between two quaternions, computed stably (2 arcsin of half the
    chord, not arccos of a dot product near 1, which loses half the digits)."""
    a = np.asarray(a, np.float64) / np.linalg.norm(a)
    b = np.asarray(b, np.float64) / np.linalg.norm(b)
    chord = min(np.linalg.norm(a - b), np.linalg.norm(a + b))
    return 4 * np.arcsin(min(1.0, chord / 2))


average = jax.jit(quat.markley_average)


@given(seed=st.integers(0, 10_000), n=st.integers(2, 9))
def test_markley_matches_scipy_mean(seed, n):
    rng = np.random.default_rng(seed)
    rots = Rotation.random(n, rng=rng)
    # Keep the set within a hemisphere-ish spread so the top eigenvalue is well separated
    # (with a degenerate eigenvalue any unit vector of the eigenspace is "the" mean).
    base = Rotation.random(rng=rng)
    rots = base * Rotation.from_rotvec(rots.as_rotvec() * 0.4)
    w = rng.uniform(0.05, 1.0, n)
    signs = rng.choice([-1.0, 1.0], size=(n, 1))  # antipodal inputs: q and -q
    q = wxyz(rots) * signs
    expected = wxyz(rots.mean(weights=w))
    f = jax.jit(quat.markley_average)
    with jax.enable_x64(True):
        got = np.asarray(f(jnp.asarray(q), jnp.asarray(w / w.sum())))
    assert angle_np(got, expected) < 1e-5
    got32 = np.asarray(f(jnp.asarray(q, jnp.float32), jnp.asarray(w / w.sum(), jnp.float32)))
    assert angle_np(got32, expected) < 1e-3


@given(st.integers(0, 10_000))
def test_markley_sign_invariance_and_linear_weights(seed):
    rng = np.random.default_rng(seed)
    q = wxyz(Rotation.random(4, rng=rng))
    w = rng.uniform(0.1, 1.0, 4)
    with jax.enable_x64(True):
        a = np.asarray(average(jnp.asarray(q), jnp.asarray(w)))
        b = np.asarray(average(jnp.asarray(-q), jnp.asarray(3.0 * w)))
    assert angle_np(a, b) < 1e-9


@pytest.mark.parametrize("n", [1, 2, 5])
def test_average_of_copies_is_that_quaternion(n):
    q0 = wxyz(Rotation.from_rotvec([0.3, -1.2, 2.0]))
    qs = np.tile(q0, (n, 1)) * np.array([1, -1, 1, -1, 1][:n])[:, None]
    got = np.asarray(average(jnp.asarray(qs, jnp.float32), jnp.full(n, 1.0 / n, jnp.float32)))
    assert angle_np(got, q0) < 1e-3


def test_zero_weight_is_ignored():
    qs = wxyz(Rotation.from_rotvec([[0, 0, 0.5], [1.0, 0, 0], [0, 2.0, 0]]))
    got = np.asarray(average(jnp.asarray(qs), jnp.array([0.0, 1.0, 0.0])))
    assert angle_np(got, qs[1]) < 1e-5


@given(st.integers(0, 10_000), st.floats(0.01, 0.5))
def test_rotate_towards(seed, step):
    rng = np.random.default_rng(seed)
    a, b = wxyz(Rotation.random(2, rng=rng))
    f = jax.jit(quat.rotate_towards)
    theta = angle_np(a, b)
    out = np.asarray(f(jnp.asarray(a), jnp.asarray(b), step))
    if theta <= step:
        assert angle_np(out, b) < 1e-5
    else:
        assert angle_np(out, a) == pytest.approx(step, abs=1e-4)
        assert angle_np(out, b) == pytest.approx(theta - step, abs=1e-4)  # on the geodesic


def test_rotate_opposite_turns_about_ee_x():
    a = wxyz(Rotation.from_rotvec([0.2, 0.4, -0.3]))
    b = wxyz(Rotation.from_quat(np.r_[a[1:], a[:1]]) * Rotation.from_rotvec([np.pi, 0, 0]))
    out = np.asarray(quat.rotate_towards(jnp.asarray(a), jnp.asarray(b), 0.1))
    ra = Rotation.from_quat(np.r_[a[1:], a[:1]])
    rel = (ra.inv() * Rotation.from_quat(np.r_[out[1:], out[:1]])).as_rotvec()
    np.testing.assert_allclose(rel, [0.1, 0.0, 0.0], atol=1e-5)


turn = jax.jit(lambda a, b, m: quat.turn_towards(a, b, trig.sincos(0.5 * m)))


@given(st.integers(0, 10_000), st.floats(0.0, 3.0), st.sampled_from(["random", "same", "opposite"]))
def test_turn_towards_is_rotate_towards(seed, step, case):
    """The stepped users' form (no arccos, no per-step sine) gives the slerp's point,
    also for equal and opposite orientations (the tie) and for no turn at all."""
    rng = np.random.default_rng(seed)
    a, b = wxyz(Rotation.random(2, rng=rng))
    if case == "same":
        b = a * rng.choice([-1.0, 1.0])
    elif case == "opposite":  # 180 degrees apart: <a, b> = 0
        b = wxyz(Rotation.from_quat(np.r_[a[1:], a[:1]]) * Rotation.from_rotvec([0, np.pi, 0]))
    with jax.enable_x64(True):
        args = (jnp.asarray(a), jnp.asarray(b), jnp.float64(step))
        want = np.asarray(quat.rotate_towards(*args))
        got = np.asarray(turn(*args))
    np.testing.assert_allclose(got, want, atol=1e-12)
    # float32 against float32: at the tie, the rounding of <a, b> and of the relative
    # axis picks the side in both forms alike.
    args = (jnp.asarray(a, jnp.float32), jnp.asarray(b, jnp.float32), jnp.float32(step))
    np.testing.assert_allclose(np.asarray(turn(*args)), np.asarray(quat.rotate_towards(*args)),
                               atol=2e-6)


@given(st.integers(0, 10_000))
def test_from_matrix_round_trip(seed):
    r = Rotation.random(rng=np.random.default_rng(seed))
    q = np.asarray(quat.from_matrix(jnp.asarray(r.as_matrix(), jnp.float32)))
    assert angle_np(q, wxyz(r)) < 1e-3
    np.testing.assert_allclose(np.asarray(quat.to_matrix(jnp.asarray(q))), r.as_matrix(),
                               atol=1e-5)


@given(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1))
def test_frame_from_approach_matches_cpu(x, y, z):
    a = np.array([x, y, z])
    if np.linalg.norm(a) < 1e-3:
        a = np.array([0.0, 0.0, -1.0])
    got = np.asarray(frame_from_approach(jnp.asarray(a, jnp.float32)))
    np.testing.assert_allclose(got, cpu_frame(a), atol=1e-5)


def test_point_to_axis_orientation():
    q_fixed = jnp.array([1.0, 0.0, 0.0, 0.0])
    axis = jnp.array([0.2, -0.1])
    p = jnp.array([-0.3, 0.4, 0.1])
    q = np.asarray(task_orientation(1, q_fixed, axis, p))
    expected = wxyz(Rotation.from_matrix(cpu_frame([0.5, -0.5, 0.0])))
    assert angle_np(q, expected) < 1e-5
    on_axis = np.asarray(task_orientation(1, q_fixed, axis, jnp.array([0.2, -0.1, 0.5])))
    np.testing.assert_allclose(on_axis, q_fixed)
    fixed = np.asarray(task_orientation(0, q_fixed, axis, p))
    np.testing.assert_allclose(fixed, q_fixed)


def _two_cylinders():
    ident = jnp.tile(jnp.array([1.0, 0.0, 0.0, 0.0]), (3, 1))
    init = Spaces(jnp.zeros(3, jnp.int32), jnp.array([[0.0, -0.1, 0.0], [0.0, 0.1, 0.0],
                                                      [5.0, 0.0, 0.0]]),
                  ident, jnp.tile(jnp.array([0.2, 0.2, 0.0]), (3, 1)))
    opt = init._replace(dims=jnp.tile(jnp.array([0.05, 0.2, 0.0]), (3, 1)))
    return init, opt


def test_meta_weights_inverse_square():
    _, opt = _two_cylinders()
    p = jnp.array([-0.15, 0.0, 0.0])
    opt = prepare_all(*opt)
    w = np.asarray(meta_weights(opt, jnp.array([True, True, False]), p))
    d = np.array([np.hypot(0.15, 0.1) - 0.05] * 2)
    expected = (1 / d**2) / np.sum(1 / d**2)
    np.testing.assert_allclose(w[:2], expected, rtol=1e-5)
    assert w[2] == 0.0
    p2 = jnp.array([-0.15, -0.05, 0.0])  # closer to task 0
    w2 = np.asarray(meta_weights(opt, jnp.array([True, True, False]), p2))
    d2 = np.array([np.hypot(0.15, 0.05) - 0.05, np.hypot(0.15, 0.15) - 0.05])
    np.testing.assert_allclose(w2[:2], (1 / d2**2) / np.sum(1 / d2**2), rtol=1e-5)


def test_meta_target_region_and_mask():
    init, opt = (prepare_all(*s) for s in _two_cylinders())
    orient = (jnp.ones(3, jnp.int32), jnp.tile(jnp.array([1.0, 0, 0, 0]), (3, 1)),
              jnp.array([[0.0, -0.1], [0.0, 0.1], [5.0, 0.0]]))
    cluster = jnp.array([0, 0, -1])
    mask = jnp.array([True, True, True])
    inside, q = meta_target(init, opt, mask, cluster, orient, jnp.array([-0.15, 0.0, 0.0]), 1e-4)
    assert bool(inside)
    # Symmetric point: the average of the two point-to-axis frames looks along +x.
    expected = wxyz(Rotation.from_matrix(cpu_frame([1.0, 0.0, 0.0])))
    assert angle_np(np.asarray(q), expected) < 1e-4
    outside, _ = meta_target(init, opt, mask, cluster, orient, jnp.array([-0.5, 0.0, 0.0]), 1e-4)
    assert not bool(outside)
    # Masking task 1 removes it from the average: the target is task 0's frame.
    inside, q = meta_target(init, opt, jnp.array([True, False, True]), cluster, orient,
                            jnp.array([-0.15, 0.0, 0.0]), 1e-4)
    expected0 = wxyz(Rotation.from_matrix(cpu_frame([0.15, -0.1, 0.0])))
    assert bool(inside) and angle_np(np.asarray(q), expected0) < 1e-4


@given(yaw=st.floats(-np.pi, np.pi), tilt=st.floats(0.05, 1.5))
def test_fixed_direction_recognises_horizontal_frames(yaw, tilt):
    """A horizontal approach frame is yaw(psi) * q_forward: its direction comes back as
    (cos psi, sin psi). A frame approaching at a tilt is not one."""
    a = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    q = jnp.asarray(wxyz(Rotation.from_matrix(cpu_frame(a))))
    d, is_yaw = fixed_direction(q)
    assert bool(is_yaw)
    np.testing.assert_allclose(np.asarray(d), a[:2], atol=1e-6)
    tilted = np.array([np.cos(yaw) * np.cos(tilt), np.sin(yaw) * np.cos(tilt), -np.sin(tilt)])
    _, tilted_yaw = fixed_direction(jnp.asarray(wxyz(Rotation.from_matrix(cpu_frame(tilted)))))
    assert not bool(tilted_yaw)


def _yaw_cluster_scene(rng: np.random.Generator, T: int = 7):
    """T random cylinders and cones near the origin, in two clusters plus an unclustered
    and a masked task; orientation spaces point-to-axis or fixed horizontal frames."""
    kinds = rng.choice([0, 2], T)
    centers = rng.uniform(-0.15, 0.15, (T, 3))
    quats = wxyz(Rotation.random(T, random_state=rng))
    dims = np.stack([rng.uniform(0.05, 0.2, T), np.where(kinds == 2, rng.uniform(0.2, 0.5, T),
                                                         rng.uniform(0.05, 0.3, T)),
                     np.zeros(T)], axis=1)
    init = Spaces(jnp.asarray(kinds, jnp.int32), jnp.asarray(centers), jnp.asarray(quats),
                  jnp.asarray(dims))
    opt = init._replace(dims=init.dims * jnp.asarray([[0.6, 1.0, 1.0]]))
    cluster = np.array(([0, 1] * T)[:T])
    cluster[-2] = -1
    mask = np.ones(T, bool)
    mask[-1] = False
    yaws = rng.uniform(-np.pi, np.pi, T)
    q_fixed = np.stack([wxyz(Rotation.from_matrix(cpu_frame([np.cos(y), np.sin(y), 0.0])))
                        for y in yaws])
    orient = (jnp.asarray(rng.integers(0, 2, T), jnp.int32), jnp.asarray(q_fixed),
              jnp.asarray(centers[:, :2] + rng.normal(0, 0.02, (T, 2))))
    return prepare_all(*init), prepare_all(*opt), jnp.asarray(mask), jnp.asarray(cluster), orient


_general_targets = jax.jit(jax.vmap(meta_target, in_axes=(None,) * 5 + (0, None)))
_closed_targets = jax.jit(jax.vmap(meta_target_yaw, in_axes=(None,) * 7 + (0, None)))


@given(seed=st.integers(0, 10_000))
def test_meta_target_yaw_equals_markley_average(seed):
    """The closed form for horizontal approach frames gives the general Markley target
    (float64: to the resolution of the angle), at random points, on task axes, in
    regions of either cluster and outside."""
    rng = np.random.default_rng(seed)
    with jax.enable_x64(True):
        init, opt, mask, cluster, orient = _yaw_cluster_scene(rng)
        pts = rng.uniform(-0.35, 0.35, (300, 3))
        pts[:5, :2] = np.asarray(orient[2])[:5]  # on point-to-axis axes
        pts = jnp.asarray(pts)
        fixed_dir, is_yaw = yaw_directions(orient[1])
        assert bool(is_yaw.all())
        general = _general_targets(init, opt, mask, cluster, orient, pts, 1e-4)
        closed = _closed_targets(init, opt, mask, cluster, orient[0], fixed_dir, orient[2], pts,
                                 1e-4)
    np.testing.assert_array_equal(np.asarray(general[0]), np.asarray(closed[0]))
    assert np.asarray(general[0]).any()
    worst = max(angle_np(a, b)
                for a, b in zip(np.asarray(general[1]), np.asarray(closed[1]), strict=True))
    assert worst < 1e-6, worst


def test_horizontal_frames_are_told_apart_alike_on_both_halves():
    """The bake's test (which decides the layout's meta formula) and the JAX half's
    (which gives the closed form its directions) agree: side frames in every yaw are
    horizontal approach frames, a top grasp and tilted frames are not."""
    rng = np.random.default_rng(5)
    quats = [wxyz(Rotation.from_matrix(cpu_frame([np.cos(a), np.sin(a), 0.0])))
             for a in rng.uniform(-np.pi, np.pi, 20)]
    quats += [wxyz(Rotation.from_matrix(cpu_frame([0.0, 0.0, -1.0]))),
              wxyz(Rotation.from_matrix(cpu_frame([1.0, 0.0, 0.3])))]
    quats.append(wxyz(Rotation.random(random_state=rng)))
    with jax.enable_x64(True):
        _, is_yaw = yaw_directions(jnp.asarray(np.stack(quats)))
    assert np.asarray(is_yaw).tolist() == [True] * 20 + [False] * 3
    assert [is_horizontal_approach(q) for q in quats] == [True] * 20 + [False] * 3
