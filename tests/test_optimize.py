"""The optimized mode (reference/model): spaces built from parameter vectors, the
search against brute force, its bounds and held-out starts, the plain NumPy Automaton
on the spaces it found, and the command line."""

from __future__ import annotations

import json
from dataclasses import replace

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from reference_automaton import OUTCOME_NAMES, rollout

from geometry_precompute import (
    InputError,
    bake,
    extra_scene_paths,
    load_scene,
    precompute,
    scene_from_dict,
    shipped_scene_paths,
)
from shacc_jax import optimize
from shacc_jax.optimize import cut, objective, optimized_spaces, search, spaces_at
from shacc_jax.runplan import run, search_scenes_per_call
from shacc_jax.types import Geometry, Params, SearchProblem
from sweeps.app.cli import main

SMALL = {"optimize_population": 8, "optimize_generations": 4, "optimize_starts": 16}


@pytest.fixture(scope="module")
def small_search(shipped_results):
    results = [precompute(r.scene, r.settings.with_overrides(SMALL)) for r in shipped_results]
    baked = bake(results)
    return results, baked, search(baked)


def test_affine_maps_rebuild_every_template():
    """The bake's affine maps give the CPU templates' own shapes at any parameters, for
    all four templates (cylinder, cone, disk and box)."""
    results = [precompute(load_scene(p)) for p in shipped_scene_paths() + extra_scene_paths()]
    assert {s.template for r in results for s in r.spaces} == \
        {"side_grasp", "handle_grasp", "top_grasp", "drawer_pull"}
    baked = bake(results)
    pb = SearchProblem(*(np.asarray(getattr(baked, k)) for k in SearchProblem._fields))
    rng = np.random.default_rng(0)
    for _ in range(5):
        q = baked.q_min + rng.uniform(size=baked.q_min.shape) * (baked.q_init - baked.q_min)
        center, dims = spaces_at(baked.center_init, baked.dims_init, pb, q, xp=np)
        for s, r in enumerate(results):
            for t, space in enumerate(r.spaces):
                shape = space.shape(q[s, t, :len(space.param_names)])
                np.testing.assert_allclose(center[s, t], shape.center, atol=1e-12)
                np.testing.assert_allclose(dims[s, t], shape.dims, atol=1e-12)
    # Shrinking's own parameters give the baked shrunk spaces.
    center, dims = spaces_at(baked.center_init, baked.dims_init, pb, baked.q_shrunk, xp=np)
    np.testing.assert_allclose(center, baked.center_opt, atol=1e-12)
    np.testing.assert_allclose(dims, baked.dims_opt, atol=1e-12)


def _two_mugs(front_y: float, rear: tuple[float, float]) -> dict:
    return {"name": "two-mugs", "objects": [
        {"id": "a", "kind": "mug", "position": [0.0, front_y, 0.0]},
        {"id": "b", "kind": "mug", "position": [rear[0], rear[1], 0.0]}],
        "tasks": [{"id": "ga", "object": "a", "template": "side_grasp"},
                  {"id": "gb", "object": "b", "template": "side_grasp"}],
        "settings": {"optimize_starts": 48}}


def test_search_finds_the_brute_force_best():
    """Two side grasps (one radius each): a 41 x 41 grid of the two radii, every point
    scored by the same objective, against the search with its default sizes. Scene 0
    is a mug behind a mug: Shrinking shrinks both to their minimum, the best keeps the
    rear one whole (better than both the initial and the Shrinking sizes). With the
    ``search`` selection the result is the brute force's best on the search starts;
    with validation (the default) that larger space is genuinely better, so it is
    still what is chosen."""
    scenes = [scene_from_dict(_two_mugs(0.0, (0.15, 0.0))),
              scene_from_dict(_two_mugs(-0.05, (0.12, 0.05)))]
    results = [precompute(sc, sc.settings(overrides={"optimize_selection": sel}))
               for sel in ("search", "validation") for sc in scenes]
    baked = bake(results)
    found = search(baked)
    with jax.enable_x64(True):  # as the search
        _brute_force(baked, found, results)
    assert found.winner[2] != 0  # not Shrinking's sizes
    np.testing.assert_allclose(found.q[2, :, 0], found.q[0, :, 0], atol=0.01)
    assert found.validation[2] > found.validation_shrunk[2]


def _brute_force(baked, found, results):
    geometry = Geometry.from_bake(baked, np.float64)
    params = Params.from_bake(baked, np.float64)
    problem = SearchProblem.from_bake(baked, np.float64)
    n = 41
    g = np.linspace(0.0, 1.0, n)
    for s in range(2):
        sc, pa, pb = (jax.tree.map(lambda a, s=s: a[s], x) for x in (geometry, params, problem))
        lo, hi = np.asarray(pb.q_min[:, 0]), np.asarray(pb.q_init[:, 0])
        grid = np.zeros((n * n, 2, 2))
        grid[:, 0, 0] = np.repeat(lo[0] + g * (hi[0] - lo[0]), n)
        grid[:, 1, 0] = np.tile(lo[1] + g * (hi[1] - lo[1]), n)
        hits, v = map(np.asarray, jax.jit(jax.vmap(
            lambda q, sc=sc, pa=pa, pb=pb: objective(sc, pa, pb, q)))(jnp.asarray(grid)))
        n_counted = int(pb.opt_start_mask.sum()) * int(sc.task_mask.sum())
        best = np.lexsort((v, hits))[-1]
        assert round(float(found.objective[s]) * n_counted) >= hits[best]
        assert found.volume[s] >= 0.99 * v[best]
        np.testing.assert_allclose(found.q[s, :, 0], grid[best, :, 0], atol=0.01)
        assert found.objective[s] > max(found.objective_init[s], found.objective_shrunk[s])
    np.testing.assert_allclose(found.q[0, :, 0], [results[0].spaces[0].q_min[0],
                                                  results[0].spaces[1].q_init[0]], atol=1e-3)


def test_search_stays_in_bounds_and_beats_its_seeds(small_search):
    """The chosen candidate is within the bounds and, on the validation starts, at least
    as good as Shrinking's and the initial sizes (it is chosen there, ties to
    Shrinking); the search's best on its own starts only grows."""
    _, baked, found = small_search
    assert np.all(found.q >= baked.q_min - 1e-6) and np.all(found.q <= baked.q_init + 1e-6)
    masked = ~baked.q_mask
    np.testing.assert_array_equal(found.q[masked], baked.q_init[masked])
    assert np.all(found.validation >= np.maximum(found.validation_init,
                                                 found.validation_shrunk))
    shrunk = found.winner == 0
    np.testing.assert_array_equal(found.q[shrunk], baked.q_shrunk[shrunk])
    assert np.all(found.validation[~shrunk] > found.validation_shrunk[~shrunk])
    assert np.all(np.diff(found.history, axis=1) >= 0)
    assert np.all(found.history[:, -1] >= found.objective - 1e-12)
    assert np.all(found.history[:, 0] >= found.objective_shrunk - 1e-12)


def test_objective_is_the_reference_automatons_success(small_search):
    """The search's objective for its best candidate, recomputed by the plain NumPy
    Automaton (shrinking rules) on the search starts with the spaces it found."""
    results, baked, found = small_search
    center, dims = optimized_spaces(baked, found)
    for s in (1, 4, 9):
        b = replace(baked, starts=baked.opt_starts, center_opt=center, dims_opt=dims)
        T, N = len(results[s].spaces), int(baked.opt_start_mask[s].sum())
        ok = sum(rollout(b, s, "shrinking", n, t).outcome == "success"
                 for n in range(N) for t in range(T))
        assert ok / (N * T) == pytest.approx(float(found.objective[s]), abs=1e-6)


def test_optimized_mode_is_shacc_on_the_found_spaces(small_search):
    """Held out: the optimized mode runs on the scene's grid, whose starts differ from
    the search's, and agrees rollout for rollout with the NumPy Automaton's shacc rules
    on the spaces the search found."""
    results, baked, _ = small_search
    ev, found = run(baked, ("shrinking", "optimized"))
    center, dims = optimized_spaces(baked, found)
    best = replace(baked, center_opt=center, dims_opt=dims)
    for s in (1, 9):
        grid, opt = baked.starts[s], baked.opt_starts[s][baked.opt_start_mask[s]]
        assert not np.any(np.all(np.isclose(grid[:, None, :3], opt[None, :, :3]), axis=-1))
        assert not np.any(np.all(np.isclose(grid[:, None, 3:], opt[None, :, 3:]), axis=-1))
        for n in range(baked.n_starts):
            for t in range(len(results[s].spaces)):
                ref = rollout(best, s, "shacc", n, t)
                assert OUTCOME_NAMES[ev.rollouts.outcome[s, 1, n, t]] == ref.outcome
                assert ev.rollouts.step[s, 1, n, t] == ref.step


def test_search_starts_lie_on_the_start_plane(small_search):
    results, baked, _ = small_search
    for s in range(len(results)):
        opt = baked.opt_starts[s][baked.opt_start_mask[s]]
        grid = baked.starts[s]
        assert len(opt) == SMALL["optimize_starts"]
        np.testing.assert_allclose(opt[:, 0], grid[0, 0])
        for k in (1, 2):
            assert grid[:, k].min() - 1e-12 <= opt[:, k].min()
            assert opt[:, k].max() <= grid[:, k].max() + 1e-12
        np.testing.assert_allclose(np.linalg.norm(opt[:, 3:], axis=1), 1.0)
    other = bake([precompute(results[0].scene, results[0].settings.with_overrides(
        {"optimize_seed": 7}))])
    assert not np.allclose(other.opt_starts[0, :16], baked.opt_starts[0])


def test_a_batch_needs_one_search_size(shipped_results):
    a = precompute(shipped_results[0].scene,
                   shipped_results[0].settings.with_overrides({"optimize_population": 8}))
    with pytest.raises(InputError, match="optimize_population"):
        run(bake([a, shipped_results[1]]), ("optimized",))


def test_optimize_command(tmp_path, capsys):
    scene = str(shipped_scene_paths()[8])
    out = tmp_path / "o.json"
    sets = [f"--set={k}={v}" for k, v in SMALL.items()]
    assert main(["optimize", scene, *sets, "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "optimized" in printed and "convergence" in printed
    d = json.loads(out.read_text())
    assert list(d["modes"]) == ["baseline", "shrinking", "shacc", "optimized"]
    assert set(d["modes"]["optimized"]) == set(d["modes"]["shacc"])
    opt = d["optimize"]
    assert set(opt["params"]) == set(d["tasks"])
    assert all(set(p) == {"radius"} for p in opt["params"].values())
    assert len(opt["objective"]["per_generation"]) == SMALL["optimize_generations"]
    success = opt["success"]
    assert set(success) == {"search", "validation", "held_out"}
    assert success["validation"]["optimized"] >= success["validation"]["shrinking"]
    assert success["held_out"]["optimized"] == d["modes"]["optimized"]["success_rate"]
    assert opt["chosen"] == "shrinking" or opt["chosen"].startswith(("search #", "initial"))
    assert "validation" in printed and "chosen:" in printed
    assert opt["settings"]["optimize_population"] == 8
    assert len(opt["search_starts"]) == SMALL["optimize_starts"]
    for task, p in opt["params"].items():
        assert 0.095 - 1e-6 <= p["radius"] <= 0.2 + 1e-6, task


def test_a_scenes_search_does_not_depend_on_its_batch(small_search, shipped_results):
    """A scene searched alone, or beside scenes with more tasks, or two scenes per
    call, gives exactly the same parameters (groups by task count; float64)."""
    from geometry_precompute import random_scene

    results, _, found = small_search
    other = random_scene(3, "uniform", 5, 5)
    extra = precompute(other, other.settings(overrides=SMALL))
    mixed = bake([results[4], extra, results[9]])
    together = search(mixed, scenes_per_call=1)
    alone = search(bake([results[9]]))
    np.testing.assert_array_equal(together.q[2, :3], found.q[9])
    np.testing.assert_array_equal(alone.q[0], found.q[9])
    np.testing.assert_array_equal(together.q[0, :3], found.q[4])
    np.testing.assert_array_equal(together.history[2], found.history[9])


def test_a_search_too_large_for_memory_is_refused_before_it_starts(shipped_results):
    r = precompute(shipped_results[0].scene, shipped_results[0].settings.with_overrides(
        {"optimize_population": 4096, "optimize_starts": 65536}))
    baked = bake([r])
    with pytest.raises(InputError, match="optimize_population x optimize_starts"):
        search_scenes_per_call(baked, budget_bytes=2**30)
    assert search_scenes_per_call(bake([shipped_results[0]]), budget_bytes=2**30) >= 1


def test_a_given_search_is_used_not_run_again(small_search, monkeypatch):
    """``run(..., found=...)`` (reproduce's finer field grid) evaluates the
    given parameters and never searches."""
    _, baked, found = small_search
    ref, _ = run(baked, ("optimized",))

    def no_search(*args, **kwargs):
        raise AssertionError("searched again")

    monkeypatch.setattr(optimize, "search", no_search)
    again, used = run(baked, ("optimized",), found=found)
    assert used is found
    np.testing.assert_array_equal(again.rollouts.outcome, ref.rollouts.outcome)


def test_a_small_batchs_optimized_mode_runs_in_the_paper_modes_program(small_search):
    """A small batch evaluates the optimized mode in the program of the paper's modes
    that it has just run (nothing more is traced or compiled), with the same bits as
    in a program of its own."""
    _, baked, found = small_search
    paper = ("baseline", "shrinking", "shacc")
    run(baked, paper)
    traced: list[float] = []

    def count(event: str, duration: float, **kwargs) -> None:
        if event == "/jax/core/compile/jaxpr_trace_duration":
            traced.append(duration)

    jax.monitoring.register_event_duration_secs_listener(count)
    try:
        both, _ = run(baked, (*paper, "optimized"), found=found)
    finally:
        jax.monitoring.unregister_event_duration_listener(count)
    assert traced == []
    alone, _ = run(baked, ("optimized",), found=found)
    for name, got in both.rollouts._asdict().items():
        np.testing.assert_array_equal(got[:, 3], getattr(alone.rollouts, name)[:, 0],
                                      err_msg=name)
    np.testing.assert_array_equal(both.metrics.u_scene[:, 3], alone.metrics.u_scene[:, 0])


def test_cut_cuts_every_task_axis(shipped_results):
    """``cut`` takes scenes and their first n tasks: every array whose second axis is
    the tasks (by the bake's shapes, padded to 5 tasks) becomes n long there, and
    nothing else changes."""
    baked = bake(shipped_results[:3], max_tasks=6)
    for tree in (Geometry, Params, SearchProblem):
        host = jax.tree.map(np.asarray, tree.from_bake(baked))
        got = cut(host, np.array([2, 0]), 3)
        for name, a, c in zip(tree._fields, host, got, strict=True):
            task_axis = a.ndim >= 2 and a.shape[1] == 6
            want = (2, 3, *a.shape[2:]) if task_axis else (2, *a.shape[1:])
            assert c.shape == want, (name, c.shape, want)
            np.testing.assert_array_equal(c[1], a[0][:3] if task_axis else a[0])


ROW = {"name": "three-mugs-row", "objects": [
    {"id": k, "kind": "mug", "position": [0.0, y, 0.0]}
    for k, y in (("a", -0.21), ("b", 0.0), ("c", 0.21))],
    "tasks": [{"id": f"g{k}", "object": k, "template": "side_grasp"} for k in "abc"],
    "settings": {"start_grid": [16, 16]}}


def test_the_optimized_mode_never_loses_to_a_perfect_shrinking_held_out():
    """Three mugs in a row, 0.21 m apart: Shrinking already succeeds from every search
    start. The earlier objective (``search``: ties to larger spaces) grows the radii
    until neighbours overlap again where no search start looks, and loses on the
    held-out grid; with validation (the default) the optimized mode must not lose."""
    scene = scene_from_dict(ROW)
    results = [precompute(scene, scene.settings(overrides={"optimize_selection": sel}))
               for sel in ("search", "validation")]
    ev, found = run(bake(results), ("shrinking", "optimized"))
    u = ev.metrics.u_scene  # (scene, mode)
    assert u[0, 0] == u[1, 0] == 1.0  # Shrinking: perfect on the held-out grid
    assert found.objective_shrunk[0] == 1.0
    assert u[0, 1] < u[0, 0]  # the earlier objective overfits and loses
    assert u[1, 1] >= u[1, 0]  # never loses with validation
    assert found.clutteredness[1] <= found.clutteredness[0]


def test_validation_starts_are_neither_the_search_starts_nor_the_grid(small_search):
    """Drawn on the start plane from their own seed (and their own stream: equal seeds
    give other starts), the same on every call."""
    results, baked, _ = small_search
    pb = SearchProblem.from_bake(baked, np.float64)
    with jax.enable_x64(True):
        starts, mask = jax.vmap(lambda p: optimize.validation_starts(p, 256))(pb)
    starts, mask = np.asarray(starts), np.asarray(mask)
    assert mask.all() and starts.shape == (len(results), 256, 7)
    for s in range(len(results)):
        val = starts[s, :, :3]
        opt = baked.opt_starts[s][baked.opt_start_mask[s]][:, :3]
        grid = baked.starts[s, :, :3]
        for other in (opt, grid):
            gap = np.linalg.norm(val[:, None] - other[None], axis=-1).min()
            assert gap > 1e-6
        np.testing.assert_allclose(val[:, 0], grid[0, 0])
        assert val[:, 1:].min(0).tolist() >= (grid[:, 1:].min(0) - 1e-12).tolist()
        assert val[:, 1:].max(0).tolist() <= (grid[:, 1:].max(0) + 1e-12).tolist()
    same_seed = bake([precompute(results[0].scene, results[0].settings.with_overrides(
        {"optimize_seed": 5, "optimize_validation_seed": 5, **SMALL}))])
    pb = SearchProblem.from_bake(same_seed, np.float64)
    with jax.enable_x64(True):
        val = np.asarray(optimize.validation_starts(jax.tree.map(lambda a: a[0], pb), 16)[0])
    assert np.linalg.norm(val[:, None, :3] - same_seed.opt_starts[0][None, :, :3],
                          axis=-1).min() > 1e-6
