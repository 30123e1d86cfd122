"""Bodies, scenes, initial conditions and vector fields (no integration)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from jrigid import initial
from jrigid import quaternion as quat
from jrigid.body import RigidBody
from jrigid.formulations import (
    BodyOmega,
    EulerAngles,
    QuaternionAcceleration,
    QuaternionOmega,
    get_formulation,
)
from jrigid.scene import FreeFlight, FreeRotation, Gravity, Pivot, Scene, Torque
from jrigid.state import Kinematics, State

floats = st.floats(-2.0, 2.0, allow_nan=False)
vec3 = st.tuples(floats, floats, floats).map(np.array)
quats = st.tuples(floats, floats, floats, floats).filter(
    lambda v: np.linalg.norm(v) > 0.1
).map(lambda v: np.array(v) / np.linalg.norm(v))


def scipy_rot(q):
    return Rotation.from_quat(np.array(q, dtype=float), scalar_first=True)


# --------------------------------------------------------------------------- bodies


def test_body_rejects_nonphysical_inertia():
    with pytest.raises(ValueError, match="triangle"):
        RigidBody(jnp.array([1.0, 1.0, 3.0]))
    with pytest.raises(ValueError, match="positive definite"):
        RigidBody(jnp.array([1.0, -1.0, 1.0]))
    with pytest.raises(ValueError, match="finite"):
        RigidBody(jnp.array([1.0, jnp.nan, 1.0]))
    with pytest.raises(ValueError, match="mass"):
        RigidBody(jnp.array([1.0, 1.0, 1.0]), mass=0.0)
    with pytest.raises(ValueError, match="shape"):
        RigidBody(jnp.array([1.0, 1.0]))
    # The Hairer–Lubich–Wanner body is allowed only when asked for.
    body = RigidBody(jnp.array([2.0, 1.0, 2.0 / 3.0]), allow_nonphysical=True)
    assert body.allow_nonphysical


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"moments": jnp.ones((2, 3))}, r"moments must have shape \(3,\), got \(2, 3\)"),
        ({"moments": jnp.ones((1, 3))}, r"moments must have shape \(3,\)"),
        ({"mass": jnp.ones(3)}, r"mass must have shape \(\), got \(3,\)"),
        ({"com": jnp.ones((2, 3))}, r"com must have shape \(3,\)"),
        ({"com": jnp.ones(2)}, r"com must have shape \(\.\.\., 3\)"),
        ({"frame": jnp.ones(3)}, r"frame must have shape \(\.\.\., 4\)"),
        ({"frame": jnp.zeros(4)}, r"frame must be a unit quaternion.*norm 0\)"),
        ({"frame": jnp.array([2.0, 0.0, 0.0, 0.0])}, "frame must be a unit quaternion"),
        ({"frame": jnp.array([1.0, jnp.nan, 0.0, 0.0])}, "frame must be a unit quaternion"),
        ({"mass": jnp.inf}, "mass must be finite and positive"),
    ],
)
def test_body_rejects_batches_vector_mass_and_bad_frames(kwargs, match):
    args = {"moments": jnp.array([1.0, 1.5, 2.0]), **kwargs}
    with pytest.raises(ValueError, match=match):
        RigidBody(**args)


def test_body_shape_errors_are_static_and_frame_errors_reach_jit():
    with pytest.raises(ValueError, match="moments must have shape"):
        jax.jit(lambda m: RigidBody(m).moments)(jnp.ones((4, 3)))
    # Inside a transformation the value checks run in RigidBody.check (as simulate does).
    run = jax.jit(lambda f: RigidBody(jnp.array([1.0, 1.5, 2.0]), frame=f).check().frame)
    np.testing.assert_array_equal(run(jnp.array([1.0, 0.0, 0.0, 0.0])), [1.0, 0.0, 0.0, 0.0])
    with pytest.raises(Exception, match="frame must be a unit quaternion"):
        jax.block_until_ready(run(jnp.zeros(4)))
    # Batches of bodies are built inside vmap, where each body has its own (3,) moments.
    bodies = jax.vmap(RigidBody)(jnp.array([[1.0, 1.5, 2.0], [1.0, 1.0, 1.0]]))
    assert bodies.moments.shape == (2, 3)


def test_body_given_a_tensor_as_moments_points_to_from_tensor():
    """A non-symmetric 3x3 used to be read as three moment vectors, "not positive definite"."""
    bad = jnp.array([[1.0, 0.0, 0.0], [3.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    with pytest.raises(ValueError, match="from_tensor") as info:
        RigidBody(bad)
    assert "positive definite" not in str(info.value)
    with pytest.raises(ValueError, match="not symmetric") as info:
        RigidBody.from_tensor(bad)
    assert "positive definite" not in str(info.value)
    with pytest.raises(ValueError, match=r"tensor must have shape \(3, 3\)"):
        RigidBody.from_tensor(jnp.stack([jnp.eye(3), jnp.eye(3)]))


def test_body_accepts_needles():
    """(1e-12, 1e12, 1e12) is a physical body (a thin rod with a finite radius)."""
    body = RigidBody(jnp.array([1e-12, 1e12, 1e12]))
    np.testing.assert_array_equal(body.check().moments, [1e-12, 1e12, 1e12])
    RigidBody.from_tensor(jnp.diag(jnp.array([1e12, 1e-12, 1e12])))


@pytest.mark.parametrize(
    "g, match",
    [
        (jnp.ones(2), r"shape \(3,\), got shape \(2,\)"),
        (jnp.ones((1, 3)), r"got shape \(1, 3\)"),
        (jnp.ones((3, 3)), r"got shape \(3, 3\)"),
        (jnp.ones(4), r"got shape \(4,\)"),
        (jnp.nan, "g must be finite"),
        (jnp.array([0.0, jnp.inf, -9.81]), "g must be finite"),
    ],
)
def test_gravity_rejects_wrong_shapes_and_non_finite_values(g, match):
    with pytest.raises(ValueError, match=match):
        Gravity(g)
    np.testing.assert_array_equal(Gravity(2).g, [0.0, 0.0, -2.0])  # ints are fine


def test_gravity_shape_check_is_static_under_jit():
    with pytest.raises(ValueError, match="Gravity: g must be"):
        jax.jit(lambda g: Gravity(g).g)(jnp.ones(2))
    np.testing.assert_array_equal(jax.jit(lambda g: Gravity(g).g)(1.5), [0.0, 0.0, -1.5])


def test_body_from_tensor_diagonalises_and_keeps_frame():
    rng = np.random.default_rng(0)
    frame = scipy_rot(rng.normal(size=4))
    moments = np.array([1.0, 1.5, 2.0])
    tensor = frame.as_matrix() @ np.diag(moments) @ frame.as_matrix().T
    com_ref = np.array([0.1, -0.2, 0.3])
    body = RigidBody.from_tensor(tensor, mass=2.0, com=com_ref)
    np.testing.assert_allclose(body.moments, moments, atol=1e-12)
    # frame maps principal-frame vectors to the reference frame: R diag(m) Rᵀ = tensor.
    R = scipy_rot(body.frame).as_matrix()
    np.testing.assert_allclose(R @ np.diag(body.moments) @ R.T, tensor, atol=1e-12)
    np.testing.assert_allclose(R @ np.asarray(body.com), com_ref, atol=1e-12)
    # The reference frame's orientation is q ⊗ frame*.
    q = jnp.array(scipy_rot(rng.normal(size=4)).as_quat(scalar_first=True))
    ref = scipy_rot(body.reference_orientation(q))
    np.testing.assert_allclose(
        (ref * scipy_rot(body.frame)).as_matrix(), scipy_rot(q).as_matrix(), atol=1e-12
    )
    with pytest.raises(ValueError):
        RigidBody.from_tensor(np.diag([1.0, 1.0, 3.0]))


def test_pivot_inertia_is_parallel_axis_shift():
    body = RigidBody(jnp.array([0.5, 0.6, 0.8]), mass=2.0, com=jnp.array([0.1, 0.2, 0.7]))
    r = np.array([0.1, 0.2, 0.7])
    expected = np.diag([0.5, 0.6, 0.8]) + 2.0 * (r @ r * np.eye(3) - np.outer(r, r))
    np.testing.assert_allclose(Scene(body, Pivot()).inertia(), expected, atol=1e-14)
    np.testing.assert_allclose(Scene(body, FreeRotation()).inertia(), np.diag([0.5, 0.6, 0.8]))
    np.testing.assert_allclose(Scene(body, FreeFlight()).inertia(), np.diag([0.5, 0.6, 0.8]))


def test_scene_rejects_bad_parts():
    body = RigidBody(jnp.ones(3))
    with pytest.raises(ValueError, match="holder"):
        Scene(body, holder="pivot")
    with pytest.raises(ValueError, match="loads"):
        Scene(body, loads=("gravity",))
    with pytest.raises(ValueError, match="frame"):
        Torque(lambda t, k, p: k.omega, frame="lab")
    assert Scene(body, loads=Gravity()).loads[0].g[2] == -9.81


# --------------------------------------------------------------------------- loads


@settings(max_examples=25, deadline=None)
@given(q=quats, omega=vec3)
def test_gravity_torque_is_r_cross_f_about_pivot(q, omega):
    com = np.array([0.1, -0.3, 0.8])
    g = np.array([0.0, 0.0, -2.0])
    scene = Scene(RigidBody(jnp.array([1.0, 1.2, 1.5]), mass=3.0, com=com), Pivot(), Gravity(g))
    force, torque = scene.wrench(0.0, Kinematics(jnp.asarray(q), jnp.asarray(omega)))
    R = scipy_rot(q).as_matrix()
    torque_space = np.cross(R @ com, 3.0 * g)
    np.testing.assert_allclose(R @ np.asarray(torque), torque_space, atol=1e-12)
    np.testing.assert_allclose(force, 0.0)
    kin = Kinematics(jnp.asarray(q), jnp.asarray(omega))
    np.testing.assert_allclose(scene.potential_energy(kin), -3.0 * g @ (R @ com), atol=1e-12)


def test_gravity_in_free_flight_and_free_rotation():
    body = RigidBody(jnp.array([1.0, 1.2, 1.5]), mass=2.0, com=jnp.array([0.0, 0.0, 1.0]))
    kin = Kinematics(quat.identity(), jnp.ones(3), jnp.array([0.0, 0.0, 5.0]), jnp.zeros(3))
    force, torque = Scene(body, FreeFlight(), Gravity(9.81)).wrench(0.0, kin)
    np.testing.assert_allclose(force, [0.0, 0.0, -2 * 9.81])
    np.testing.assert_allclose(torque, 0.0)
    np.testing.assert_allclose(
        Scene(body, FreeFlight(), Gravity(9.81)).potential_energy(kin), 2 * 9.81 * 5.0
    )
    force, torque = Scene(body, FreeRotation(), Gravity(9.81)).wrench(0.0, kin)
    np.testing.assert_allclose(torque, 0.0)


def _spin_damping(t, kin, params):
    return -params["c"] * kin.omega


def _space_twist(t, kin, params):
    return params * jnp.array([0.0, 0.0, 1.0])


def test_user_torque_frames():
    q = jnp.array(scipy_rot([0.3, 0.1, -0.4, 0.8]).as_quat(scalar_first=True))
    omega = jnp.array([0.5, -1.0, 2.0])
    body = RigidBody(jnp.array([1.0, 1.2, 1.5]))
    scene = Scene(body, loads=(Torque(_spin_damping, {"c": 0.3}),))
    _, torque = scene.wrench(0.0, Kinematics(q, omega))
    np.testing.assert_allclose(torque, -0.3 * omega)
    scene = Scene(body, loads=(Torque(_space_twist, 2.0, frame="space"),))
    _, torque = scene.wrench(0.0, Kinematics(q, omega))
    np.testing.assert_allclose(scipy_rot(q).apply(np.array(torque)), [0.0, 0.0, 2.0], atol=1e-14)
    assert scene.needs_orientation
    assert not Scene(body, loads=(Torque(_spin_damping, {"c": 0.3}),)).needs_orientation


# --------------------------------------------------------------------------- initial conditions


@settings(max_examples=25, deadline=None)
@given(q=quats, omega=vec3)
def test_from_omega_body_and_space(q, omega):
    s = initial.from_omega(q, omega)
    np.testing.assert_allclose(s.omega, omega, atol=1e-12)
    np.testing.assert_allclose(jnp.dot(s.q, s.qdot), 0.0, atol=1e-12)
    s = initial.from_omega(q, omega, frame="space")
    np.testing.assert_allclose(s.omega_space, omega, atol=1e-12)
    np.testing.assert_allclose(scipy_rot(q).apply(np.array(s.omega)), omega, atol=1e-12)


def test_from_omega_rejects_bad_quaternions():
    with pytest.raises(ValueError, match="zero quaternion"):
        initial.from_omega(jnp.zeros(4), jnp.ones(3))
    with pytest.raises(ValueError, match="non-finite"):
        initial.from_omega(jnp.array([1.0, jnp.nan, 0.0, 0.0]), jnp.ones(3))
    with pytest.raises(ValueError, match="non-finite"):
        initial.from_omega(None, jnp.array([1.0, jnp.inf, 0.0]))
    with pytest.raises(ValueError, match="both"):
        initial.from_omega(None, jnp.ones(3), x=jnp.zeros(3))
    # A non-unit quaternion is normalised.
    s = initial.from_omega(jnp.array([2.0, 0.0, 0.0, 0.0]), jnp.ones(3))
    np.testing.assert_allclose(s.q, [1.0, 0.0, 0.0, 0.0])


@pytest.mark.parametrize("scale", [1e-300, 1e300])
def test_from_omega_normalises_quaternions_of_any_scale(scale):
    """The orientation used to become zeros (1e300) or be refused as zero (1e-300)."""
    q = np.array([0.5, -0.5, 0.5, 0.5])
    s = initial.from_omega(scale * q, jnp.array([0.1, 0.2, 0.3]))
    np.testing.assert_allclose(s.q, q, rtol=1e-15)
    np.testing.assert_allclose(s.omega, [0.1, 0.2, 0.3], rtol=1e-14)


def test_from_euler_rates_matches_derivative_of_from_euler():
    angles = jnp.array([0.3, 0.7, -1.1])
    rates = jnp.array([0.4, -0.2, 3.0])
    s = initial.from_euler_rates(angles, rates)
    # Independent: q̇ = d/dt from_euler(angles + t rates) by forward-mode AD.
    _, qdot = jax.jvp(lambda a: quat.from_euler("ZXZ", a), (angles,), (rates,))
    np.testing.assert_allclose(s.qdot, qdot, atol=1e-12)
    r = Rotation.from_euler("ZXZ", np.asarray(angles))
    np.testing.assert_allclose(
        scipy_rot(s.q).as_matrix(), r.as_matrix(), atol=1e-12
    )


@pytest.mark.parametrize("energy_fraction", [0.0, 0.3, 0.7, 1.0])
def test_from_momentum_energy(energy_fraction):
    scene = Scene(RigidBody(jnp.array([1.0, 2.0, 2.5])))
    L = np.array([0.3, -1.0, 2.0])
    l2 = L @ L
    lo, hi = l2 / (2 * 2.5), l2 / (2 * 1.0)
    energy = lo + energy_fraction * (hi - lo)
    s = initial.from_momentum_energy(scene, L, energy)
    omega = np.asarray(s.omega)
    moments = np.array([1.0, 2.0, 2.5])
    np.testing.assert_allclose(0.5 * omega @ (moments * omega), energy, rtol=1e-12)
    np.testing.assert_allclose(scipy_rot(s.q).apply(moments * omega), L, atol=1e-12)
    with pytest.raises(ValueError, match="energy"):
        initial.from_momentum_energy(scene, L, 1.01 * hi)


@pytest.mark.parametrize("offset", [0.0, 1e-12, 1e-9, 6e-7, 7e-7, 1e-5, 0.3])
@pytest.mark.parametrize("sign", [-1.0, 1.0])
def test_from_momentum_energy_near_the_body_axis_and_its_opposite(offset, sign):
    """``q ⊗ L_body ⊗ q* = momentum`` to rounding when the momentum is (anti)parallel to
    the body-frame L or nearly so: within 7e-7 rad of antiparallel the perpendicular part
    was lost (error 6e-7), and near it the rotation carried 1e-10."""
    moments = np.array([1.0, 2.0, 3.0])
    scene = Scene(RigidBody(jnp.asarray(moments)))
    L = np.array([offset, 0.3 * offset, sign])
    s = initial.from_momentum_energy(scene, L, L @ L / 6)  # body-frame L along ±(0, 0, 1)
    got = scipy_rot(s.q).apply(moments * np.asarray(s.omega))
    np.testing.assert_allclose(got, L, rtol=0, atol=4e-15)


def test_tilted():
    s = initial.tilted(1, 0.01, 2.0)
    np.testing.assert_allclose(s.omega, [0.0, 2 * np.cos(0.01), 2 * np.sin(0.01)], atol=1e-14)
    s = initial.tilted(0, 0.1, 1.0, toward=2)
    np.testing.assert_allclose(s.omega, [np.cos(0.1), 0.0, np.sin(0.1)], atol=1e-14)
    with pytest.raises(ValueError):
        initial.tilted(3, 0.1, 1.0)
    with pytest.raises(ValueError):
        initial.tilted(1, 0.1, 1.0, toward=1)


# --------------------------------------------------------------------------- vector fields


def _torqued_scene():
    body = RigidBody(jnp.array([1.0, 1.5, 2.0]), mass=1.5, com=jnp.array([0.1, 0.0, 0.6]))
    return Scene(body, Pivot(), (Gravity(1.3), Torque(_spin_damping, {"c": 0.2})))


def _euler_rhs_numpy(inertia, omega, torque):
    return np.linalg.solve(inertia, torque - np.cross(omega, inertia @ omega))


@settings(max_examples=25, deadline=None)
@given(q=quats, omega=vec3)
def test_quaternion_acceleration_is_derivative_of_rate(q, omega):
    """q̈ from (17.50) equals d/dt [½ q ⊗ (0, ω)] along (q̇, ω̇) with ω̇ from Euler's equations."""
    scene = _torqued_scene()
    s = initial.from_omega(q, omega)
    d = QuaternionAcceleration().vector_field(0.0, s, scene)
    np.testing.assert_allclose(d.q, s.qdot, atol=1e-14)
    _, torque = scene.wrench(0.0, Kinematics(s.q, s.omega))
    omega_dot = _euler_rhs_numpy(np.asarray(scene.inertia()), omega, np.asarray(torque))
    _, qdd = jax.jvp(quat.derivative, (s.q, jnp.asarray(omega)), (s.qdot, jnp.asarray(omega_dot)))
    np.testing.assert_allclose(d.qdot, qdd, atol=1e-12)
    # The stabilising term vanishes on the constraint manifold.
    d2 = QuaternionAcceleration(stabilization=2.0).vector_field(0.0, s, scene)
    np.testing.assert_allclose(d2.qdot, d.qdot, atol=1e-13)


def test_euler_equations_component_form():
    """Diagonal inertia: the component form (17.35) written out independently."""
    I1, I2, I3 = 1.0, 2.0, 3.0
    w = np.array([0.3, -0.7, 1.1])
    n = np.array([0.1, 0.2, -0.3])
    expected = [
        (n[0] - (I3 - I2) * w[2] * w[1]) / I1,
        (n[1] - (I1 - I3) * w[0] * w[2]) / I2,
        (n[2] - (I2 - I1) * w[1] * w[0]) / I3,
    ]
    scene = Scene(RigidBody(jnp.array([I1, I2, I3])))
    np.testing.assert_allclose(scene.omega_dot(jnp.asarray(w), jnp.asarray(n)), expected)


@settings(max_examples=25, deadline=None)
@given(
    angles=st.tuples(floats, st.floats(0.2, 2.9), floats).map(np.array),
    omega=vec3,
)
def test_euler_angle_rates_invert_17_36(angles, omega):
    rates = EulerAngles().angle_rates(jnp.asarray(angles), jnp.asarray(omega))
    np.testing.assert_allclose(
        initial.euler_rates_to_omega(angles, rates), omega, atol=1e-10
    )


def test_formulations_agree_on_rates():
    """All formulations give the same ω̇ and q̇ at one state."""
    scene = _torqued_scene()
    s = initial.from_omega(jnp.array(scipy_rot([0.2, 0.4, -0.1, 0.9]).as_quat(scalar_first=True)),
                           jnp.array([0.4, -0.3, 2.0]))
    qa = QuaternionAcceleration().vector_field(0.0, s, scene)
    y = QuaternionOmega().from_state(scene, s)
    qo = QuaternionOmega().vector_field(0.0, y, scene)
    np.testing.assert_allclose(qo.q, qa.q, atol=1e-14)
    omega_dot_acc = 2 * quat.multiply(quat.conjugate(s.q), qa.qdot)[1:]
    np.testing.assert_allclose(qo.omega, omega_dot_acc, atol=1e-12)
    ye = EulerAngles().from_state(scene, s)
    eu = EulerAngles().vector_field(0.0, ye, scene)
    np.testing.assert_allclose(eu.omega, qo.omega, atol=1e-12)
    free = Scene(scene.body)
    bo = BodyOmega().vector_field(0.0, s.omega, free)
    np.testing.assert_allclose(
        bo, QuaternionOmega().vector_field(0.0, y, free).omega, atol=1e-14
    )


def test_get_formulation():
    assert isinstance(get_formulation("quaternion_acceleration"), QuaternionAcceleration)
    assert isinstance(get_formulation("euler_angles"), EulerAngles)
    f = QuaternionAcceleration(stabilization=1.0)
    assert get_formulation(f) is f
    with pytest.raises(ValueError, match="unknown formulation"):
        get_formulation("rodrigues")
    with pytest.raises(ValueError, match="orientation"):
        BodyOmega().check_scene(_torqued_scene())


def test_projection_restores_constraints_and_keeps_omega():
    s = initial.from_omega(jnp.array([0.5, 0.5, 0.5, 0.5]), jnp.array([1.0, -2.0, 0.5]))
    off = State(1.01 * s.q, s.qdot + 0.003 * s.q)
    p = QuaternionAcceleration().project(off, None)
    np.testing.assert_allclose(jnp.linalg.norm(p.q), 1.0, atol=1e-15)
    np.testing.assert_allclose(jnp.dot(p.q, p.qdot), 0.0, atol=1e-15)
    np.testing.assert_allclose(p.omega, off.omega, atol=1e-12)
