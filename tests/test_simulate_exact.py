"""simulate(..., solver="exact"): the closed-form torque-free path against the numerical one."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from jrigid import initial
from jrigid.body import RigidBody
from jrigid.integrate import simulate
from jrigid.scene import FreeFlight, Gravity, Pivot, Scene, Torque

MOMENTS = jnp.array([1.3, 2.1, 3.2])  # asymmetric
Q0 = jnp.array(Rotation.from_euler("ZXZ", [0.3, 1.1, -0.7]).as_quat(scalar_first=True))
OMEGA0 = jnp.array([0.4, 1.2, -0.5])  # well away from any principal axis
TS = jnp.linspace(0.0, 20.0, 81)


def same_rotation(q1, q2, atol):
    q1, q2 = np.asarray(q1), np.asarray(q2)
    sign = np.sign(np.sum(q1 * q2, axis=-1))[..., None]
    np.testing.assert_allclose(sign * q1, q2, atol=atol)


@pytest.fixture(scope="module")
def pair():
    scene = Scene(RigidBody(MOMENTS))
    state = initial.from_omega(Q0, OMEGA0)
    exact = simulate(scene, state, TS, solver="exact", dense=True)
    numerical = simulate(scene, state, TS, rtol=1e-10, atol=1e-12)
    return exact, numerical


def test_agrees_with_numerical_path(pair):
    exact, numerical = pair
    np.testing.assert_allclose(exact.omega, numerical.omega, atol=1e-8)
    same_rotation(exact.q, numerical.q, atol=1e-8)
    # derived quantities come from the same construction
    np.testing.assert_allclose(exact.L_space, numerical.L_space, atol=1e-8)
    np.testing.assert_allclose(exact.omega_space, numerical.omega_space, atol=1e-8)
    np.testing.assert_allclose(exact.kinetic_energy, numerical.kinetic_energy, atol=1e-8)
    np.testing.assert_allclose(exact.axes, numerical.axes, atol=1e-8)
    np.testing.assert_allclose(exact.ts, TS)
    assert exact.formulation == numerical.formulation
    assert int(exact.result) == 0 and bool(exact.succeeded)
    assert float(exact.t_stop) == float(TS[-1])
    assert all(int(v) == 0 for v in exact.stats.values())
    assert set(exact.stats) == set(numerical.stats)
    # the variables are on the constraint manifold
    np.testing.assert_allclose(exact.norm_error, 0.0, atol=1e-14)
    np.testing.assert_allclose(exact.tangent_error, 0.0, atol=1e-14)


def test_initial_state_reproduced(pair):
    exact, _ = pair
    same_rotation(exact.q[0], Q0, atol=1e-15)
    np.testing.assert_allclose(exact.omega[0], OMEGA0, atol=1e-14)


def test_conserves_energy_and_momentum(pair):
    exact, _ = pair
    e = np.asarray(exact.energy)
    assert np.max(np.abs(e - e[0])) <= 1e-12 * abs(e[0])
    ls = np.asarray(exact.L_space)
    assert np.max(np.abs(ls - ls[0])) <= 1e-12 * np.linalg.norm(ls[0])
    # a non-trivial motion: body-frame ω and L change a lot
    assert np.ptp(np.asarray(exact.omega), axis=0).min() > 0.1


def test_nonzero_start_time(pair):
    # autonomous motion: starting the same state at t = 3.5 shifts the solution in time
    _, numerical = pair
    scene = Scene(RigidBody(MOMENTS))
    shifted = simulate(scene, initial.from_omega(Q0, OMEGA0), TS + 3.5, solver="exact",
                       dense=True)
    np.testing.assert_allclose(shifted.ts, TS + 3.5)
    np.testing.assert_allclose(shifted.omega, numerical.omega, atol=1e-8)
    same_rotation(shifted.q, numerical.q, atol=1e-8)
    # dense output: the closed form at other times, with the same start time
    again = shifted.at(TS[::-1] + 3.5)
    np.testing.assert_allclose(again.omega, shifted.omega[::-1], atol=1e-14)
    same_rotation(again.q, shifted.q[::-1], atol=1e-14)


def test_free_flight_parabola(pair):
    exact, _ = pair
    g = jnp.array([0.3, -0.2, -9.81])
    scene = Scene(RigidBody(MOMENTS, mass=2.5), FreeFlight(), Gravity(g))
    x0, v0 = jnp.array([1.0, -2.0, 0.5]), jnp.array([0.7, 0.1, 4.0])
    traj = simulate(scene, initial.from_omega(Q0, OMEGA0, x=x0, v=v0), TS, solver="exact")
    t = np.asarray(TS)[:, None]
    x_ref = np.asarray(x0) + np.asarray(v0) * t + 0.5 * np.asarray(g) * t**2
    v_ref = np.asarray(v0) + np.asarray(g) * t
    np.testing.assert_allclose(traj.x, x_ref, rtol=1e-14, atol=1e-12)
    np.testing.assert_allclose(traj.v, v_ref, rtol=1e-14, atol=1e-12)
    # rotation unaffected by the uniform field
    same_rotation(traj.q, exact.q, atol=1e-14)
    np.testing.assert_allclose(traj.omega, exact.omega, atol=1e-14)
    e = np.asarray(traj.energy)  # kinetic (rotation + translation) + potential
    assert np.max(np.abs(e - e[0])) <= 1e-12 * np.max(np.abs(traj.potential_energy))


def _torque(t, kin, params):
    return params * kin.omega


@pytest.mark.parametrize(
    "scene, words",
    [
        (Scene(RigidBody(MOMENTS, com=jnp.array([0.0, 0.0, 1.0])), Pivot(), Gravity(1.0)),
         ["torque-free", "symmetric top", "I1 == I2"]),
        (Scene(RigidBody(MOMENTS), loads=Torque(_torque, -0.1)), ["torque-free", "Torque"]),
        (Scene(RigidBody(MOMENTS), FreeFlight(), (Gravity(), Torque(_torque, -0.1))),
         ["torque-free", "Torque"]),
        (Scene(RigidBody(MOMENTS, com=jnp.array([0.0, 0.0, 1.0])), Pivot()), ["I1 == I2"]),
    ],
)
def test_scene_with_torque_rejected(scene, words):
    state = initial.from_omega(Q0, OMEGA0)
    if scene.translates:
        state = initial.from_omega(Q0, OMEGA0, x=jnp.zeros(3), v=jnp.zeros(3))
    with pytest.raises(ValueError) as err:
        simulate(scene, state, TS, solver="exact")
    for word in words:
        assert word in str(err.value)


def test_heavy_symmetric_top_in_closed_form():
    """solver='exact' on a Lagrange top (Problem 17.2) against a tight numerical solve."""
    body = RigidBody(jnp.array([1.0, 1.0, 0.5]), 1.0, jnp.array([0.0, 0.0, 1.0]))
    scene = Scene(body, Pivot(), Gravity(1.0))
    state = initial.from_euler_rates(jnp.array([0.0, 0.6, 0.0]), jnp.array([0.2, 0.1, 5.0]))
    ts = jnp.linspace(0.0, 30.0, 31)
    closed = simulate(scene, state, ts, solver="exact", dense=True)
    numeric = simulate(scene, state, ts, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(closed.omega, numeric.omega, atol=1e-9)
    same_rotation(closed.q, numeric.q, atol=1e-9)
    assert int(closed.stats["num_steps"]) == 0
    mid = closed.at(jnp.array([12.5]))
    # evaluated directly at 12.5 (the same shapes and options: the same compiled program)
    direct = simulate(scene, state, ts.at[13].set(12.5), solver="exact", dense=True)
    np.testing.assert_allclose(mid.omega[0], direct.omega[13], atol=1e-13)
    e = np.asarray(closed.energy)
    assert np.abs(e - e[0]).max() < 1e-12


def test_heavy_top_members_that_are_not_lagrange_tops_get_a_code():
    """Under vmap the top's symmetry and the axis of its centre of mass are values: with
    throw=False a member that fails them gets invalid_input (the batch raised), and its
    healthy neighbours their closed form."""
    from jrigid.trajectory import Result

    state = initial.from_omega(None, jnp.array([0.5, -1.0, 4.0]))
    ts = jnp.linspace(0.0, 3.0, 4)

    def run(moments, com, throw):
        scene = Scene(RigidBody(moments, 1.3, com), Pivot(), Gravity(9.81))
        return simulate(scene, state, ts, solver="exact", throw=throw)

    moments = jnp.array([[1.0, 1.0, 0.5], [1.0, 1.2, 0.5], [1.0, 1.0, 0.5]])
    coms = jnp.array([[0.0, 0.0, 0.5], [0.0, 0.0, 0.5], [0.1, 0.0, 0.5]])
    trajs = jax.vmap(lambda m, c: run(m, c, False))(moments, coms)
    np.testing.assert_array_equal(trajs.result, [Result.success] + [Result.invalid_input] * 2)
    assert np.isnan(np.asarray(trajs.q[1:])).all()
    alone = run(moments[0], coms[0], True)
    np.testing.assert_allclose(trajs.q[0], alone.q, rtol=0, atol=1e-14)
    with pytest.raises(eqx.EquinoxRuntimeError, match="heavy symmetric top"):
        jax.block_until_ready(jax.vmap(lambda m, c: run(m, c, True).q)(moments, coms))


@pytest.mark.parametrize("omega0", [(0.0, -2.0, 0.0), (2.0, 0.0, 0.0)])
def test_spin_about_a_body_axis_stays_a_spin_with_its_derivatives(omega0):
    """ω0 exactly along a body axis came back from (q, q̇) inside the compiled program as
    (4e-17, 2, 4e-18): about the intermediate axis the closed form then flipped the body
    (the rounding grows as e^{rt}) and dq/dω0 was off by O(1) (2.3 against entries of
    0.6 at t = 1). The reference derivative: the numerical solver's forward mode."""
    q0 = jnp.array([0.9, 0.1, -0.3, 0.2]) / jnp.linalg.norm(jnp.array([0.9, 0.1, -0.3, 0.2]))
    scene = Scene(RigidBody(jnp.array([1.0, 2.0, 3.0])))
    omega0 = jnp.array(omega0)
    traj = simulate(scene, initial.from_omega(q0, omega0), jnp.linspace(0.0, 100.0, 11),
                    solver="exact")
    np.testing.assert_allclose(traj.omega, np.broadcast_to(omega0, (11, 3)), rtol=0, atol=1e-13)

    def q_end(w, solver):
        traj = simulate(scene, initial.from_omega(q0, w), jnp.array([0.0, 2.0]), solver=solver,
                        rtol=None if solver == "exact" else 1e-12,
                        atol=None if solver == "exact" else 1e-14)
        return traj.q[-1] * jnp.sign(traj.q[-1, 0])

    reference = jax.jacfwd(q_end)(omega0, None)
    np.testing.assert_allclose(jax.jacfwd(q_end)(omega0, "exact"), reference, rtol=0, atol=1e-9)
    np.testing.assert_allclose(jax.jacrev(q_end)(omega0, "exact"), reference, rtol=0, atol=1e-9)


@pytest.mark.parametrize("option", ["saveat", "event", "stepsize_controller"])
def test_options_without_meaning_for_the_closed_form_refused(option):
    """An event, a SaveAt and a step-size controller were silently ignored (an event
    never fired, the solve reported success)."""
    import diffrax

    value = {"saveat": diffrax.SaveAt(steps=True),
             "event": diffrax.Event(lambda t, y, args, **kw: t - 3.0),
             "stepsize_controller": diffrax.PIDController(rtol=1e-6, atol=1e-8)}[option]
    with pytest.raises(ValueError, match=f"closed form.*no {option}"):
        simulate(Scene(RigidBody(MOMENTS)), initial.from_omega(Q0, OMEGA0), TS, solver="exact",
                 **{option: value})


def test_unknown_solver_string():
    with pytest.raises(ValueError, match="'exact'"):
        simulate(Scene(RigidBody(MOMENTS)), initial.from_omega(Q0, OMEGA0), TS, solver="rk4")


def test_bad_input_still_checked():
    state = initial.from_omega(Q0, OMEGA0)
    with pytest.raises(ValueError, match="strictly increasing"):
        simulate(Scene(RigidBody(MOMENTS)), state, TS[::-1], solver="exact")


def test_jit_vmap_over_omega0():
    scene = Scene(RigidBody(MOMENTS))
    omegas = jnp.array([[0.4, 1.2, -0.5], [1.0, 0.05, 0.02], [0.0, 0.0, 2.0], [0.1, -2.0, 0.3]])
    ts = TS

    @eqx.filter_jit
    def run(omega0):
        traj = simulate(scene, initial.from_omega(Q0, omega0), ts, solver="exact")
        return traj.q, traj.omega, traj.result

    q, omega, result = jax.vmap(run)(omegas)
    assert q.shape == (4, 81, 4) and omega.shape == (4, 81, 3)
    np.testing.assert_array_equal(result, 0)
    for k in range(len(omegas)):
        ref = simulate(scene, initial.from_omega(Q0, omegas[k]), ts, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(omega[k], ref.omega, atol=1e-8)
        same_rotation(q[k], ref.q, atol=1e-8)


def test_grad_wrt_moment_matches_numerical():
    ts = jnp.linspace(0.0, 5.0, 3)
    w = jnp.array([0.3, -0.2, 0.5, 0.1])

    def loss(i2, solver, **kw):
        scene = Scene(RigidBody(jnp.stack([MOMENTS[0], i2, MOMENTS[2]])))
        traj = simulate(scene, initial.from_omega(Q0, OMEGA0), ts, solver=solver, **kw)
        return jnp.sum(traj.omega[-1] ** 2) + jnp.dot(traj.q[-1], w) ** 2

    g_exact = jax.jit(jax.grad(loss), static_argnums=1)(MOMENTS[1], "exact")
    # forward mode through diffrax compiles faster than its reverse mode
    fwd = lambda i2: loss(i2, None, rtol=1e-11, atol=1e-13, adjoint=diffrax.ForwardMode())
    g_num = jax.jit(jax.jacfwd(fwd))(MOMENTS[1])
    assert abs(float(g_exact)) > 1e-2
    np.testing.assert_allclose(g_exact, g_num, rtol=1e-6)
