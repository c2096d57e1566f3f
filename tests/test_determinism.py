"""A rollout's numbers do not depend on the batch it is evaluated in
(shacc_jax/determinism.py): any split of the start grid or of the scenes gives the
same bits, and so a sweep's tables are the same whatever the memory budget and
however it was resumed."""

from __future__ import annotations

import shutil
from dataclasses import replace
from functools import partial
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

import shacc_jax
from geometry_precompute import DEFAULTS, bake, precompute, random_scene
from shacc_jax.runplan import bytes_per_rollout, run
from sweeps.config import parse_config
from sweeps.distributed.runner import run_sweep


def _run(baked):
    """The rollouts of a bake, by the door the command line uses (so that the tests
    below share its compiled programs)."""
    return run(baked).evaluation.rollouts


def _same_bits(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.fixture(scope="module")
def batch():
    scenes = [random_scene(40 + i, ("uniform", "gaussian")[i % 2], 3, 8) for i in range(5)]
    return bake([precompute(s, s.settings(DEFAULTS, {"start_grid": [4, 3], "v_max": 0.4}))
                 for s in scenes])


def test_any_split_of_the_start_grid_gives_the_same_bits(batch):
    whole = _run(batch)
    N = batch.n_starts
    for size in (2, 5):  # pieces of 2 and 5 (the last one of 2): the shapes below
        for a in range(0, N - 1, size):
            idx = np.arange(a, min(a + size, N))
            part = _run(replace(batch, starts=batch.starts[:, idx],
                                start_index=batch.start_index[:, idx]))
            for name in whole._fields:
                assert _same_bits(np.take(getattr(whole, name), idx, axis=2),
                                  getattr(part, name)), (name, size, a)


def test_any_split_of_the_scenes_gives_the_same_bits(batch):
    whole = _run(batch)
    results = [precompute(random_scene(40 + i, ("uniform", "gaussian")[i % 2], 3, 8),
                          {"start_grid": [4, 3], "v_max": 0.4}) for i in range(5)]
    for lo, hi in ((0, 2), (2, 5), (1, 3)):
        part = _run(bake(results[lo:hi], batch.n_tasks, max_objects=batch.obj_mask.shape[1]))
        for name in whole._fields:
            assert _same_bits(getattr(whole, name)[lo:hi], getattr(part, name)), (name, lo)


def test_pieces_of_the_memory_budget_give_the_same_bits_and_metrics(batch):
    modes = shacc_jax.MODES
    whole = run(batch, modes, budget_bytes=10**12).evaluation
    per_start = bytes_per_rollout(False) * batch.n_scenes * batch.n_tasks * len(modes)
    for starts in (2, 5):
        pieces = run(batch, modes, budget_bytes=starts * per_start).evaluation
        for a, b in zip(whole, pieces, strict=True):
            for x, y in zip(a, b, strict=True):
                assert _same_bits(x, y)
    # Rates are exact fractions of the counts, in double precision.
    m = whole.metrics
    assert m.u_scene.dtype == np.float64
    np.testing.assert_array_equal(m.u_scene, m.outcome_counts[..., 0] / m.n_rollouts)


SWEEP = """
name = "budget"
chunk = 2
[source]
kind = "random"
count = 5
tasks = [3, 6]
seed = 11
[settings]
start_grid = [4, 2]
[axes]
v_max = [0.15, 0.5]
"""


def _tables(out: Path) -> dict:
    """Every column of every table, as the bytes of its values (NaN is NaN)."""
    found = {}
    for name in ("scenes", "rollouts", "tasks", "starts"):
        table = pq.read_table(out / name)
        for col in table.column_names:
            values = table[col].combine_chunks()
            if hasattr(values, "dictionary"):
                values = values.dictionary_decode()
            array = values.to_numpy(zero_copy_only=False)
            found[(name, col)] = values.to_pylist() if array.dtype == object else array.tobytes()
    return found


def test_sweep_tables_are_the_same_bits_whatever_the_budget_and_resume(tmp_path, monkeypatch):
    cfg = parse_config(__import__("tomllib").loads(SWEEP), "budget.toml", tmp_path)
    cache = tmp_path / "cache"
    run_sweep(cfg, tmp_path / "whole", cache, workers=1, progress=False)
    # A rollout needs 1 300 bytes on a CPU: 2 x 2 scenes x 6 tasks x 3 modes x 2 starts.
    monkeypatch.setenv("SHACC_MEMORY_BUDGET", str(2 * 2 * 6 * 3 * 2 * 1300))
    run_sweep(cfg, tmp_path / "pieces", cache, workers=1, progress=False)
    # Resumed under another budget: the last two chunks removed, then written again.
    resumed = tmp_path / "resumed"
    shutil.copytree(tmp_path / "pieces", resumed)
    parts = sorted((resumed / "scenes").glob("part-*.parquet"))
    for p in parts[-2:]:
        p.unlink()
        (resumed / "rollouts" / p.name).unlink()
    monkeypatch.setenv("SHACC_MEMORY_BUDGET", str(3 * 2 * 6 * 3 * 2 * 1300))
    run_sweep(cfg, resumed, cache, workers=1, progress=False)
    whole = _tables(tmp_path / "whole")
    assert _tables(tmp_path / "pieces") == whole
    assert _tables(resumed) == whole


def test_the_suite_runs_strict_on_two_devices():
    """conftest's settings hold in every test process: no implicit rank or dtype
    promotion, and two CPU devices, so the multi-device split runs in CI too."""
    import jax

    flags = jax.config
    assert flags.jax_numpy_rank_promotion == "raise"
    assert flags.jax_numpy_dtype_promotion == "strict"
    assert len(jax.devices("cpu")) == 2


def test_one_scene_in_pieces_of_two_starts_gives_the_same_bits():
    """One scene of 6 tasks (a sweep's chunk of one), whole and in pieces of two starts:
    the meta skill's sums over tasks were reductions whose order XLA's CPU backend chose
    by the shape, and 3 of these scenes' shacc orientations differed in their last
    bits (and delta_R by up to 1e-3 rad)."""
    modes = ("baseline", "shacc")
    scenes = [random_scene(11 + k, "uniform" if k % 2 == 0 else "gaussian", 3, 6, "paper")
              for k in (7, 9, 11)]
    results = [precompute(s, s.settings(DEFAULTS, {"start_grid": [4, 4], "v_max": 0.1}))
               for s in scenes]
    objects = max(len(s.objects) for s in scenes)
    for r in results:
        one = bake([r], 6, max_objects=objects)
        per_start = bytes_per_rollout(False) * 6 * len(modes)
        whole = run(one, modes, budget_bytes=10**12).evaluation.rollouts
        pieces = run(one, modes, budget_bytes=2 * per_start).evaluation.rollouts
        for name in whole._fields:
            assert _same_bits(getattr(whole, name), getattr(pieces, name)), \
                (r.scene.name, name)


def test_sweep_tables_are_the_same_bits_with_and_without_the_compilation_cache(
        tmp_path, monkeypatch):
    """The program a sweep's evaluation worker runs does not depend on the cache: with
    the cache off the worker once started JAX before the CPU code generation was
    pinned (so its tables differed in 7 092 of 47 296 delta_R values). The pin is not
    inherited from this process here, as it is not from a user's shell."""
    cfg = parse_config(__import__("tomllib").loads(SWEEP), "cache.toml", tmp_path)
    monkeypatch.setenv("XLA_FLAGS", "")
    run_sweep(cfg, tmp_path / "cached", tmp_path / "cache", workers=1, progress=False)
    monkeypatch.setenv("SHACC_COMPILE_CACHE", "off")
    run_sweep(cfg, tmp_path / "plain", tmp_path / "cache", workers=1, progress=False)
    assert _tables(tmp_path / "plain") == _tables(tmp_path / "cached")


def test_no_division_by_a_square_root_in_the_programs():
    """XLA rewrites ``a / sqrt(b)`` into ``a * rsqrt(b)``, which its CPU backend computes
    from the processor's approximate instruction, so results differed between Intel and
    AMD processors. No division in the evaluation's programs (closed form; stepped
    users with collision checks) takes a square root as its divisor
    (``quaternion.sqrt_divisor``). Checked on the traced programs, which costs no
    compilation: every division's divisor is followed to where it is made, through
    nested jitted functions (their results and arguments), as XLA sees it once it has
    inlined them. (Read from the lowered text, SSA names repeat across a program's
    regions, and a name of one region matched a square root of another.)"""
    import jax
    from jax.extend.core import Literal, jaxprs_in_params

    from shacc_jax.runplan import plan
    from shacc_jax.types import Geometry, Params

    # What XLA inlines: a value made in one is the same value in the caller.
    calls = ("jit", "pjit", "closed_call", "checkpoint", "custom_jvp_call", "custom_vjp_call")

    def roots_divided(jaxpr, rooted_in=()) -> tuple[int, int, list, list]:
        """(square roots, divisions, divisions by a square root) in ``jaxpr``, whose
        invars ``rooted_in`` are square roots; also which of its outvars are."""
        rooted = {v for v, r in zip(jaxpr.invars, rooted_in, strict=False) if r}
        n_roots = n_divs = 0
        bad: list = []
        for e in jaxpr.eqns:
            name = e.primitive.name
            if name == "sqrt":
                n_roots += 1
                rooted.update(e.outvars)
            elif name == "div":
                n_divs += 1
                if not isinstance(e.invars[1], Literal) and e.invars[1] in rooted:
                    bad.append(e)
            for sub in jaxprs_in_params(e.params):
                inner = [v in rooted if not isinstance(v, Literal) else False
                         for v in e.invars] if name in calls else []
                r, d, b, out = roots_divided(sub, inner)
                n_roots, n_divs, bad = n_roots + r, n_divs + d, bad + b
                if name in calls:
                    rooted.update(v for v, o in zip(e.outvars, out, strict=False) if o)
        return n_roots, n_divs, bad, [not isinstance(v, Literal) and v in rooted
                                      for v in jaxpr.outvars]

    scenes = [random_scene(60 + i, ("uniform", "gaussian")[i % 2], 3, 5) for i in range(2)]
    for over in ({}, {"user_noise": 0.1, "user_tremor": 0.01, "collision": "on"}):
        b = bake([precompute(s, s.settings(DEFAULTS, {"start_grid": [2, 2], **over}))
                  for s in scenes])
        args = (Geometry.from_bake(b, np.float32), Params.from_bake(b, np.float32))
        traced = jax.make_jaxpr(partial(shacc_jax.evaluate,
                                        layout=plan(b, shacc_jax.MODES).layout))(*args)
        n_roots, n_divs, bad, _ = roots_divided(traced.jaxpr)
        assert n_roots and n_divs, over  # the walk reads this program
        assert not bad, (over, [str(e)[:200] for e in bad[:3]])
