"""Clusters and Shrinking (reference/model): properties over random scenes."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from geometry_precompute import DEFAULTS, precompute, random_scene
from geometry_precompute.clusters import clusters_from_pairs
from geometry_precompute.intersect import SpaceSet
from geometry_precompute.shapes import Shape
from geometry_precompute.shrinking import shrink
from geometry_precompute.templates import resolve_tasks

IDENT = (1.0, 0.0, 0.0, 0.0)


def test_touching_does_not_count():
    a = Shape("cylinder", (0, 0, 0), IDENT, (0.2, 0.15, 0))
    touching = Shape("cylinder", (0.4, 0, 0), IDENT, (0.2, 0.15, 0))
    overlapping = Shape("cylinder", (0.399, 0, 0), IDENT, (0.2, 0.15, 0))
    assert not SpaceSet([a, touching]).intersects(0, 1)
    assert SpaceSet([a, overlapping]).intersects(0, 1)


def test_clusters_are_components_in_task_order():
    xs = [0.0, 0.3, 0.6, 2.0, 5.0, 5.3]  # chain 0-1-2, single 3, pair 4-5
    shapes = [Shape("cylinder", (x, 0, 0), IDENT, (0.2, 0.15, 0)) for x in xs]
    pairs = SpaceSet(shapes).intersecting_pairs()
    assert pairs == [(0, 1), (1, 2), (4, 5)]
    assert clusters_from_pairs(6, pairs) == [[0, 1, 2], [3], [4, 5]]


def _spaces(seed, kind):
    scene = random_scene(seed, kind, 5, 10)
    return scene, resolve_tasks(scene, DEFAULTS)


@given(st.integers(0, 10_000), st.sampled_from(["uniform", "gaussian"]),
       st.sampled_from([0.05, 0.1, 0.3]))
def test_shrinking_properties(seed, kind, sigma):
    _, spaces = _spaces(seed, kind)
    initial_pairs = SpaceSet([s.shape() for s in spaces]).intersecting_pairs()
    touched = {i for p in initial_pairs for i in p}
    history: list = []
    res = shrink(spaces, sigma, 1000, history=history)
    # Ends within ceil(1 / sigma) passes.
    assert res.iterations <= math.ceil(1 / sigma)
    assert len(history) == res.iterations
    prev = [s.q_init for s in spaces]
    for qs in history:  # never grows, always within [min, init]
        for i, (q, p, s) in enumerate(zip(qs, prev, spaces, strict=True)):
            assert np.all(q <= p + 1e-15), i
            assert np.all(q >= s.q_min - 1e-15) and np.all(q <= s.q_init + 1e-15)
        prev = qs
    for i, (q, s) in enumerate(zip(res.q_opt, spaces, strict=True)):
        if i not in touched:  # a space with no intersection never shrinks
            assert np.array_equal(q, s.q_init)
    for i, j in res.still_intersecting:  # only spaces at their bounds still intersect
        for k in (i, j):
            assert np.allclose(res.q_opt[k], spaces[k].q_min, rtol=0, atol=1e-9)


@given(st.integers(0, 10_000), st.sampled_from(["uniform", "gaussian"]))
def test_c_final_not_above_c_init(seed, kind):
    r = precompute(random_scene(seed, kind, 5, 10))
    assert 0.0 <= r.C_final <= r.C_init + 1e-12
    if r.C_init == 0.0:
        assert r.iterations == 0 and r.shapes_opt == r.shapes_init


def test_c_zero_scene_untouched(shipped_results):
    for r in shipped_results:
        if r.C_init == 0.0:
            assert all(np.array_equal(q, s.q_init)
                       for q, s in zip(r.q_opt, r.spaces, strict=True))


def test_max_iter_caps_passes():
    _, spaces = _spaces(3, "gaussian")
    assert shrink(spaces, 0.05, max_iter=2).iterations <= 2


def test_sigma_one_sends_every_overlapping_space_to_its_minimum():
    _, spaces = _spaces(11, "gaussian")
    touched = {i for p in SpaceSet([s.shape() for s in spaces]).intersecting_pairs() for i in p}
    assert touched
    res = shrink(spaces, 1.0)
    assert res.iterations == 1
    for i, s in enumerate(spaces):
        expected = s.q_min if i in touched else s.q_init
        np.testing.assert_allclose(res.q_opt[i], expected)


def _pseudocode(spaces, sigma, max_iter):
    """Shrinking as the reference writes it: every pass tests every pair with coal's signed
    distance (no closed forms, no skipped tests) on NumPy arrays."""
    from geometry_precompute.intersect import INTERSECT_TOL

    q = [s.q_init.copy() for s in spaces]
    history = []

    def intersecting():
        sets = SpaceSet([s.shape(x) for s, x in zip(spaces, q, strict=True)])
        n = len(spaces)
        return [(i, j) for i in range(n) for j in range(i + 1, n)
                if sets.signed_distance(i, j) < -INTERSECT_TOL]

    iterations = 0
    for _ in range(max_iter):
        overlapping = sorted({i for p in intersecting() for i in p})
        shrinkable = [i for i in overlapping if np.any(
            q[i] - spaces[i].q_min > 1e-9 * (spaces[i].q_init - spaces[i].q_min))]
        if not shrinkable:
            break
        for i in shrinkable:
            s = spaces[i]
            q[i] = np.maximum(s.q_min, q[i] - sigma * (s.q_init - s.q_min))
        iterations += 1
        history.append([x.copy() for x in q])
    return q, iterations, intersecting(), history


@pytest.mark.parametrize("seed, sigma, max_iter", [
    (s, sigma, m) for s in range(6) for sigma, m in ((0.05, 1000), (0.13, 1000), (0.05, 3))])
def test_shrink_equals_the_pseudocode(seed, sigma, max_iter):
    """Bisection over each pair's passes gives the pseudocode's answers, bit for bit:
    parameters, passes, the pairs still intersecting, the history."""
    _, spaces = _spaces(100 + seed, "gaussian" if seed % 2 else "uniform")
    q, iterations, still, history = _pseudocode(spaces, sigma, max_iter)
    assert iterations >= 1  # a scene that shrinks
    got_history: list = []
    res = shrink(spaces, sigma, max_iter, history=got_history)
    assert res.iterations == iterations
    assert [x.tolist() for x in res.q_opt] == [x.tolist() for x in q]
    assert res.still_intersecting == still
    assert [[x.tolist() for x in h] for h in got_history] == [[x.tolist() for x in h]
                                                            for h in history]
