"""state: a State's angular velocities (17.42) against scipy rotations, batch shapes, and
non-finite states refused by the solve's input checks."""

import jax.numpy as jnp
import numpy as np
import pytest
from _simulate import TS, free_scene
from scipy.spatial.transform import Rotation

from jrigid.integrate import Result, simulate
from jrigid.state import Kinematics, State, omega_from_rate

RNG = np.random.default_rng(5)


def _rate(q, omega):
    """q̇ of a rotation turning at body rate ω: the derivative of R(t) = R0 exp(t [ω]×),
    by a central difference of scipy rotations (an independent route to 17.44)."""
    h = 1e-6
    rot = Rotation.from_quat(q, scalar_first=True)
    plus = (rot * Rotation.from_rotvec(h * omega)).as_quat(scalar_first=True)
    minus = (rot * Rotation.from_rotvec(-h * omega)).as_quat(scalar_first=True)
    sign = np.sign(np.sum(plus * q, -1))[..., None]  # stay on q's side of the double cover
    return (sign * plus - np.sign(np.sum(minus * q, -1))[..., None] * minus) / (2 * h)


def test_omega_from_a_rotation_rate_batched():
    q = Rotation.random(5, random_state=RNG).as_quat(scalar_first=True)
    omega = RNG.normal(size=(5, 3))
    state = State(jnp.asarray(q), jnp.asarray(_rate(q, omega)))
    assert state.omega.shape == (5, 3) and state.omega_space.shape == (5, 3)
    np.testing.assert_allclose(state.omega, omega, atol=1e-8)
    space = Rotation.from_quat(q, scalar_first=True).apply(omega)
    np.testing.assert_allclose(state.omega_space, space, atol=1e-8)
    kin = Kinematics(jnp.asarray(q[0]), jnp.asarray(omega[0]))
    np.testing.assert_allclose(kin.omega_space, space[0], atol=1e-12)
    assert state.x is None and state.v is None


def test_omega_is_that_of_the_unit_rotation_off_the_constraint():
    """Scaling q and q̇ by s (|q| drifted) leaves ω unchanged: ω is the rate of q/|q|."""
    q = Rotation.random(random_state=RNG).as_quat(scalar_first=True)
    omega = RNG.normal(size=3)
    qdot = _rate(q, omega)
    for s in (1e-3, 1.0, 7.0):
        np.testing.assert_allclose(omega_from_rate(jnp.asarray(s * q), jnp.asarray(s * qdot)),
                                   omega, atol=1e-8)


@pytest.mark.parametrize("where", ["q", "qdot"])
def test_nan_state_is_refused(where):
    q = jnp.asarray(Rotation.random(random_state=RNG).as_quat(scalar_first=True))
    qdot = jnp.zeros(4)
    state = State(q.at[1].set(jnp.nan), qdot) if where == "q" else State(q, qdot.at[0].set(
        jnp.nan))
    with pytest.raises(ValueError, match="finite"):
        simulate(free_scene(), state, TS[:11])
    traj = simulate(free_scene(), state, TS[:11], throw=False)
    assert int(traj.result) == Result.invalid_input
    assert np.isnan(np.asarray(traj.q)).all()


def test_wrongly_shaped_state_is_refused():
    with pytest.raises(ValueError, match="shape|4"):
        simulate(free_scene(), State(jnp.ones(3), jnp.zeros(3)), TS[:11])


@pytest.mark.parametrize("scale", [None, 1.0, 0.7, 1.3])
def test_kinematics_frame_changes_match_scipy_with_and_without_the_raw_quaternion(scale):
    # q_raw of any norm rotates as q_raw / |q_raw| (rotation, then division by |q_raw|²)
    q = Rotation.random(random_state=RNG).as_quat(scalar_first=True)
    v, omega = RNG.normal(size=3), RNG.normal(size=3)
    raw = None if scale is None else jnp.asarray(scale * q)
    kin = Kinematics(jnp.asarray(q), jnp.asarray(omega), q_raw=raw)
    rot = Rotation.from_quat(q, scalar_first=True)
    np.testing.assert_allclose(kin.to_space(jnp.asarray(v)), rot.apply(v), rtol=1e-13, atol=1e-14)
    np.testing.assert_allclose(kin.to_body(jnp.asarray(v)), rot.inv().apply(v), rtol=1e-13,
                               atol=1e-14)
    np.testing.assert_allclose(kin.omega_space, rot.apply(omega), rtol=1e-13, atol=1e-14)
