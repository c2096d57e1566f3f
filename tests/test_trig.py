"""The vectorisable sine and cosine (``shacc_jax.trig``) against float64 libm."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from shacc_jax.trig import sincos

sincos_jit = jax.jit(sincos)


def test_float32_is_within_1e_7_of_float64():
    """Dense and random arguments over the range the stepped users use (angles, the
    tremor's reduced phase) and on to where the reduction stops being exact."""
    rng = np.random.default_rng(0)
    x = np.concatenate([np.linspace(-20.0, 20.0, 400_001),
                        rng.uniform(-12_800, 12_800, 400_000)]).astype(np.float32)
    s, c = (np.asarray(v) for v in sincos_jit(jnp.asarray(x)))
    assert s.dtype == c.dtype == np.float32
    x64 = x.astype(np.float64)
    assert np.abs(s - np.sin(x64)).max() <= 1e-7
    assert np.abs(c - np.cos(x64)).max() <= 1e-7
    # Exact where the reduction leaves no remainder.
    zero = np.asarray(sincos_jit(jnp.zeros(1, jnp.float32)))
    np.testing.assert_array_equal(zero, [[0.0], [1.0]])


@given(st.floats(-1e4, 1e4, width=32))
def test_float32_identities(x):
    """sin^2 + cos^2 = 1 and the quadrant's signs, for any float32 argument."""
    s, c = (float(v) for v in sincos_jit(jnp.float32(x)))
    assert abs(s * s + c * c - 1.0) < 4e-7
    assert abs(s - np.sin(np.float64(np.float32(x)))) <= 1e-7
    assert abs(c - np.cos(np.float64(np.float32(x)))) <= 1e-7


def test_other_dtypes_are_libm():
    """float64 (x64) takes jnp.sin and jnp.cos, bit for bit."""
    with jax.enable_x64(True):
        x = jnp.linspace(-50.0, 50.0, 1001, dtype=jnp.float64)
        s, c = sincos_jit(x)
        np.testing.assert_array_equal(np.asarray(s), np.asarray(jnp.sin(x)))
        np.testing.assert_array_equal(np.asarray(c), np.asarray(jnp.cos(x)))
