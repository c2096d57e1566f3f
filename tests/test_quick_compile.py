"""Small CPU programs are compiled with LLVM's passes off (``program_cache.quick``), large
ones with XLA's defaults: a scene evaluated alone and the same scene inside a sweep
then come from programs compiled at different levels, so the two levels must give the
same bits. Held here for the closed form of shacc (the meta skill) with collision
checks, and for the stepped users with every imperfection in an intent mode (the
stepping loop, the users, the posterior)."""

from __future__ import annotations

import jax
import numpy as np
import pytest

from geometry_precompute import (
    bake,
    load_scene,
    precompute,
    random_scene,
    shipped_scene_paths,
)
from shacc_jax import evaluation, program_cache
from shacc_jax.runplan import LEVEL_COST, program_work
from shacc_jax.types import inputs

LEVEL = "xla_backend_optimization_level"
EVERY_USER = {"user_noise": 0.2, "user_noise_tau": 0.5, "user_tremor": 0.01,
              "user_input": "modes", "user_switch": 0.3}


def _at_levels(baked, modes):
    """Every field of the evaluation compiled at backend level 0 and at level 3."""
    g, p, layout = inputs(baked, modes)
    lowered = evaluation.evaluate.lower(g, p, layout)
    out = []
    for level in (0, 3):
        ev = jax.device_get(lowered.compile({LEVEL: level})(g, p))
        out.append(jax.tree.leaves(ev))
    return out


def _assert_same_bits(a, b):
    assert len(a) == len(b)
    for i, (x, y) in enumerate(zip(a, b, strict=True)):
        x, y = np.asarray(x), np.asarray(y)
        assert x.shape == y.shape and x.tobytes() == y.tobytes(), i


def test_the_closed_form_with_collision_checks_is_the_same_bits_at_either_level():
    results = [precompute(load_scene(p), {"collision": "on", "start_grid": [4, 3]})
               for p in shipped_scene_paths()[:6]]
    low, high = _at_levels(bake(results), ("shacc",))
    _assert_same_bits(low, high)
    assert any(np.asarray(x).dtype.kind == "f" for x in low)


def test_every_user_in_an_intent_mode_stepped_is_the_same_bits_at_either_level():
    results = [precompute(random_scene(70 + i, ("uniform", "gaussian")[i], 3, 5),
                          {**EVERY_USER, "start_grid": [3, 3]}) for i in range(2)]
    low, high = _at_levels(bake(results), ("ho",))
    _assert_same_bits(low, high)


@pytest.mark.parametrize(("work", "quick"), [(400, True),
                                             (program_cache.QUICK_COMPILE_ROLLOUTS, True),
                                             (program_cache.QUICK_COMPILE_ROLLOUTS + 1,
                                              False)])
def test_only_small_cpu_programs_compile_quickly(work, quick):
    assert program_cache.quick(work, [np.zeros(2)]) is quick  # the suite runs on CPUs
    x = jax.device_put(np.zeros(2), jax.devices("cpu")[0])
    assert program_cache.quick(work, [x]) is quick


def test_a_programs_work_weighs_each_modes_rollouts_by_their_cost():
    results = [precompute(load_scene(p), {"start_grid": [4, 3]})
               for p in shipped_scene_paths()[:2]]
    b = bake(results)
    g, p, layout = inputs(b, ("baseline", "shacc"))
    S, N, T = g.starts.shape[0], g.starts.shape[1], g.task_mask.shape[1]
    assert program_work(g, p, layout) == S * N * T * 2
    points = type(p)._make(np.stack([a, a, a]) for a in p)
    assert program_work(g, points, layout) == 3 * S * N * T * 2
    g, p, layout = inputs(b, ("baseline", "blend"))
    assert program_work(g, p, layout) == S * N * T * (1 + LEVEL_COST["intent"])
    user = bake([precompute(load_scene(p), {"start_grid": [4, 3], "user_tremor": 0.01})
                 for p in shipped_scene_paths()[:2]])
    g, p, layout = inputs(user, ("baseline",))
    assert layout.stepped_users and program_work(g, p, layout) == S * N * T * LEVEL_COST["stepped"]


def test_a_program_run_many_times_counts_the_work_of_every_call(monkeypatch, tmp_path):
    """The compiler options of a program weigh its work by its calls: every piece of a
    batch split by the memory budget, and every batch of that shape the caller said it
    will run (``calls``: a sweep's chunks, all padded to one shape). A sweep of many
    small chunks is then compiled at XLA's default level, as one batch of all of them
    would be."""
    from test_sweep import CONFIG, write

    import shacc_jax
    from sweeps.config import load_config
    from sweeps.distributed.plan import plan
    from sweeps.distributed.runner import program_calls, warm_up_job

    seen: list[tuple[int, bool]] = []
    decide = program_cache.quick

    def recording(work, leaves):
        seen.append((work, decide(work, leaves)))
        return seen[-1][1]

    monkeypatch.setattr(program_cache, "quick", recording)
    b = bake([precompute(load_scene(shipped_scene_paths()[0]), {"start_grid": [2, 2]})])
    g, p, layout = inputs(b, ("baseline",))
    once = program_work(g, p, layout)
    assert once < program_cache.QUICK_COMPILE_ROLLOUTS
    calls = program_cache.QUICK_COMPILE_ROLLOUTS // once + 1
    single = shacc_jax.run(b, ("baseline",), calls=1)
    many = shacc_jax.run(b, ("baseline",), calls=calls)
    assert seen == [(once, True), (calls * once, False)]
    np.testing.assert_array_equal(single.evaluation.rollouts.outcome,
                                  many.evaluation.rollouts.outcome)
    # The grid's four starts in two pieces of two: one program of half the work, run
    # twice.
    seen.clear()
    half = shacc_jax.plan(b, ("baseline",)).bytes_per_piece // 2
    shacc_jax.run(b, ("baseline",), budget_bytes=half)
    assert [w for w, _ in seen] == [2 * (once // 2)] * 2

    cfg = load_config(write(tmp_path, CONFIG))  # 3 scenes, a chunk each, one points group
    chunks = plan(cfg)
    assert program_calls(cfg) == {len(chunks[0].points): len(chunks)}
    assert warm_up_job(cfg, chunks[2:], None)[0].calls == len(chunks)  # resumed: the same
