"""The fast intersection volumes (geometry_precompute/overlap.py) against exact
volumes, plain numerical integration, Monte Carlo and fine mesh booleans; and the
precompute against its recorded boolean-era answers (tests/data)."""

from __future__ import annotations

import hashlib
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial.transform import Rotation

from geometry_precompute import DEFAULTS, precompute, random_scene
from geometry_precompute.clusters import clusters_from_pairs
from geometry_precompute.clutteredness import clutteredness, overlap_volumes
from geometry_precompute.frames import (
    frame_from_approach,
    quat_from_matrix,
    quat_of_approach,
    quat_of_rotation,
    random_quats,
)
from geometry_precompute.meshes import shape_manifold
from geometry_precompute.overlap import disk_rect_area, fast_volumes, lens_area, pair_kind
from geometry_precompute.shapes import Shape

DATA = Path(__file__).parent / "data"
IDENT = (1.0, 0.0, 0.0, 0.0)


def level_cone(apex, yaw, length=0.2, alpha=0.4):
    q = tuple(quat_from_matrix(frame_from_approach((math.cos(yaw), math.sin(yaw), 0.0))))
    return Shape("cone", tuple(apex), q, (length, alpha, 0.0))


def upright(center, r, h, kind="cylinder"):
    return Shape(kind, tuple(center), IDENT, (r, h, 0.0))


def boolean(a: Shape, b: Shape, sections: int = 512) -> float:
    return (shape_manifold(a, sections) ^ shape_manifold(b, sections)).volume()


def test_lens_area_exact_cases():
    assert lens_area(0.1, 0.2, 0.31) == 0.0
    assert lens_area(0.1, 0.2, 0.05) == pytest.approx(math.pi * 0.01, rel=1e-14)
    r, d = 0.1, 0.12  # two equal circles: 2 r^2 acos(d / 2r) - d/2 sqrt(4r^2 - d^2)
    exact = 2 * r * r * math.acos(d / (2 * r)) - d / 2 * math.sqrt(4 * r * r - d * d)
    assert lens_area(r, r, d) == pytest.approx(exact, rel=1e-13)


@given(st.floats(0.01, 1.0), st.floats(-1.2, 1.2), st.floats(0.0, 1.0),
       st.floats(-1.2, 1.2), st.floats(0.0, 1.0))
def test_disk_rect_area_against_integration(r, x0, w, y0, h):
    x1, y1 = x0 + w, y0 + h
    lo, hi = max(x0, -r), min(x1, r)
    x = np.linspace(lo, max(hi, lo), 200_001)
    s = np.sqrt(np.maximum(r * r - x * x, 0.0))
    ref = np.trapezoid(np.clip(np.minimum(y1, s) - np.maximum(y0, -s), 0.0, None), x)
    assert disk_rect_area(r, x0, x1, y0, y1) == pytest.approx(ref, abs=2e-6 * r * r)


def test_cone_cylinder_containment_is_exact():
    cone = level_cone((0.0, 0.0, 0.1), 0.7)
    small = upright((0.15 * math.cos(0.7), 0.15 * math.sin(0.7), 0.1), 0.01, 0.02)
    vol, rest = fast_volumes([cone, small], [(0, 1)])
    assert rest == [] and vol[(0, 1)] == pytest.approx(small.volume(), rel=1e-7)
    big = upright((0.0, 0.0, 0.1), 0.5, 0.4)
    vol, _ = fast_volumes([big, cone], [(0, 1)])
    assert vol[(0, 1)] == pytest.approx(cone.volume(), rel=1e-7)


@given(st.floats(-0.25, 0.25), st.floats(-0.25, 0.25), st.floats(0.0, 0.12),
       st.floats(-math.pi, math.pi), st.floats(0.03, 0.12), st.floats(0.05, 0.3),
       st.floats(0.1, 0.3), st.floats(0.15, 0.6))
def test_cone_cylinder_against_fine_booleans(x, y, zc, yaw, r, h, length, alpha):
    cone = level_cone((0.0, 0.0, 0.08), yaw, length, alpha)
    cyl = upright((x, y, zc), r, h)
    assert pair_kind(cone, cyl) == "cone_cyl"
    vol, _ = fast_volumes([cone, cyl], [(0, 1)])
    # The 512-gon boolean is itself off by about 1e-6 of the volume.
    assert vol[(0, 1)] == pytest.approx(boolean(cone, cyl), rel=2e-5, abs=1e-10)


def test_cone_cylinder_with_breaks_close_together():
    """The top edge's chord starts 0.5 mm before a corner crosses the circle: a branch
    point just outside the next piece (found by hypothesis; 8 nodes erred by 2.5e-5)."""
    cone = level_cone((0.0, 0.0, 0.08), 0.0, 0.25, 0.375)
    cyl = upright((0.0625, 0.0625, 0.0), 0.0625, 0.125)
    vol, _ = fast_volumes([cone, cyl], [(0, 1)])
    # 4096-gon booleans give 1.2608646806e-05 (1024: ...6806, 2048: ...6805).
    assert vol[(0, 1)] == pytest.approx(boolean(cone, cyl, 4096), rel=2e-6)


def test_cone_cylinder_against_monte_carlo():
    cone = level_cone((0.0, -0.2, 0.05), math.pi / 2, 0.3, math.radians(30))
    cyl = upright((0.0, 0.05, 0.075), 0.2, 0.15)
    vol = fast_volumes([cone, cyl], [(0, 1)])[0][(0, 1)]
    lo, hi = cone.aabb()
    pts = np.random.default_rng(3).uniform(lo, hi, size=(2_000_000, 3))
    loc = (pts - np.asarray(cone.center)) @ cone.rotation
    in_cone = (loc[:, 2] >= 0) & (loc[:, 2] <= 0.3) & (
        np.hypot(loc[:, 0], loc[:, 1]) <= loc[:, 2] * math.tan(math.radians(30)))
    in_cyl = (np.hypot(pts[:, 0], pts[:, 1] - 0.05) <= 0.2) & (np.abs(pts[:, 2] - 0.075) <= 0.075)
    p = np.mean(in_cone & in_cyl)
    box = float(np.prod(hi - lo))
    se = box * math.sqrt(p * (1 - p) / len(pts))
    assert abs(vol - box * p) <= 4 * se


@given(st.floats(-0.25, 0.25), st.floats(-0.25, 0.25), st.floats(-math.pi, math.pi),
       st.floats(-math.pi, math.pi), st.floats(0.08, 0.25), st.floats(0.08, 0.25),
       st.floats(0.15, 0.6), st.floats(0.15, 0.6))
def test_cone_cone_against_fine_booleans(x, y, yaw1, yaw2, len1, len2, alpha1, alpha2):
    a = level_cone((0.0, 0.0, 0.05), yaw1, len1, alpha1)
    b = level_cone((x, y, 0.05), yaw2, len2, alpha2)
    assert pair_kind(a, b) == "cone_cone"
    vol, _ = fast_volumes([a, b], [(0, 1)])
    assert vol[(0, 1)] == pytest.approx(boolean(a, b, 1024), rel=2e-5, abs=1e-10)


@pytest.mark.parametrize("apex, yaw", [
    ((0.0, 0.0), 0.3),                  # identical
    ((0.05, 0.01), 0.0),                # parallel, apex inside: the second cone, cut
    ((0.2, 0.01), math.pi),             # facing each other
    ((0.1, -0.1), math.pi / 2),         # crossing at right angles
    ((0.2, 0.2), 0.0),                  # apart
])
def test_cone_cone_special_positions(apex, yaw):
    a = level_cone((0.0, 0.0, 0.05), 0.0 if yaw != 0.3 else 0.3)
    b = level_cone((*apex, 0.05), yaw)
    exact = {0.3: a.volume()}.get(yaw)
    if apex == (0.05, 0.01):  # b inside a up to a's base plane, 0.05 short of b's
        exact = math.pi / 3 * (0.15 * math.tan(0.4)) ** 2 * 0.15
    ref = exact if exact is not None else boolean(a, b, 1024)
    for first, second in ((a, b), (b, a)):
        vol = fast_volumes([first, second], [(0, 1)])[0][(0, 1)]
        assert vol == pytest.approx(ref, rel=2e-5, abs=1e-12)


def test_other_pairs_go_to_the_boolean():
    cone_a, cone_b = level_cone((0, 0, 0.05), 0.0), level_cone((0.05, 0.02, 0.06), 0.5)
    box = Shape("box", (0.05, 0.0, 0.05), IDENT, (0.05, 0.05, 0.05))
    tilted = Shape("cylinder", (0.0, 0.0, 0.05),
                   tuple(quat_from_matrix(Rotation.from_rotvec([0.3, 0, 0]).as_matrix())),
                   (0.05, 0.1, 0.0))
    shapes = [cone_a, cone_b, box, tilted]
    pairs = [(i, j) for i in range(4) for j in range(i + 1, 4)]
    vol, rest = fast_volumes(shapes, pairs)
    assert vol == {} and rest == pairs
    fast = overlap_volumes(shapes, 32, pairs)[1]
    slow = overlap_volumes(shapes, 32, pairs, method="boolean")[1]
    assert fast == slow


def test_fast_clutteredness_invariant_under_yaw_and_translation():
    shapes = [upright((0.0, 0.0, 0.075), 0.2, 0.15), upright((0.0, 0.25, 0.075), 0.2, 0.15),
              level_cone((0.1, -0.1, 0.05), 1.0)]
    rot = Rotation.from_rotvec([0.0, 0.0, 0.9])
    moved = []
    for s in shapes:
        c = rot.apply(s.center) + np.array([0.3, -0.2, 0.1])
        q = quat_from_matrix((rot * Rotation.from_matrix(s.rotation)).as_matrix())
        moved.append(Shape(s.kind, tuple(c), tuple(q), s.dims))
    assert [pair_kind(moved[0], m) for m in moved[1:]] == ["cyl_cyl", "cyl_cone"]
    assert clutteredness(moved) == pytest.approx(clutteredness(shapes), rel=1e-9)


def _cross_frame(a):
    """frame_from_approach as it was written with NumPy (the reference)."""
    a = np.asarray(a, dtype=np.float64)
    z = a / np.linalg.norm(a)
    u = np.array([1.0, 0.0, 0.0]) if abs(z[2]) > 0.99 else np.array([0.0, 0.0, 1.0])
    x = np.cross(u, z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


def test_frames_equal_to_numpy_and_scipy():
    """The frames written out in floats equal NumPy's to two units in the last place
    (entries lie in [-1, 1]): bit for bit on most processors, but on AVX-512 ones
    OpenBLAS runs np.linalg.norm's dot product with a kernel that rounds differently
    (with OPENBLAS_CORETYPE=Haswell they agree bit for bit again). The quaternions equal
    scipy's bit for bit."""
    rng = np.random.default_rng(0)
    yaws = rng.uniform(-4, 4, 5000)
    dirs = np.concatenate([np.stack([np.cos(yaws), np.sin(yaws), 0 * yaws], 1),
                           rng.normal(size=(15_000, 3))])
    ours = np.stack([frame_from_approach(a) for a in dirs])
    numpy_way = np.stack([_cross_frame(a) for a in dirs])
    np.testing.assert_allclose(ours, numpy_way, rtol=0, atol=2 * np.finfo(np.float64).eps)
    mats = np.concatenate([np.stack([frame_from_approach(a) for a in dirs[::50]]),
                           Rotation.random(2000, rng=1).as_matrix()])
    # quat_from_matrix skips scipy's check that the matrices are rotations: the same
    # quaternions (w first, w >= 0) as scipy's checked conversion, bit for bit.
    xyzw = Rotation.from_matrix(mats).as_quat()
    checked = np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1)
    checked = np.where(checked[:, :1] < 0, -checked, checked)
    assert np.array_equal(quat_from_matrix(mats), checked)
    mats = np.concatenate([mats, Rotation.random(20_000, rng=2).as_matrix(),
                           [np.eye(3), frame_from_approach((0.0, 0.0, -1.0))]])
    for m in mats:
        assert quat_of_rotation(m) == tuple(quat_from_matrix(m))


@given(st.integers(1, 300), st.integers(0, 2**63 - 1), st.integers(0, 5))
def test_random_quats_are_scipys_random_rotations(n, seed, before):
    """The start orientations without scipy: the same quaternions as scipy's
    Rotation.random through quat_from_matrix, bit for bit, from a generator already
    drawn from (the search's starts draw their positions first), and the generator left
    where scipy leaves it."""
    ours, theirs = np.random.default_rng(seed), np.random.default_rng(seed)
    assert np.array_equal(ours.random(before), theirs.random(before))
    got = random_quats(n, ours)
    want = quat_from_matrix(Rotation.random(n, rng=theirs).as_matrix())
    assert got.shape == (n, 4) and got.dtype == np.float64
    assert np.array_equal(got, want)
    assert ours.random() == theirs.random()
    assert quat_of_approach((1.0, 0.0, 0.0)) == tuple(quat_from_matrix(
        frame_from_approach((1.0, 0.0, 0.0))))


@given(st.integers(1, 14), st.lists(st.tuples(st.integers(0, 13), st.integers(0, 13)),
                                    max_size=30))
def test_clusters_match_scipy(n, edges):
    pairs = [(min(i, j), max(i, j)) for i, j in edges if i < n and j < n and i != j]
    graph = coo_matrix((np.ones(len(pairs)), ([p[0] for p in pairs], [p[1] for p in pairs])),
                       shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    expected = sorted(([i for i in range(n) if labels[i] == lab] for lab in set(labels)),
                      key=lambda c: c[0])
    assert clusters_from_pairs(n, pairs) == expected


# --- the precompute against its recorded answers (issue 15) -------------------------

@pytest.fixture(scope="module")
def recorded():
    sys.path.insert(0, str(DATA))
    try:
        from make_precompute_reference import scenes
    finally:
        sys.path.remove(str(DATA))
    ref = json.loads((DATA / "precompute_reference.json").read_text())
    return [(key, sc, ref[key]) for key, sc in scenes()]


def test_cache_key_names_the_precompute_version(monkeypatch):
    """Results cached before the fast volumes are computed again, not mixed in."""
    import geometry_precompute.cache as cache

    sc = random_scene(3, "uniform", 3, 3)
    key = cache.scene_key(sc, DEFAULTS)
    monkeypatch.setattr(cache, "PRECOMPUTE_VERSION", 1)
    assert cache.scene_key(sc, DEFAULTS) != key


def test_generator_output_is_the_versioned_one():
    """The precompute cache keys random scenes by their arguments and GENERATOR_VERSION:
    if this digest changes, so did the scenes a seed gives; raise the version (and
    update the digest) so that no cached result of an older scene is read."""
    from geometry_precompute.generate import GENERATOR_VERSION
    from geometry_precompute.scene import scene_to_dict

    scenes = [scene_to_dict(random_scene(i, k, 2, 12)) for i in range(4)
              for k in ("uniform", "gaussian")]
    digest = hashlib.sha256(json.dumps(scenes, sort_keys=True, default=str).encode())
    assert (GENERATOR_VERSION, digest.hexdigest()) == (
        1, "397f7cc60987b1df040ffc289fa26f109934bf1308aee49154235b210a7116d0")


def test_random_scenes_are_cached_by_their_arguments(tmp_path, monkeypatch):
    """A warm cache answers a random scene's arguments without building the scene, with
    the result of the scene those arguments give; the key names the generator's and the
    precompute's versions and the precompute settings."""
    import geometry_precompute.cache as cache

    ref = (7, "gaussian", 4, 6)
    first, hit, _ = cache.cached(ref, DEFAULTS, tmp_path)
    assert not hit
    monkeypatch.setattr(cache, "random_scene", None)  # building a scene would fail now
    again, hit, _ = cache.cached(ref, DEFAULTS, tmp_path)
    assert hit and again.scene == random_scene(*ref) == first.scene
    assert [list(map(float, q)) for q in again.q_opt] == [list(map(float, q)) for q in first.q_opt]
    assert again.C_final == first.C_final
    key = cache.random_key(ref, DEFAULTS)
    assert cache.random_key(ref, DEFAULTS.with_overrides({"shrink_step": 0.004})) != key
    assert cache.random_key(ref, DEFAULTS.with_overrides({"v_max": 0.1})) == key
    monkeypatch.setattr(cache, "GENERATOR_VERSION", 0)
    assert cache.random_key(ref, DEFAULTS) != key


def test_recorded_scenes_cover_the_set(recorded):
    assert len(recorded) == 213
    assert sum(key.startswith("random:") for key, _, _ in recorded) == 200


def test_precompute_answers_unchanged(recorded):
    """Clusters and Shrinking (parameters to the last bit, iterations, pairs that still
    intersect) equal those recorded from the boolean implementation; C is within 0.002
    of 128-section booleans and, over the set, closer to them than 32-section
    booleans are."""
    err = {"init": [], "final": []}
    err32 = {"init": [], "final": []}
    for key, sc, d in recorded:
        r = precompute(sc, sc.settings())
        assert r.clusters == d["clusters"], key
        assert [[float(v) for v in q] for q in r.q_opt] == d["q_opt"], key
        assert r.iterations == d["iterations"], key
        assert [list(p) for p in r.still_intersecting] == d["still_intersecting"], key
        for k, c in (("init", r.C_init), ("final", r.C_final)):
            assert abs(c - d[f"C_{k}_128"]) <= 0.002, key
            err[k].append(abs(c - d[f"C_{k}_128"]))
            err32[k].append(abs(d[f"C_{k}_32"] - d[f"C_{k}_128"]))
    for k in err:
        assert max(err[k]) < max(err32[k]) and np.mean(err[k]) < np.mean(err32[k]) / 5, k


def test_cached_start_draws_equal_the_generator():
    """The start orientations and search starts, drawn once per process, equal drawing
    them from a new generator each time (numpy's uniform is lo + (hi - lo) u)."""
    from geometry_precompute.starts import optimize_start_poses, start_orientations, start_plane

    for i in range(30):
        sc = random_scene(i, "uniform", 2, 12)
        s = DEFAULTS.with_overrides({"optimize_seed": i % 4, "seed": i % 3,
                                     "optimize_starts": 1 + i, "start_grid": [2 + i % 3, 3],
                                     "start_orientation": "forward" if i % 5 == 0 else "random"})
        n = s["optimize_starts"]
        rng = np.random.default_rng(s["optimize_seed"])
        x, (y0, y1), (z0, z1) = start_plane(sc, s)
        pts = np.stack([np.full(n, x), rng.uniform(y0, y1, n), rng.uniform(z0, z1, n)], 1)
        if s["start_orientation"] == "forward":
            q = np.tile(quat_from_matrix(frame_from_approach((1.0, 0.0, 0.0))), (n, 1))
            q0 = np.tile(q[0], (s["start_grid"][0] * 3, 1))
        else:
            q = quat_from_matrix(Rotation.random(n, rng=rng).as_matrix())
            q0 = quat_from_matrix(Rotation.random(
                s["start_grid"][0] * 3, rng=np.random.default_rng(s["seed"])).as_matrix())
        assert np.array_equal(optimize_start_poses(sc, s), np.concatenate([pts, q], 1))
        assert np.array_equal(start_orientations(s), q0)


def test_a_precompute_task_keeps_its_batch_as_arrays(tmp_path, monkeypatch):
    """A precompute task's second run reads its bakes from one array file of the cache,
    the same bits as the first run's, without the scenes' entries (nor any bake); a
    damaged or foreign file is a miss and is written again; other points, another
    key."""
    import geometry_precompute.batch as batch
    from geometry_precompute import load_scene, shipped_scene_paths

    refs = [(3, "uniform", 3, 4), (4, "gaussian", 3, 4), load_scene(shipped_scene_paths()[0])]
    points = [{}, {"v_max": 0.3}]

    def run(pts=points):
        return batch.precompute_batch(refs, pts, str(tmp_path), 4, 4)

    # Another version's entries: one unused for two days (removed by the first store),
    # one used an hour ago (kept).
    stale, recent = tmp_path / "batch-0000000000000000-a.npz", tmp_path / "batch-1-b.npz"
    for path, age in ((stale, 2 * 86400), (recent, 3600)):
        path.write_bytes(b"old")
        os.utime(path, (time.time() - age, time.time() - age))
    first = run()
    assert (first.precomputed, first.cache_hits) == (3, 0)
    assert not stale.exists() and recent.exists()
    recent.unlink()
    (entry,) = tmp_path.glob("batch-*.npz")
    for scene_entry in tmp_path.glob("*.json"):
        scene_entry.unlink()
    monkeypatch.setattr(batch, "bake_batch", None)  # baking would fail now
    again = run()
    assert (again.precomputed, again.cache_hits) == (0, 3)
    assert again.scenes == first.scenes and again.scene_warnings == first.scene_warnings
    for a, b in zip(first.bakes, again.bakes, strict=True):
        assert a.arrays().keys() == b.arrays().keys()
        for k, x in a.arrays().items():
            y = b.arrays()[k]
            assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), k
        assert a.labels["names"] == b.labels["names"]
        assert a.labels["task_ids"] == b.labels["task_ids"]
        assert a.labels["C_init"].tolist() == b.labels["C_init"].tolist()
    assert again.bakes[1].v_max.tolist() == [0.3] * 3  # each point its own bake
    monkeypatch.undo()

    good = entry.read_bytes()
    for damaged in (good[:len(good) // 2], good[:-1] + bytes([good[-1] ^ 1])):
        entry.write_bytes(damaged)
        for scene_entry in tmp_path.glob("*.json"):
            scene_entry.unlink()
        assert run().precomputed == 3  # a miss: without the scenes' entries, computed
        assert entry.read_bytes() == good
    other = run([{"omega_max": 1.0}])
    assert other.precomputed == 0 and len(list(tmp_path.glob("batch-*.npz"))) == 2
    foreign = next(p for p in tmp_path.glob("batch-*.npz") if p != entry)
    entry.write_bytes(foreign.read_bytes())  # another key's entry under this name
    assert run().precomputed == 0 and entry.read_bytes() == good  # rebuilt from the scenes


def test_a_cache_folder_loses_only_other_versions_files_unused_for_a_day(tmp_path):
    """``fileio.prune_stale`` removes the files of the pattern that another version of
    the code wrote and nothing used for a day; its own version's, recent ones and other
    names stay; reading a file (``mark_used``) keeps it; it looks once per process and
    folder."""
    from geometry_precompute import fileio

    now, day = time.time(), fileio.STALE_AFTER_S
    ages = {"batch-aaaa-k1.npz": 2 * day, "batch-bbbb-k2.npz": 2 * day,
            "batch-bbbb-k3.npz": day - 600, "scene-bbbb-k4.npz": 2 * day,
            "batch-cccc-k5.npz": 2 * day}
    for name, age in ages.items():
        (tmp_path / name).write_bytes(b"x")
        os.utime(tmp_path / name, (now - age, now - age))
    fileio.mark_used(tmp_path / "batch-cccc-k5.npz")  # read just now
    assert fileio.prune_stale(tmp_path, "batch-*.npz", "aaaa") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "batch-aaaa-k1.npz", "batch-bbbb-k3.npz", "batch-cccc-k5.npz", "scene-bbbb-k4.npz"]
    os.utime(tmp_path / "batch-cccc-k5.npz", (now - 2 * day, now - 2 * day))
    assert fileio.prune_stale(tmp_path, "batch-*.npz", "aaaa") == 0  # looked already
    assert fileio.prune_stale(tmp_path, "batch-*.npz", "aaaa", once=False) == 1
    assert not (tmp_path / "batch-cccc-k5.npz").exists()


def test_a_batch_entry_that_is_not_valid_is_not_marked_used(tmp_path):
    """Reading a sealed batch entry that is not one of this format (another layout
    under the right key) is a miss and leaves its modification time alone, so that
    pruning may take it."""
    from geometry_precompute import batch_cache, fileio

    key = "k" * 16
    path = batch_cache.path_of(tmp_path, key)
    path.write_bytes(fileio.seal(key, b"not an npz of ours"))
    old = time.time() - 3 * fileio.STALE_AFTER_S
    os.utime(path, (old, old))
    assert batch_cache.read(tmp_path, key, 1, 1) is None
    assert path.stat().st_mtime == pytest.approx(old, abs=1)
