"""Bad and extreme input to jrigid.quaternion: shapes, the 180° tie, reflections, huge norms.

References: scipy's ``Rotation`` (its canonical sign rule and ``as_rotvec``), numpy, and
analytic identities (scale invariance of the conversions).
"""

import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _rotations import assert_same_rotation, random_quaternions, scipy_rot
from scipy.spatial.transform import Rotation

import jrigid.quaternion as jq

Q4 = [0.5, 0.5, 0.5, 0.5]
V3 = [1.0, 2.0, 3.0]

# (call, expected trailing shape named in the message)
WRONG_SHAPES = [
    (lambda: jq.from_rotvec([1.0, 2.0]), "(..., 3)"),
    (lambda: jq.from_matrix(np.eye(2)), "(..., 3, 3)"),
    (lambda: jq.from_matrix(np.eye(4)[:3]), "(..., 3, 3)"),
    (lambda: jq.project_to_rotation(np.eye(2)), "(..., 3, 3)"),
    (lambda: jq.check_rotation_matrix(np.eye(2)), "(..., 3, 3)"),
    (lambda: jq.from_axis_angle([1.0, 0.0], 0.3), "(..., 3)"),
    (lambda: jq.rodrigues_matrix([1.0, 0.0, 0.0, 0.0], 0.3), "(..., 3)"),
    (lambda: jq.from_euler("ZXZ", [0.1, 0.2]), "(..., 3)"),
    (lambda: jq.rotate(Q4, [1.0, 2.0]), "(..., 3)"),
    (lambda: jq.rotate([1.0, 0.0, 0.0], V3), "(..., 4)"),
    (lambda: jq.multiply([1.0, 0.0, 0.0], Q4), "(..., 4)"),
    (lambda: jq.multiply(Q4, [1.0, 0.0, 0.0, 0.0, 0.0]), "(..., 4)"),
    (lambda: jq.derivative(Q4, [1.0, 2.0]), "(..., 3)"),
    (lambda: jq.angular_velocity(Q4, [1.0, 2.0, 3.0]), "(..., 4)"),
    (lambda: jq.slerp(Q4, [1.0, 0.0], 0.5), "(..., 4)"),
    (lambda: jq.distance([1.0], Q4), "(..., 4)"),
    (lambda: jq.check_quaternion([1.0, 0.0, 0.0]), "(..., 4)"),
    (lambda: jq.gimbal_lock("ZXZ", [1.0, 0.0, 0.0]), "(..., 4)"),
]
for _f in (
    jq.to_matrix, jq.to_rotvec, jq.normalize, jq.from_xyzw, jq.to_xyzw, jq.norm,
    jq.inverse, jq.conjugate, jq.canonicalize, jq.to_axis_angle, jq.w_matrix,
    jq.w_matrix_space, jq.passive_matrix,
):
    for _n in (3, 5):
        WRONG_SHAPES.append((lambda f=_f, n=_n: f(np.ones(n)), "(..., 4)"))
for _n in (3, 5):
    WRONG_SHAPES.append((lambda n=_n: jq.to_euler("XYZ", np.ones(n)), "(..., 4)"))


@pytest.mark.parametrize("call, expected", WRONG_SHAPES)
def test_wrong_trailing_shape_is_a_value_error_naming_the_shape(call, expected):
    with pytest.raises(ValueError, match=expected.replace("(", r"\(").replace(")", r"\)")):
        call()


def test_shape_check_is_static_under_jit():
    """The check runs while tracing: jit raises the same ValueError, before any compile."""
    with pytest.raises(ValueError, match=r"\(\.\.\., 4\)"):
        jax.jit(jq.to_matrix)(jnp.ones(3))
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        jax.jit(jq.from_rotvec)(jnp.ones((2, 2)))
    # A batch of correct elements is fine; the scalar-first quaternion needs a last axis.
    assert jq.to_matrix(jnp.ones((2, 3, 4))).shape == (2, 3, 3, 3)
    with pytest.raises(ValueError):
        jq.normalize(1.0)


# --------------------------------------------------------------------------- 180° tie


def _half_turns():
    """Quaternions with w = 0 exactly (and -0.0), zeros in every position, both signs."""
    rng = np.random.default_rng(5)
    vecs = [
        [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.6, -0.8],
        [0.6, 0.0, -0.8], [-0.6, 0.8, 0.0], *rng.normal(size=(4, 3)).tolist(),
    ]
    q = np.array([[0.0, *v] for v in vecs])
    q[:, 1:] /= np.linalg.norm(q[:, 1:], axis=-1, keepdims=True)
    neg = -q  # w = -0.0
    return np.concatenate([q, neg])


def test_to_rotvec_at_exactly_180_degrees_is_sign_invariant_and_matches_scipy():
    q = _half_turns()
    rv = np.asarray(jq.to_rotvec(q))
    np.testing.assert_array_equal(rv, np.asarray(jq.to_rotvec(-q)))
    np.testing.assert_allclose(rv, scipy_rot(q).as_rotvec(), atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(rv, axis=-1), np.pi, rtol=1e-15)
    axis, angle = jq.to_axis_angle(q)
    axis_neg, _ = jq.to_axis_angle(-q)
    np.testing.assert_array_equal(axis, axis_neg)
    np.testing.assert_allclose(np.asarray(axis) * np.asarray(angle)[:, None], rv, atol=1e-15)


def test_canonicalize_is_scipys_canonical_form():
    rng = np.random.default_rng(6)
    q = np.concatenate([_half_turns(), random_quaternions(rng, (20,)), [[0.0, 0, 0, -1.0]]])
    expected = scipy_rot(q).as_quat(canonical=True, scalar_first=True)  # renormalised
    np.testing.assert_allclose(jq.canonicalize(q), expected, atol=1e-15)
    np.testing.assert_array_equal(jq.canonicalize(q), jq.canonicalize(-q))


# --------------------------------------------------------------------------- from_matrix


def test_from_matrix_refuses_a_reflection():
    rng = np.random.default_rng(8)
    rot = scipy_rot(random_quaternions(rng, (4,))).as_matrix()
    reflections = rot @ np.diag([1.0, 1.0, -1.0])
    with pytest.raises(ValueError, match=r"reflection \(det R = -1\)"):
        jq.from_matrix(reflections[0])
    with pytest.raises(ValueError, match=r"batch index \(0,\).*reflection"):
        jq.from_matrix(reflections)
    with pytest.raises(ValueError, match="reflection"):
        jq.from_matrix(-np.eye(3))


def test_from_matrix_refuses_non_orthogonal_input_and_points_to_projection():
    rng = np.random.default_rng(9)
    q = random_quaternions(rng, (6,))
    m = scipy_rot(q).as_matrix()
    for bad in (2.0 * m[0], m[0] + 1e-3 * rng.normal(size=(3, 3)), np.ones((3, 3))):
        with pytest.raises(ValueError, match="not orthogonal.*project_to_rotation"):
            jq.from_matrix(bad)
    # The documented way: project first (nearest rotation, as scipy's from_matrix does).
    noisy = m + 1e-3 * rng.normal(size=m.shape)
    out = jq.from_matrix(jq.project_to_rotation(noisy))
    assert_same_rotation(out, Rotation.from_matrix(noisy).as_quat(scalar_first=True), 1e-12)
    # A looser tolerance is available explicitly.
    assert np.all(np.isfinite(jq.from_matrix(noisy, atol=1e-1)))


def test_from_matrix_under_jit_gives_nan_only_for_non_rotations():
    rng = np.random.default_rng(10)
    q = random_quaternions(rng, (4,))
    m = scipy_rot(q).as_matrix()
    batch = np.stack([m[0], m[1] @ np.diag([-1.0, 1.0, 1.0]), 3.0 * m[2], m[3]])
    out = np.asarray(jax.jit(jq.from_matrix)(batch))
    assert np.all(np.isnan(out[1:3]))
    assert_same_rotation(out[[0, 3]], q[[0, 3]])
    # Gradients of the valid entries stay finite.
    g = jax.grad(lambda x: jnp.sum(jq.from_matrix(x)[0]))(jnp.asarray(m[0]))
    assert np.all(np.isfinite(g))


# --------------------------------------------------------------------------- extreme norms


@pytest.mark.parametrize("scale", [1e300, 1e-300, 1e150, 1e-150])
def test_scale_invariant_functions_are_exact_at_extreme_norms(scale):
    rng = np.random.default_rng(11)
    q = random_quaternions(rng, (5,))
    p = random_quaternions(rng, (5,))
    big = q * scale
    tol = dict(rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(jq.normalize(big), q, **tol)
    np.testing.assert_allclose(jq.norm(big) / scale, 1.0, rtol=1e-14)
    np.testing.assert_allclose(jq.inverse(big) * scale, jq.conjugate(q), **tol)
    np.testing.assert_allclose(jq.to_matrix(big), scipy_rot(q).as_matrix().reshape(5, 3, 3),
                               **tol)
    np.testing.assert_allclose(jq.passive_matrix(big), np.swapaxes(jq.to_matrix(q), -1, -2),
                               **tol)
    np.testing.assert_allclose(jq.to_rotvec(big), scipy_rot(q).as_rotvec(), **tol)
    np.testing.assert_allclose(jq.to_axis_angle(big)[1], jq.to_axis_angle(q)[1], **tol)
    np.testing.assert_allclose(jq.to_euler("ZXZ", big), scipy_rot(q).as_euler("ZXZ"),
                               rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(jq.distance(big, p * scale), jq.distance(q, p), **tol)
    axis = rng.normal(size=(5, 3))
    np.testing.assert_allclose(jq.from_axis_angle(axis * scale, 0.7),
                               jq.from_axis_angle(axis, 0.7), **tol)
    np.testing.assert_allclose(jq.rodrigues_matrix(axis * scale, 0.7),
                               jq.rodrigues_matrix(axis, 0.7), **tol)
    jq.check_quaternion(big, unit=False)  # neither zero nor non-finite
    with pytest.raises(ValueError, match="not unit"):
        jq.check_quaternion(big)


def test_from_rotvec_extreme_lengths():
    axis = np.array([0.36, 0.48, 0.8])
    # A tiny rotation vector is the identity to first order (no underflow to NaN).
    np.testing.assert_allclose(jq.from_rotvec(axis * 1e-300), [1.0, *(0.5e-300 * axis)],
                               rtol=1e-15)
    # A huge one no longer overflows to NaN: its angle mod 2π is lost, a unit q remains.
    np.testing.assert_allclose(jq.norm(jq.from_rotvec(axis * 1e300)), 1.0, rtol=1e-12)


@pytest.mark.parametrize("dtype, top", [(np.float64, 1.7e308), (np.float32, 3.0e38)])
def test_scale_invariant_functions_at_the_top_of_the_float_range(dtype, top):
    """Components above ``1/tiny`` (4.5e307 in float64, 8.5e37 in float32) had a norm of 0
    and NaN conversions: the rescaling divided by the reciprocal of the largest component,
    a number below the smallest normal one, which a CPU flushes to zero."""
    q = np.array([0.6, -0.0, 0.8, 0.0], dtype)
    big = jnp.asarray(q * top, dtype)
    assert float(jq.norm(big)) == pytest.approx(top, rel=1e-6)
    np.testing.assert_allclose(jq.normalize(big), q, atol=1e-6)
    np.testing.assert_allclose(jq.to_matrix(big), jq.to_matrix(jnp.asarray(q)), atol=1e-6)
    np.testing.assert_allclose(jq.to_rotvec(big), jq.to_rotvec(jnp.asarray(q)), atol=1e-6)
    np.testing.assert_allclose(jq.to_euler("XYZ", big), jq.to_euler("XYZ", jnp.asarray(q)),
                               atol=1e-5)
    axis = jnp.asarray([top, 0.0, 0.0], dtype)  # a huge rotation vector: still unit
    assert float(jq.norm(jq.from_rotvec(axis))) == pytest.approx(1.0, rel=1e-6)
    assert abs(float(jq.from_rotvec(axis)[1])) > 0.0


def test_normalize_gradient_is_exact_at_extreme_norms():
    """d normalize(c q)/dq = J(q) / c, the derivative of the unscaled function."""
    q = jnp.array([0.1, -0.5, 0.7, 0.3])
    jac = jax.jacfwd(jq.normalize)(q)
    for c in (1e300, 1e-300):
        np.testing.assert_allclose(jax.jacfwd(jq.normalize)(c * q) * c, jac, rtol=1e-13)
        np.testing.assert_allclose(jax.jacrev(jq.normalize)(c * q) * c, jac, rtol=1e-13)
    # The gradient of the norm is the unit vector at every scale.
    np.testing.assert_allclose(jax.grad(jq.norm)(1e300 * q), jq.normalize(q), rtol=1e-14)


def test_normalize_keeps_the_single_rsqrt_rounding_in_the_normal_range():
    """Within the safe range the result is bit for bit ``q * rsqrt(q·q)`` (no rescaling),
    which keeps checkpointed reverse passes identical to the forward pass."""
    rng = np.random.default_rng(12)
    q = jnp.asarray(rng.normal(size=(200, 4)) * 10.0 ** rng.uniform(-100, 100, (200, 1)))
    ref = jax.jit(lambda x: x * jax.lax.rsqrt(jnp.sum(x * x, axis=-1, keepdims=True)))
    np.testing.assert_array_equal(jax.jit(jq.normalize)(q), ref(q))


def test_zero_quaternion_gives_nan_from_every_conversion():
    z = jnp.zeros(4)
    for out in (jq.normalize(z), jq.to_matrix(z), jq.to_rotvec(z), jq.to_euler("ZYX", z),
                jq.inverse(z), *jq.to_axis_angle(z), jq.distance(z, jq.identity())):
        assert np.all(np.isnan(out))
    assert jq.norm(z) == 0.0


def test_project_to_rotation_of_non_finite_input_is_nan_and_returns():
    """LAPACK's SVD never returned on an infinite entry: the call hung."""
    code = (
        "import jax; jax.config.update('jax_enable_x64', True)\n"
        "import numpy as np, jrigid.quaternion as jq\n"
        "m = np.stack([np.eye(3), np.diag([np.inf, 1.0, 1.0]), np.full((3, 3), np.nan)])\n"
        "out = np.asarray(jq.project_to_rotation(m))\n"
        "assert np.array_equal(out[0], np.eye(3)) and np.isnan(out[1:]).all(), out\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
