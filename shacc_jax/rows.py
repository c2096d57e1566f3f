"""One row of an array, or of every leaf of a pytree, at a traced index.

The stepped programs read a lane's scene, start and task out of the batch's arrays
thousands of times while they are traced. ``a[i]`` with a traced ``i`` goes through
jnp's general indexing (negative indices wrapped, then a dynamic slice): under vmap
that cost 2.3-3.4 ms of tracing a call on the 2-core CPU, against 0.19-0.23 ms for
``lax.dynamic_index_in_dim`` (the same gather once batched). Every index read here
lies in range (a scene, start or task of the batch), where the two agree: out of
range, both clamp to the nearest row; only a negative index would differ (jnp
counts it from the end).
"""

from __future__ import annotations

from typing import TypeVar

import jax
from jax import lax
from jaxtyping import Array, Int

T = TypeVar("T")


def row(a: Array, i: Int[Array, ""] | int) -> Array:
    """``a[i]`` along the leading axis, for ``0 <= i < a.shape[0]``."""
    return lax.dynamic_index_in_dim(a, i, 0, keepdims=False)


def rows(tree: T, i: Int[Array, ""] | int) -> T:
    """:func:`row` of every leaf of ``tree``."""
    return jax.tree.map(lambda a: row(a, i), tree)
