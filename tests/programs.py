"""The evaluation program as the commands compile it, for tests that call it directly.

The commands choose each program's compiler options by its size
(``shacc_jax.program_cache.quick``): a small CPU program compiles with LLVM's passes
off, a large one with XLA's defaults (it would otherwise run ten times slower than it
took to compile). A test that calls ``shacc_jax.evaluate`` itself gets the same rule
here (``program_cache.compiled_as``, as the commands' ``program_cache.call``), so its
time goes where a user's would."""

from __future__ import annotations

import jax

import shacc_jax
from shacc_jax import program_cache
from shacc_jax.runplan import program_work


def evaluate(geometry, params, layout):
    """``shacc_jax.evaluate``, compiled at the level the commands would choose."""
    work = program_work(geometry, params, layout)
    run = program_cache.compiled_as("evaluate", shacc_jax.evaluate, ("layout",), work,
                                    jax.tree.leaves((geometry, params)))
    return run(geometry, params, layout=layout)
