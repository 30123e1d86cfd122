"""Parametrisations of jrigid.fit.params: physical for every input, invertible."""

import hypothesis.strategies as st
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from scipy.spatial.transform import Rotation

from jrigid import inertia
from jrigid.fit import params

extreme = st.one_of(
    st.floats(-1e308, 1e308, allow_nan=False, allow_infinity=False),
    st.sampled_from([0.0, -0.0, 1e-300, -1e-300, 1e308, -1e308, 745.0, -745.0, 40.0, -40.0]),
)

_ratios = jax.jit(params.moment_ratios)
_moments = jax.jit(params.moments)
_tensor = jax.jit(params.inertia_tensor)


@settings(max_examples=50, deadline=None)
@given(st.lists(extreme, min_size=2, max_size=2), st.floats(1e-6, 1e6))
def test_moment_ratios_always_physical(raw, trace):
    m = _ratios(jnp.asarray(raw), trace)
    inertia.validate(m, kind="moments")  # raises if not physical
    np.testing.assert_allclose(float(jnp.sum(m)), trace, rtol=1e-12)
    i1, i2, i3 = np.asarray(m)
    assert min(i1 + i2 - i3, i1 + i3 - i2, i2 + i3 - i1) > 0


@settings(max_examples=50, deadline=None)
@given(st.lists(extreme, min_size=3, max_size=3), st.lists(extreme, min_size=4, max_size=4))
def test_moments_and_tensor_always_physical(raw, raw_axes):
    m = _moments(jnp.asarray(raw))
    assert bool(jnp.all(jnp.isfinite(m)))
    inertia.validate(m, kind="moments")
    t = _tensor(jnp.asarray(raw), jnp.asarray(raw_axes))
    inertia.validate(t, kind="tensor")
    # the tensor's eigenvalues are the moments
    np.testing.assert_allclose(
        np.sort(np.linalg.eigvalsh(np.asarray(t))), np.sort(np.asarray(m)), rtol=1e-9
    )


def test_float32_extremes_physical(float32):
    for raw in ([1e38, -1e38, 0.0], [-1e38, -1e38, 1e38], [0.0, 0.0, -1e38], [3e4, -3e4, 88.0]):
        m = params.moments(jnp.asarray(raw, dtype=jnp.float32))
        assert m.dtype == jnp.float32
        inertia.validate(m, kind="moments")


@pytest.mark.parametrize(
    "moments",
    [
        inertia.box(1.0, 1.0, 0.6, 0.3),
        inertia.solid_cylinder(2.0, 0.5, 0.1),
        inertia.ellipsoid(1.0, 0.6, 0.4, 0.25),
        jnp.array([1.0, 1.0, 1.0]),
    ],
)
def test_inverse_round_trip(moments):
    m = jnp.asarray(moments)
    m = jnp.diagonal(m) if m.ndim == 2 else m
    np.testing.assert_allclose(
        params.moment_ratios(params.moment_ratios_raw(m), jnp.sum(m)), m, rtol=1e-12
    )
    np.testing.assert_allclose(params.moments(params.moments_raw(m)), m, rtol=1e-12)


def test_inverse_rejects_nonphysical():
    with pytest.raises(ValueError, match="triangle"):
        params.moment_ratios_raw(jnp.array([2.0, 1.0, 2.0 / 3.0]))


def test_unit_quaternion_matches_scipy_and_zero_is_safe():
    raw = jnp.array([0.3, -1.2, 0.5, 2.0])
    q = params.unit_quaternion(raw)
    ref = Rotation.from_quat(np.asarray(raw), scalar_first=True).as_quat(scalar_first=True)
    np.testing.assert_allclose(np.abs(np.dot(q, ref)), 1.0, rtol=1e-14)
    np.testing.assert_allclose(
        params.unit_quaternion(jnp.array([1e300, 1e300, 0, 0]))[:2], [2**-0.5, 2**-0.5], rtol=1e-14
    )
    np.testing.assert_array_equal(params.unit_quaternion(jnp.zeros(4)), [1.0, 0, 0, 0])
    g = jax.jacfwd(params.unit_quaternion)(jnp.zeros(4))
    assert bool(jnp.all(jnp.isfinite(g)))


def test_tensor_axes_are_columns():
    raw_axes = jnp.asarray(Rotation.from_euler("zyx", [0.4, -0.3, 1.1]).as_quat(scalar_first=True))
    raw_m = params.moments_raw(jnp.array([1.0, 2.0, 2.5]))
    t = np.asarray(params.inertia_tensor(raw_m, raw_axes))
    r = Rotation.from_quat(np.asarray(raw_axes), scalar_first=True).as_matrix()
    for i, mi in enumerate([1.0, 2.0, 2.5]):
        np.testing.assert_allclose(t @ r[:, i], mi * r[:, i], rtol=1e-10, atol=1e-12)


def test_positive_clips_but_stays_positive():
    assert float(params.positive(-1e308)) > 0
    assert np.isfinite(float(params.positive(1e308)))
    np.testing.assert_allclose(params.positive(params.positive_raw(3.7, 2.0), 2.0), 3.7)


def test_shape_errors():
    with pytest.raises(ValueError, match=r"\(\.\.\., 2\)"):
        params.moment_ratios(jnp.zeros(3))
    with pytest.raises(ValueError, match=r"\(\.\.\., 4\)"):
        params.unit_quaternion(jnp.zeros(3))
