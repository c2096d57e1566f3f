"""The random numbers of stepped rollouts: a counter-based stream per rollout.

Every number a stepped rollout draws comes from JAX's counter-based threefry stream
keyed by (seed, scene, task, start) (:func:`rollout_key`): its once-drawn numbers
(:func:`rollout_draws`, the key folded with 0), each step's (:func:`step_draws`, with
1, counter k), and its population's draws (``populations``, with 2). Never by batch
position or mode: a rollout draws the same numbers in every mode (modes compare pair by
pair) and in every batch, piece or device it runs in. :func:`user_draws` gives them as
arrays, which the tests' NumPy Automaton replays.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int


def rollout_key(seed: Int[Array, ""], scene_key: Int[Array, ""], task: Int[Array, ""],
                start: Int[Array, ""]) -> Array:
    """The key of one rollout's random numbers: threefry, folded with the scene's own
    number (``Geometry.scene_key``), the task index and the start index.

    >>> import jax.numpy as jnp
    >>> a = rollout_key(jnp.int32(0), jnp.int32(7), jnp.int32(1), jnp.int32(2))
    >>> b = rollout_key(jnp.int32(0), jnp.int32(7), jnp.int32(1), jnp.int32(3))
    >>> bool((jax.random.key_data(a) != jax.random.key_data(b)).any())
    True
    """
    key = jax.random.key(seed.astype(jnp.uint32), impl="threefry2x32")
    for part in (scene_key, task, start):
        key = jax.random.fold_in(key, part.astype(jnp.uint32))
    return key


class StepDraws(NamedTuple):
    """One step's random numbers: the three N(0, 1) components of the wandering hand's
    innovation xi_k (``user_models``: w_{k+1} = a w_k + sqrt(1 - a^2) user_noise xi_k)."""

    xi: Float[Array, "... 3"]


class RolloutDraws(NamedTuple):
    """A rollout's random numbers drawn once: the tremor's unit axis and its phase; the
    wandering hand's first rotation vector in units of ``user_noise`` (three N(0, 1)
    components); the change of mind's two uniform numbers in [0, 1): whether it happens
    (below ``user_switch``) and which other task is headed for first."""

    tremor_axis: Float[Array, "... 3"]
    tremor_phase: Float[Array, "..."]
    noise0: Float[Array, "... 3"]
    switch: Float[Array, "..."]
    other: Float[Array, "..."]


def step_draws(key: Array, k: Int[Array, ""], dtype) -> StepDraws:
    """The random numbers of step k (0 for the step from p_0 to p_1) of the rollout
    ``key``: two threefry blocks, counters (k, 0) and (k, 1) under the rollout's step
    key, give three 32-bit words; each becomes a float in (0, 1) of 24 bits, u = (w >> 8
    + 1/2) / 2^24, and that a N(0, 1) number, sqrt(2) erfinv(2u - 1)."""
    return step_draws_of(step_key(key), k, dtype)


def step_key(key: Array) -> Array:
    """The raw threefry key of a rollout's per-step numbers (``key`` folded with 1)."""
    return jax.random.key_data(jax.random.fold_in(key, 1))


def step_draws_of(raw: Array, k: Int[Array, ""], dtype) -> StepDraws:
    """:func:`step_draws` of the raw key :func:`step_key` gives (what a lane carries)."""
    return _draws_of(_step_words(raw, k), dtype)


def _step_words(raw: Array, k: Int[Array, ""]) -> tuple[Array, Array, Array]:
    """The three 32-bit words of step k: the first word of the threefry blocks with
    counters (k, 0) and (k, 1), then the second word of the first (``threefry_2x32`` of
    the counters [k, k, 0, 1], its first three words)."""
    kk = k.astype(jnp.uint32)
    a0, a1 = _threefry(raw[0], raw[1], kk, jnp.zeros_like(kk))
    b0, _ = _threefry(raw[0], raw[1], kk, jnp.ones_like(kk))
    return a0, b0, a1


# Threefry-2x32 of Salmon et al. (2011), 20 rounds, as JAX computes it.
_ROTATIONS = ((13, 15, 26, 6), (17, 29, 16, 24))


def _threefry(k0: Array, k1: Array, x0: Array, x1: Array) -> tuple[Array, Array]:
    """One threefry-2x32 block, written out: equal bit for bit to ``threefry_2x32``
    (tests/test_users.py), which on a CPU runs as a loop of five iterations, each a
    dozen small loops over the batch."""
    ks = (k0, k1, k0 ^ k1 ^ jnp.uint32(0x1BD11BDA))
    x0, x1 = x0 + ks[0], x1 + ks[1]
    for i in range(5):
        for r in _ROTATIONS[i % 2]:
            x0 = x0 + x1
            x1 = ((x1 << jnp.uint32(r)) | (x1 >> jnp.uint32(32 - r))) ^ x0
        x0, x1 = x0 + ks[(i + 1) % 3], x1 + ks[(i + 2) % 3] + jnp.uint32(i + 1)
    return x0, x1


def _draws_of(words: tuple[Array, Array, Array], dtype) -> StepDraws:
    u = ((jnp.stack(words) >> 8).astype(jnp.float32) + 0.5) * (1.0 / (1 << 24))
    xi = jnp.sqrt(2.0) * jax.scipy.special.erfinv(2.0 * u - 1.0)
    return StepDraws(jnp.moveaxis(xi, 0, -1).astype(dtype))


def rollout_draws(key: Array, dtype) -> RolloutDraws:
    """The numbers the rollout ``key`` draws once: e uniform on the sphere (from z
    uniform in [-1, 1] and an angle uniform in [0, 2 pi)) and phi in [0, 2 pi) (the key
    folded with 0); the wandering hand's first vector (folded with 3); the change of
    mind's two uniform numbers (folded with 4). Folds 1 and 2 are the steps' and the
    populations'."""
    u = jax.random.uniform(jax.random.fold_in(key, 0), (3,), dtype)
    z = 2.0 * u[0] - 1.0
    rho = jnp.sqrt(jnp.maximum(1.0 - z * z, 0.0))
    lon = 2.0 * jnp.pi * u[1]
    switch = jax.random.uniform(jax.random.fold_in(key, 4), (2,), dtype)
    return RolloutDraws(jnp.stack([rho * jnp.cos(lon), rho * jnp.sin(lon), z]),
                        2.0 * jnp.pi * u[2],
                        jax.random.normal(jax.random.fold_in(key, 3), (3,), dtype),
                        switch[0], switch[1])


def user_draws(seed, scene_key, task, start, n_steps: int, dtype=jnp.float32
               ) -> tuple[StepDraws, RolloutDraws]:
    """Every random number of one rollout, as arrays: its first ``n_steps`` steps'
    (:class:`StepDraws`, each (n_steps,)) and its once-drawn ones. What the stepped
    kernel draws, for slow references to replay.

    >>> steps, once = user_draws(0, 7, 1, 2, n_steps=5)
    >>> steps.xi.shape, once.tremor_axis.shape
    ((5, 3), (3,))
    """
    key = rollout_key(*(jnp.asarray(v, jnp.int32) for v in (seed, scene_key, task, start)))
    steps = jax.vmap(lambda k: step_draws(key, k, dtype))(jnp.arange(n_steps, dtype=jnp.int32))
    return steps, rollout_draws(key, dtype)
