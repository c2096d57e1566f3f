"""The exported-program cache gives the same evaluation as the plain jit, survives a
damaged entry, and keys on shapes (a new shape is a new entry); ``ahead`` compiles a
list of calls' programs side by side, once each."""

from __future__ import annotations

import logging
import os
import time
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import memory_maps

import shacc_jax
from shacc_jax import program_cache


def evaluate(baked):
    return shacc_jax.run(baked).evaluation  # through the program cache, NumPy results


def test_exported_program_equals_plain_jit(shipped_bake, tmp_path, caplog):
    """The exported program gives the plain jit's answers: traced and stored, read back
    as a new process would, and rebuilt over a damaged entry. Each program a process
    prepares is told on the programs' logger, traced or read back."""
    caplog.set_level(logging.INFO, logger=program_cache.LOG.name)
    previous = program_cache.get_dir()  # an earlier in-process `main()` may have set one
    program_cache.set_dir(None)
    plain = evaluate(shipped_bake)
    program_cache.set_dir(tmp_path)
    program_cache.forget_loaded()
    # Another version's program, unused for two days: the first store removes it.
    stale = tmp_path / "export-evaluate-0000000000000000-a.bin"
    stale.write_bytes(b"old")
    os.utime(stale, (time.time() - 2 * 86400, time.time() - 2 * 86400))
    try:
        caplog.clear()
        first = evaluate(shipped_bake)          # exports and stores
        told = [r.getMessage() for r in caplog.records]
        assert len(told) == 2 and told[0].startswith("evaluate program (")
        assert told[0].endswith(": preparing") and " traced in " in told[1]
        assert not stale.exists()
        (entry,) = tmp_path.glob("export-evaluate-*.bin")
        program_cache.forget_loaded()            # as a new process would
        caplog.clear()
        second = evaluate(shipped_bake)         # deserialises
        assert " read back in " in caplog.records[-1].getMessage()
        entry.write_bytes(b"damaged")
        program_cache.forget_loaded()
        third = evaluate(shipped_bake)          # rebuilt over the damaged entry
        assert entry.read_bytes() != b"damaged"
    finally:
        program_cache.set_dir(previous)
        program_cache.forget_loaded()
    for other in (first, second, third):
        for a, b in zip(jax.tree.leaves(plain), jax.tree.leaves(other), strict=True):
            np.testing.assert_array_equal(a, b)


def test_new_shapes_make_a_new_entry(shipped_results, tmp_path):
    from geometry_precompute import bake

    previous = program_cache.get_dir()
    program_cache.set_dir(tmp_path)
    program_cache.forget_loaded()
    try:
        evaluate(bake(shipped_results[:2]))
        evaluate(bake(shipped_results[2:4]))  # same shapes: same entry
        assert len(list(tmp_path.glob("export-*.bin"))) == 1
        evaluate(bake(shipped_results[:3]))   # three scenes: a new one
        assert len(list(tmp_path.glob("export-*.bin"))) == 2
    finally:
        program_cache.set_dir(previous)
        program_cache.forget_loaded()


def test_lean_locations_drop_the_stack_frames(monkeypatch):
    """After compile_cache.lean_locations a traced program names no Python file in its
    source locations (XLA formats them into annotations at every load), a user's
    JAX_TRACEBACK_IN_LOCATIONS_LIMIT wins, and the exported program's key changes with
    the setting (an entry traced with frames is not reused without them)."""
    from sweeps import compile_cache

    def locations() -> str:  # a new function each time: JAX reuses a function's trace
        return jax.jit(lambda x: x * 2.0 + 1.0).lower(np.ones(3, np.float32)).as_text(
            debug_info=True)

    here = __file__.rsplit("/", 1)[-1]
    leaves, tree = jax.tree.flatten((np.ones(3, np.float32),))
    previous = jax.config.jax_traceback_in_locations_limit
    try:
        jax.config.update("jax_traceback_in_locations_limit", 10)
        assert here in locations()
        framed = program_cache.program_key("f", (), tree, leaves)
        monkeypatch.setenv(compile_cache.LOCATIONS_ENV, "10")
        compile_cache.lean_locations()  # the user's setting: left alone
        assert jax.config.jax_traceback_in_locations_limit == 10
        monkeypatch.delenv(compile_cache.LOCATIONS_ENV)
        compile_cache.lean_locations()
        assert jax.config.jax_traceback_in_locations_limit == 0
        assert here not in locations()
        assert program_cache.program_key("f", (), tree, leaves) != framed
    finally:
        jax.config.update("jax_traceback_in_locations_limit", previous)


def test_the_python_api_keeps_its_programs_too(tmp_path):
    """A script or notebook that evaluates through ``sweeps.pipeline`` (no ``shacc``
    command) turns the compile cache on by itself; SHACC_COMPILE_CACHE=off turns it off."""
    import os
    import subprocess
    import sys

    script = ("from geometry_precompute import load_scene, precompute, shipped_scene_paths\n"
              "from sweeps.pipeline import evaluate_results\n"
              "r = precompute(load_scene(shipped_scene_paths()[0]), {'start_grid': [2, 2]})\n"
              "evaluate_results([r], modes=('baseline',))\n")
    env = {k: v for k, v in os.environ.items() if k != "SHACC_COMPILE_CACHE"}
    env.update(JAX_PLATFORMS="cpu", XDG_CACHE_HOME=str(tmp_path / "home"))
    subprocess.run([sys.executable, "-c", script], env={**env, "SHACC_COMPILE_CACHE": "off"},
                   check=True, timeout=300)
    assert not (tmp_path / "home").exists()
    subprocess.run([sys.executable, "-c", script], env=env, check=True, timeout=300)
    compiled = tmp_path / "home" / "shacc" / "compiled"
    assert list(compiled.glob("programs/export-*.bin"))
    assert list(compiled.glob("xla/*-sealed"))


def test_released_programs_give_back_their_memory_maps(shipped_results):
    """Each compiled program maps its code into the process in many regions; a process
    that kept every program crashed in XLA's compiler once it passed the kernel's limit
    (vm.max_map_count). release_compiled gives the regions back, and the evaluation
    after it is the same."""
    from geometry_precompute import bake

    release_compiled = program_cache.release_compiled
    release_compiled()
    before = memory_maps()
    first = evaluate(bake(shipped_results[:1]))
    held = memory_maps()
    assert held - before > 100  # the program's code, held by JAX's caches
    released = []
    for _ in range(3):  # compiled (or loaded) and released again: nothing accumulates
        release_compiled()
        released.append(memory_maps())
        again = evaluate(bake(shipped_results[:1]))
        for a, b in zip(jax.tree.leaves(first), jax.tree.leaves(again), strict=True):
            np.testing.assert_array_equal(a, b)
    assert released[0] - before < (held - before) / 2
    assert max(released) - min(released) < 60, released


@partial(jax.jit, static_argnames=("k",))
def scaled_dot(x, y, k):
    if x.shape[0] == 5:
        raise ValueError("five rows are refused")  # at trace time, in ahead()'s thread
    return {"dot": jnp.sum(x * y) * k}


@pytest.mark.parametrize("exported", [False, True])
def test_ahead_compiles_each_program_once_side_by_side(tmp_path, exported):
    """ahead() compiles every distinct program of a list of calls in threads, in the
    caller's x64 mode; the calls that follow compile nothing; a trace's error is raised
    by its own future only."""
    compiles = []

    def listen(event, duration, **kwargs):
        if event == "/jax/core/compile/backend_compile_duration":
            compiles.append(duration)

    previous = program_cache.get_dir()
    program_cache.set_dir(tmp_path if exported else None)
    program_cache.forget_loaded()
    jax.monitoring.register_event_duration_secs_listener(listen)
    rng = np.random.default_rng(0)
    calls = [(rng.random((n, 3)), rng.random((n, 3))) for n in (2, 4, 2, 5)]
    try:
        with jax.enable_x64(True):
            with program_cache.ahead("ahead-test", scaled_dot, {"k": 3},
                                     [(args, None) for args in calls]) as ready:
                assert len(ready) == 4 and ready[0] is ready[2]  # one program, one future
                for f in ready[:3]:
                    f.result()
                with pytest.raises(ValueError, match="five rows"):
                    ready[3].result()
            assert len(compiles) == 2
            got = [program_cache.call("ahead-test", scaled_dot, {"k": 3}, args, {"dot": 0})
                   for args in calls[:3]]
        assert len(compiles) == 2  # the calls found their programs compiled
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)
        program_cache.set_dir(previous)
        program_cache.forget_loaded()
    for (x, y), out in zip(calls, got, strict=False):
        assert out["dot"].dtype == np.float64  # compiled in x64, as the caller runs
        np.testing.assert_allclose(out["dot"], 3 * np.sum(x * y), rtol=1e-12)


def test_xla_entries_nothing_loaded_for_a_week_are_removed(tmp_path):
    """JAX's keys do not say which code made an executable, so ``xla/`` loses the
    entries nothing has loaded for ``XLA_STALE_AFTER_S``: the first entry a process
    stores removes them and keeps a younger one; loading an entry touches it, so an
    entry in use is never old."""
    import subprocess
    import sys

    from sweeps import compile_cache

    folder = tmp_path / "compiled"
    xla = folder / "xla"
    xla.mkdir(parents=True)
    now, week = time.time(), compile_cache.XLA_STALE_AFTER_S
    old, young = xla / "jit_old-1234-sealed", xla / "jit_young-5678-sealed"
    for path, age in ((old, week + 3600), (young, week - 3600)):
        path.write_bytes(b"x")
        os.utime(path, (now - age, now - age))
    script = ("from sweeps import compile_cache\n"
              "compile_cache.enable()\n"
              "import jax, jax.numpy as jnp\n"
              "print(jax.jit(lambda x: 2 * x + 1)(jnp.arange(3.0)).tolist())\n")
    env = {**os.environ, "JAX_PLATFORMS": "cpu", "SHACC_COMPILE_CACHE": str(folder)}

    def run() -> None:
        out = subprocess.run([sys.executable, "-c", script], env=env, check=True,
                             timeout=300, capture_output=True, text=True).stdout
        assert out.strip() == "[1.0, 3.0, 5.0]"

    run()
    assert not old.exists() and young.exists()
    stored = set(xla.glob("*-sealed")) - {young}
    assert stored  # the program's executable was stored
    for path in stored:  # ... and then left unused for longer than the limit
        os.utime(path, (now - 2 * week, now - 2 * week))
    run()  # loads it (nothing new is stored, so nothing is pruned)
    assert set(xla.glob("*-sealed")) - {young} == stored
    assert all(time.time() - p.stat().st_mtime < 600 for p in stored)  # touched on load
