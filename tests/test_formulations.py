"""formulations: every formulation's vector field, its variables, and the motions they give.

The vector fields are compared with Euler's equations written out independently (numpy,
scipy rotations); whole motions with a Dopri8 reference at rtol 1e-12.
"""


import jax.numpy as jnp
import numpy as np
import pytest
from _simulate import (
    OMEGA0,
    Q0,
    TS,
    free_scene,
    same_rotation,
    top_scene,
)
from _simulate import free_reference as _free_reference
from _simulate import top_reference as _top_reference
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from jrigid import initial
from jrigid.body import RigidBody
from jrigid.formulations import (
    FORMULATIONS,
    QuaternionAcceleration,
    check_scene,
    get_formulation,
)
from jrigid.integrate import simulate
from jrigid.leapfrog import leapfrog
from jrigid.scene import Gravity, Pivot, Scene, Torque
from jrigid.state import State


@pytest.fixture(scope="module")
def free_reference():
    return _free_reference()


@pytest.fixture(scope="module")
def top_reference():
    return _top_reference()


# --------------------------------------------------------------------------- formulations agree


@pytest.mark.parametrize(
    "formulation", ["quaternion_acceleration", "quaternion_omega", "body_omega", "euler_angles"]
)
def test_formulations_agree_free_rotor(free_reference, formulation):
    traj = simulate(free_scene(), initial.from_omega(Q0, OMEGA0), TS,
                    formulation=formulation, rtol=1e-10, atol=1e-12)
    assert int(traj.result) == 0
    np.testing.assert_allclose(traj.omega, free_reference.omega, atol=1e-8)
    np.testing.assert_allclose(traj.L, free_reference.L, atol=1e-8)
    if formulation == "body_omega":
        assert traj.q is None and traj.L_space is None
        with pytest.raises(ValueError, match="orientation"):
            traj.euler("ZXZ")
    else:
        same_rotation(traj.q, free_reference.q, 1e-8)
        np.testing.assert_allclose(traj.L_space, free_reference.L_space, atol=1e-8)


@pytest.mark.parametrize("formulation", ["quaternion_acceleration", "quaternion_omega",
                                         "euler_angles", "leapfrog"])
def test_formulations_agree_heavy_top(top_reference, formulation):
    state, ref = top_reference
    if formulation == "leapfrog":
        traj, tol = leapfrog(top_scene(), state, TS, dt=1e-3), 1e-4
    else:
        traj, tol = simulate(top_scene(), state, TS, formulation=formulation,
                             rtol=1e-10, atol=1e-12), 1e-7
    assert int(traj.result) == 0
    np.testing.assert_allclose(traj.omega, ref.omega, atol=tol)
    same_rotation(traj.q, ref.q, tol)
    np.testing.assert_allclose(traj.energy, ref.energy[0], atol=tol)


# --------------------------------------------------------------------------- vector fields

RNG = np.random.default_rng(17)
TORQUE_BODY = np.array([0.3, -0.2, 0.5])
COM = np.array([0.0, 0.0, 0.7])  # a pivoted body's centre of mass, on principal axis 3


def _hamilton(p, q):
    """Quaternion product (w, x, y, z), written out."""
    p0, pv, q0, qv = p[0], np.asarray(p[1:]), q[0], np.asarray(q[1:])
    return np.concatenate([[p0 * q0 - pv @ qv], p0 * qv + q0 * pv + np.cross(pv, qv)])


def _constant_torque(t, kin, params):
    return params


def _scenes():
    """(name, scene, body-frame torque(q)): a torque-driven free body and a pivoted top."""
    body = RigidBody(jnp.array([1.0, 2.0, 2.5]))
    driven = Scene(body, loads=(Torque(_constant_torque, jnp.asarray(TORQUE_BODY)),))
    top = Scene(RigidBody(jnp.array([1.0, 1.2, 0.6]), mass=1.5, com=jnp.asarray(COM)),
                Pivot(), Gravity(9.81))

    def gravity_torque(q):  # r × (Rᵀ M g) about the pivot, body frame
        weight = Rotation.from_quat(q, scalar_first=True).inv().apply([0.0, 0.0, -1.5 * 9.81])
        return np.cross(COM, weight)

    return [("driven", driven, lambda q: TORQUE_BODY, np.array([1.0, 2.0, 2.5])),
            ("top", top, gravity_torque,
             np.array([1.0, 1.2, 0.6]) + 1.5 * (COM @ COM - COM * COM))]  # parallel axis


def _euler_rhs(moments, omega, torque):
    """Euler's equations ω̇ = I⁻¹(−ω × Iω + τ) (17.34/17.35)."""
    return (np.cross(-omega, moments * omega) + torque) / moments


@pytest.mark.parametrize("case", [0, 1], ids=["driven", "top"])
@pytest.mark.parametrize("name", list(FORMULATIONS))
def test_vector_field_is_eulers_equations(name, case):
    label, scene, torque, moments = _scenes()[case]
    formulation = FORMULATIONS[name]()
    if name == "body_omega" and label == "top":
        with pytest.raises(ValueError, match="orientation"):
            formulation.check_scene(scene)
        return
    q = Rotation.random(random_state=RNG).as_quat(scalar_first=True)
    omega = RNG.normal(size=3)
    state = initial.from_omega(jnp.asarray(q), jnp.asarray(omega))
    y = formulation.from_state(scene, state)
    dy = formulation.vector_field(0.0, y, scene)
    expected = _euler_rhs(moments, omega, torque(q))
    if name == "quaternion_acceleration":
        # q̇ = ½ q ⊗ (0, ω) (17.44) and q̈ = ½ q̇ ⊗ (0, ω) + ½ q ⊗ (0, ω̇) (17.50)
        qdot = 0.5 * _hamilton(q, np.concatenate([[0.0], omega]))
        qddot = (0.5 * _hamilton(qdot, np.concatenate([[0.0], omega]))
                 + 0.5 * _hamilton(q, np.concatenate([[0.0], expected])))
        np.testing.assert_allclose(dy.q, qdot, atol=1e-13)
        np.testing.assert_allclose(dy.qdot, qddot, atol=1e-12)
    elif name == "quaternion_omega":
        np.testing.assert_allclose(dy.q, 0.5 * _hamilton(q, np.concatenate([[0.0], omega])),
                                   atol=1e-13)
        np.testing.assert_allclose(dy.omega, expected, atol=1e-12)
    elif name == "body_omega":
        np.testing.assert_allclose(dy, expected, atol=1e-12)
    else:  # euler_angles: ω = (φ̇ sθ sψ + θ̇ cψ, φ̇ sθ cψ − θ̇ sψ, φ̇ cθ + ψ̇) (17.36)
        np.testing.assert_allclose(dy.omega, expected, atol=1e-12)
        _, th, ps = np.asarray(y.angles)
        dphi, dth, dps = np.asarray(dy.angles)
        from_rates = [dphi * np.sin(th) * np.sin(ps) + dth * np.cos(ps),
                      dphi * np.sin(th) * np.cos(ps) - dth * np.sin(ps),
                      dphi * np.cos(th) + dps]
        np.testing.assert_allclose(from_rates, omega, atol=1e-12)


_FINITE = st.floats(-1.0, 1.0, allow_nan=False)


@settings(max_examples=30, deadline=None)
@given(q=st.lists(_FINITE, min_size=4, max_size=4).filter(lambda v: np.dot(v, v) > 0.05),
       qdot=st.lists(_FINITE, min_size=4, max_size=4), s=st.floats(0.5, 2.0),
       case=st.sampled_from([0, 1]))
def test_quaternion_acceleration_is_homogeneous_of_degree_one(q, qdot, s, case):
    # Off the constraint too (any |q|, any q·q̇, as at a Runge–Kutta stage), the field at
    # (s q, s q̇) is s times the field at (q, q̇): a stage's error in scale stays a scale
    _, scene, _, _ = _scenes()[case]
    field = QuaternionAcceleration()
    y = State(jnp.asarray(q), jnp.asarray(qdot))
    scaled = field.vector_field(0.0, State(s * y.q, s * y.qdot), scene)
    dy = field.vector_field(0.0, y, scene)
    np.testing.assert_allclose(scaled.q, s * dy.q, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(scaled.qdot, s * dy.qdot, rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("rate", [-0.3, 0.2])
@pytest.mark.parametrize("case", [0, 1], ids=["driven", "top"])
def test_quaternion_acceleration_keeps_a_change_of_scale_out_of_the_rotation(case, rate):
    # q̇ = q ⊗ p with p = (s, ω/2), s ≠ 0 (q·q̇ ≠ 0, as at a stage): the field is
    # q̇ ⊗ p + ½ q ⊗ (0, ω̇), ω̇ Euler's equations at the unit state, so that ṗ = ½ (0, ω̇)
    # and the scale's rate s never enters the rotation
    _, scene, torque, moments = _scenes()[case]
    q = 1.3 * Rotation.random(random_state=RNG).as_quat(scalar_first=True)
    omega = RNG.normal(size=3)
    p = np.concatenate([[rate], 0.5 * omega])
    qdot = _hamilton(q, p)
    dy = QuaternionAcceleration().vector_field(0.0, State(jnp.asarray(q), jnp.asarray(qdot)),
                                               scene)
    omega_dot = _euler_rhs(moments, omega, torque(q / np.linalg.norm(q)))
    expected = _hamilton(qdot, p) + 0.5 * _hamilton(q, np.concatenate([[0.0], omega_dot]))
    np.testing.assert_allclose(dy.qdot, expected, atol=1e-11)
    # ṗ = d/dt (q⁻¹ ⊗ q̇) from the field: (0, ω̇/2), whatever s is
    q_inv = np.concatenate([[q[0]], -q[1:]]) / (q @ q)
    p_dot = _hamilton(q_inv, np.asarray(dy.qdot)) - _hamilton(_hamilton(q_inv, qdot), p)
    np.testing.assert_allclose(p_dot, np.concatenate([[0.0], 0.5 * omega_dot]), atol=1e-11)


@pytest.mark.parametrize("s", [0.8, 1.25])
@pytest.mark.parametrize("case", [0, 1], ids=["driven", "top"])
@pytest.mark.parametrize("name", ["quaternion_acceleration", "quaternion_omega"])
def test_vector_field_off_the_constraint_acts_on_the_unit_rotation(name, case, s):
    # |q| = s (a stage of a Runge–Kutta step): the loads see the rotation q/|q| and ω is the
    # rate of q/|q|, so ω̇ is Euler's equations at the unit state (scipy's rotation)
    _, scene, torque, moments = _scenes()[case]
    formulation = FORMULATIONS[name]()
    q = Rotation.random(random_state=RNG).as_quat(scalar_first=True)
    omega = RNG.normal(size=3)
    expected = _euler_rhs(moments, omega, torque(q))
    qdot = 0.5 * _hamilton(q, np.concatenate([[0.0], omega]))
    if name == "quaternion_acceleration":
        y = formulation.from_state(scene, initial.from_omega(jnp.asarray(q), jnp.asarray(omega)))
        y = type(y)(s * y.q, s * y.qdot, y.x, y.v)
        dy = formulation.vector_field(0.0, y, scene)
        # homogeneous of degree one: the unit state's q̈ = ½ q̇ ⊗ (0, ω) + ½ q ⊗ (0, ω̇), scaled
        qddot = s * (0.5 * _hamilton(qdot, np.concatenate([[0.0], omega]))
                     + 0.5 * _hamilton(q, np.concatenate([[0.0], expected])))
        np.testing.assert_allclose(dy.qdot, qddot, atol=1e-12)
        # the chapter's ½ Wᵀ (ω̇, −2 Σ q̇ₘ²): its centripetal term is cubic in the scale
        dy = QuaternionAcceleration(centripetal=True).vector_field(0.0, y, scene)
        qddot = 0.5 * _hamilton(s * q, np.concatenate([[0.0], expected])) - s**3 * (qdot @ qdot) * q
        np.testing.assert_allclose(dy.qdot, qddot, atol=1e-12)
    else:
        y = formulation.from_state(scene, initial.from_omega(jnp.asarray(q), jnp.asarray(omega)))
        y = type(y)(s * y.q, y.omega, y.x, y.v)
        dy = formulation.vector_field(0.0, y, scene)
        np.testing.assert_allclose(dy.q, s * qdot, atol=1e-13)
        np.testing.assert_allclose(dy.omega, expected, atol=1e-12)


@pytest.mark.parametrize("name", list(FORMULATIONS))
def test_from_state_and_back(name):
    """A state turned into the formulation's variables gives back its q (as a rotation)
    and its ω through ``kinematics``."""
    formulation = FORMULATIONS[name]()
    scene = free_scene()
    q = Rotation.random(random_state=RNG).as_quat(scalar_first=True)
    omega = RNG.normal(size=3)
    state = initial.from_omega(jnp.asarray(q), jnp.asarray(omega))
    kin = formulation.kinematics(scene, formulation.from_state(scene, state))
    np.testing.assert_allclose(kin.omega, omega, atol=1e-13)
    if formulation.has_orientation:
        same_rotation(kin.q, q, 1e-13)
    else:
        assert kin.q is None


def test_unknown_formulation_names_the_choices():
    assert get_formulation("quaternion_omega") is get_formulation("quaternion_omega")
    with pytest.raises(ValueError, match="unknown formulation 'matrix'.*body_omega"):
        get_formulation("matrix")


def test_check_scene_by_object_or_name_and_its_errors():
    pivoted = Scene(RigidBody(jnp.array([1.0, 1.0, 0.5]), 1.0, jnp.array([0.0, 0.0, 1.0])),
                    Pivot(), (Gravity(1.0),))
    check_scene("quaternion_acceleration", pivoted)
    check_scene(get_formulation("quaternion_omega"), pivoted)
    with pytest.raises(ValueError, match="body_omega carries no orientation"):
        check_scene("body_omega", pivoted)
    with pytest.raises(ValueError, match="unknown formulation 'matrix'"):
        check_scene("matrix", pivoted)


@pytest.mark.parametrize("options, match", [
    (dict(stabilization=-1.0), "stabilization must be a number >= 0"),
    (dict(stabilization=float("nan")), "stabilization must be a number >= 0"),
    (dict(stabilization="1"), "stabilization must be a number >= 0"),
    (dict(stabilization=True), "stabilization must be a number >= 0"),
    (dict(centripetal=1), "centripetal must be True or False"),
    (dict(centripetal="no"), "centripetal must be True or False"),
    (dict(tolerance_scale=0.5), "tolerance_scale must be a number >= 1"),
    (dict(tolerance_scale=float("inf")), "tolerance_scale must be a number >= 1"),
    (dict(tolerance_scale="6"), "tolerance_scale must be a number >= 1"),
    (dict(acceptance=0.9), "acceptance must be a number >= 1"),
    (dict(acceptance=float("nan")), "acceptance must be a number >= 1"),
    (dict(acceptance=False), "acceptance must be a number >= 1"),
])
def test_quaternion_acceleration_refuses_bad_options(options, match):
    with pytest.raises(ValueError, match=match):
        QuaternionAcceleration(**options)


def test_step_tolerances_tighten_within_what_the_dtype_resolves():
    """The second-order form's controller works to ``rtol / s`` (and ``atol / s``), but
    not below 100 eps of the solve's dtype nor above what was asked; other forms and
    ``s = 1`` pass the tolerances through."""
    eps64, eps32 = float(jnp.finfo(jnp.float64).eps), float(jnp.finfo(jnp.float32).eps)
    form = QuaternionAcceleration(tolerance_scale=6.0)
    rtol, atol = form.step_tolerances(1e-8, 1e-10, eps64)
    assert float(rtol) == pytest.approx(1e-8 / 6) and float(atol) == pytest.approx(1e-10 / 6)
    rtol, atol = form.step_tolerances(3e-14, 3e-16, eps64)  # floored at 100 eps
    assert float(rtol) == pytest.approx(100 * eps64)
    assert float(atol) == pytest.approx(3e-16 * 100 * eps64 / 3e-14)
    rtol, atol = form.step_tolerances(1e-5, 1e-7, eps32)  # float32: nothing left to tighten
    assert float(rtol) == pytest.approx(1e-5) and float(atol) == pytest.approx(1e-7)
    rtol, atol = form.step_tolerances(1e-3, 1e-5, eps32)
    assert float(rtol) == pytest.approx(1e-3 / 6) and float(atol) == pytest.approx(1e-5 / 6)
    rtol, atol = form.step_tolerances(0.0, 1e-9, eps64)  # atol alone: scaled
    assert float(rtol) == 0.0 and float(atol) == pytest.approx(1e-9 / 6)
    for other in (QuaternionAcceleration(tolerance_scale=1), get_formulation("quaternion_omega")):
        assert other.step_tolerances(1e-8, 1e-10, eps64) == (1e-8, 1e-10)
