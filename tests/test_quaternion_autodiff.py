"""Gradients: finite at the identity, at 180° and at gimbal lock; correct where defined."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import jrigid.quaternion as jq

# Quaternions at the edge cases: identity, 180° about x / y / z / a diagonal, tiny angle,
# and with negative scalar part.
EDGE_Q = np.array(
    [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
        [0.0, 1 / np.sqrt(2), 1 / np.sqrt(2), 0.0],
        [np.cos(5e-10), np.sin(5e-10), 0.0, 0.0],
        [-1.0, 0.0, 0.0, 0.0],
        # Last row: a generic rotation, where derivatives are also checked against
        # finite differences.
        Rotation.random(rng=np.random.default_rng(1)).as_quat(scalar_first=True),
    ]
)
EDGE_ROTVEC = np.array(
    [[0.0, 0.0, 0.0], [1e-9, 0.0, 0.0], [np.pi, 0.0, 0.0], [0.0, 0.0, -np.pi], [2.0, -1.0, 0.5]]
)
P_FIXED = np.array([0.5, 0.5, -0.5, 0.5])

Q_FUNCTIONS = {
    "norm": jq.norm,
    "normalize": jq.normalize,
    "inverse": jq.inverse,
    "to_rotvec": jq.to_rotvec,
    "to_axis_angle.axis": lambda q: jq.to_axis_angle(q)[0],
    "to_axis_angle.angle": lambda q: jq.to_axis_angle(q)[1],
    "to_matrix": jq.to_matrix,
    "passive_matrix": jq.passive_matrix,
    "to_euler.ZXZ": lambda q: jq.to_euler("ZXZ", q),
    "to_euler.xyz": lambda q: jq.to_euler("xyz", q),
    "multiply": lambda q: jq.multiply(q, q),
    "rotate": lambda q: jq.rotate(q, jnp.array([0.3, -1.0, 2.0], q.dtype)),
    "angular_velocity": lambda q: jq.angular_velocity(q, jnp.array([0.1, 0.2, 0.3, 0.4], q.dtype)),
    "distance.self": lambda q: jq.distance(q, jax.lax.stop_gradient(q)),
    "distance.identity": lambda q: jq.distance(q, jq.identity(dtype=q.dtype)),
    "slerp.self": lambda q: jq.slerp(q, jax.lax.stop_gradient(q), 0.3),
    "slerp.identity": lambda q: jq.slerp(jq.identity(dtype=q.dtype), q, 0.7),
    "roundtrip.matrix": lambda q: jq.from_matrix(jq.to_matrix(q)),
}
# These hold their second argument fixed with stop_gradient, so finite differences of
# the function (which move both arguments) are not comparable.
STOPPED_GRADIENT = {"distance.self", "slerp.self"}
ROTVEC_FUNCTIONS = {
    "from_rotvec": jq.from_rotvec,
    "from_axis_angle": lambda r: jq.from_axis_angle(jnp.array([1.0, 2.0, 2.0], r.dtype), r[0]),
    "rodrigues_matrix": lambda r: jq.rodrigues_matrix(jnp.array([0.0, 0.0, 1.0], r.dtype), r[0]),
    "passive_axis_matrix": lambda r: jq.passive_axis_matrix("y", r[0]),
    "passive_zxz_matrix": lambda r: jq.passive_zxz_matrix(r[0], r[1], r[2]),
    "from_matrix": lambda r: jq.from_matrix(jq.rodrigues_matrix(jnp.array([1.0, 0, 0]), r[0])),
    "from_matrix.rotvec": lambda r: jq.from_matrix(jq.to_matrix(jq.from_rotvec(r))),
    "project_to_rotation": lambda r: jq.project_to_rotation(jq.to_matrix(jq.from_rotvec(r))),
    "log_exp": lambda r: jq.to_rotvec(jq.from_rotvec(r)),
    "from_euler.ZXZ": lambda r: jq.from_euler("ZXZ", r),
    "project_to_rotation.general": lambda r: jq.project_to_rotation(
        jq.to_matrix(jq.from_rotvec(r)) + 0.1 * jnp.outer(r, r)
    ),
    "slerp.t": lambda r: jq.slerp(jnp.asarray(P_FIXED, r.dtype), jq.from_rotvec(r), r[0] / 4),
}


def _jacobians(functions, xs, step=1e-6):
    """Forward and reverse Jacobians of every function at every row of xs.

    Also returns central differences with ``step`` at the last row of xs. One compiled
    call for all functions (jit of vmap of jacfwd and jacrev; grad is jacrev contracted
    with a cotangent) keeps the suite fast.
    """
    xs = jnp.asarray(xs)
    n = xs.shape[-1]
    shifts = step * np.concatenate([np.eye(n), -np.eye(n)])
    shifted = xs[-1][None, :] + jnp.asarray(shifts, xs.dtype)

    @jax.jit
    def run(xs, shifted):
        jac = jax.vmap(
            lambda x: {name: (jax.jacfwd(f)(x), jax.jacrev(f)(x)) for name, f in functions.items()}
        )(xs)
        values = jax.vmap(lambda x: {name: f(x) for name, f in functions.items()})(shifted)
        return jac, values

    jac, values = jax.tree.map(np.asarray, run(xs, shifted))
    finite_difference = {
        name: np.moveaxis((v[:n] - v[n:]) / (2 * step), 0, -1) for name, v in values.items()
    }
    return jac, finite_difference


def _check(jf, jr, dtype):
    """Both Jacobians have the input dtype, are finite, and agree with each other."""
    for d in (jf, jr):
        assert d.dtype == dtype
        assert np.all(np.isfinite(d)), d
    tol = 1e-5 if dtype == np.float32 else 1e-12
    np.testing.assert_allclose(jf, jr, rtol=tol, atol=tol)


@pytest.fixture(scope="module")
def q_jacobians():
    return _jacobians(Q_FUNCTIONS, EDGE_Q)


@pytest.fixture(scope="module")
def rotvec_jacobians():
    return _jacobians(ROTVEC_FUNCTIONS, EDGE_ROTVEC)


@pytest.mark.parametrize("name", sorted(Q_FUNCTIONS))
def test_quaternion_function_derivatives_finite_at_edges(name, q_jacobians):
    jac, finite_difference = q_jacobians
    _check(*jac[name], np.float64)
    if name in STOPPED_GRADIENT:
        return
    np.testing.assert_allclose(jac[name][0][-1], finite_difference[name], rtol=1e-6, atol=1e-8)


@pytest.mark.parametrize("name", sorted(ROTVEC_FUNCTIONS))
def test_rotvec_function_derivatives_finite_at_edges(name, rotvec_jacobians):
    jac, finite_difference = rotvec_jacobians
    _check(*jac[name], np.float64)
    np.testing.assert_allclose(jac[name][0][-1], finite_difference[name], rtol=1e-6, atol=1e-8)


GIMBAL_SEQUENCES = ["ZXZ", "yxy", "XYZ", "zyx"]


def _gimbal_angles(seq):
    if seq[0].lower() == seq[2].lower():
        middles = [0.0, np.pi, 0.0]
    else:
        middles = [np.pi / 2, -np.pi / 2, np.pi / 2]
    angles = np.array([[0.3, m, 0.5] for m in middles])
    angles[2, 0] = -2.9
    return angles


@pytest.fixture(scope="module")
def gimbal_jacobians():
    """Jacobians of to_euler of every sequence at every sequence's gimbal points."""
    qs = np.concatenate([np.asarray(jq.from_euler(s, _gimbal_angles(s))) for s in GIMBAL_SEQUENCES])
    return _jacobians({s: (lambda x, s=s: jq.to_euler(s, x)) for s in GIMBAL_SEQUENCES}, qs)[0]


@pytest.mark.parametrize("seq", GIMBAL_SEQUENCES)
def test_euler_derivatives_finite_at_gimbal_lock(seq, gimbal_jacobians):
    q = jq.from_euler(seq, _gimbal_angles(seq))
    assert np.all(jq.gimbal_lock(seq, q))
    _check(*gimbal_jacobians[seq], np.float64)


def test_float32_derivatives_finite_at_edges(float32):
    names = ["to_rotvec", "to_euler.ZXZ", "distance.identity"]
    jac = _jacobians({n: Q_FUNCTIONS[n] for n in names}, jnp.asarray(EDGE_Q, jnp.float32))[0]
    for name in names:
        _check(*jac[name], np.float32)
    names = ["from_rotvec", "from_matrix.rotvec"]
    jac = _jacobians(
        {n: ROTVEC_FUNCTIONS[n] for n in names}, jnp.asarray(EDGE_ROTVEC, jnp.float32)
    )[0]
    for name in names:
        _check(*jac[name], np.float32)


# ---------------------------------------------------------------------------
# Correct values, not only finite ones
# ---------------------------------------------------------------------------


def test_log_and_exp_jacobians_at_identity():
    """d log / dq at the identity is [0 | 2 I]; d exp / dr at 0 is [0; ½ I]."""
    jlog = jax.jacfwd(jq.to_rotvec)(jq.identity())
    np.testing.assert_allclose(jlog, np.concatenate([np.zeros((3, 1)), 2 * np.eye(3)], 1), atol=0)
    thetas = np.array([0.0, 1e-6, 2e-5, 1e-3, 0.5])
    jexp = jax.jit(jax.vmap(jax.jacfwd(jq.from_rotvec)))(thetas[:, None] * np.array([1.0, 0, 0]))
    np.testing.assert_allclose(
        jexp[0], np.concatenate([np.zeros((1, 3)), 0.5 * np.eye(3)], 0), atol=0
    )
    # Taylor branch and exact branch agree in slope across the threshold.
    np.testing.assert_allclose(jexp[:, 1, 0], 0.5 * np.cos(thetas / 2), rtol=1e-12)
    np.testing.assert_allclose(jexp[:, 0, 0], -0.5 * np.sin(thetas / 2), atol=1e-15)


def test_from_matrix_jacobian_at_identity():
    """q ≈ (1, (R21 - R12)/4, (R02 - R20)/4, (R10 - R01)/4) near the identity."""
    j = np.asarray(jax.jacfwd(jq.from_matrix)(jnp.eye(3)))
    expected = np.zeros((4, 3, 3))
    expected[1, 2, 1], expected[1, 1, 2] = 0.25, -0.25
    expected[2, 0, 2], expected[2, 2, 0] = 0.25, -0.25
    expected[3, 1, 0], expected[3, 0, 1] = 0.25, -0.25
    # The w row depends on the trace: (1 + tr)/4 / |·| has zero derivative at tr = 3
    # along rotations, but not along arbitrary matrix perturbations; check the others.
    np.testing.assert_allclose(j[1:], expected[1:], atol=1e-15)


def test_angle_derivative_at_half_turn():
    """d angle / d t of q(t) = exp(t n) is |n| = 1, also at and through 180°."""
    n = jnp.array([0.6, 0.0, 0.8])
    ts = np.array([np.pi - 1e-3, np.pi, np.pi + 1e-3, 1e-9, 0.5])
    slope = jax.jit(jax.vmap(jax.grad(lambda s: jq.to_axis_angle(jq.from_rotvec(s * n))[1])))(ts)
    expected = np.where(ts <= np.pi, 1.0, -1.0)  # the angle folds back into [0, π]
    np.testing.assert_allclose(slope, expected, rtol=1e-9)
