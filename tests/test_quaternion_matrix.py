"""Rotation matrices: quaternion ↔ matrix, Rodrigues (17.16-17.17), passive (17.8, 17.10, 17.28)."""

import hypothesis.strategies as st
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _rotations import assert_same_rotation, random_quaternions, scipy_rot
from hypothesis import given, settings
from scipy.spatial.transform import Rotation

import jrigid.quaternion as jq

BATCH_SHAPES = [(), (1,), (3, 1, 2)]
SETTINGS = settings(max_examples=25, deadline=None)
seeds = st.integers(0, 2**32 - 1)
batch_shapes = st.sampled_from(BATCH_SHAPES)








def edge_rotvecs():
    rng = np.random.default_rng(7)
    axes = [[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [0, -1, 1], [1, 1, 1]]
    axes += rng.normal(size=(4, 3)).tolist()
    out = [[0.0, 0.0, 0.0]]
    for a in axes:
        a = np.asarray(a, float) / np.linalg.norm(a)
        for angle in (np.pi, np.pi - 1e-9, 1e-9, 1e-5, 2.5):
            out.append(angle * a)
    return np.asarray(out)


EDGE_ROTVECS = edge_rotvecs()
EDGE = Rotation.from_rotvec(EDGE_ROTVECS).as_quat(scalar_first=True)


def skew(v):
    x, y, z = v
    return np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])


# ---------------------------------------------------------------------------
# to_matrix / from_matrix
# ---------------------------------------------------------------------------


@given(seed=seeds, shape=batch_shapes)
@SETTINGS
def test_to_matrix_matches_scipy(seed, shape):
    rng = np.random.default_rng(seed)
    q = random_quaternions(rng, shape)
    m = jq.to_matrix(q)
    assert m.shape == shape + (3, 3)
    np.testing.assert_allclose(np.reshape(m, (-1, 3, 3)), scipy_rot(q).as_matrix(), atol=1e-14)
    # Active: R v equals the quaternion rotation of v.
    v = rng.normal(size=shape + (3,))
    np.testing.assert_allclose(np.einsum("...ij,...j->...i", m, v), jq.rotate(q, v), atol=1e-13)
    # Scale invariance (implicit normalisation, as scipy).
    np.testing.assert_allclose(jq.to_matrix(3.0 * q), m, atol=1e-14)


def test_to_matrix_edge_cases():
    np.testing.assert_allclose(jq.to_matrix(EDGE), scipy_rot(EDGE).as_matrix(), atol=1e-14)
    np.testing.assert_array_equal(jq.to_matrix(jq.identity()), np.eye(3))


@given(seed=seeds, shape=batch_shapes)
@SETTINGS
def test_from_matrix_matches_scipy(seed, shape):
    rng = np.random.default_rng(seed)
    q = random_quaternions(rng, shape)
    m = scipy_rot(q).as_matrix().reshape(shape + (3, 3))
    out = jq.from_matrix(m)
    assert out.shape == shape + (4,)
    assert_same_rotation(out, q, atol=1e-13)
    np.testing.assert_allclose(jq.norm(out), 1.0, rtol=1e-15)


def test_from_matrix_edge_cases_including_180_degrees():
    m = Rotation.from_rotvec(EDGE_ROTVECS).as_matrix()
    out = jq.from_matrix(m)
    assert_same_rotation(out, EDGE, atol=1e-12)
    assert_same_rotation(out, Rotation.from_matrix(m).as_quat(scalar_first=True), atol=1e-12)
    # Each Shepperd branch is exercised: 180° about x, y, z pivot on x, y, z.
    for i in range(3):
        e = np.zeros(3)
        e[i] = 1.0
        half_turn = 2 * np.outer(e, e) - np.eye(3)
        expected = np.zeros(4)
        expected[1 + i] = 1.0
        assert_same_rotation(jq.from_matrix(half_turn), expected, atol=0)


def test_from_matrix_jit_vmap():
    m = Rotation.from_rotvec(EDGE_ROTVECS).as_matrix()
    eager = jq.from_matrix(m)
    np.testing.assert_allclose(jax.jit(jq.from_matrix)(m), eager, atol=1e-15)
    np.testing.assert_allclose(jax.vmap(jq.from_matrix)(m), eager, atol=1e-15)
    np.testing.assert_allclose(
        jax.jit(jq.to_matrix)(EDGE), jax.vmap(jq.to_matrix)(EDGE), atol=1e-15
    )


def test_from_matrix_near_orthogonal_input_is_first_order_accurate():
    """Documented: a rotation perturbed within the tolerance gives it to first order."""
    rng = np.random.default_rng(3)
    q = random_quaternions(rng, (50,))
    m = scipy_rot(q).as_matrix()
    for delta in (1e-7, 1e-8):
        noisy = m + delta * rng.normal(size=m.shape)
        out = jq.from_matrix(noisy)
        np.testing.assert_allclose(jq.norm(out), 1.0, rtol=1e-15)
        assert_same_rotation(out, q, atol=10 * delta)
        # The nearest rotation (scipy orthogonalises by SVD) agrees to first order too.
        ref = Rotation.from_matrix(noisy).as_quat(scalar_first=True)
        assert_same_rotation(out, ref, atol=10 * delta)


def test_project_to_rotation():
    rng = np.random.default_rng(4)
    q = random_quaternions(rng, (3, 1, 2))
    m = scipy_rot(q).as_matrix().reshape(3, 1, 2, 3, 3)
    noisy = m + 0.2 * rng.normal(size=m.shape)
    p = np.asarray(jq.project_to_rotation(noisy))
    assert p.shape == (3, 1, 2, 3, 3)
    np.testing.assert_allclose(
        np.swapaxes(p, -1, -2) @ p, np.broadcast_to(np.eye(3), p.shape), atol=1e-13
    )
    np.testing.assert_allclose(np.linalg.det(p), 1.0, rtol=1e-13)
    # Matches scipy's SVD orthogonalisation (for det > 0 inputs).
    flat = noisy.reshape(-1, 3, 3)
    keep = np.linalg.det(flat) > 0
    np.testing.assert_allclose(
        p.reshape(-1, 3, 3)[keep], Rotation.from_matrix(flat[keep]).as_matrix(), atol=1e-12
    )
    # A rotation is its own projection; a reflection is mapped to a proper rotation.
    np.testing.assert_allclose(jq.project_to_rotation(m), m, atol=1e-13)
    reflected = np.asarray(jq.project_to_rotation(-m[0, 0, 0]))
    np.testing.assert_allclose(np.linalg.det(reflected), 1.0, rtol=1e-13)


# ---------------------------------------------------------------------------
# Rodrigues (17.16-17.17)
# ---------------------------------------------------------------------------


@given(seed=seeds, shape=batch_shapes)
@SETTINGS
def test_rodrigues_matrix(seed, shape):
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=shape + (3,))
    angle = rng.uniform(-4, 4, size=shape)
    m = jq.rodrigues_matrix(axis, angle)
    assert m.shape == shape + (3, 3)
    unit = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    ref = Rotation.from_rotvec((unit * angle[..., None]).reshape(-1, 3)).as_matrix()
    np.testing.assert_allclose(np.reshape(m, (-1, 3, 3)), ref, atol=1e-14)
    # (17.16) applied to a vector.
    v = rng.normal(size=shape + (3,))
    c, s = np.cos(angle)[..., None], np.sin(angle)[..., None]
    vr = np.sum(v * unit, axis=-1, keepdims=True)
    expected = (1 - c) * vr * unit + s * np.cross(unit, v) + c * v
    np.testing.assert_allclose(np.einsum("...ij,...j->...i", m, v), expected, atol=1e-13)
    # Same as the quaternion route.
    np.testing.assert_allclose(m, jq.to_matrix(jq.from_axis_angle(axis, angle)), atol=1e-14)


def test_rodrigues_about_z_is_planar_rotation():
    """Exercise 17.5: r = (0, 0, 1) gives the 2D rotation in the x-y plane."""
    t = 0.3
    np.testing.assert_allclose(
        jq.rodrigues_matrix(jnp.array([0.0, 0.0, 1.0]), t),
        [[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1]],
        atol=1e-16,
    )


# ---------------------------------------------------------------------------
# The chapter's passive matrices (17.8, 17.10, 17.28)
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("axis", [0, 1, 2, "x", "y", "z", "X", "Z"])
def test_passive_axis_matrix_is_transpose_of_active(axis):
    i = "xyz".index(axis.lower()) if isinstance(axis, str) else axis
    angles = np.array([-2.0, 0.0, 0.4, np.pi])
    m = jq.passive_axis_matrix(axis, angles)
    assert m.shape == (4, 3, 3)
    e = np.eye(3)[i]
    active = Rotation.from_rotvec(angles[:, None] * e).as_matrix()
    np.testing.assert_allclose(m, np.swapaxes(active, -1, -2), atol=1e-15)
    np.testing.assert_allclose(m, np.swapaxes(jq.rodrigues_matrix(e, angles), -1, -2), atol=1e-15)


def test_passive_z_matrix_as_printed():
    """(17.8) entry by entry."""
    t = 0.7
    c, s = np.cos(t), np.sin(t)
    np.testing.assert_allclose(
        jq.passive_axis_matrix("z", t), [[c, s, 0], [-s, c, 0], [0, 0, 1]], atol=1e-16
    )


@given(seed=seeds, shape=batch_shapes)
@SETTINGS
def test_passive_zxz_matrix(seed, shape):
    rng = np.random.default_rng(seed)
    phi, theta, psi = (rng.uniform(-np.pi, np.pi, size=shape) for _ in range(3))
    m = jq.passive_zxz_matrix(phi, theta, psi)
    assert m.shape == shape + (3, 3)
    # Transpose of the active intrinsic ZXZ matrix (scipy).
    active = Rotation.from_euler("ZXZ", np.stack([phi, theta, psi], -1).reshape(-1, 3)).as_matrix()
    np.testing.assert_allclose(np.reshape(m, (-1, 3, 3)), np.swapaxes(active, -1, -2), atol=1e-14)
    # The chapter's product R_z(ψ) R_x(θ) R_z(φ) of passive (17.8) matrices.
    product = (
        jq.passive_axis_matrix("z", psi)
        @ jq.passive_axis_matrix("x", theta)
        @ jq.passive_axis_matrix("z", phi)
    )
    np.testing.assert_allclose(m, product, atol=1e-14)
    # And the active form from from_euler.
    q = jq.from_euler("ZXZ", np.stack([phi, theta, psi], -1))
    np.testing.assert_allclose(m, np.swapaxes(jq.to_matrix(q), -1, -2), atol=1e-14)


def test_passive_zxz_scalar_broadcast():
    m = jq.passive_zxz_matrix(0.1, np.array([0.2, 0.3]), 0.4)
    assert m.shape == (2, 3, 3)
    np.testing.assert_allclose(m[1], jq.passive_zxz_matrix(0.1, 0.3, 0.4), atol=1e-16)


@given(seed=seeds, shape=batch_shapes)
@SETTINGS
def test_passive_matrix(seed, shape):
    rng = np.random.default_rng(seed)
    q = random_quaternions(rng, shape)
    m = jq.passive_matrix(q)
    assert m.shape == shape + (3, 3)
    np.testing.assert_allclose(
        np.reshape(m, (-1, 3, 3)), np.swapaxes(scipy_rot(q).as_matrix(), -1, -2), atol=1e-14
    )
    np.testing.assert_allclose(m, np.swapaxes(jq.to_matrix(q), -1, -2), atol=1e-14)
    # Space -> body.
    v = rng.normal(size=shape + (3,))
    np.testing.assert_allclose(
        np.einsum("...ij,...j->...i", m, v), jq.rotate_inverse(q, v), atol=1e-13
    )


def test_passive_matrix_edge_cases():
    np.testing.assert_allclose(
        jq.passive_matrix(EDGE), np.swapaxes(scipy_rot(EDGE).as_matrix(), -1, -2), atol=1e-14
    )


def test_skew_relation_of_active_matrix():
    """dR/dθ at θ = 0 about axis n is skew(n) for the active Rodrigues matrix."""
    n = np.array([1.0, -2.0, 0.5])
    n /= np.linalg.norm(n)
    d = jax.jacfwd(lambda t: jq.rodrigues_matrix(n, t))(0.0)
    np.testing.assert_allclose(d, skew(n), atol=1e-15)


# ---------------------------------------------------------------------------
# float32
# ---------------------------------------------------------------------------


def test_float32_matrices(float32):
    rng = np.random.default_rng(8)
    q64 = np.concatenate([random_quaternions(rng, (20,)), EDGE])
    q = jnp.asarray(q64, jnp.float32)
    m = jq.to_matrix(q)
    assert m.dtype == jnp.float32
    np.testing.assert_allclose(m, scipy_rot(q64).as_matrix(), atol=2e-6)
    out = jq.from_matrix(jnp.asarray(scipy_rot(q64).as_matrix(), jnp.float32))
    assert out.dtype == jnp.float32
    assert_same_rotation(out, q64, atol=2e-6)
    for m32 in (
        jq.passive_matrix(q),
        jq.rodrigues_matrix(q[:20, 1:], q[:20, 0]),
        jq.passive_axis_matrix("y", q[:, 0]),
        jq.passive_zxz_matrix(q[:, 0], q[:, 1], q[:, 2]),
        jq.project_to_rotation(m),
    ):
        assert m32.dtype == jnp.float32
        assert np.all(np.isfinite(m32))


@pytest.mark.parametrize("entry", [np.inf, -np.inf, np.nan])
def test_a_non_finite_matrix_gives_an_all_nan_quaternion(entry):
    """An inf made ``RᵀR − 1`` NaN, which passed the orthogonality test: half NaN out."""
    for i in range(9):
        m = np.eye(3)
        m.flat[i] = entry
        assert np.all(np.isnan(np.asarray(jq.from_matrix(jnp.asarray(m))))), i


@pytest.mark.parametrize("atol", [float("nan"), -1.0, 0.5, "0.1"])
def test_from_matrix_refuses_a_tolerance_out_of_range(atol):
    """atol=NaN accepted 3·I as a rotation; a negative one blamed the matrix."""
    with pytest.raises(ValueError, match="atol"):
        jq.from_matrix(3.0 * jnp.eye(3), atol=atol)
    np.testing.assert_allclose(jq.from_matrix(jnp.eye(3), atol=0.1), [1.0, 0, 0, 0])


@pytest.mark.parametrize("delta", [1e-9, 1e-7, 2e-7])
def test_from_matrix_of_a_nearly_orthogonal_matrix_is_the_nearest_rotation(delta):
    """It gave the normalised Shepperd estimate, off by about 0.12·delta (scipy returns
    the nearest rotation), with a derivative off the rotations."""
    rng = np.random.default_rng(7)
    for _ in range(20):
        R0 = Rotation.random(random_state=rng).as_matrix()
        S = rng.uniform(-1.0, 1.0, (3, 3))
        M = R0 @ (np.eye(3) + delta * (S + S.T) / 2)
        want = Rotation.from_matrix(M).as_quat(canonical=True, scalar_first=True)
        got = np.asarray(jq.canonicalize(jq.from_matrix(jnp.asarray(M))))
        np.testing.assert_allclose(got, want, atol=1e-15)
    R0 = Rotation.from_rotvec([0.0, 0.0, 1.0]).as_matrix()
    _, dq = jax.jvp(jq.from_matrix, (jnp.asarray(R0),),
                    (jnp.asarray(R0 @ np.diag([1.0, 0.0, 0.0])),))
    np.testing.assert_allclose(np.asarray(dq), 0.0, atol=1e-15)
