"""Inputs past the numeric ranges: a clear error, never a traceback; and work larger
than memory split into pieces with the same results as one piece."""

from __future__ import annotations

import math
from dataclasses import replace

import jax
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from geometry_precompute import (
    SPECS,
    InputError,
    load_scene,
    precompute,
    scene_from_dict,
    shipped_scene_paths,
)
from geometry_precompute.settings import INT32_MAX, MAX_STARTS
from shacc_jax.runplan import bytes_per_rollout, plan, run
from sweeps.pipeline import evaluate_results

SCENE = shipped_scene_paths()[8]


def _scene(settings=None, **obj):
    a = {"id": "a", "kind": "mug", "position": [0.0, 0.0, 0.0], **obj}
    return {"name": "r", "objects": [a, {"id": "b", "kind": "mug", "position": [0.12, 0, 0]}],
            "tasks": [{"id": "t", "object": "a", "template": "side_grasp"},
                      {"id": "u", "object": "b", "template": "side_grasp"}],
            "settings": settings or {}}


@pytest.mark.parametrize("settings,field,words", [
    ({"max_steps": 3_000_000_000}, "settings.max_steps", "[1, 1000000000]"),
    ({"seed": 2**31}, "settings.seed", f"[0, {INT32_MAX}]"),
    ({"start_grid": [2000, 2000]}, None, None),                     # valid: 4 M starts
    ({"start_grid": [1_000_000, 1_000_000]}, "settings.start_grid", str(MAX_STARTS)),
    ({"shrink_step": 1e-9}, "settings.shrink_step", "[0.001, 1]"),
    ({"mesh_sections": 10**6}, "settings.mesh_sections", "[8, 1024]"),
])
def test_settings_ranges(settings, field, words):
    if field is None:
        scene_from_dict(_scene(settings))
        return
    with pytest.raises(InputError) as e:
        scene_from_dict(_scene(settings), "s.toml")
    assert f"s.toml: {field}:" in str(e.value) and words in str(e.value)


@pytest.mark.parametrize("obj,field", [
    ({"position": [1e30, 0.0, 0.0]}, "objects[a].position[0]"),
    ({"position": [0.0, -101.0, 0.0]}, "objects[a].position[1]"),
    ({"radius": 1e30}, "objects[a].radius"),
    ({"yaw": 1e300}, "objects[a].yaw"),
])
def test_scene_field_ranges(obj, field):
    with pytest.raises(InputError) as e:
        scene_from_dict(_scene(**obj), "s.toml")
    assert f"s.toml: {field}: must be" in str(e.value)


def test_two_far_objects_are_rejected_cleanly():
    data = _scene(position=[1e30, 1e30, 0.0])
    data["objects"][1]["position"] = [1e30, 1e30 + 1.0, 0.0]
    with pytest.raises(InputError, match=r"position\[0\]: must be within \[-100, 100\]"):
        scene_from_dict(data)


def _value_strategy(spec):
    number = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                       st.integers(min_value=-(2**70), max_value=2**70))
    junk = st.one_of(st.text(max_size=5), st.booleans(), st.none(), st.lists(number,
                                                                              max_size=3))
    if spec.kind in ("int_pair", "float_pair"):
        return st.one_of(st.lists(number, min_size=2, max_size=2), junk)
    if spec.kind == "choice":
        return st.one_of(st.sampled_from(spec.choices), junk)
    return st.one_of(number, junk)


@pytest.mark.parametrize("name", [n for n in SPECS if SPECS[n].stage != "analysis"])
def test_any_value_of_a_setting_loads_cleanly_or_is_rejected(name):
    """Values from the setting's whole type range go through load and precompute: a
    clean InputError or a finite result, never another exception."""
    spec = SPECS[name]

    @settings(max_examples=12, deadline=None)
    @given(_value_strategy(spec))
    def check(value):
        try:
            scene = scene_from_dict(_scene({name: value}))
            r = precompute(scene)
        except InputError:
            return
        assert math.isfinite(r.C_init) and math.isfinite(r.C_final)
        assert all(np.all(np.isfinite(q)) for q in r.q_opt)

    check()


def test_grid_in_pieces_equals_one_piece(shipped_results):
    """A grid that needs several pieces at a small forced budget gives the same results
    as one piece, bit for bit (each rollout depends only on its own start; every piece
    has at least two)."""
    from geometry_precompute import bake

    baked = bake(shipped_results[8:10])
    per_start = bytes_per_rollout(False) * baked.n_scenes * baked.n_tasks * 3
    # Room for 10 starts: 4 pieces of 9. Room for 8: 5 pieces of 8, the last padded.
    assert plan(baked, budget_bytes=per_start * 10).pieces == (0, 9, 18, 27)
    assert plan(baked, budget_bytes=per_start * 8).pieces == (0, 8, 16, 24, 32)
    whole = run(baked, budget_bytes=2**40).evaluation
    pieces = run(baked, budget_bytes=per_start * 8).evaluation  # 36 starts, 5 pieces
    for name, a, b in zip(whole.rollouts._fields, whole.rollouts, pieces.rollouts, strict=True):
        np.testing.assert_array_equal(a, b, err_msg=name)
    for name, a, b in zip(whole.metrics._fields, whole.metrics, pieces.metrics, strict=True):
        np.testing.assert_array_equal(a, b, err_msg=name)


def test_only_the_named_fields_reach_the_host(shipped_results):
    """``run(fields=...)`` (what a sweep's chunks use) copies only those Rollouts fields:
    equal to the full evaluation's, the others None, also when the batch is split into
    pieces and with a points axis; a name that is no field is refused."""
    from geometry_precompute import bake

    baked = bake(shipped_results[8:10])
    whole = run(baked, budget_bytes=2**40).evaluation
    keep = ("outcome", "step", "delta_R")
    per_start = bytes_per_rollout(False) * baked.n_scenes * baked.n_tasks * 3
    one = run(baked, fields=keep, budget_bytes=2**40).evaluation
    pieces = run(baked, fields=keep, budget_bytes=per_start * 10).evaluation
    points = run(baked, fields=keep, points=[baked, baked]).evaluation
    for got in (one, pieces, *(jax.tree.map(lambda a, i=i: a[i], points) for i in (0, 1))):
        for name in whole.rollouts._fields:
            if name in keep:
                np.testing.assert_array_equal(getattr(whole.rollouts, name),
                                              getattr(got.rollouts, name), err_msg=name)
            else:
                assert getattr(got.rollouts, name) is None, name
        np.testing.assert_array_equal(got.metrics.outcome_counts, whole.metrics.outcome_counts)
    with pytest.raises(ValueError, match=r"'orientaton' not among the Rollouts fields"):
        plan(baked, fields=("orientaton",))
    with pytest.raises(ValueError, match="not the string 'outcome'"):
        plan(baked, fields="outcome")


def test_the_plan_is_a_pure_function_of_the_bake_and_its_arguments(shipped_results):
    """plan() reads shapes and settings only: pieces from the budget, the device split
    with its padding (parts of at least two scenes), the backend's block size, the
    fields; describe() says all of it."""
    from geometry_precompute import bake

    baked = bake(shipped_results[:5])  # S = 5, N = 36
    S, T = 5, baked.n_tasks
    per_start = bytes_per_rollout(False, "gpu") * S * T * 2
    p = plan(baked, ("baseline", "shacc"), budget_bytes=per_start * 12,
             devices=["gpu:0", "gpu:1", "gpu:2"], backend="gpu", fields=("outcome",),
             metrics=False)
    assert p.pieces == (0, 12, 24) and p.starts_per_piece == 12
    assert p.devices == ("gpu:0", "gpu:1") and p.scenes_per_part == 3
    assert p.padded_scenes == 6 and p.fields == ("outcome",) and not p.metrics
    assert p.layout.lanes_per_block == 1 << 17 and p.layout.modes == ("baseline", "shacc")
    assert p == plan(baked, ("baseline", "shacc"), budget_bytes=per_start * 12,
                     devices=["gpu:0", "gpu:1", "gpu:2"], backend="gpu", fields=["outcome"],
                     metrics=False)
    text = p.describe()
    for words in ("5 scenes x 36 starts", "3 piece(s) of 12 starts", "2 (gpu:0, gpu:1)",
                  "3 scenes each (1 padding)", "copied back: outcome",
                  "blocks of 131072 lanes"):
        assert words in text, (words, text)
    one = plan(baked, budget_bytes=2**40, devices=["cpu:0"], backend="cpu")
    assert one.pieces == (0,) and one.padded_scenes == 5 and one.layout.lanes_per_block == 256
    # A one-start grid still runs programs of two starts (the start repeated).
    single = replace(baked, starts=baked.starts[:, :1], start_index=baked.start_index[:, :1])
    assert plan(single, budget_bytes=2**40, devices=["cpu:0"]).starts_per_piece == 2


def test_budget_from_the_environment_splits_evaluate(monkeypatch):
    r = precompute(load_scene(SCENE))
    whole = evaluate_results([r])
    # 7 starts per piece (3 tasks, 3 modes)
    monkeypatch.setenv("SHACC_MEMORY_BUDGET", str(bytes_per_rollout(False) * 3 * 3 * 7))
    pieces = evaluate_results([r])
    np.testing.assert_array_equal(whole.evaluation.rollouts.outcome,
                                  pieces.evaluation.rollouts.outcome)
    np.testing.assert_array_equal(whole.evaluation.metrics.outcome_counts,
                                  pieces.evaluation.metrics.outcome_counts)


def test_one_start_that_does_not_fit_says_how_much_it_needs(monkeypatch):
    r = precompute(load_scene(SCENE))
    monkeypatch.setenv("SHACC_MEMORY_BUDGET", "1K")
    need = f"{2 * bytes_per_rollout(False) * 3 * 3 / 1024:.1f}".replace(".", r"\.")
    with pytest.raises(InputError, match=rf"two start poses .* need {need} KB, more than the "
                       r"budget of 1\.0 KB"):
        evaluate_results([r])
    monkeypatch.setenv("SHACC_MEMORY_BUDGET", "lots")
    with pytest.raises(InputError, match="SHACC_MEMORY_BUDGET"):
        evaluate_results([r])


def test_collision_checks_are_budgeted_as_they_need(shipped_results):
    """With collision checks on, a rollout needs several times the memory (measured:
    benchmarks/RESULTS.md), so a budget that holds the plain batch in one piece splits the
    checked one; its results equal the whole batch's."""
    from geometry_precompute import bake

    plain = bake(shipped_results[8:9])
    checked = replace(plain, collision=np.ones_like(plain.collision))
    assert bytes_per_rollout(True) >= 4 * bytes_per_rollout(False)
    modes = ("baseline",)  # one mode: the pieces do not depend on which (suite time)
    limit = bytes_per_rollout(False) * plain.n_tasks * len(modes) * plain.n_starts
    assert plan(plain, modes, budget_bytes=limit).pieces == (0,)
    split = plan(checked, modes, budget_bytes=limit)
    assert len(split.pieces) > 1 and split.starts_per_piece < plain.n_starts
    pieces = run(checked, modes, budget_bytes=limit).evaluation
    whole = run(checked, modes, budget_bytes=2**40).evaluation
    np.testing.assert_array_equal(whole.rollouts.outcome, pieces.rollouts.outcome)
    np.testing.assert_array_equal(whole.rollouts.step, pieces.rollouts.step)


def test_stepped_users_are_budgeted_as_they_need(shipped_results):
    """Stepped users hold only their queue's slots beside the outputs (measured:
    benchmarks/RESULTS.md), so on a CPU a budget that splits the closed form's batch
    holds the same batch with a noisy user in one piece; collision checks still cost
    more."""
    from geometry_precompute import bake

    plain = bake(shipped_results[8:9])
    noisy = replace(plain, user_noise=np.full_like(plain.user_noise, 0.2))
    modes = ("baseline",)
    per_start = plain.n_tasks * len(modes)
    assert bytes_per_rollout(False, "cpu", stepped=True) < bytes_per_rollout(False, "cpu")
    assert bytes_per_rollout(True, "cpu", stepped=True) > bytes_per_rollout(False, "cpu",
                                                                            stepped=True)
    limit = bytes_per_rollout(False, "cpu", stepped=True) * per_start * plain.n_starts
    stepped = plan(noisy, modes, budget_bytes=limit, backend="cpu")
    assert stepped.layout.stepped_users and stepped.pieces == (0,)
    closed = plan(plain, modes, budget_bytes=limit, backend="cpu")
    assert not closed.layout.stepped_users and len(closed.pieces) > 1


def test_evaluate_plan_prints_the_plan_and_evaluates_nothing(monkeypatch, capsys):
    """``shacc evaluate --plan``: the RunPlan for the batch, with the pieces the budget
    allows; no evaluation runs."""
    from shacc_jax import runplan
    from sweeps.app.cli import main

    def refuse(*args, **kwargs):
        raise AssertionError("evaluated")

    monkeypatch.setattr(runplan, "execute", refuse)
    assert main(["evaluate", str(SCENE), "--plan"]) == 0
    out = capsys.readouterr().out
    assert "1 scenes x 36 starts x 3 tasks" in out and "1 piece(s) of 36 starts" in out
    monkeypatch.setenv("SHACC_MEMORY_BUDGET", str(bytes_per_rollout(False) * 3 * 3 * 7))
    assert main(["evaluate", str(SCENE), "--plan", "--modes", "baseline", "shrinking", "shacc",
                 "optimized"]) == 0
    out = capsys.readouterr().out
    assert "6 piece(s) of 6 starts" in out and "optimized: the search first" in out
