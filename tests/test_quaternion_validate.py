"""Bad input: clear errors from the checks, documented values from the conversions."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import jrigid.quaternion as jq

UNIT = np.array([0.5, 0.5, -0.5, 0.5])
ROT = Rotation.from_rotvec([0.3, -0.2, 1.0]).as_matrix()


def test_check_quaternion_accepts_valid_input():
    q = jq.check_quaternion(UNIT)
    np.testing.assert_array_equal(q, UNIT)
    batch = Rotation.random(6, rng=np.random.default_rng(0)).as_quat(scalar_first=True)
    np.testing.assert_array_equal(
        jq.check_quaternion(batch.reshape(3, 1, 2, 4)), batch.reshape(3, 1, 2, 4)
    )
    np.testing.assert_array_equal(jq.check_quaternion(3 * UNIT, unit=False), 3 * UNIT)
    # Within tolerance.
    jq.check_quaternion(UNIT * (1 + 1e-8))
    jq.check_quaternion(UNIT * 1.01, atol=0.02)


@pytest.mark.parametrize(
    ("q", "kwargs", "match"),
    [
        (np.zeros(4), {}, "zero quaternion"),
        (np.zeros(4), {"unit": False}, "zero quaternion"),
        (2 * UNIT, {}, "not unit length"),
        (UNIT * (1 + 1e-3), {}, "not unit length"),
        (np.array([np.nan, 0.0, 0.0, 1.0]), {}, "non-finite"),
        (np.array([np.inf, 0.0, 0.0, 1.0]), {"unit": False}, "non-finite"),
        (np.stack([UNIT, np.zeros(4)]), {}, "zero quaternion"),
        (np.zeros(3), {}, r"shape \(\.\.\., 4\)"),
        (np.float64(1.0), {}, r"shape \(\.\.\., 4\)"),
    ],
)
def test_check_quaternion_raises_value_error(q, kwargs, match):
    with pytest.raises(ValueError, match=match):
        jq.check_quaternion(q, **kwargs)


def test_check_quaternion_inside_jit_and_vmap():
    f = eqx.filter_jit(lambda q: jq.to_matrix(jq.check_quaternion(q)))
    np.testing.assert_allclose(f(UNIT), jq.to_matrix(UNIT), atol=1e-15)
    with pytest.raises(eqx.EquinoxRuntimeError, match="zero quaternion"):
        jax.block_until_ready(f(jnp.zeros(4)))
    # Under plain jax.jit, JAX wraps the error in its own type; the message is kept.
    with pytest.raises(Exception, match="not unit length"):
        jax.block_until_ready(jax.jit(jq.check_quaternion)(2 * UNIT))
    g = eqx.filter_jit(jax.vmap(jq.check_quaternion))
    with pytest.raises(eqx.EquinoxRuntimeError, match="zero quaternion"):
        jax.block_until_ready(g(np.stack([UNIT, np.zeros(4)])))
    # A traced tolerance (its value cannot be formatted into the message).
    tol = jax.jit(lambda a: jq.check_quaternion(UNIT, atol=a))(1e-6)
    np.testing.assert_array_equal(tol, UNIT)
    with pytest.raises(Exception, match="not unit length"):
        jax.block_until_ready(jax.jit(lambda a: jq.check_quaternion(2 * UNIT, atol=a))(1e-6))
    with pytest.raises(Exception, match="not orthogonal"):
        jax.block_until_ready(jax.jit(lambda a: jq.check_rotation_matrix(2 * np.eye(3), atol=a))(
            1e-6))
    # Under grad, a valid input passes and the check is transparent.
    grad = jax.grad(lambda q: jnp.sum(jq.check_quaternion(q) ** 2))(jnp.asarray(UNIT))
    np.testing.assert_allclose(grad, 2 * UNIT)


def test_check_rotation_matrix():
    np.testing.assert_array_equal(jq.check_rotation_matrix(ROT), ROT)
    jq.check_rotation_matrix(np.stack([ROT, np.eye(3)]))
    with pytest.raises(ValueError, match="not orthogonal"):
        jq.check_rotation_matrix(ROT * 1.01)
    with pytest.raises(ValueError, match="not orthogonal"):
        jq.check_rotation_matrix(np.stack([ROT, ROT + 1e-3]))
    with pytest.raises(ValueError, match="det R"):
        jq.check_rotation_matrix(-ROT)  # a reflection: orthogonal, det = -1
    with pytest.raises(ValueError, match="non-finite"):
        jq.check_rotation_matrix(np.full((3, 3), np.nan))
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 3, 3\)"):
        jq.check_rotation_matrix(np.eye(4))
    f = eqx.filter_jit(lambda m: jq.from_matrix(jq.check_rotation_matrix(m)))
    np.testing.assert_allclose(jnp.abs(f(ROT)), np.abs(jq.from_matrix(ROT)), atol=1e-15)
    with pytest.raises(eqx.EquinoxRuntimeError, match="not orthogonal"):
        jax.block_until_ready(f(2 * ROT))


def test_check_float32_tolerance(float32):
    q = jnp.asarray(UNIT, jnp.float32) * (1 + 5e-5)
    assert jq.check_quaternion(q).dtype == jnp.float32
    assert jq.default_atol(jnp.float32) == 1e-4
    with pytest.raises(ValueError, match="not unit length"):
        jq.check_quaternion(q * 1.01)


def test_documented_values_for_bad_input():
    """The conversions do not raise: zero quaternions give NaN (documented)."""
    zero = jnp.zeros(4)
    for f in (jq.normalize, jq.inverse, jq.to_matrix, jq.passive_matrix):
        assert np.all(np.isnan(f(zero))), f
    assert np.all(np.isnan(jq.from_axis_angle(jnp.zeros(3), 1.0)[1:]))
    # A non-unit quaternion: to_matrix normalises implicitly, rotate scales by |q|².
    np.testing.assert_allclose(jq.to_matrix(2 * UNIT), jq.to_matrix(UNIT), atol=1e-15)
    v = np.array([1.0, 2.0, 3.0])
    np.testing.assert_allclose(jq.rotate(2 * UNIT, v), 4 * jq.rotate(UNIT, v), atol=1e-14)


def test_passive_axis_matrix_rejects_bad_axis():
    for axis in (3, -1, "w", "xy", True, None, 1.0, np.int64(5)):
        with pytest.raises(ValueError, match="axis must be one of"):
            jq.passive_axis_matrix(axis, 0.1)
