"""An independent estimate of C from the SDFs (reference/model).

Points are drawn uniformly inside each space i (exact inverse-CDF sampling per
kind); the fraction f_ij of them inside space j estimates V(p_i ∩ p_j) / V_i.
Each pair's intersection volume is the mean of its two estimates
(V_i f_ij + V_j f_ji) / 2, and C = sum_{i<j} V_ij / sum_i V_i with the exact
volumes. Standard error about sqrt(f (1 - f) / n) per pair.
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp

from . import quaternion as quat
from . import shapes
from .types import Spaces


def _sample_local(kind, dims, u):
    theta = 2.0 * jnp.pi * u[..., 1]
    r_cyl = dims[0] * jnp.sqrt(u[..., 0])
    cyl = jnp.stack([r_cyl * jnp.cos(theta), r_cyl * jnp.sin(theta),
                     dims[1] * (u[..., 2] - 0.5)], -1)
    z = dims[0] * jnp.cbrt(u[..., 2])
    r_cone = z * jnp.tan(jnp.clip(dims[1], 1e-3, 1.5)) * jnp.sqrt(u[..., 0])
    cone = jnp.stack([r_cone * jnp.cos(theta), r_cone * jnp.sin(theta), z], -1)
    box = (2.0 * u - 1.0) * dims[None]
    sel = jnp.where(kind == shapes.BOX, 2, jnp.where(kind == shapes.CONE, 1, 0))
    return jnp.select([sel == 0, sel == 1], [cyl, cone], box)


@partial(jax.jit, static_argnames=("n_samples",))
def clutteredness_mc(spaces: Spaces, mask, key, n_samples: int = 1 << 16):
    """Monte Carlo estimate of one scene's clutteredness C (module docstring), the
    check of the mesh booleans.

    :param spaces: the scene's T spaces (:class:`~shacc_jax.types.Spaces`: kind (T,),
        center (T, 3) m, quat (T, 4) w first, dims (T, 3) m or rad).
    :param mask: (T,) bool, the real tasks (padding False).
    :param key: a JAX PRNG key.
    :param n_samples: points drawn per space.
    :returns: C as a scalar array (dimensionless).

    Example::

        g = shacc_jax.Geometry.from_bake(bake(results))
        spaces = shacc_jax.Spaces(g.kind[0], g.center_init[0], g.quat_init[0], g.dims_init[0])
        shacc_jax.clutteredness_mc(spaces, g.task_mask[0], jax.random.key(0))  # ~ C_init
    """
    T = mask.shape[0]
    keys = jax.random.split(key, T)
    prepared = shapes.prepare_all(*spaces)

    def inside_fractions(kind, center, q, dims, k):
        u = jax.random.uniform(k, (n_samples, 3), dtype=center.dtype)
        local = _sample_local(kind, dims, u)
        world = center[None] + local @ quat.to_matrix(q).T
        sd = jax.vmap(lambda p: shapes.all_sdf(prepared, p))(world)
        return jnp.mean(sd <= 0.0, axis=0)

    frac = jax.vmap(inside_fractions)(spaces.kind, spaces.center, spaces.quat, spaces.dims, keys)
    vol = jnp.where(mask, jax.vmap(shapes.volume)(spaces.kind, spaces.dims), 0.0)
    pair = 0.5 * (vol[:, None] * frac + vol[None, :] * frac.T)
    valid = mask[:, None] & mask[None, :] & jnp.triu(jnp.ones((T, T), bool), 1)
    return jnp.sum(jnp.where(valid, pair, 0.0)) / jnp.sum(vol)
