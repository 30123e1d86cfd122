"""body: RigidBody checks its values, eagerly and under jit, allows a non-physical body only
when asked, and diagonalises a full tensor (checked with scipy rotations)."""


import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from jrigid.body import RigidBody

# --------------------------------------------------------------------------- checks


def test_nonphysical_body_allowed_when_asked():
    moments = jnp.array([2.0, 1.0, 2.0 / 3.0])  # Hairer–Lubich–Wanner
    allowed = RigidBody(moments, allow_nonphysical=True)
    checked = jax.jit(lambda b: b.check())(allowed)  # simulate runs this inside its jit
    np.testing.assert_allclose(checked.moments, moments)
    strict = eqx.filter_jit(lambda m: RigidBody(m).check().moments)
    with pytest.raises(eqx.EquinoxRuntimeError, match="triangle"):
        jax.block_until_ready(strict(moments))


@pytest.mark.parametrize(
    "moments, message",
    [
        ([1.0, 1.0, 3.0], "triangle"),  # I1 + I2 < I3: no mass distribution has these
        ([1.0, -2.0, 2.5], "positive"),
        ([1.0, np.nan, 2.5], "finite"),
    ],
    ids=["triangle", "negative", "nan"],
)
def test_nonphysical_inertia_raises_naming_the_problem(moments, message):
    with pytest.raises(ValueError, match=message):
        RigidBody(jnp.array(moments))
    # Under jit the values are checked by traced flags (as simulate does): the same one.
    flags = jax.jit(lambda m: [bad for bad, _ in RigidBody(m).problems()])(jnp.array(moments))
    texts = [text for _, text in RigidBody(jnp.array([1.0, 2.0, 2.5])).problems()]
    failing = [text for bad, text in zip(flags, texts, strict=True) if bool(bad)]
    assert len(failing) == 1 and message in failing[0], failing


def test_other_bad_values_and_shapes_raise():
    with pytest.raises(ValueError, match="mass must be finite and positive"):
        RigidBody(jnp.array([1.0, 2.0, 2.5]), mass=0.0)
    with pytest.raises(ValueError, match="com must be finite"):
        RigidBody(jnp.array([1.0, 2.0, 2.5]), com=jnp.array([0.0, np.inf, 0.0]))
    with pytest.raises(ValueError, match="from_tensor"):
        RigidBody(jnp.eye(3))
    with pytest.raises(ValueError, match="shape"):
        RigidBody(jnp.ones((2, 3)))


def test_from_tensor_diagonalises_a_rotated_tensor():
    """A diagonal tensor turned by a known rotation R: moments ascending, and the frame
    maps the principal axes back (T = F diag(I) Fᵀ)."""
    moments = np.array([3.0, 1.0, 2.5])
    R = Rotation.from_euler("xyz", [0.3, -0.5, 1.1]).as_matrix()
    tensor = R @ np.diag(moments) @ R.T
    com = np.array([0.1, 0.2, 0.3])
    body = RigidBody.from_tensor(jnp.asarray(tensor), mass=2.0, com=jnp.asarray(com))
    np.testing.assert_allclose(body.moments, np.sort(moments), rtol=1e-12)
    F = Rotation.from_quat(np.asarray(body.frame), scalar_first=True).as_matrix()
    np.testing.assert_allclose(F @ np.diag(np.asarray(body.moments)) @ F.T, tensor, atol=1e-12)
    np.testing.assert_allclose(F @ np.asarray(body.com), com, atol=1e-12)
    with pytest.raises(ValueError, match="triangle"):
        RigidBody.from_tensor(jnp.diag(jnp.array([1.0, 1.0, 3.0])))


def test_from_tensor_checks_a_traced_tensor_and_names_com():
    """Under jit/vmap an asymmetric tensor was read as its symmetric part, silently (the
    moments keep no trace of it); a wrongly shaped com was blamed on "v"."""
    asymmetric = jnp.array([[2.0, -0.6, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]])
    symmetric = (asymmetric + asymmetric.T) / 2
    moments = jax.jit(lambda t: RigidBody.from_tensor(t).moments)
    np.testing.assert_allclose(moments(symmetric), np.linalg.eigvalsh(symmetric), rtol=1e-12)
    with pytest.raises(Exception, match="not symmetric"):
        jax.block_until_ready(moments(asymmetric))
    with pytest.raises(eqx.EquinoxRuntimeError, match="not symmetric"):
        jax.block_until_ready(
            eqx.filter_jit(jax.vmap(lambda t: RigidBody.from_tensor(t).moments))(asymmetric[None])
        )
    with pytest.raises(ValueError, match="com must have shape"):
        RigidBody.from_tensor(symmetric, 1.0, jnp.ones(2))
