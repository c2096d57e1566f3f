"""A rollout's numbers do not depend on the batch it is evaluated in.

A sweep evaluates a chunk in one call or, when memory is short, in pieces over the
start grid; a resumed sweep may run on another machine, with other devices. Its
tables must come out the same bit for bit, so the arithmetic of one rollout may not
depend on how many others share its compiled program. Two things made it depend:

- **Reductions.** XLA picks the order of a float reduction over a trailing axis
  (``jnp.sum(v * v)`` of a vmapped vector, ``jnp.linalg.norm``, and ``jnp.dot`` of
  vmapped vectors, which becomes a batched matrix product) from the shapes of the
  whole program. The kernels therefore sum vectors' components with explicit additions
  in index order (``quaternion.ordered_sum``, ``dot``, ``norm``). A sum over the
  leading axis of an array (the meta skill's sums over tasks, laid out (T, ...))
  adds in index order for each element on both backends, and stays ``jnp.sum``:
  written out, it made the GPU evaluation twice as slow (0.25 against 0.12 s for
  10.8 M rollouts on an H100). Min and max reductions are exact in any order.
- **Fused multiply-adds on the CPU.** LLVM contracts a multiply and an add into one
  FMA where it vectorises a loop and not in the loop's scalar remainder, so which
  rounding a rollout got depended on its position in the batch (measured: 1e-7 m in
  a projection, and once a ray interval of a side grasp that collapsed to a point in
  a one-start piece, so a rollout activated 73 steps later). :func:`pin_cpu_codegen`
  compiles CPU programs for AVX without FMA (``--xla_cpu_max_isa=AVX`` on x86-64):
  the 2-core CPU evaluated 43 200 rollouts in 0.151 s with it and 0.156 s without.

With both, every Rollouts field of a batch equals that of the same rollouts
evaluated in any split of its start grid, bit for bit (tests/test_determinism.py),
as long as every split holds two starts or more (``runplan``). On an H100 the
same holds (``benchmarks/bench_determinism.py``: 0 differing bytes over 200 scenes in
every split; before these changes 53 321 in pieces of two starts). On aarch64 (NEON
has FMA and XLA has no switch for it) only the reductions are fixed.
"""

from __future__ import annotations

import os
import platform

FLAG = "--xla_cpu_max_isa=AVX"


def pin_cpu_codegen() -> bool:
    """Add :data:`FLAG` to ``XLA_FLAGS`` unless the user chose an ISA there already.
    Effective only before JAX starts its CPU backend (importing ``shacc_jax`` does
    this first); returns whether the flag is in place."""
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_cpu_max_isa" in flags:
        return FLAG in flags.split()
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return False
    os.environ["XLA_FLAGS"] = f"{flags} {FLAG}".strip()
    return True
