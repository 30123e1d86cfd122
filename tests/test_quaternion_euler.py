"""Euler angles for all 12 sequences (intrinsic and extrinsic) against scipy."""

import hypothesis.strategies as st
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _rotations import assert_same_rotation
from hypothesis import given, settings
from scipy.spatial.transform import Rotation

import jrigid.quaternion as jq

SETTINGS = settings(max_examples=25, deadline=None)
SEQUENCES = jq.EULER_SEQUENCES


def is_symmetric(seq):
    return seq[0].lower() == seq[2].lower()


def singular_middles(seq):
    return (0.0, np.pi) if is_symmetric(seq) else (np.pi / 2, -np.pi / 2)




def angle_diff(a, b):
    """Difference of angles modulo 2π, in [-π, π)."""
    return (np.asarray(a) - np.asarray(b) + np.pi) % (2 * np.pi) - np.pi


def test_sequence_list():
    assert len(SEQUENCES) == 24
    assert len(set(SEQUENCES)) == 24
    assert "ZXZ" in SEQUENCES and "zyx" in SEQUENCES


@pytest.mark.parametrize("seq", SEQUENCES)
def test_matches_scipy_on_random_rotations(seq):
    rng = np.random.default_rng(abs(hash(seq)) % 2**32)
    r = Rotation.random(200, rng=rng)
    q = r.as_quat(scalar_first=True)
    angles = jq.to_euler(seq, q)
    assert angles.shape == (200, 3)
    np.testing.assert_allclose(angles, r.as_euler(seq), atol=1e-12)
    # -q is the same rotation, with the same angles.
    np.testing.assert_allclose(jq.to_euler(seq, -q), angles, atol=1e-12)
    # from_euler of scipy's angles is the same rotation.
    ref_angles = r.as_euler(seq)
    assert_same_rotation(jq.from_euler(seq, ref_angles), q, atol=1e-13)
    # Ranges: second angle in [0, π] (proper) or [-π/2, π/2] (Tait-Bryan).
    mid = np.asarray(angles[:, 1])
    if is_symmetric(seq):
        assert np.all((mid >= 0) & (mid <= np.pi))
    else:
        assert np.all(np.abs(mid) <= np.pi / 2)
    assert np.all((np.asarray(angles) >= -np.pi) & (np.asarray(angles) < np.pi))


@given(seq=st.sampled_from(SEQUENCES), seed=st.integers(0, 2**32 - 1))
@SETTINGS
def test_from_euler_matches_scipy(seq, seed):
    rng = np.random.default_rng(seed)
    angles = rng.uniform(-2 * np.pi, 2 * np.pi, size=(3, 1, 2, 3))
    q = jq.from_euler(seq, angles)
    assert q.shape == (3, 1, 2, 4)
    ref = Rotation.from_euler(seq, angles.reshape(-1, 3)).as_quat(scalar_first=True)
    assert_same_rotation(np.reshape(q, (-1, 4)), ref, atol=1e-14)


@pytest.mark.parametrize("seq", SEQUENCES)
def test_gimbal_lock_third_angle_zero_and_matches_scipy(seq):
    rng = np.random.default_rng(1)
    for middle in singular_middles(seq):
        angles = rng.uniform(-3, 3, size=(20, 3))
        angles[:, 1] = middle
        r = Rotation.from_euler(seq, angles)
        q = r.as_quat(scalar_first=True)
        out = np.asarray(jq.to_euler(seq, q))
        assert np.all(np.isfinite(out))
        np.testing.assert_array_equal(out[:, 2], 0.0)
        np.testing.assert_allclose(
            angle_diff(out, r.as_euler(seq, suppress_warnings=True)), 0, atol=1e-12
        )
        assert_same_rotation(jq.from_euler(seq, out), q, atol=1e-12)
        assert np.all(jq.gimbal_lock(seq, q))


@pytest.mark.parametrize("seq", ["ZXZ", "xyz", "yzy", "ZYX"])
@pytest.mark.parametrize("offset", [1e-9, 1e-6, 1e-3])
def test_near_gimbal_lock(seq, offset):
    rng = np.random.default_rng(2)
    for middle in singular_middles(seq):
        angles = rng.uniform(-3, 3, size=(10, 3))
        # Move towards the inside of the valid range.
        angles[:, 1] = middle + (offset if middle in (0.0, -np.pi / 2) else -offset)
        r = Rotation.from_euler(seq, angles)
        q = r.as_quat(scalar_first=True)
        out = jq.to_euler(seq, q)
        assert np.all(np.isfinite(out))
        # Within eps of the singularity the second angle is snapped: error ~ offset.
        assert_same_rotation(jq.from_euler(seq, out), q, atol=1e-12 + offset)
        np.testing.assert_allclose(
            angle_diff(out, r.as_euler(seq, suppress_warnings=True)), 0, atol=1e-9
        )
        assert np.all(np.asarray(jq.gimbal_lock(seq, q)) == (offset < 1e-7))


@pytest.mark.parametrize("seq", ["XYZ", "zyx", "ZXZ", "xzx"])
def test_tiny_angles(seq):
    angles = np.array([[1e-9, 2e-9, -3e-9], [0.5, 1e-9, 0.3], [1e-9, 1.0, 1e-9]])
    if is_symmetric(seq):
        angles[:, 1] += 0.5  # keep away from the proper-Euler singularity at 0
    q = jq.from_euler(seq, angles)
    assert_same_rotation(q, Rotation.from_euler(seq, angles).as_quat(scalar_first=True), atol=1e-16)
    out = jq.to_euler(seq, q)
    np.testing.assert_allclose(out, angles, atol=1e-15)


def test_chapter_zxz_is_precession_nutation_spin():
    """Intrinsic ZXZ: precession φ about z, nutation θ about the new x, spin ψ about the new z."""
    phi, theta, psi = 0.3, 0.8, -1.1
    ez, ex = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
    q = jq.multiply(
        jq.multiply(jq.from_axis_angle(ez, phi), jq.from_axis_angle(ex, theta)),
        jq.from_axis_angle(ez, psi),
    )
    np.testing.assert_allclose(jq.from_euler("ZXZ", [phi, theta, psi]), q, atol=1e-15)
    np.testing.assert_allclose(jq.to_euler("ZXZ", q), [phi, theta, psi], atol=1e-14)
    # The body z axis has polar angle θ and azimuth φ - π/2.
    body_z = jq.rotate(q, ez)
    np.testing.assert_allclose(
        body_z,
        [np.sin(theta) * np.sin(phi), -np.sin(theta) * np.cos(phi), np.cos(theta)],
        atol=1e-15,
    )


@pytest.mark.parametrize(
    "seq", ["XXY", "xyZ", "abc", "XY", "XYZW", "", "ZxZ", 3, None, "xyx ", "XZZ"]
)
def test_invalid_sequence_raises(seq):
    for f in (lambda: jq.from_euler(seq, np.zeros(3)), lambda: jq.to_euler(seq, jq.identity())):
        with pytest.raises(ValueError, match="invalid Euler sequence.*ZXZ"):
            f()


def test_wrong_angle_shape_raises():
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        jq.from_euler("XYZ", np.zeros(2))


def test_jit_vmap():
    rng = np.random.default_rng(3)
    q = Rotation.random(8, rng=rng).as_quat(scalar_first=True)
    seqs = ("XYZ", "zxz", "yzy")

    def kernel(x):
        angles = {s: jq.to_euler(s, x) for s in seqs}
        return angles, {s: jq.from_euler(s, a) for s, a in angles.items()}

    angles, back = jax.jit(jax.vmap(kernel))(q)
    for s in seqs:
        eager = jq.to_euler(s, q)
        np.testing.assert_allclose(angles[s], eager, atol=1e-14)
        np.testing.assert_allclose(back[s], jq.from_euler(s, eager), atol=1e-15)


def test_float32(float32):
    rng = np.random.default_rng(4)
    r = Rotation.random(50, rng=rng)
    q = jnp.asarray(r.as_quat(scalar_first=True), jnp.float32)

    def compute(q, locked_angles, seq_index):
        seq = ("XYZ", "zxz")[seq_index]
        out = jq.to_euler(seq, q)
        # Gimbal lock built in float32 (with rounding noise) from a matrix round trip.
        ql = jq.from_matrix(jq.to_matrix(jq.from_euler(seq, locked_angles)))
        locked = jq.to_euler(seq, ql)
        return out, jq.from_euler(seq, out), ql, locked, jq.from_euler(seq, locked)

    for k, seq in enumerate(("XYZ", "zxz")):
        angles = rng.uniform(-3, 3, size=(20, 3)).astype(np.float32)
        angles[:, 1] = singular_middles(seq)[0]
        out, back, ql, locked, locked_back = jax.jit(compute, static_argnums=2)(q, angles, k)
        for x in (out, back, locked):
            assert x.dtype == jnp.float32
        np.testing.assert_allclose(angle_diff(out, r.as_euler(seq)), 0, atol=5e-5)
        assert_same_rotation(back, q, atol=2e-6)
        np.testing.assert_array_equal(locked[:, 2], 0.0)
        assert_same_rotation(locked_back, ql, atol=5e-6)


@pytest.mark.filterwarnings("ignore:Gimbal lock detected")
@pytest.mark.parametrize("seq", ["ZXZ", "zxz", "XYX", "yzy"])
def test_symmetric_middle_angle_at_pi_is_plus_pi(seq):
    """A half turn about the middle axis gives θ = +π (scipy's value, inside [0, π])."""
    axis = {"x": 0, "y": 1, "z": 2}[seq[1].lower()]
    rotvec = np.zeros(3)
    rotvec[axis] = np.pi
    q = Rotation.from_rotvec(rotvec).as_quat(scalar_first=True)
    angles = np.asarray(jq.to_euler(seq, jnp.asarray(q)))
    expected = Rotation.from_quat(q, scalar_first=True).as_euler(seq)
    np.testing.assert_allclose(angles[1], np.pi, atol=1e-12)
    np.testing.assert_allclose(angles[1], expected[1], atol=1e-12)


@pytest.mark.parametrize("bad", [[np.nan, 0.0, 0.0, 1.0], [0.0, np.inf, 0.0, 0.0]])
@pytest.mark.parametrize("seq", ["XYZ", "ZXZ", "xyz", "zxz"])
def test_a_non_finite_quaternion_has_no_angles_and_no_lock(seq, bad):
    """All three angles NaN (one NaN entry used to leave the others finite, the third
    forced to 0 as at a lock) and no gimbal lock reported."""
    assert np.all(np.isnan(np.asarray(jq.to_euler(seq, jnp.asarray(bad)))))
    assert not bool(jq.gimbal_lock(seq, jnp.asarray(bad)))


@pytest.mark.parametrize("eps", [0.5, -1e-3, float("nan"), "1e-3", True])
def test_a_gimbal_lock_tolerance_out_of_range_is_refused(eps):
    """A large tolerance returned 'locked' angles 0.18 rad from the rotation (eps = 0.5)."""
    q = jq.from_euler("XYZ", jnp.array([0.3, 1.2, -0.5]))
    for f in (jq.to_euler, jq.gimbal_lock):
        with pytest.raises(ValueError, match="eps"):
            f("XYZ", q, eps=eps)


def test_angles_returned_as_locked_stand_for_the_rotation_within_eps():
    """Within eps of lock the third angle is set to zero: the rotation the angles give is
    within about eps/2 of q, for every accepted eps (up to 1e-2)."""
    for eps in (1e-2, 1e-4, 1e-6):
        q = jq.from_euler("XYZ", jnp.array([0.3, np.pi / 2 - 0.9 * eps, -0.5]))
        assert bool(jq.gimbal_lock("XYZ", q, eps=eps))
        back = jq.from_euler("XYZ", jq.to_euler("XYZ", q, eps=eps))
        assert float(jq.distance(back, q)) <= eps
