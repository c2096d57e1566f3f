"""vmap over several leading axes as one, and several batches stacked as one.

Every level of ``jax.vmap`` batches each primitive of the mapped function once more
while JAX traces it, and each loop body (``while_loop``, ``scan``) once more as a
whole. A function mapped over scenes, starts and tasks by three nested vmaps is
therefore traced about three times over; mapped once over the S x N x T lanes it is
traced once.

The lanes compute the same operations either way, but XLA may simplify the two
programs differently: mapped as one axis, the activation pass moved 15 recorded
fields by an ulp in a few rollouts, so it keeps its nested vmaps
(``automaton.activation_pass_on``). Where this module is used, every recorded field
(``tests/data/evaluation_reference.npz``) came out the same bits, compared byte for
byte.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from jaxtyping import Array


def vmap_leading(fn: Callable[..., Any], n: int) -> Callable[..., Any]:
    """``fn`` mapped over the leading ``n`` axes of every leaf of its arguments, which
    must all have those ``n`` axes (give shared values by closure, and values that vary
    along some of the axes only by :func:`spread`). The outputs get the ``n`` axes back."""

    def mapped(*args):
        lead = jax.tree.leaves(args)[0].shape[:n]
        size = math.prod(lead)
        flat = jax.tree.map(lambda a: a.reshape(size, *a.shape[n:]), args)
        return jax.tree.map(lambda a: a.reshape(*lead, *a.shape[1:]), jax.vmap(fn)(*flat))

    return mapped


def spread(a: Array, lead: tuple[int, ...], axes: tuple[int, ...]) -> Array:
    """``a``, whose leading axes are the ``axes`` of ``lead`` (in order), broadcast to
    all of ``lead``: e.g. per-start values (N, ...) spread over (N, T) lanes with
    ``axes=(0,)``."""
    rest = a.shape[len(axes):]
    shape = tuple(lead[i] if i in axes else 1 for i in range(len(lead)))
    return jnp.broadcast_to(a.reshape(*shape, *rest), (*lead, *rest))


def stacked(*trees: Any) -> Any:
    """The batches ``trees`` (pytrees of one structure) as one: each leaf concatenated
    along its leading axis, in order. :func:`unstacked` splits the result of a function
    mapped over the joined batch back."""
    return jax.tree.map(lambda *xs: jnp.concatenate(xs), *trees)


def unstacked(tree: Any, n: int) -> list[Any]:
    """``tree`` split into ``n`` equal parts along every leaf's leading axis: the
    inverse of :func:`stacked` for ``n`` batches of one size."""
    size = jax.tree.leaves(tree)[0].shape[0] // n
    return [jax.tree.map(lambda a, i=i: a[i * size:(i + 1) * size], tree) for i in range(n)]
