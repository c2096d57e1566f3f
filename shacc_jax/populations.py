"""Populations of users: each rollout draws its user's settings from the stream.

A populated user setting (``geometry_precompute.population.POPULATED``) holds a
distribution instead of a value; each rollout draws its value from its own stream
(``streams.rollout_key`` folded with 2), so a rollout's user is the same in every mode
and batch. ``Rollouts.user`` records the draws (:func:`drawn_values`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from geometry_precompute.population import NORMAL, POPULATED, UNIFORM, VALUES

from .flatmap import spread, vmap_leading
from .streams import rollout_key
from .types import Geometry, Params


def population_values(key: Array, x: Params, dtype) -> Float[Array, " U"]:
    """The values of the populated user settings (``POPULATED``, seven, in its order) of
    the rollout ``key`` under one scene's settings ``x``:
    a setting without a population keeps its value; one with draws from a uniform
    number u in [0, 1) of the rollout's stream (``key`` folded with 2, one per
    setting): uniform low + u (high - low); the normal truncated to [low, high] by its
    inverse distribution function on [F(low), F(high)]; a list's entry floor(u n).

    >>> import jax.numpy as jnp
    >>> from shacc_jax.types import Params
    >>> x = Params._make(jnp.zeros(()) for _ in Params._fields)._replace(
    ...     user_noise=jnp.float32(0.3), user_dist=jnp.array([0, 1, 0, 0, 0, 0, 0]),
    ...     user_dist_args=jnp.array([[0, 0, 0, 0], [0.2, 0.4, 0.2, 0.4]] + [[0] * 4] * 5,
    ...                              jnp.float32), user_dist_values=jnp.zeros((7, 16)))
    >>> v = population_values(jax.random.key(0), x, jnp.float32)
    >>> float(v[0]), 0.2 <= float(v[1]) < 0.4
    (0.30000001192092896, True)
    """
    u = jax.random.uniform(jax.random.fold_in(key, 2), (len(POPULATED),), dtype)
    plain = jnp.stack([getattr(x, k) for k in POPULATED]).astype(dtype)
    a = x.user_dist_args.astype(dtype)
    uniform = a[:, 0] + u * (a[:, 1] - a[:, 0])
    mean, sd, lo, hi = a[:, 0], jnp.where(a[:, 1] > 0, a[:, 1], 1.0), a[:, 2], a[:, 3]
    f_lo = jax.scipy.special.ndtr((lo - mean) / sd)
    f_hi = jax.scipy.special.ndtr((hi - mean) / sd)
    normal = jnp.clip(mean + sd * jax.scipy.special.ndtri(f_lo + u * (f_hi - f_lo)), lo, hi)
    n = jnp.maximum(a[:, 0].astype(jnp.int32), 1)
    index = jnp.minimum((u * n.astype(dtype)).astype(jnp.int32), n - 1)
    listed = jnp.take_along_axis(x.user_dist_values.astype(dtype), index[:, None], 1)[:, 0]
    kind = x.user_dist
    return jnp.select([kind == UNIFORM, kind == NORMAL, kind == VALUES],
                      [uniform, normal, listed], plain)


def with_population(key: Array, x: Params, dtype) -> Params:
    """One rollout's settings ``x`` with its drawn values of the populated settings
    (:func:`population_values`)."""
    v = population_values(key, x, dtype)
    return x._replace(**{k: v[i] for i, k in enumerate(POPULATED)})


def drawn_values(geometry: Geometry, params: Params) -> Float[Array, "N T 4"]:
    """Every rollout's drawn user settings of one scene (:func:`population_values`),
    (N, T, 4): what ``Rollouts.user`` holds for each mode."""
    dtype = geometry.starts.dtype
    T = geometry.task_mask.shape[0]

    def one(index, task):
        key = rollout_key(params.user_seed, geometry.scene_key, task, index)
        return population_values(key, params, dtype)

    lanes = (geometry.start_index.shape[0], T)
    return vmap_leading(one, 2)(spread(geometry.start_index, lanes, (0,)),
                                spread(jnp.arange(T, dtype=jnp.int32), lanes, (1,)))
