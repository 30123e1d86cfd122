"""The reductions written out elementwise (jrigid._folds) agree with numpy's, on short
axes (written out) and long ones (left to XLA), and the RMS norm's derivative with
optimistix's."""

import jax
import jax.numpy as jnp
import numpy as np
import optimistix
import pytest

from jrigid import _folds


@pytest.mark.parametrize("n", [1, 2, 7, _folds.SMALL, _folds.SMALL + 1, 300])
def test_folds_agree_with_numpy(n):
    rng = np.random.default_rng(n)
    for _ in range(5):
        b = rng.random((3, n)) < 0.1
        x = rng.standard_normal((3, n))
        for axis in (-1, None):
            np.testing.assert_array_equal(_folds.every(b, axis), np.all(b, axis=axis))
            np.testing.assert_array_equal(_folds.some(b, axis), np.any(b, axis=axis))
        assert _folds.largest(jnp.asarray(x[0])) == x[0].max()
        assert _folds.first_true(jnp.asarray(b[0])) == np.argmax(b[0])
        assert _folds.first_true(jnp.asarray(b[0])).dtype == jnp.int32
        np.testing.assert_allclose(_folds.total(jnp.asarray(x)), x.sum(-1), rtol=1e-14)
        np.testing.assert_allclose(_folds.total(jnp.asarray(x), axis=0), x.sum(0), rtol=1e-14)


def test_rms_norm_and_its_derivative_match_optimistix():
    rng = np.random.default_rng(3)
    tree = {"a": jnp.asarray(rng.standard_normal(4)), "b": jnp.asarray(rng.standard_normal(3))}
    np.testing.assert_allclose(_folds.rms_norm(tree), optimistix.rms_norm(tree), rtol=1e-15)
    ours = jax.grad(_folds.rms_norm)(tree)
    theirs = jax.grad(optimistix.rms_norm)(tree)
    for k in tree:
        np.testing.assert_allclose(ours[k], theirs[k], rtol=1e-14)
    zero = {"a": jnp.zeros(4)}  # zero derivative, not NaN, where the norm is zero
    assert _folds.rms_norm(zero) == 0
    np.testing.assert_array_equal(jax.grad(_folds.rms_norm)(zero)["a"], 0.0)
    assert _folds.rms_norm({}) == 0


def test_a_solve_holds_few_reductions():
    """Each reduction costs a call of the compiled solve about 0.2 µs whether it runs
    or not: the default solve's input checks, step-size control, projection and outcome
    hold none (26 reductions on a free rotor before, 29 on a heavy top); those left are
    in the step's stage sums and its first step size."""
    import jrigid
    from jrigid import initial

    rotor = jrigid.Scene(jrigid.RigidBody(jnp.array([1.0, 2.0, 3.0])), jrigid.FreeRotation())
    top = jrigid.Scene(jrigid.RigidBody(jnp.array([1.0, 1.0, 0.5]), mass=1.0,
                                        com=jnp.array([0.0, 0.0, 1.0])),
                       jrigid.Pivot(), loads=(jrigid.Gravity(1.0),))
    state = initial.from_omega(omega=jnp.array([1.0, 0.3, 0.7]))

    def solve(scene, state):
        return jrigid.simulate(scene, state, jnp.array([0.0, 1.0]), throw=False).q

    for scene in (rotor, top):
        text = jax.jit(solve).lower(scene, state).compile().as_text()
        assert text.count(" reduce(") <= 10, text.count(" reduce(")
