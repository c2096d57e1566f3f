"""Sine and cosine that XLA's CPU backend vectorises (reference/model, "Simulated users").

XLA lowers ``jnp.sin`` and ``jnp.cos`` to LLVM's vector intrinsics, which its CPU
backend turns into one libm call per element: 4 to 10 ns an element on the 2-core
benchmark machine (more for larger arguments), against about 1 ns for a polynomial
written as plain arithmetic, which XLA fuses and vectorises. The stepped users take
five of them a step, so :func:`sincos` gives float32 the polynomial: Cody and Waite's
reduction by pi/2 (pi/2 split in three parts, the first two exact in few bits) and
Cephes' minimax polynomials of ``sinf`` and ``cosf`` on [-pi/4, pi/4]. Other dtypes
(float64 under x64) take ``jnp.sin`` and ``jnp.cos``.

Accuracy (tests/test_trig.py): within 1e-7 of the float64 sine and cosine for float32
arguments while the reduction is exact, the quadrant count below 2^13 (|x| < 12 867;
``jnp.sin``: 3.3e-8); beyond, it loses bits (1e-6 at 1e5). The callers keep their
arguments small: angles of at most a few radians and the tremor's phase reduced to
whole cycles first.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array

# pi/2 = PIO2_1 + PIO2_2 + PIO2_3: PIO2_1 and PIO2_2 have 8 and 11 significant bits, so
# j * PIO2_1 and j * PIO2_2 are exact in float32 for |j| < 2^13 (Cephes' DP1..DP3 for
# pi/4, doubled).
PIO2_1 = 1.5703125
PIO2_2 = 4.837512969970703125e-4
PIO2_3 = 7.54978995489188216e-8
# Cephes' sinf and cosf: sin r = r + r^3 S(r^2), cos r = 1 - r^2 / 2 + r^4 C(r^2) on
# [-pi/4, pi/4].
SIN = (-1.6666654611e-1, 8.3321608736e-3, -1.9515295891e-4)
COS = (4.166664568298827e-2, -1.388731625493765e-3, 2.443315711809948e-5)


def sincos(x: Array) -> tuple[Array, Array]:
    """(sin x, cos x), elementwise; float32 by the polynomials of the module docstring.

    >>> import jax.numpy as jnp
    >>> s, c = sincos(jnp.float32(jnp.pi / 6))
    >>> round(float(s), 6), round(float(c), 6)
    (0.5, 0.866025)
    """
    x = jnp.asarray(x)
    if x.dtype != jnp.float32:
        return jnp.sin(x), jnp.cos(x)
    j = jnp.round(x * (2.0 / jnp.pi))
    r = ((x - j * PIO2_1) - j * PIO2_2) - j * PIO2_3
    z = r * r
    s = r + r * z * (SIN[0] + z * (SIN[1] + z * SIN[2]))
    c = 1.0 - 0.5 * z + z * z * (COS[0] + z * (COS[1] + z * COS[2]))
    quadrant = j.astype(jnp.int32) & 3
    sin = jnp.where(quadrant == 0, s, jnp.where(quadrant == 1, c,
                                                jnp.where(quadrant == 2, -s, -c)))
    cos = jnp.where(quadrant == 0, c, jnp.where(quadrant == 1, -s,
                                                jnp.where(quadrant == 2, -c, s)))
    return sin, cos
