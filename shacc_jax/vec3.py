"""A stepped lane's 3-vectors as three arrays (x, y, z), not one stacked (3,) array.

XLA's CPU backend computes a stacked result's whole expression once per component,
and batched 3-vector products become library calls: the baseline mode's stepped pass
(50 scenes, 2-core CPU) took 0.30 s with the vectors stacked and 0.26 s on components.
Sums are written out in index order (the same in any batch: ``determinism``).
"""

from __future__ import annotations

from collections.abc import Callable

import jax.numpy as jnp
from jaxtyping import Array

V3 = tuple[Array, Array, Array]


def length(v) -> Array:
    """|v| of a (3,) array or a :data:`V3`."""
    return jnp.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


def of(v: Array) -> V3:
    """The :data:`V3` of a (3,) array."""
    return (v[0], v[1], v[2])


def xyz(component: Callable[[int], Array]) -> V3:
    """The :data:`V3` of ``component(i)``, i = 0, 1, 2."""
    return (component(0), component(1), component(2))
