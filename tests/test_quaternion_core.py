"""Quaternion algebra, rotation of vectors, axis-angle, rotation vectors, slerp, kinematics.

Reference values come from scipy's ``Rotation`` and from analytic results.
"""

import hypothesis.strategies as st
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _rotations import assert_same_rotation, random_quaternions, scipy_rot
from hypothesis import given, settings
from scipy.spatial.transform import Rotation, Slerp

import jrigid.quaternion as jq

BATCH_SHAPES = [(), (1,), (3, 1, 2)]
SETTINGS = settings(max_examples=30, deadline=None)
seeds = st.integers(0, 2**32 - 1)
batch_shapes = st.sampled_from(BATCH_SHAPES)








def edge_quaternions():
    """Identity, 180° about the axes and random axes, tiny angles, angles near π."""
    rng = np.random.default_rng(7)
    axes = [
        [1, 0, 0],
        [0, 1, 0],
        [0, 0, 1],
        [1, 1, 0],
        [-1, 2, 3],
        *rng.normal(size=(3, 3)).tolist(),
    ]
    rotvecs = [[0.0, 0.0, 0.0]]
    for a in axes:
        a = np.asarray(a, float) / np.linalg.norm(a)
        for angle in (np.pi, 1e-9, np.pi - 1e-9, 1e-4, 2.0):
            rotvecs.append(angle * a)
    q = Rotation.from_rotvec(rotvecs).as_quat(scalar_first=True)
    return np.concatenate([q, -q[::3]], axis=0)


EDGE = edge_quaternions()


# ---------------------------------------------------------------------------
# Algebra
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("shape", BATCH_SHAPES)
def test_identity(shape):
    q = jq.identity(shape)
    assert q.shape == shape + (4,)
    assert q.dtype == jnp.float64
    np.testing.assert_array_equal(
        np.asarray(q).reshape(-1, 4), [[1, 0, 0, 0]] * int(np.prod(shape))
    )
    assert jq.identity(dtype=jnp.float32).dtype == jnp.float32
    with pytest.raises(ValueError, match="floating dtype"):
        jq.identity(dtype=jnp.int32)


def test_hamilton_rules():
    """i² = j² = k² = ijk = -1 (17.20) and the products (17.22)."""
    one, i, j, k = np.eye(4)
    m = jq.multiply
    for x in (i, j, k):
        np.testing.assert_array_equal(m(x, x), -one)
    np.testing.assert_array_equal(m(m(i, j), k), -one)
    np.testing.assert_array_equal(m(i, j), k)
    np.testing.assert_array_equal(m(j, k), i)
    np.testing.assert_array_equal(m(k, i), j)
    np.testing.assert_array_equal(m(j, i), -k)
    np.testing.assert_array_equal(m(k, j), -i)
    np.testing.assert_array_equal(m(i, k), -j)


@given(seed=seeds, shape=batch_shapes)
@SETTINGS
def test_multiply_matches_scipy_composition(seed, shape):
    rng = np.random.default_rng(seed)
    p, q = random_quaternions(rng, shape), random_quaternions(rng, shape)
    pq = jq.multiply(p, q)
    assert pq.shape == shape + (4,)
    expected = (scipy_rot(p) * scipy_rot(q)).as_quat(scalar_first=True)
    assert_same_rotation(np.reshape(pq, (-1, 4)), expected)


@given(seed=seeds, shape=batch_shapes)
@SETTINGS
def test_group_axioms(seed, shape):
    rng = np.random.default_rng(seed)
    # Non-unit quaternions: the algebra does not need unit length.
    p, q, r = (random_quaternions(rng, shape, scale=rng.uniform(0.5, 2.0)) for _ in range(3))
    m = jq.multiply
    np.testing.assert_allclose(m(m(p, q), r), m(p, m(q, r)), atol=1e-13)
    e = jq.identity(shape)
    np.testing.assert_allclose(m(e, p), p, atol=1e-15)
    np.testing.assert_allclose(m(p, e), p, atol=1e-15)
    np.testing.assert_allclose(m(p, jq.inverse(p)), e, atol=1e-14)
    np.testing.assert_allclose(m(jq.inverse(p), p), e, atol=1e-14)
    np.testing.assert_allclose(
        jq.norm(m(p, q)), np.linalg.norm(p, axis=-1) * np.linalg.norm(q, axis=-1), rtol=1e-13
    )
    np.testing.assert_allclose(
        jq.conjugate(m(p, q)), m(jq.conjugate(q), jq.conjugate(p)), atol=1e-14
    )
    # q q* = |q|² (the chapter's norm squared)
    qq = np.asarray(m(q, jq.conjugate(q)))
    np.testing.assert_allclose(qq[..., 0], np.sum(q * q, axis=-1), rtol=1e-14)
    np.testing.assert_allclose(qq[..., 1:], 0.0, atol=1e-15)


def test_multiply_broadcasts_batch_dims():
    rng = np.random.default_rng(0)
    p = random_quaternions(rng, (3, 1, 2))
    q = random_quaternions(rng, (5, 1))
    out = jq.multiply(p, q)
    assert out.shape == (3, 5, 2, 4)
    np.testing.assert_allclose(out[2, 4, 1], jq.multiply(p[2, 0, 1], q[4, 0]), atol=1e-15)
    single = jq.multiply(p, q[0, 0])
    assert single.shape == (3, 1, 2, 4)


def test_conjugate_normalize_inverse_values():
    q = np.array([1.0, -2.0, 3.0, 4.0])
    np.testing.assert_array_equal(jq.conjugate(q), [1.0, 2.0, -3.0, -4.0])
    np.testing.assert_allclose(jq.norm(q), np.sqrt(30.0), rtol=1e-15)
    np.testing.assert_allclose(jq.normalize(q), q / np.sqrt(30.0), rtol=1e-15)
    np.testing.assert_allclose(jq.inverse(q), [1.0, 2.0, -3.0, -4.0] / np.float64(30.0), rtol=1e-15)
    np.testing.assert_array_equal(jq.canonicalize(-q), q)
    np.testing.assert_array_equal(jq.canonicalize(q), q)


def test_normalize_zero_is_nan():
    """Documented behaviour: the zero quaternion has no direction."""
    assert np.all(np.isnan(jq.normalize(jnp.zeros(4))))


# ---------------------------------------------------------------------------
# Rotating vectors (17.26)
# ---------------------------------------------------------------------------


@given(seed=seeds, shape=batch_shapes)
@SETTINGS
def test_rotate_matches_scipy(seed, shape):
    rng = np.random.default_rng(seed)
    q = random_quaternions(rng, shape)
    v = rng.normal(size=shape + (3,))
    out = jq.rotate(q, v)
    assert out.shape == shape + (3,)
    np.testing.assert_allclose(
        np.reshape(out, (-1, 3)), scipy_rot(q).apply(v.reshape(-1, 3)), atol=1e-13
    )
    back = jq.rotate_inverse(q, out)
    np.testing.assert_allclose(back, v, atol=1e-13)
    # Literal (17.26): q ⊗ (0, v) ⊗ q*.
    pure = np.concatenate([np.zeros(shape + (1,)), v], axis=-1)
    literal = jq.multiply(jq.multiply(q, pure), jq.conjugate(q))
    np.testing.assert_allclose(literal[..., 0], 0.0, atol=1e-14)
    np.testing.assert_allclose(literal[..., 1:], out, atol=1e-13)
    # Rotation preserves length (exercise 17.8b).
    np.testing.assert_allclose(np.linalg.norm(out, axis=-1), np.linalg.norm(v, axis=-1), rtol=1e-13)


@given(seed=seeds, shape=batch_shapes)
@SETTINGS
def test_rotate_composes_as_multiply(seed, shape):
    rng = np.random.default_rng(seed)
    p, q = random_quaternions(rng, shape), random_quaternions(rng, shape)
    v = rng.normal(size=shape + (3,))
    np.testing.assert_allclose(
        jq.rotate(jq.multiply(p, q), v), jq.rotate(p, jq.rotate(q, v)), atol=1e-13
    )


def test_rotate_edge_cases_match_scipy():
    v = np.random.default_rng(1).normal(size=(len(EDGE), 3))
    np.testing.assert_allclose(jq.rotate(EDGE, v), scipy_rot(EDGE).apply(v), atol=1e-13)
    # 90° about z maps x to y (right-hand rule, active).
    q = jq.from_axis_angle(jnp.array([0.0, 0.0, 1.0]), jnp.pi / 2)
    np.testing.assert_allclose(jq.rotate(q, jnp.array([1.0, 0.0, 0.0])), [0, 1, 0], atol=1e-15)


def test_rotate_broadcasts_one_quaternion_over_many_vectors():
    rng = np.random.default_rng(3)
    q = random_quaternions(rng, ())
    v = rng.normal(size=(3, 1, 2, 3))
    out = jq.rotate(q, v)
    assert out.shape == (3, 1, 2, 3)
    np.testing.assert_allclose(out.reshape(-1, 3), scipy_rot(q).apply(v.reshape(-1, 3)), atol=1e-13)


# ---------------------------------------------------------------------------
# Axis-angle (17.25, 17.27) and rotation vectors
# ---------------------------------------------------------------------------


@given(seed=seeds, shape=batch_shapes)
@SETTINGS
def test_axis_angle_matches_scipy(seed, shape):
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=shape + (3,))
    angle = rng.uniform(-2 * np.pi, 2 * np.pi, size=shape)
    q = jq.from_axis_angle(axis, angle)
    assert q.shape == shape + (4,)
    unit = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    expected = Rotation.from_rotvec((unit * angle[..., None]).reshape(-1, 3))
    # (17.25) is sign-definite: compare the quaternion itself, not up to sign.
    np.testing.assert_allclose(
        np.reshape(q, (-1, 4)),
        np.concatenate(
            [
                np.cos(angle / 2).reshape(-1, 1),
                (np.sin(angle / 2)[..., None] * unit).reshape(-1, 3),
            ],
            axis=-1,
        ),
        atol=1e-15,
    )
    assert_same_rotation(np.reshape(q, (-1, 4)), expected.as_quat(scalar_first=True))
    # Exercise 17.8a: unit length.
    np.testing.assert_allclose(jq.norm(q), 1.0, rtol=1e-15)

    axis_out, angle_out = jq.to_axis_angle(q)
    assert axis_out.shape == shape + (3,) and angle_out.shape == shape
    rv = expected.as_rotvec()
    np.testing.assert_allclose(np.reshape(angle_out, -1), np.linalg.norm(rv, axis=-1), atol=1e-12)
    np.testing.assert_allclose(np.reshape(axis_out * angle_out[..., None], (-1, 3)), rv, atol=1e-12)


def test_axis_angle_broadcasts_scalar_angle():
    q = jq.from_axis_angle(np.eye(3), 0.5)
    assert q.shape == (3, 4)
    q = jq.from_axis_angle(np.array([0.0, 0.0, 2.0]), np.linspace(0, 1, 5))
    assert q.shape == (5, 4)
    np.testing.assert_allclose(q[:, 3], np.sin(np.linspace(0, 1, 5) / 2), atol=1e-15)


def test_to_axis_angle_edge_cases():
    axis, angle = jq.to_axis_angle(EDGE)
    rv = scipy_rot(EDGE).as_rotvec()
    np.testing.assert_allclose(angle, np.linalg.norm(rv, axis=-1), atol=1e-12)
    assert np.all((angle >= 0) & (angle <= np.pi))
    np.testing.assert_allclose(np.linalg.norm(axis, axis=-1), 1.0, rtol=1e-14)
    # The rotation is recovered exactly, including at 0 and π.
    assert_same_rotation(jq.from_axis_angle(axis, angle), EDGE, atol=1e-12)
    # Identity: the documented default axis.
    axis0, angle0 = jq.to_axis_angle(jq.identity())
    np.testing.assert_array_equal(axis0, [1.0, 0.0, 0.0])
    assert angle0 == 0.0
    # Tiny angle: accurate where the chapter's 2 arccos(q0) would return 0.
    _, tiny = jq.to_axis_angle(jq.from_axis_angle(jnp.array([0.0, 1.0, 0.0]), 1e-9))
    np.testing.assert_allclose(tiny, 1e-9, rtol=1e-12)


@given(seed=seeds, shape=batch_shapes, log_angle=st.floats(-12, np.log10(np.pi)))
@SETTINGS
def test_rotvec_matches_scipy(seed, shape, log_angle):
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=shape + (3,))
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    rotvec = axis * 10.0**log_angle
    q = jq.from_rotvec(rotvec)
    assert q.shape == shape + (4,)
    expected = Rotation.from_rotvec(rotvec.reshape(-1, 3)).as_quat(scalar_first=True)
    np.testing.assert_allclose(np.reshape(q, (-1, 4)), expected, atol=1e-15)
    back = jq.to_rotvec(q)
    # -q is the same rotation and gives the same rotation vector.
    np.testing.assert_array_equal(jq.to_rotvec(-q), back)
    if 10.0**log_angle < np.pi - 1e-6:
        np.testing.assert_allclose(back, rotvec, rtol=1e-10, atol=1e-15)
    else:
        # Within rounding of π, w = cos(θ/2) may round to either sign and ±axis are
        # both right: compare as rotations, and the angle.
        assert_same_rotation(jq.from_rotvec(back), q, atol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(back, axis=-1), np.pi, rtol=1e-12)


def test_to_rotvec_edge_cases_match_scipy():
    rv = np.asarray(jq.to_rotvec(EDGE))
    ref = scipy_rot(EDGE).as_rotvec()
    angle = np.linalg.norm(ref, axis=-1)
    at_pi = np.abs(angle - np.pi) < 1e-6
    # Away from π the rotation vector is unique.
    np.testing.assert_allclose(rv[~at_pi], ref[~at_pi], atol=1e-12)
    # At (or within 1e-9 of) π, ±axis are both valid: compare as rotations.
    assert_same_rotation(jq.from_rotvec(rv), EDGE, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(rv[at_pi], axis=-1), angle[at_pi], atol=1e-12)


# ---------------------------------------------------------------------------
# slerp, distance, scipy interop
# ---------------------------------------------------------------------------


@given(seed=seeds, t=st.floats(0.0, 1.0))
@SETTINGS
def test_slerp_matches_scipy(seed, t):
    rng = np.random.default_rng(seed)
    p, q = random_quaternions(rng, (2,))
    key = Rotation.from_quat(np.stack([p, q]), scalar_first=True)
    expected = Slerp([0.0, 1.0], key)([t]).as_quat(scalar_first=True)[0]
    out = jq.slerp(p, q, t)
    assert_same_rotation(out, expected, atol=1e-12)
    # Constant speed along the shorter arc.
    d = float(jq.distance(p, q))
    assert d <= np.pi
    np.testing.assert_allclose(jq.distance(out, p), t * d, atol=1e-12)
    np.testing.assert_allclose(jq.distance(out, q), (1 - t) * d, atol=1e-12)


def test_slerp_endpoints_shorter_arc_and_batch():
    rng = np.random.default_rng(5)
    p = random_quaternions(rng, (3, 1, 2))
    q = random_quaternions(rng, (3, 1, 2))
    np.testing.assert_allclose(jq.slerp(p, q, 0.0), p, atol=1e-14)
    assert_same_rotation(jq.slerp(p, q, 1.0), q, atol=1e-13)
    # -q gives the same path (shorter arc), and p == q is exact.
    t = np.linspace(0, 1, 4).reshape(4, 1, 1, 1)
    out = jq.slerp(p, q, t)
    assert out.shape == (4, 3, 1, 2, 4)
    np.testing.assert_allclose(jq.slerp(p, -q, t), out, atol=1e-13)
    np.testing.assert_allclose(jq.slerp(p, p, 0.3), p, atol=1e-15)
    # any finite non-zero norm: a unit result, ±q at t = 1 (it was scaled by |p|)
    out = jq.slerp(2.0 * p, -3.0 * q, t)
    np.testing.assert_allclose(jq.norm(out), 1.0, rtol=1e-14)
    np.testing.assert_allclose(out, jq.slerp(p, q, t), atol=1e-13)


def test_distance():
    p = jq.from_axis_angle(jnp.array([1.0, 2.0, 3.0]), 0.7)
    q = jq.from_axis_angle(jnp.array([1.0, 2.0, 3.0]), -0.4)
    np.testing.assert_allclose(jq.distance(p, q), 1.1, rtol=1e-14)
    np.testing.assert_allclose(jq.distance(p, -q), 1.1, rtol=1e-14)
    rng = np.random.default_rng(2)
    a, b = random_quaternions(rng, (2, 10))
    ref = (scipy_rot(a).inv() * scipy_rot(b)).magnitude()
    np.testing.assert_allclose(jq.distance(a, b), ref, atol=1e-12)
    np.testing.assert_allclose(jq.squared_distance(a, -2.0 * b), ref**2, atol=1e-12)


def test_squared_distance_is_smooth_where_the_rotations_coincide():
    """The Hessian of the squared angle in the rotation vector is 2 I, also at p = q,
    where that of ``distance**2`` is zero (the angle has no derivative there)."""
    q = jnp.array([0.5, 0.5, 0.5, 0.5])
    for w in (jnp.zeros(3), jnp.array([1e-3, 0.0, 0.0]), jnp.array([0.3, -0.2, 1.0])):
        hessian = jax.hessian(lambda w: jq.squared_distance(jq.multiply(q, jq.from_rotvec(w)), q))
        np.testing.assert_allclose(hessian(w), 2 * np.eye(3), atol=1e-12)
    zero = jax.hessian(lambda w: jq.distance(jq.multiply(q, jq.from_rotvec(w)), q) ** 2)
    np.testing.assert_array_equal(zero(jnp.zeros(3)), 0.0)  # what distance**2 gives there
    half_turn = jq.squared_distance(jnp.array([0.0, 1, 0, 0]), jnp.array([1.0, 0, 0, 0]))
    np.testing.assert_allclose(half_turn, np.pi**2, rtol=1e-15)


@pytest.mark.parametrize("shape", BATCH_SHAPES)
def test_xyzw_matches_scipy(shape):
    rng = np.random.default_rng(4)
    q = random_quaternions(rng, shape)
    xyzw = jq.to_xyzw(q)
    # scipy renormalises on input, hence the one-ulp tolerance.
    np.testing.assert_allclose(
        np.reshape(xyzw, (-1, 4)), scipy_rot(q).as_quat(scalar_first=False), atol=1e-15
    )
    np.testing.assert_array_equal(jq.from_xyzw(xyzw), q)
    r = Rotation.from_quat(np.reshape(np.asarray(xyzw), (-1, 4)))
    assert_same_rotation(r.as_quat(scalar_first=True), np.reshape(q, (-1, 4)))


# ---------------------------------------------------------------------------
# Kinematics (17.37-17.44)
# ---------------------------------------------------------------------------


def _scipy_finite_difference(make_rotation, h=1e-5):
    """Central difference of scipy quaternions of make_rotation(t) at t = 0."""
    qp = make_rotation(h).as_quat(scalar_first=True)
    qm = make_rotation(-h).as_quat(scalar_first=True)
    q0 = make_rotation(0.0).as_quat(scalar_first=True)
    qp *= np.sign(np.sum(qp * q0, axis=-1, keepdims=True))
    qm *= np.sign(np.sum(qm * q0, axis=-1, keepdims=True))
    return q0, (qp - qm) / (2 * h)


@given(seed=seeds)
@SETTINGS
def test_angular_velocity_of_scipy_motion(seed):
    """q(t) = q0 ∘ exp(ω_b t) turns at body rate ω_b; q(t) = exp(ω_s t) ∘ q0 at space rate ω_s."""
    rng = np.random.default_rng(seed)
    r0 = Rotation.from_quat(random_quaternions(rng, (4,)), scalar_first=True)
    omega = rng.normal(size=(4, 3))
    q0, qdot = _scipy_finite_difference(lambda t: r0 * Rotation.from_rotvec(omega * t))
    np.testing.assert_allclose(jq.angular_velocity(q0, qdot), omega, atol=1e-8)
    np.testing.assert_allclose(
        2 * jnp.einsum("...ij,...j->...i", jq.w_matrix(q0), qdot), omega, atol=1e-8
    )
    np.testing.assert_allclose(jq.derivative(q0, omega), qdot, atol=1e-8)
    np.testing.assert_allclose(jq.angular_velocity_space(q0, qdot), r0.apply(omega), atol=1e-8)

    q0, qdot = _scipy_finite_difference(lambda t: Rotation.from_rotvec(omega * t) * r0)
    np.testing.assert_allclose(jq.angular_velocity_space(q0, qdot), omega, atol=1e-8)
    np.testing.assert_allclose(
        2 * jnp.einsum("...ij,...j->...i", jq.w_matrix_space(q0), qdot), omega, atol=1e-8
    )
    np.testing.assert_allclose(jq.derivative_space(q0, omega), qdot, atol=1e-8)


def test_space_angular_velocity_rotates_vectors():
    """(17.40): d/dt (R(t) r0) = ω_space × r, with R(t) from scipy."""
    rng = np.random.default_rng(11)
    r0 = Rotation.from_quat(random_quaternions(rng, ()), scalar_first=True)
    omega_b = rng.normal(size=3)
    q0, qdot = _scipy_finite_difference(lambda t: r0 * Rotation.from_rotvec(omega_b * t))
    x = rng.normal(size=3)
    h = 1e-5
    rdot = (
        (r0 * Rotation.from_rotvec(omega_b * h)).apply(x)
        - (r0 * Rotation.from_rotvec(-omega_b * h)).apply(x)
    ) / (2 * h)
    omega_s = jq.angular_velocity_space(q0, qdot)
    np.testing.assert_allclose(np.cross(omega_s, r0.apply(x)), rdot, atol=1e-8)


@given(seed=seeds, shape=batch_shapes)
@SETTINGS
def test_kinematics_round_trips_and_w_matrix(seed, shape):
    rng = np.random.default_rng(seed)
    q = random_quaternions(rng, shape)
    omega = rng.normal(size=shape + (3,))
    qdot = jq.derivative(q, omega)
    assert qdot.shape == shape + (4,)
    np.testing.assert_allclose(jq.angular_velocity(q, qdot), omega, atol=1e-13)
    # q̇ is tangent: q·q̇ = 0 (the chapter's fourth row of (17.42)).
    np.testing.assert_allclose(np.sum(q * np.asarray(qdot), axis=-1), 0.0, atol=1e-14)

    w = np.asarray(jq.w_matrix(q))
    assert w.shape == shape + (3, 4)
    # Orthonormal rows, W q = 0, ω = 2 W q̇ (17.42) and q̇ = ½ Wᵀ ω (17.44).
    np.testing.assert_allclose(
        w @ np.swapaxes(w, -1, -2), np.broadcast_to(np.eye(3), shape + (3, 3)), atol=1e-14
    )
    np.testing.assert_allclose(np.einsum("...ij,...j->...i", w, q), 0.0, atol=1e-14)
    np.testing.assert_allclose(2 * np.einsum("...ij,...j->...i", w, qdot), omega, atol=1e-13)
    np.testing.assert_allclose(0.5 * np.einsum("...ji,...j->...i", w, omega), qdot, atol=1e-14)
    # The chapter's full 4x4 W with fourth row q is orthogonal.
    w4 = np.concatenate([w, q[..., None, :]], axis=-2)
    np.testing.assert_allclose(
        np.swapaxes(w4, -1, -2) @ w4, np.broadcast_to(np.eye(4), shape + (4, 4)), atol=1e-14
    )

    # Tangent q̇ (not built by derivative) round-trips as well.
    raw = rng.normal(size=shape + (4,))
    tangent = raw - np.sum(raw * q, axis=-1, keepdims=True) * q
    np.testing.assert_allclose(
        jq.derivative(q, jq.angular_velocity(q, tangent)), tangent, atol=1e-13
    )
    # Space and body rates are related by the rotation.
    np.testing.assert_allclose(jq.angular_velocity_space(q, qdot), jq.rotate(q, omega), atol=1e-13)
    np.testing.assert_allclose(jq.derivative_space(q, jq.rotate(q, omega)), qdot, atol=1e-14)


def test_w_matrix_is_the_chapter_matrix():
    """(17.43) printed row by row."""
    q0, q1, q2, q3 = 0.1, 0.2, 0.3, 0.4
    expected = [
        [-q1, q0, q3, -q2],
        [-q2, -q3, q0, q1],
        [-q3, q2, -q1, q0],
    ]
    np.testing.assert_array_equal(jq.w_matrix(jnp.array([q0, q1, q2, q3])), expected)


# ---------------------------------------------------------------------------
# Transformations: jit and vmap agree with eager batched calls
# ---------------------------------------------------------------------------

FUNCTIONS = {
    "conjugate": lambda p, q, v: jq.conjugate(p),
    "norm": lambda p, q, v: jq.norm(p),
    "normalize": lambda p, q, v: jq.normalize(p),
    "inverse": lambda p, q, v: jq.inverse(p),
    "canonicalize": lambda p, q, v: jq.canonicalize(p),
    "to_rotvec": lambda p, q, v: jq.to_rotvec(p),
    "to_axis_angle": lambda p, q, v: jq.to_axis_angle(p),
    "xyzw": lambda p, q, v: jq.from_xyzw(jq.to_xyzw(p)),
    "w_matrix": lambda p, q, v: jq.w_matrix(p),
    "w_matrix_space": lambda p, q, v: jq.w_matrix_space(p),
    "multiply": lambda p, q, v: jq.multiply(p, q),
    "distance": lambda p, q, v: jq.distance(p, q),
    "slerp": lambda p, q, v: jq.slerp(p, q, 0.3),
    "angular_velocity": lambda p, q, v: jq.angular_velocity(p, q),
    "angular_velocity_space": lambda p, q, v: jq.angular_velocity_space(p, q),
    "rotate": lambda p, q, v: jq.rotate(p, v),
    "rotate_inverse": lambda p, q, v: jq.rotate_inverse(p, v),
    "derivative": lambda p, q, v: jq.derivative(p, v),
    "derivative_space": lambda p, q, v: jq.derivative_space(p, v),
    "from_axis_angle": lambda p, q, v: jq.from_axis_angle(v, p[..., 0]),
    "from_rotvec": lambda p, q, v: jq.from_rotvec(v),
}


def _all_functions(p, q, v):
    return {name: f(p, q, v) for name, f in FUNCTIONS.items()}


@pytest.fixture(scope="module")
def transformed_results():
    """Every function evaluated eagerly on a batch, and under jit of vmap."""
    rng = np.random.default_rng(1)
    p = np.concatenate([EDGE, random_quaternions(rng, (5,))])
    q = random_quaternions(rng, p.shape[:1])
    v = rng.normal(size=(len(p), 3))
    eager = _all_functions(p, q, v)
    # One compile covers both transformations: jit of vmap of the single-element kernel.
    transformed = jax.jit(jax.vmap(_all_functions))(p, q, v)
    return eager, transformed


@pytest.mark.parametrize("name", sorted(FUNCTIONS))
def test_jit_and_vmap_agree_with_eager(name, transformed_results):
    eager, transformed = transformed_results
    pairs = zip(jax.tree.leaves(transformed[name]), jax.tree.leaves(eager[name]), strict=True)
    for a, b in pairs:
        assert a.shape == b.shape
        np.testing.assert_allclose(a, b, atol=1e-14)


# ---------------------------------------------------------------------------
# float32
# ---------------------------------------------------------------------------


def test_float32_core(float32):
    rng = np.random.default_rng(3)
    q64 = random_quaternions(rng, (20,))
    v64 = rng.normal(size=(20, 3))
    r = scipy_rot(q64)
    rv = r.as_rotvec()

    @jax.jit
    def compute(q, v, rv, tiny):
        return {
            "multiply": jq.multiply(q, q[::-1]),
            "rotate": jq.rotate(q, v),
            "to_rotvec": jq.to_rotvec(q),
            "from_rotvec": jq.from_rotvec(rv),
            "slerp": jq.slerp(q, q[::-1], 0.5),
            "omega": jq.angular_velocity(q, jq.derivative(q, v)),
            "angle": jq.to_axis_angle(q)[1],
            "tiny": jq.to_rotvec(jq.from_rotvec(tiny)),
            "identity": jq.identity(),
        }

    f32 = lambda x: jnp.asarray(x, jnp.float32)
    tiny = np.array([1e-9, -2e-9, 3e-9])
    out = compute(f32(q64), f32(v64), f32(rv), f32(tiny))
    for name, value in out.items():
        assert value.dtype == jnp.float32, name
    np.testing.assert_allclose(out["rotate"], r.apply(v64), atol=2e-6)
    np.testing.assert_allclose(out["to_rotvec"], rv, atol=2e-6)
    assert_same_rotation(out["from_rotvec"], r.as_quat(scalar_first=True), atol=1e-6)
    assert_same_rotation(out["multiply"], (r * r[::-1]).as_quat(scalar_first=True), atol=1e-6)
    np.testing.assert_allclose(out["omega"], v64, atol=2e-6)
    np.testing.assert_allclose(out["angle"], r.magnitude(), atol=2e-6)
    slerp_ref = [
        Slerp([0, 1], r[[k, 19 - k]])([0.5]).as_quat(scalar_first=True)[0] for k in range(20)
    ]
    assert_same_rotation(out["slerp"], np.asarray(slerp_ref), atol=2e-6)
    # Tiny angles in float32 stay accurate (Taylor branch).
    np.testing.assert_allclose(out["tiny"], tiny, rtol=1e-6)


def test_xyzw_shape_error_names_the_scalar_last_order():
    with pytest.raises(ValueError, match=r"q_xyzw must have shape .*\(x, y, z, w\)"):
        jq.from_xyzw(jnp.ones(3))


def test_axis_of_a_rotation_by_a_subnormal_size_angle_is_kept():
    """A vector part whose squares underflow (below ~1e-154 in float64) still has its
    axis and angle, as scipy's rotation vector has."""
    axis, angle = jq.to_axis_angle(jnp.array([1.0, 0.0, 3e-200, 4e-200]))
    np.testing.assert_allclose(np.asarray(axis), [0.0, 0.6, 0.8], rtol=1e-15)
    np.testing.assert_allclose(float(angle), 1e-199, rtol=1e-15)


@pytest.mark.parametrize("exponent", [-120, -100, -69, -60, 0, 60, 120])
def test_rotations_near_the_identity_at_any_scale(exponent):
    """A quaternion near the identity scaled by 1e-60…1e-120 (the product of two scaled
    by 1e-60 in squared_distance) gave NaN: the Taylor branch of to_rotvec divided by
    w³, which underflows."""
    scale = 10.0**exponent
    q = jnp.array([1.0, 1e-9, 0.0, 0.0]) * scale
    np.testing.assert_allclose(jq.to_rotvec(q), [2e-9, 0.0, 0.0], rtol=1e-12, atol=0)
    p = jnp.array([0.8, 0.2, 0.1, 0.3]) * scale
    assert float(jq.squared_distance(p, p)) <= 1e-30  # (rounding: an angle of ~1e-17)
