"""collision = "on": the exact gripper check against CPU MuJoCo, designed scenes with
and without a collision on the straight path, the shacc rotation changing the outcome,
and the whole evaluation against the NumPy reference with CPU MuJoCo collisions."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from reference_automaton import OUTCOME_NAMES, Collider, rollout
from scipy.spatial.transform import Rotation
from test_automaton import compare, reference_table, run

import shacc_jax
from geometry_precompute import bake, precompute, scene_from_dict
from geometry_precompute.schema import BOX, CYLINDER
from shacc_jax import automaton as am
from shacc_jax import body_distance as bodies
from shacc_jax import collision as col
from shacc_jax import gripper as grip
from shacc_jax import path_cull as cull
from shacc_jax import stepping
from shacc_jax.types import COLLISION, SUCCESS, Geometry, Params

MODES = {m: i for i, m in enumerate(shacc_jax.MODES)}


def designed(obstacle_y: float, **settings):
    """A mug 0.35 m behind a taskless box standing on the straight line from the
    start pose to the mug's side-grasp space, or beside it (obstacle_y)."""
    scene = scene_from_dict({
        "name": "obstacle",
        "settings": {"collision": "on", "start_orientation": "forward", "start_grid": [1, 1],
                     "start_y_halfwidth": 0.0, "start_z_range": [0.08, 0.08], **settings},
        "objects": [{"id": "mug", "kind": "mug", "position": [0.35, 0.0, 0.0]},
                    {"id": "box", "kind": "box", "position": [0.1, obstacle_y, 0.0],
                     "half_extents": [0.03, 0.08, 0.1]}],
        "tasks": [{"id": "grasp", "object": "mug", "template": "side_grasp"}],
    }, "<designed>")
    return precompute(scene, scene.settings())


def test_gripper_capsules_match_the_reference_layout():
    baked = bake([designed(0.3)])
    ref = Collider(baked, 0)
    rng = np.random.default_rng(3)
    for _ in range(20):
        p, r = rng.normal(size=3) * 0.1, Rotation.random(random_state=rng)
        q = jnp.asarray(np.roll(r.as_quat(), 1), jnp.float32)
        centres, mats, sizes = grip.gripper_geoms(jnp.asarray(p, jnp.float32), q,
                                                 Params.from_bake(baked).gripper()[0])
        ref.deepest(p, r)  # poses the reference capsules
        np.testing.assert_allclose(centres, ref.data.geom_xpos[ref.capsules], atol=1e-6)
        np.testing.assert_allclose(np.abs(mats.reshape(3, 9)),  # the palm's axis sign is free
                                   np.abs(ref.data.geom_xmat[ref.capsules]), atol=1e-6)
        np.testing.assert_allclose(sizes, ref.model.geom_size[ref.capsules, :2], atol=1e-7)


def test_capsule_axes_are_mujocos_capsules():
    """The capsules' definition (``capsule_axes``, elementwise, as the fused pair check
    uses it) against the reference's MuJoCo capsules: each axis runs between the geom's
    centre -/+ half its length along its local z (either way round), with its radius,
    on random poses."""
    baked = bake([designed(0.3)])
    ref = Collider(baked, 0)
    dims = Params.from_bake(baked).gripper()[0]
    rng = np.random.default_rng(5)
    for _ in range(20):
        p, r = rng.normal(size=3) * 0.1, Rotation.random(random_state=rng)
        q = jnp.asarray(np.roll(r.as_quat(), 1), jnp.float32)
        ref.deepest(p, r)  # poses the reference capsules
        for c, (start, extent, radius) in enumerate(
                grip.capsule_axes(jnp.asarray(p, jnp.float32), q, dims)):
            g = ref.capsules[c]
            half = ref.data.geom_xmat[g].reshape(3, 3)[:, 2] * ref.model.geom_size[g, 1]
            lo, hi = ref.data.geom_xpos[g] - half, ref.data.geom_xpos[g] + half
            a, b = np.array(start, float), np.array(start, float) + np.array(extent, float)
            gap = min(max(np.abs(a - lo).max(), np.abs(b - hi).max()),
                      max(np.abs(a - hi).max(), np.abs(b - lo).max()))
            assert gap < 1e-6, (c, a, b, lo, hi)
            np.testing.assert_allclose(float(radius), ref.model.geom_size[g, 0], rtol=1e-6)


def test_penetrations_agree_with_cpu_mujoco():
    """10^5 random gripper poses among two cylinders and a yawed box, against CPU
    MuJoCo's ``mj_geomDistance`` on the same geoms: no penetration deeper than 0.1 mm
    is missed and none is invented, and where MuJoCo finds the gripper clear by less
    than a centimetre its distance is ours to rounding (float32)."""
    scene = scene_from_dict({
        "name": "poses",
        "objects": [{"id": "a", "kind": "mug", "position": [0.0, 0.0, 0.0]},
                    {"id": "b", "kind": "cup", "position": [0.15, 0.0, 0.0]},
                    {"id": "c", "kind": "box", "position": [0.0, 0.2, 0.0], "yaw": 0.4,
                     "half_extents": [0.05, 0.08, 0.04]}],
        "tasks": [{"id": "t", "object": "a", "template": "side_grasp"}],
    }, "<poses>")
    baked = bake([precompute(scene, scene.settings())])
    sc = Geometry.from_bake(baked)
    objects = col.scene_objects(sc.obj_kind[0], sc.obj_center[0], sc.obj_quat[0],
                                sc.obj_size[0], sc.obj_mask[0])
    rng = np.random.default_rng(0)
    n = 100_000
    P = rng.uniform([-0.1, -0.1, 0.0], [0.25, 0.3, 0.15], (n, 3))
    R = Rotation.random(n, random_state=1)
    Q = np.roll(R.as_quat(), 1, axis=1)
    gripper = Params.from_bake(baked).gripper()[0]
    got = np.asarray(jax.jit(jax.vmap(lambda p, q: col.deepest(objects, p, q, gripper)))(
        jnp.asarray(P, jnp.float32), jnp.asarray(Q, jnp.float32)))
    ref = Collider(baked, 0)
    want = np.array([ref.deepest(p, r) for p, r in zip(P, R, strict=True)])
    pen_got, pen_want = got < -col.PENETRATION_EPS, want < -col.PENETRATION_EPS
    assert 0.2 < pen_want.mean() < 0.8  # both kinds of pose are well represented
    assert not (pen_want & ~pen_got).any(), np.flatnonzero(pen_want & ~pen_got)[:5]
    assert not (pen_got & ~pen_want).any(), np.flatnonzero(pen_got & ~pen_want)[:5]
    close = (want > 0) & (want < 0.01)  # the reference skips pairs more than 1 cm apart
    assert close.sum() > 3_000
    np.testing.assert_allclose(got[close], want[close], atol=1e-6)


def test_designed_scene_collides_only_with_the_obstacle_on_the_path():
    blocked, aside = designed(0.0), designed(0.3)
    for result, expect in ((blocked, COLLISION), (aside, SUCCESS)):
        b = bake([result])
        ev = run(b)
        assert (ev.rollouts.outcome[0, :, 0, 0] == expect).all(), ev.rollouts.outcome
        for m, mode in enumerate(shacc_jax.MODES):
            ref = rollout(b, 0, mode, 0, 0)
            assert ref.outcome == ("collision" if expect == COLLISION else "success")
            assert ref.step == ev.rollouts.step[0, m, 0, 0]
    # With collision checking off, the blocked path is a success: the box has no task.
    off = bake([precompute(blocked.scene, blocked.settings.with_overrides(
        {"collision": "off"}))])
    assert (run(off).rollouts.outcome[0, :, 0, 0] == SUCCESS).all()


@pytest.fixture(scope="module")
def colliding(shipped_results):
    picks = [shipped_results[i] for i in (2, 8, 9)]  # tight row, mug behind two, cluster
    rs = [precompute(r.scene, r.settings.with_overrides({"collision": "on"})) for r in picks]
    b = bake(rs)
    return b, run(b)


def test_shacc_rotation_changes_the_collision_outcome(colliding):
    """Shrinking and shacc walk the same straight paths; only shacc turns the gripper in
    meta regions. On these cluttered scenes that turn saves rollouts from collisions
    they have in shrinking (turning towards the target's grasp orientation lines the
    fingers up with the gap); each changed case is confirmed by the reference."""
    b, ev = colliding
    out = ev.rollouts.outcome
    shr, sha = out[:, MODES["shrinking"]], out[:, MODES["shacc"]]
    turned_in = np.argwhere((sha == COLLISION) & (shr != COLLISION))
    turned_out = np.argwhere((shr == COLLISION) & (sha != COLLISION))
    assert len(turned_out) >= 5
    for s, n, t in [*turned_in[:1], *turned_out[:3]]:
        a, c = rollout(b, s, "shrinking", n, t), rollout(b, s, "shacc", n, t)
        assert (a.outcome == "collision") != (c.outcome == "collision")
        assert ev.rollouts.meta_steps[s, MODES["shacc"], n, t] > 0


def test_collision_rollouts_agree_with_reference(colliding):
    """Rollout by rollout against the NumPy Automaton with CPU MuJoCo collisions
    (``mj_geomDistance``): at least 99.9 % identical in outcome and step (here, with
    972 rollouts, every one), and the agreeing ones in everything else too."""
    b, ev = colliding
    ro = ev.rollouts
    table = reference_table(b, [3, 3, 3])
    agree = {key: ref for key, ref in table.items()
             if (OUTCOME_NAMES[ro.outcome[key]], int(ro.step[key])) == (ref.outcome, ref.step)}
    assert len(agree) >= 0.999 * len(table), sorted(set(table) - set(agree))[:5]
    compare(ev, agree, dr_tol=5e-3)
    assert (ro.outcome == COLLISION).sum() > 20


def test_lane_passes_joined_on_a_cpu_give_each_modes_own_rollouts(colliding):
    """On a CPU (stepping.FOLD) the closed form's lane passes run as one: shacc's lanes
    on the scenes, the other modes' on copies without clusters. Shrinking's rollouts
    equal those of a program that evaluates it alone (its own lane pass), bit for bit,
    every field. Shrinking walks shacc's paths, so a copy that kept its clusters would
    turn its gripper in the meta regions and fail. (Baseline activates where it enters
    a cluster member's initial space, so it never has a meta window; shacc's rollouts
    are held to the reference in the test above.)"""
    assert stepping.FOLD["cpu"]
    b, ev = colliding
    alone = run(b, modes=("shrinking",))
    for field in ev.rollouts._fields:
        a = getattr(ev.rollouts, field)[:, MODES["shrinking"]]
        assert np.array_equal(a, getattr(alone.rollouts, field)[:, 0], equal_nan=True), field


def test_mixed_batch_and_no_recompile(count_compiles):
    """Scenes with and without collision checking, and of different object counts, in
    one batch: each scene's rollouts equal its own evaluation's. New object poses and
    gripper sizes reuse the compiled computation."""
    one, two = designed(0.0), designed(0.3, **{"gripper.opening": 0.14})
    off = precompute(one.scene, one.settings.with_overrides({"collision": "off"}))
    b = bake([one, two, off])
    ev = run(b)
    for s, r in enumerate((one, two, off)):
        alone = run(bake([r], max_tasks=1))
        np.testing.assert_array_equal(ev.rollouts.outcome[s], alone.rollouts.outcome[0])
    assert ev.rollouts.outcome[0, 0, 0, 0] == COLLISION
    assert ev.rollouts.outcome[2, 0, 0, 0] == SUCCESS
    moved = bake([designed(0.05), designed(-0.2, **{"gripper.finger_radius": 0.02}), off])
    with count_compiles("evaluate") as found:
        run(moved)
    assert found == []


def test_importing_the_package_starts_no_jax_backend():
    """No module of the package may create a JAX array at import time: a process that
    imports it for anything else would start a backend (on a GPU machine, take most of
    the GPU's memory)."""
    import subprocess
    import sys

    code = ("import sweeps.distributed.runner, shacc_jax, shacc_jax.collision\n"
            "from jax._src import xla_bridge\n"
            "assert not xla_bridge._backends, xla_bridge._backends\n")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_worker_and_scene_modules_import_no_jax_or_collision_library():
    """The precompute workers' module imports nothing from JAX (spawned workers import
    the module of the task they are sent), nor does a sweep's client, and reading a
    scene file imports neither JAX nor coal, trimesh or manifold3d; the JAX half
    imports none of the mesh and collision libraries, nor scipy.spatial (a third of a
    second, which the CPU half imports where it uses it)."""
    import subprocess
    import sys

    from geometry_precompute import shipped_scene_paths

    heavy = "('jax', 'coal', 'trimesh', 'manifold3d')"
    # The sweep's client (runner, cluster, command line) loads no JAX either: only its
    # evaluation workers do.
    code = ("import sys\n"
            "import geometry_precompute.batch, sweeps.distributed.runner\n"
            "import sweeps.distributed.cluster, sweeps.app.cli\n"
            "from geometry_precompute import load_scene\n"
            f"load_scene({str(shipped_scene_paths()[0])!r})\n"
            f"loaded = [m for m in {heavy} if m in sys.modules]\n"
            "assert not loaded, loaded\n"
            "import shacc_jax\n"
            f"loaded = [m for m in {heavy}[1:] if m in sys.modules]\n"
            "assert not loaded, loaded\n")
    subprocess.run([sys.executable, "-c", code], check=True)
    # Alone, it loads neither the mesh libraries nor the CPU half's scene model: of
    # geometry_precompute only the schema and what it needs (errors, the metrics).
    cpu_half = ("'geometry_precompute.loading', 'geometry_precompute.scene', "
                "'geometry_precompute.templates', 'geometry_precompute.precomputing', "
                "'geometry_precompute.baking'")
    alone = ("import sys\nimport shacc_jax\n"
             f"loaded = [m for m in {heavy}[1:] + ('scipy.spatial', {cpu_half}) "
             "if m in sys.modules]\n"
             "assert not loaded, loaded\n")
    subprocess.run([sys.executable, "-c", alone], check=True)


def _point_parallelogram_distance(x, c0, e1, e2):
    """NumPy reference: distance from x to {c0 + a e1 + b e2 : a, b in [0, 1]}, the
    least of the face's interior solution (where it lies inside) and the four edges."""
    best = np.inf
    G = np.array([[e1 @ e1, e1 @ e2], [e1 @ e2, e2 @ e2]])
    if abs(np.linalg.det(G)) > 1e-14:
        a, b = np.linalg.solve(G, [e1 @ (x - c0), e2 @ (x - c0)])
        if 0 <= a <= 1 and 0 <= b <= 1:
            best = np.linalg.norm(c0 + a * e1 + b * e2 - x)
    for start, e in ((c0, e1), (c0 + e2, e1), (c0, e2), (c0 + e1, e2)):
        s = np.clip((x - start) @ e / (e @ e), 0.0, 1.0)
        best = min(best, np.linalg.norm(start + s * e - x))
    return best


@given(seed=st.integers(0, 10_000), parallel=st.booleans())
def test_swept_capsule_interval_is_exact(seed, parallel):
    """The closed-form set of t at which t u comes within rho of a parallelogram (the
    Minkowski difference of two capsule axes) against a dense scan of t with the NumPy
    distance; ``parallel`` makes the two axes parallel (a degenerate face)."""
    rng = np.random.default_rng(seed)
    u = rng.normal(size=3)
    u /= np.linalg.norm(u)
    c0, e1 = rng.uniform(-0.2, 0.2, 3), rng.normal(size=3) * 0.1
    e2 = -0.7 * e1 if parallel else rng.normal(size=3) * 0.1
    rho = rng.uniform(0.01, 0.1)
    lo, hi = (float(v) for v in jax.jit(cull.line_rounded_parallelogram)(
        *(jnp.asarray(a, jnp.float64 if jax.config.x64_enabled else jnp.float32)
          for a in (u, c0, e1, e2, rho))))
    ts = np.linspace(-0.6, 0.6, 2401)
    d = np.array([_point_parallelogram_distance(t * u, c0, e1, e2) for t in ts])
    inside = ts[d <= rho - 1e-5]
    outside = ts[d > rho + 1e-5]
    if inside.size:
        assert lo <= inside.min() and inside.max() <= hi
        assert lo > inside.min() - 1e-3 and hi < inside.max() + 1e-3  # and tight
    assert not ((outside >= lo) & (outside <= hi)).any()


@given(seed=st.integers(0, 10_000))
def test_path_window_holds_every_penetrating_sample(seed):
    """Random objects (cylinders and boxes, any orientation), random straight paths and
    start orientations, half of them axis-aligned (parallel axes, degenerate faces):
    every sample at which the exact check finds the gripper in an object lies in the
    window that ``path_window`` computes in closed form for that object (its tightness
    is the interval's, tested above)."""
    rng = np.random.default_rng(seed)
    O, n, steps = 4, 64, STEPS
    kind = rng.choice([CYLINDER, BOX], O)
    centre = rng.uniform([-0.15, -0.15, 0.0], [0.15, 0.15, 0.1], (O, 3))
    aligned = seed % 2 == 0
    quat = (np.tile([1.0, 0, 0, 0], (O, 1)) if aligned
            else np.roll(Rotation.random(O, random_state=rng).as_quat(), 1, axis=1))
    size = rng.uniform(0.01, 0.08, (O, 3))
    p0 = rng.uniform(-0.3, 0.3, (n, 3))
    if aligned:
        c0 = p0.copy()
        c0[np.arange(n), rng.integers(0, 3, n)] += rng.choice([-0.5, 0.5], n)
        turns = [Rotation.identity(), Rotation.from_euler("x", 90, degrees=True),
                 Rotation.from_euler("y", 90, degrees=True)]
        r0 = np.stack([np.roll(turns[i].as_quat(), 1) for i in rng.integers(0, 3, n)])
    else:
        c0 = rng.uniform(-0.2, 0.2, (n, 3))
        r0 = np.roll(Rotation.random(n, random_state=rng).as_quat(), 1, axis=1)
    first, last, pen = _window_and_penetrations(
        jnp.asarray(kind), *(jnp.asarray(a, jnp.float32) for a in (centre, quat, size, p0, c0, r0)))
    k = np.arange(steps + 1)[None, :, None]  # (path, sample, object)
    inside = (k >= np.asarray(first)[:, None, :]) & (k <= np.asarray(last)[:, None, :])
    pen = np.asarray(pen)
    assert pen.any() and not (pen & ~inside).any()


STEPS = 120


@jax.jit
def _window_and_penetrations(kind, centre, quat, size, p0, c0, r0):
    """Each path's window per object and, at each of its samples, whether the gripper
    (in its start orientation) penetrates each object."""
    gripper = jnp.asarray([0.1, 0.01, 0.08, 0.012], jnp.float32)
    mask = jnp.ones(kind.shape, bool)
    steps = jnp.asarray(float(STEPS), jnp.float32)
    objects = col.scene_objects(kind, centre, quat, size, mask)

    def one(p0, c0, r0):
        diff = c0 - p0
        length = jnp.linalg.norm(diff)
        s = jnp.asarray(0.005, jnp.float32)
        path = am.Path(p0, c0, diff / length, length,
                       jnp.minimum(jnp.ceil(length / s), steps + 1), s)
        first, last = cull.path_window(cull.object_bounds(kind, centre, quat, size), centre,
                                      mask, gripper, r0, path,
                                      jnp.asarray(jnp.inf, jnp.float32), steps)

        def per_object(k):  # (O,): whether the gripper penetrates each object at sample k
            a, d, radius = col.pair_axes(objects, am.sample(path, k), r0, gripper)
            dist = bodies.segment_distance(a, d, kind[None, :], size[None, :, :])
            return jnp.any(dist < radius[:, None] - col.PENETRATION_EPS, axis=0) & mask

        return first, last, jax.vmap(per_object)(jnp.arange(STEPS + 1.0))

    return jax.vmap(one)(p0, c0, r0)



def _np_point_distance(x, kind, size):
    if kind == BOX:
        return float(np.linalg.norm(np.maximum(np.abs(x) - size, 0.0)))
    return float(np.hypot(max(np.hypot(x[0], x[1]) - size[0], 0.0),
                          max(abs(x[2]) - size[1], 0.0)))


def test_segment_distance_searches_find_the_minimum():
    """The segment-to-solid distance's search against a dense sampling of the segment in
    NumPy: never below the true minimum (which lies within the sampling's spacing times
    |d| below the sampled one) and never more than 1e-6 m above the sampled minimum."""
    rng = np.random.default_rng(11)
    n = 200
    a = rng.uniform(-0.15, 0.15, (n, 3))
    d = rng.normal(size=(n, 3)) * rng.uniform(0.01, 0.15, (n, 1))
    kind = rng.choice([CYLINDER, BOX], n)
    size = rng.uniform(0.01, 0.08, (n, 3))
    args = [jnp.asarray(x, jnp.float32) for x in (a, d, kind, size)]
    got = np.asarray(jax.jit(bodies.segment_distance)(*args))
    ts = np.linspace(0.0, 1.0, 4001)
    for i in range(n):
        sampled = min(_np_point_distance(a[i] + t * d[i], kind[i], size[i]) for t in ts)
        floor = sampled - np.linalg.norm(d[i]) * (ts[1] - ts[0]) - 1e-6
        assert floor <= got[i] <= sampled + 1e-6
    assert 0.05 < (got < 1e-9).mean() < 0.5  # some segments touch their object, most not


@pytest.mark.parametrize(("share", "spread"), [(32, 0.2), (32, 0.4), (1, 0.2), (4096, 0.4)])
def test_gathered_search_decides_as_the_direct_check(monkeypatch, share, spread):
    """``first_penetration`` (lower and upper bounds, then the exact search on the pairs
    between them, gathered into rounds) against ``penetrates`` pose by pose, on random
    poses among random objects, with one round for all pairs, the default share, and
    many small rounds; poses spread widely (penetrations rare, most lanes need the
    search) and closely (most lanes collide, many surely)."""
    monkeypatch.setattr(col, "ROUND_SHARE", share)
    rng = np.random.default_rng(share)
    B, W, O = 64, 16, 5
    kind = jnp.asarray(rng.choice([CYLINDER, BOX], (B, O)), jnp.int32)
    centre = jnp.asarray(rng.uniform([-0.15, -0.15, 0.0], [0.15, 0.15, 0.1], (B, O, 3)),
                         jnp.float32)
    quat = jnp.asarray(np.roll(Rotation.random(B * O, random_state=rng).as_quat(), 1, axis=1)
                       .reshape(B, O, 4), jnp.float32)
    size = jnp.asarray(rng.uniform(0.01, 0.08 * 0.2 / spread, (B, O, 3)), jnp.float32)
    mask = jnp.asarray(rng.random((B, O)) < 0.8)
    objects = jax.vmap(col.scene_objects)(kind, centre, quat, size, mask)
    p = jnp.asarray(rng.uniform(-spread, spread, (B, W, 3)), jnp.float32)
    q = jnp.asarray(np.roll(Rotation.random(B * W, random_state=rng).as_quat(), 1, axis=1)
                    .reshape(B, W, 4), jnp.float32)
    dims = jnp.asarray(np.column_stack([rng.uniform(0.05, 0.12, B), rng.uniform(0.005, 0.02, B),
                                        rng.uniform(0.04, 0.12, B), rng.uniform(0.005, 0.02, B)]),
                       jnp.float32)
    live = jnp.asarray(rng.random((B, W)) < 0.9)
    got = np.asarray(jax.jit(col.first_penetration)(objects, p, q, dims, live))
    direct = jax.vmap(jax.vmap(col.penetrates, (None, 0, 0, None)), (0, 0, 0, 0))
    want = np.asarray(jax.jit(direct)(objects, p, q, dims)) & np.asarray(live)
    first = np.where(want.any(axis=1), want.argmax(axis=1), W)
    assert 0.1 < (first < W).mean() and (first > 0).mean() > 0.2
    np.testing.assert_array_equal(got, first)


def test_objects_are_the_exported_mjcf_geoms(shipped_results):
    """The objects the check uses are MuJoCo's geoms of the exported MJCF. Every
    collidable geom of each scene's MJCF (shipped, extra and random scenes), read back by
    MuJoCo, has the bake's kind, size, position and orientation (a cylinder's axis: the
    MJCF turns a cup's cylinder by its yaw, for import-mjcf); and with the gripper's
    capsules added to that loaded model (the reference ``Collider`` from the MJCF),
    MuJoCo's ``mj_geomDistance`` decides penetrations on random poses near the objects
    as ``deepest`` does."""
    import mujoco

    from geometry_precompute import extra_scene_paths, load_scene, random_scene
    from geometry_precompute.mjcf import scene_to_mjcf

    results = [*shipped_results, *(precompute(load_scene(p)) for p in extra_scene_paths()),
               *(precompute(random_scene(seed, "gaussian", 8, 10)) for seed in range(3))]
    baked = bake(results)
    sc = Geometry.from_bake(baked)
    gripper = Params.from_bake(baked).gripper()
    types = {CYLINDER: mujoco.mjtGeom.mjGEOM_CYLINDER, BOX: mujoco.mjtGeom.mjGEOM_BOX}
    deepest = jax.jit(jax.vmap(col.deepest, (None, 0, 0, None)))
    rng = np.random.default_rng(7)
    n = 300
    decided = []
    for s, r in enumerate(results):
        ref = Collider(baked, s, mjcf=scene_to_mjcf(r, spaces="none"))
        model, data = ref.model, ref.data
        ids = [model.geom(f"object:{o.id}").id for o in r.scene.objects]
        assert ids == list(ref.objects) and len(ids) == int(baked.obj_mask[s].sum())
        for o, g in enumerate(ids):
            assert model.geom_type[g] == types[int(baked.obj_kind[s, o])]
            size = baked.obj_size[s, o] if baked.obj_kind[s, o] == BOX else baked.obj_size[s, o, :2]
            np.testing.assert_allclose(model.geom_size[g, :len(size)], size, atol=1e-6)
            np.testing.assert_allclose(data.geom_xpos[g], baked.obj_center[s, o], atol=1e-6)
            got = data.geom_xmat[g].reshape(3, 3)
            want = Rotation.from_quat(np.roll(baked.obj_quat[s, o], -1)).as_matrix()
            if baked.obj_kind[s, o] == CYLINDER:  # turned about its axis: the same solid
                got, want = got[:, 2], want[:, 2]
            np.testing.assert_allclose(got, want, atol=1e-6)
        # Random poses near a random object of the scene, against the loaded model.
        near = baked.obj_center[s, rng.integers(0, len(ids), n)]
        P = near + rng.normal(scale=0.06, size=(n, 3))
        R = Rotation.random(n, random_state=rng)
        objects = col.scene_objects(sc.obj_kind[s], sc.obj_center[s], sc.obj_quat[s],
                                    sc.obj_size[s], sc.obj_mask[s])
        got = np.asarray(deepest(objects, jnp.asarray(P, jnp.float32),
                                 jnp.asarray(np.roll(R.as_quat(), 1, axis=1), jnp.float32),
                                 gripper[s]))
        for i in range(n):
            want = ref.deepest(P[i], R[i])
            if abs(want + col.PENETRATION_EPS) > 1e-5:  # not on the decision's edge
                pen = want < -col.PENETRATION_EPS
                assert (got[i] < -col.PENETRATION_EPS) == pen, (r.scene.name, i, got[i], want)
                decided.append(pen)
    assert len(decided) > 0.99 * n * len(results)
    assert 0.2 < np.mean(decided) < 0.8  # both kinds of pose are well represented


@pytest.mark.slow
def test_collision_rollouts_agree_on_extra_and_random_scenes(mesh_scenes):
    """The extra scenes (a tray, a box, among mugs: every third start) and 100 random scenes
    with mesh objects (3 to 6 tasks, half uniform, half gaussian: every task in every
    mode from one start per scene) against the NumPy Automaton with CPU MuJoCo
    collisions on each scene's exported MJCF (a mesh as MuJoCo takes it: its convex
    hull): at least 99.9 % of the rollouts identical in outcome and step, no
    penetration deeper than 1 mm missed, and collisions with meshes among them.

    Faster twin: tests/test_collision.py::test_collision_rollouts_agree_with_reference,
    tests/test_mesh_collisions.py::test_gripper_near_meshes_agrees_with_cpu_mujoco (the
    rollouts against the same reference on three shipped scenes; the gripper against
    MuJoCo near meshes, pose by pose)."""
    from geometry_precompute import extra_scene_paths, load_scene
    from geometry_precompute.mjcf import scene_to_mjcf

    def checked(scene):
        return precompute(scene, scene.settings().with_overrides({"collision": "on"}))

    extra = [checked(load_scene(p)) for p in extra_scene_paths()]
    rand = mesh_scenes(100)
    assert sum(o.kind == "mesh" for r in rand for o in r.scene.objects) > 150
    results = extra + rand
    b = bake(results)
    assert b.obj_hull.shape[2] > 0
    mjcf = [scene_to_mjcf(r, spaces="none") for r in results]
    ro = run(b).rollouts
    N = b.n_starts
    keys = [(s, m, n, t) for s, r in enumerate(extra) for m in range(len(shacc_jax.MODES))
            for n in range(0, N, 3) for t in range(len(r.spaces))]
    keys += [(s, m, (7 * s) % N, t) for s, r in enumerate(rand, start=len(extra))
             for m in range(len(shacc_jax.MODES)) for t in range(len(r.spaces))]
    differ, with_mesh = [], 0
    for s, m, n, t in keys:
        ref = rollout(b, s, shacc_jax.MODES[m], n, t, mjcf=mjcf[s])
        got = (OUTCOME_NAMES[ro.outcome[s, m, n, t]], int(ro.step[s, m, n, t]))
        if got != (ref.outcome, ref.step):
            differ.append(((s, m, n, t), got, (ref.outcome, ref.step)))
            if ref.outcome == "collision" and got[0] != "collision":
                collider = Collider(b, s, mjcf[s])
                depth = -collider.deepest(ref.point, Rotation.from_quat(np.roll(ref.quat, -1)))
                assert depth < 1e-3, (s, m, n, t, depth)
        elif ref.outcome == "collision":
            collider = Collider(b, s, mjcf[s])
            with_mesh += collider.nearest_kind(
                ref.point, Rotation.from_quat(np.roll(ref.quat, -1))) == "mesh"
    assert len(differ) <= 0.001 * len(keys), differ[:5]
    outcomes = np.array([ro.outcome[k] for k in keys])
    assert (outcomes == COLLISION).mean() > 0.05 and (outcomes == SUCCESS).mean() > 0.2
    assert with_mesh > 20
