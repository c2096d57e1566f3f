"""Inputs past the numeric ranges: a clear error, never a traceback; and work larger
than memory split into pieces with the same results as one piece."""

from __future__ import annotations

import math
from dataclasses import replace

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
from sweeps.memory import bytes_per_rollout, evaluate_in_pieces
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
    as one piece (the integers exactly, the floats to float32 rounding)."""
    import shacc_jax
    from geometry_precompute import bake

    baked = bake(shipped_results[8:10])
    whole = evaluate_in_pieces(baked, shacc_jax.MODES, shacc_jax.evaluate, limit=2**40)
    per_start = bytes_per_rollout(False) * baked.n_scenes * baked.n_tasks * 3
    pieces = evaluate_in_pieces(baked, shacc_jax.MODES, shacc_jax.evaluate,
                                limit=per_start * 10)  # 36 starts in 4 pieces of 10
    for name, a, b in zip(whole.rollouts._fields, whole.rollouts, pieces.rollouts, strict=True):
        if np.issubdtype(a.dtype, np.integer):
            np.testing.assert_array_equal(a, b, err_msg=name)
        elif name == "delta_R":
            # 2 arccos(c) in float32: near c = 1 one float32 step of c moves the angle
            # by up to 2e-5 rad (at 0.03 rad), so the pieces are compared where the
            # rounding happens, in c = cos(delta_R / 2), to a few float32 steps.
            np.testing.assert_allclose(np.cos(a / 2), np.cos(b / 2), rtol=0,
                                       atol=4 * np.finfo(np.float32).eps, equal_nan=True,
                                       err_msg=name)
        else:
            np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6, equal_nan=True,
                                       err_msg=name)
    np.testing.assert_array_equal(whole.metrics.outcome_counts, pieces.metrics.outcome_counts)
    np.testing.assert_allclose(whole.metrics.u_scene, pieces.metrics.u_scene)
    np.testing.assert_allclose(whole.metrics.delta_R_mean, pieces.metrics.delta_R_mean,
                               rtol=1e-5, equal_nan=True)


def test_only_the_named_fields_reach_the_host(shipped_results):
    """``evaluate_on_devices(fields=...)`` (what a sweep's chunks use) copies only those
    Rollouts fields: equal to the full evaluation's, the others None, also when the
    batch is split into pieces; a name that is no field is refused."""
    from functools import partial

    import shacc_jax
    from geometry_precompute import bake
    from sweeps.pipeline import evaluate_points

    baked = bake(shipped_results[8:10])
    whole = evaluate_in_pieces(baked, shacc_jax.MODES, limit=2**40)
    keep = ("outcome", "step", "delta_R")
    run = partial(shacc_jax.evaluate_on_devices, fields=keep)
    per_start = bytes_per_rollout(False) * baked.n_scenes * baked.n_tasks * 3
    one = evaluate_in_pieces(baked, shacc_jax.MODES, run, limit=2**40)
    pieces = evaluate_in_pieces(baked, shacc_jax.MODES, run, limit=per_start * 10)
    two_points = [ev for ev, _ in evaluate_points([baked, baked], shacc_jax.MODES, keep)]
    for got in (one, pieces, *two_points):
        for name in whole.rollouts._fields:
            a, b = getattr(whole.rollouts, name), getattr(got.rollouts, name)
            if name == "delta_R":  # pieces may round differently (see the test above)
                np.testing.assert_allclose(np.cos(a / 2), np.cos(b / 2), rtol=0,
                                           atol=4 * np.finfo(np.float32).eps, equal_nan=True)
            elif name in keep:
                np.testing.assert_array_equal(a, b, err_msg=name)
            else:
                assert getattr(got.rollouts, name) is None, name
        np.testing.assert_array_equal(got.metrics.outcome_counts, whole.metrics.outcome_counts)
    with pytest.raises(ValueError, match=r"'orientaton' not among the Rollouts fields"):
        shacc_jax.evaluate_on_devices(*shacc_jax.inputs(baked), fields=("orientaton",))
    with pytest.raises(ValueError, match="not the string 'outcome'"):
        shacc_jax.evaluate_on_devices(*shacc_jax.inputs(baked), fields="outcome")


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
    import shacc_jax
    from geometry_precompute import bake

    plain = bake(shipped_results[8:9])
    checked = replace(plain, collision=np.ones_like(plain.collision))
    assert bytes_per_rollout(True) >= 4 * bytes_per_rollout(False)
    calls = []

    def counting(geometry, params, layout):
        calls.append(geometry.starts.shape[1])
        return shacc_jax.evaluate(geometry, params, layout)

    limit = bytes_per_rollout(False) * plain.n_tasks * 3 * plain.n_starts
    evaluate_in_pieces(plain, shacc_jax.MODES, counting, limit=limit)
    assert calls == [plain.n_starts]
    calls.clear()
    pieces = evaluate_in_pieces(checked, shacc_jax.MODES, counting, limit=limit)
    assert len(calls) > 1 and max(calls) < plain.n_starts
    whole = evaluate_in_pieces(checked, shacc_jax.MODES, shacc_jax.evaluate, limit=2**40)
    np.testing.assert_array_equal(whole.rollouts.outcome, pieces.rollouts.outcome)
    np.testing.assert_array_equal(whole.rollouts.step, pieces.rollouts.step)
