"""jrigid.linalg: written-out small-vector algebra against numpy."""

import jax.numpy as jnp
import numpy as np
import pytest

from jrigid import linalg

RNG = np.random.default_rng(7)


def test_dot_cross_matvec_solve_match_numpy_on_batches():
    a, b = RNG.normal(size=(5, 2, 3)), RNG.normal(size=(5, 2, 3))
    np.testing.assert_allclose(linalg.dot(jnp.asarray(a), jnp.asarray(b)), np.sum(a * b, -1),
                               rtol=1e-14)
    q = RNG.normal(size=(5, 4))
    np.testing.assert_allclose(linalg.dot(jnp.asarray(q), jnp.asarray(q)), np.sum(q * q, -1),
                               rtol=1e-14)
    np.testing.assert_allclose(linalg.norm2(jnp.asarray(a)), np.sum(a * a, -1), rtol=1e-14)
    np.testing.assert_allclose(linalg.cross(jnp.asarray(a), jnp.asarray(b)), np.cross(a, b),
                               rtol=1e-13, atol=1e-15)
    m = RNG.normal(size=(5, 2, 3, 3))
    np.testing.assert_allclose(linalg.matvec(jnp.asarray(m), jnp.asarray(a)),
                               np.einsum("...ij,...j->...i", m, a), rtol=1e-13, atol=1e-14)
    np.testing.assert_allclose(linalg.solve3(jnp.asarray(m), jnp.asarray(a)),
                               np.linalg.solve(m, a[..., None])[..., 0], rtol=1e-10)


def test_broadcasting_batch_shapes():
    a = jnp.asarray(RNG.normal(size=(4, 3)))
    b = jnp.asarray(RNG.normal(size=(3,)))
    assert linalg.dot(a, b).shape == (4,)
    assert linalg.cross(a, b).shape == (4, 3)


def test_singular_solve_is_not_finite():
    assert not np.all(np.isfinite(linalg.solve3(jnp.zeros((3, 3)), jnp.ones(3))))


def test_unit_matches_numpy_and_the_scale_safe_normalize():
    """linalg.unit is the integrators' lean form of quaternion.normalize: equal bit for
    bit at moderate scale; only normalize survives extreme norms."""
    from jrigid import quaternion as quat

    q = RNG.normal(size=(6, 4))
    u = linalg.unit(jnp.asarray(q))
    np.testing.assert_allclose(u, q / np.linalg.norm(q, axis=-1, keepdims=True), rtol=1e-15)
    np.testing.assert_array_equal(u, quat.normalize(q))
    assert linalg.unit(jnp.asarray(RNG.normal(size=3))).shape == (3,)
    assert np.isnan(np.asarray(linalg.unit(jnp.zeros(4)))).all()
    big = 1e300 * q[0]
    lean = np.asarray(linalg.unit(jnp.asarray(big)))  # |q|² overflows: zeros, not unit
    assert not np.isclose(np.linalg.norm(lean), 1.0)
    np.testing.assert_allclose(quat.normalize(big), u[0], rtol=1e-15)


def test_euler_diagonal_matches_the_vector_form_of_eulers_equations():
    # I ω̇ = N − ω × (I ω) (eq. 17.35) with numpy's cross product, on broadcast batches
    moments = RNG.uniform(0.5, 3.0, size=(4, 1, 3))
    omega, torque = RNG.normal(size=(4, 2, 3)), RNG.normal(size=(2, 3))
    expected = (torque - np.cross(omega, moments * omega)) / moments
    got = linalg.euler_diagonal(jnp.asarray(moments), jnp.asarray(omega), jnp.asarray(torque))
    assert got.shape == (4, 2, 3)
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-14)


def test_euler_diagonal_names_a_wrongly_shaped_argument():
    three = jnp.ones(3)
    with pytest.raises(ValueError, match="omega must have shape"):
        linalg.euler_diagonal(three, jnp.ones(4), three)


def test_mismatched_lengths_are_refused_not_truncated():
    """The written-out helpers index components, so a longer vector was silently cut."""
    cases = [(lambda: linalg.dot(jnp.ones(4), jnp.ones(3)),
              r"dot: b must have shape \(\.\.\., 4\)"),
             (lambda: linalg.cross(jnp.ones(4), jnp.ones(3)), "cross: a must have shape"),
             (lambda: linalg.matvec(jnp.eye(3), jnp.ones(4)), "matvec: v must have shape"),
             (lambda: linalg.solve3(jnp.eye(4), jnp.ones(4)), "solve3: m must have shape")]
    for call, message in cases:
        with pytest.raises(ValueError, match=message):
            call()
    np.testing.assert_allclose(linalg.cross([1.0, 0.0, 0.0], [0.0, 1.0, 0.0]), [0, 0, 1])
