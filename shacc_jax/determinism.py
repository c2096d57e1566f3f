"""One answer on one machine: a rollout's numbers do not depend on how it was computed.

A sweep evaluates a chunk in one call or, when memory is short, in pieces over the
start grid; it may run on one CPU device or several, be resumed, and load its compiled
program from the cache or compile it afresh. Its tables must come out the same bit for
bit every way, so the arithmetic of one rollout may not depend on how many others share
its compiled program, nor on how XLA vectorised it. Four things made it depend:

- **Reductions.** XLA picks the order of a float reduction from the shapes of the whole
  program: over a trailing axis (``jnp.sum(v * v)`` of a vmapped vector,
  ``jnp.linalg.norm``, ``jnp.dot`` of vmapped vectors, which becomes a batched matrix
  product) and over a leading one too (the meta skill's sums over tasks: measured on
  the CPU, a scene evaluated in pieces of two starts gave other orientations in 3 of
  12 scenes; on an H100, ``jnp.sum`` over the tasks gave 97 692 differing bytes when
  200 scenes were evaluated in batches of two, 538 in batches of 66). The kernels
  therefore sum with explicit additions in index order (``quaternion.ordered_sum``,
  ``dot``, ``norm``), on every backend. This costs the GPU: the closed form evaluates
  10.8 M rollouts in 0.255 s on an H100 with written-out sums over the tasks and in
  0.117 s with ``jnp.sum`` (0.289 s with the sums' operand held in memory by an
  optimization barrier); one answer comes first. Min and max reductions are exact in
  any order.
- **Fused multiply-adds on the CPU.** LLVM contracts a multiply and an add into one
  FMA where it vectorises a loop and not in the loop's scalar remainder, so which
  rounding a rollout got depended on its position in the batch (measured: 1e-7 m in
  a projection, and once a ray interval of a side grasp that collapsed to a point in
  a one-start piece, so a rollout activated 73 steps later). :data:`FLAG` compiles CPU
  programs for AVX without FMA (``--xla_cpu_max_isa=AVX`` on x86-64): the 2-core CPU
  evaluated 43 200 rollouts in 0.151 s with it and 0.156 s without. It is read once,
  when JAX starts its CPU backend, so it is set by ``runtime.configure_runtime``,
  which every entry point calls before JAX starts (a sweep's evaluation worker that
  started JAX first compiled with FMA, and its tables differed from the same sweep's
  with the compilation cache on in 7 092 of 47 296 delta_R values).
- **Approximate reciprocal square roots.** XLA rewrites ``a / sqrt(b)`` into
  ``a * rsqrt(b)``, and its CPU backend computes ``rsqrt`` from the processor's
  approximate instruction (``rsqrtps``) refined by Newton steps. The approximation
  is not specified to the bit, so Intel and AMD processors round it differently;
  ``quaternion.reciprocal_sqrt`` keeps the divisor from matching.
- **Library calls.** What XLA's CPU backend leaves to the C library (``sinf``,
  ``cosf``, ``tanf``, ``atan2f``) is glibc's, which picks an implementation by the
  processor's features: the same on every x86-64 processor with AVX2 and FMA.

With these, every Rollouts field of a batch equals that of the same rollouts evaluated
in any split of its start grid or of its scenes over devices, loaded from the cache
or compiled, bit for bit (tests/test_determinism.py), as long as every split holds two
starts or more (``runplan``). On an H100 the same holds for the splits
(``benchmarks/bench_determinism.py``). On aarch64 (NEON has FMA and XLA has no switch
for it) only the reductions are fixed. What is promised across processors and
versions is in the reference (reference/outputs.md, "Reproducibility").
"""

from __future__ import annotations

FLAG = "--xla_cpu_max_isa=AVX"
X86_64 = ("x86_64", "amd64")


def pinned_flags(flags: str, machine: str) -> tuple[str, bool]:
    """``(XLA_FLAGS with FLAG added, whether the CPU code generation is pinned)``: FLAG
    is added on x86-64 unless the flags choose an ISA already (then they are kept, and
    pinned only if that choice is FLAG's); elsewhere the flags are kept, unpinned.

    >>> pinned_flags("", "x86_64")
    ('--xla_cpu_max_isa=AVX', True)
    >>> pinned_flags("--xla_cpu_max_isa=AVX2", "x86_64")
    ('--xla_cpu_max_isa=AVX2', False)
    >>> pinned_flags("", "aarch64")
    ('', False)
    """
    if "xla_cpu_max_isa" in flags:
        return flags, FLAG in flags.split()
    if machine.lower() not in X86_64:
        return flags, False
    return f"{flags} {FLAG}".strip(), True
