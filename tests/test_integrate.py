"""integrate: simulate — solvers, transformations (jit, vmap, grad), constraints, failures,
options."""

import logging
import warnings

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest
from _simulate import (
    MOMENTS,
    N_OUT,
    OMEGA0,
    Q0,
    TS,
    free_scene,
    power_scene,
    same_rotation,
    top_scene,
)
from _simulate import free_reference as _free_reference

from jrigid import initial
from jrigid import quaternion as quat
from jrigid.body import RigidBody
from jrigid.formulations import EulerAngles
from jrigid.integrate import Result, SimulationError, simulate
from jrigid.scene import FreeFlight, Gravity, Pivot, Scene
from jrigid.solve import PrecisionWarning
from jrigid.state import State


@pytest.fixture(scope="module")
def free_reference():
    return _free_reference()


# --------------------------------------------------------------------------- solvers


@pytest.mark.parametrize(
    "solver, rtol, tol",
    [
        (diffrax.Tsit5(), 1e-9, 1e-7),
        (diffrax.Dopri5(), 1e-9, 1e-7),
        (diffrax.Dopri8(), 1e-9, 1e-7),
        (diffrax.Heun(), 1e-6, 1e-4),
        (diffrax.Kvaerno5(), 1e-8, 1e-6),
    ],
    ids=["Tsit5", "Dopri5", "Dopri8", "Heun", "Kvaerno5"],
)
def test_every_solver(free_reference, solver, rtol, tol):
    traj = simulate(free_scene(), initial.from_omega(Q0, OMEGA0), TS, solver=solver,
                    rtol=rtol, atol=1e-2 * rtol)
    assert int(traj.result) == Result.success
    np.testing.assert_allclose(traj.omega, free_reference.omega, atol=tol)
    same_rotation(traj.q, free_reference.q, tol)
    stats = {k: int(v) for k, v in traj.stats.items()}
    assert stats["num_steps"] == stats["num_accepted_steps"] + stats["num_rejected_steps"]
    assert stats["num_accepted_steps"] > 0


# --------------------------------------------------------------------------- transformations


@eqx.filter_jit
def _jitted_final_omega(moments, omega0):
    scene = Scene(RigidBody(moments))
    return simulate(scene, initial.from_omega(Q0, omega0), TS, rtol=1e-10, atol=1e-12).omega[-1]


def test_jit_matches_eager_and_still_validates(free_reference):
    np.testing.assert_allclose(
        _jitted_final_omega(MOMENTS, OMEGA0), free_reference.omega[-1], atol=1e-8
    )
    # Inside jit the inputs are checked at run time (equinox.error_if; with plain jax.jit
    # the same message arrives wrapped in a JaxRuntimeError).
    with pytest.raises(eqx.EquinoxRuntimeError, match="triangle"):
        jax.block_until_ready(_jitted_final_omega(jnp.array([1.0, 1.0, 3.0]), OMEGA0))
    with pytest.raises(eqx.EquinoxRuntimeError, match="zero quaternion|non-finite"):
        jax.block_until_ready(_jitted_final_omega(MOMENTS, OMEGA0 * jnp.nan))


def _batched_run(moments, omegas, throw):
    def run(m, w):
        return simulate(Scene(RigidBody(m)), initial.from_omega(Q0, w), TS, rtol=1e-10,
                        atol=1e-12, throw=throw)

    return jax.vmap(run)(moments, omegas)


BATCH_MOMENTS = jnp.array([[1.0, 2.0, 3.0], [1.5, 2.0, 3.0], [2.0, 2.0, 2.5]])


def test_vmap_over_states_and_parameters():
    omegas = jnp.stack([OMEGA0, 2 * OMEGA0, -OMEGA0])
    batched = _batched_run(BATCH_MOMENTS, omegas, True)
    assert batched.result.shape == (3,) and batched.q.shape == (3, N_OUT, 4)
    for i in range(3):
        single = simulate(Scene(RigidBody(BATCH_MOMENTS[i])), initial.from_omega(Q0, omegas[i]),
                          TS, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(batched.omega[i], single.omega, atol=1e-9)
    # Energy is conserved member by member.
    expected = 0.5 * jnp.sum(BATCH_MOMENTS * omegas**2, axis=-1)
    np.testing.assert_allclose(batched.kinetic_energy[:, -1], expected, rtol=1e-8)


def test_vmap_failure_flags_per_member():
    # The last member spins so fast that it needs more than max_steps steps.
    omegas = jnp.stack([OMEGA0, 2 * OMEGA0, 3e4 * OMEGA0])
    trajs = _batched_run(BATCH_MOMENTS, omegas, False)
    np.testing.assert_array_equal(trajs.result, [Result.success, Result.success,
                                                 Result.max_steps])
    assert np.all(np.isfinite(np.asarray(trajs.q[:2])))
    assert np.isnan(np.asarray(trajs.q[2, -1])).all()
    with pytest.raises(eqx.EquinoxRuntimeError, match="max_steps=100000 exhausted") as err:
        jax.block_until_ready(_batched_run(BATCH_MOMENTS, omegas, True).q)
    # readable under jit: the cause first, then the remedy
    text = str(err.value)
    cause = text.index("jrigid.simulate failed: max_steps=100000 exhausted")
    assert cause < text.index("raise max_steps, loosen rtol/atol") < text.index("throw=False")


GRAD_MOMENTS = jnp.array([1.5, 2.0, 3.0])


def _final_quantity(moments, omega0):
    scene = Scene(RigidBody(moments))
    traj = simulate(scene, initial.from_omega(Q0, omega0), TS, rtol=1e-12, atol=1e-13)
    return traj.omega[-1, 0] + traj.q[-1, 1]


def test_grad_matches_finite_differences():
    """Reverse mode against central differences along three random directions of
    (moments, ω0)."""
    grad = jax.jit(jax.grad(_final_quantity, argnums=(0, 1)))(GRAD_MOMENTS, OMEGA0)
    flat_grad = np.concatenate([np.asarray(grad[0]), np.asarray(grad[1])])
    h = 1e-5
    for direction in np.random.default_rng(0).standard_normal((3, 6)):
        d = jnp.asarray(h * direction)
        fd = (_final_quantity(GRAD_MOMENTS + d[:3], OMEGA0 + d[3:])
              - _final_quantity(GRAD_MOMENTS - d[:3], OMEGA0 - d[3:])) / (2 * h)
        np.testing.assert_allclose(flat_grad @ direction, fd, rtol=1e-5, atol=1e-7)


def test_checkpointed_reverse_mode_equals_forward_mode():
    """The default (checkpointed) reverse pass recomputes projected steps exactly.

    Near the separatrix a step recomputed with other rounding can flip an accept/reject
    decision and differentiate a different path: the gradient then drifted by up to
    1e-3 from forward mode. Forward mode and reverse with a checkpoint at every step
    differentiate the same path, so they must agree to rounding. ``jax.jacfwd`` of a
    function calling ``simulate`` works under ``jit`` (``diffrax.ForwardMode`` is picked).
    """

    def final(moments):
        state = initial.from_omega(None, jnp.array([0.01, 1.0, 0.01]))
        traj = simulate(Scene(RigidBody(moments)), state, jnp.array([0.0, 32.0]),
                        rtol=1e-10, atol=1e-12)
        return traj.q[-1, 1] + traj.omega[-1, 0]

    moments = jnp.array([1.0, 2.0, 2.5])
    forward = jax.jit(jax.jacfwd(final))(moments)
    reverse = jax.jit(jax.grad(final))(moments)
    np.testing.assert_allclose(reverse, forward, rtol=1e-8, atol=1e-9)


def test_second_derivatives_forward_over_forward():
    """``jax.jacfwd(jax.jacfwd(f))`` gives the Hessian (symmetric, and the central
    differences of the reverse-mode gradient); ``jax.hessian`` (reverse inside forward)
    is refused with a message that names the way that works."""

    def final(moments):
        traj = simulate(Scene(RigidBody(moments)), initial.from_omega(None, OMEGA0),
                        jnp.array([0.0, 2.0]), rtol=1e-10, atol=1e-12)
        return traj.omega[-1, 0]

    moments = jnp.array([1.5, 2.0, 3.0])
    hessian = jax.jacfwd(jax.jacfwd(final))(moments)
    np.testing.assert_allclose(hessian, hessian.T, atol=1e-12)
    h = 1e-4
    grad = jax.jit(jax.grad(final))
    fd = np.stack([(grad(moments.at[i].add(h)) - grad(moments.at[i].add(-h))) / (2 * h)
                   for i in range(3)])
    np.testing.assert_allclose(hessian, fd, rtol=1e-6, atol=1e-7)
    assert np.abs(hessian).max() > 0.1
    with pytest.raises(TypeError, match=r"jax.jacfwd\(jax.jacfwd\(f\)\)"):
        jax.hessian(final)(moments)


def test_tolerance_change_does_not_recompile(caplog):
    state = initial.from_omega(Q0, OMEGA0)
    simulate(free_scene(), state, TS, rtol=1e-9)
    with jax.log_compiles(), caplog.at_level(logging.WARNING):
        simulate(free_scene(), state, TS, rtol=1e-7, atol=1e-9)
        simulate(Scene(RigidBody(MOMENTS + 0.5, mass=2.0)), state, TS + 1.0, rtol=1e-6,
                 dt0=None)
    assert not [r for r in caplog.records if "Compiling" in r.message and "_solve" in r.message]


def test_equal_options_share_one_compiled_solve_and_different_ones_do_not():
    from jrigid import integrate
    from jrigid.solvers import TightDop853

    state = initial.from_omega(Q0, OMEGA0)
    simulate(free_scene(), state, TS)
    count = integrate._compiled_by_value.cache_info().currsize
    # an equal solver object that is not the default instance: found by value
    simulate(free_scene(), state, TS, solver=TightDop853())
    assert integrate._compiled_by_value.cache_info().currsize == count
    # a different one: a compiled solve of its own, and the results differ accordingly
    a = simulate(free_scene(), state, TS, solver=TightDop853(factor=1.0))
    assert integrate._compiled_by_value.cache_info().currsize == count + 1
    b = simulate(free_scene(), state, TS, solver=TightDop853(factor=10.0))
    assert int(a.stats["num_steps"]) < int(b.stats["num_steps"])


def test_float_dtype_is_jax_default_float():
    from jrigid._checks import float_dtype

    assert float_dtype() == jnp.result_type(float) == jnp.float64


def test_float_dtype_follows_x64_off(float32):
    from jrigid._checks import float_dtype

    assert float_dtype() == jnp.result_type(float) == jnp.float32


# --------------------------------------------------------------------------- constraints


def test_projection_bounds_constraint_drift():
    """Without projection |q| drifts; with it |q| − 1 stays at the interpolation error."""
    state = initial.from_omega(None, jnp.array([1.0, 0.3, 0.7]))
    ts = jnp.linspace(0.0, 2000.0, N_OUT)
    drift = {}
    for project in (False, True):
        traj = simulate(free_scene(), state, ts, rtol=1e-6, atol=1e-8, project=project)
        drift[project] = float(np.max(np.abs(np.asarray(traj.norm_error))))
    assert drift[True] < 0.5 * drift[False]
    assert drift[True] < 1e-6


def test_float32(float32):
    state = initial.from_omega(Q0.astype(jnp.float32), OMEGA0.astype(jnp.float32))
    with warnings.catch_warnings():
        warnings.simplefilter("error", PrecisionWarning)  # a short horizon: no warning
        traj = simulate(free_scene(), state, jnp.linspace(0.0, 10.0, 21))
    assert traj.q.dtype == jnp.float32
    assert int(traj.result) == 0
    e = np.asarray(traj.kinetic_energy)
    assert np.max(np.abs(e - e[0])) < 1e-5 * e[0]
    with pytest.raises(ValueError, match="machine epsilons"):
        simulate(free_scene(), state, jnp.linspace(0.0, 1.0, 3), rtol=1e-8)


# --------------------------------------------------------------------------- bad input


def test_bad_inputs_raise_value_errors():
    scene, state = free_scene(), initial.from_omega(Q0, OMEGA0)
    with pytest.raises(ValueError, match="zero quaternion"):
        simulate(scene, State(jnp.zeros(4), state.qdot), TS)
    with pytest.raises(ValueError, match="not finite"):
        simulate(scene, State(state.q, state.qdot.at[0].set(jnp.nan)), TS)
    with pytest.raises(ValueError, match="non-finite"):
        simulate(scene, State(state.q.at[1].set(jnp.nan), state.qdot), TS)
    for rtol in (0.0, -1e-6, jnp.nan, 1.0, 1e3):
        with pytest.raises(ValueError, match="rtol must be finite, > 0 and < 1"):
            simulate(scene, state, TS, rtol=rtol)
    with pytest.raises(ValueError, match="machine epsilons") as info:
        simulate(scene, state, TS, rtol=1e-17)
    assert "enable float64" not in str(info.value)  # it is on
    with pytest.raises(ValueError, match="atol"):
        simulate(scene, state, TS, atol=-1.0)
    with pytest.raises(ValueError, match="increasing"):
        simulate(scene, state, TS[::-1])
    with pytest.raises(ValueError, match="max_steps"):
        simulate(scene, state, TS, max_steps=0)
    with pytest.raises(ValueError, match="unknown formulation"):
        simulate(scene, state, TS, formulation="matrix")
    with pytest.raises(ValueError, match="FreeFlight"):
        simulate(Scene(scene.body, FreeFlight()), state, TS)
    with pytest.raises(ValueError, match="orientation"):
        simulate(top_scene(), state, TS, formulation="body_omega")
    with pytest.raises(ValueError, match="gimbal lock"):
        simulate(scene, initial.from_omega(None, OMEGA0), TS, formulation="euler_angles")
    with pytest.raises(ValueError, match="triangle"):
        simulate(Scene(RigidBody(jnp.array([1.0, 1.0, 3.0]))), state, TS)


# --------------------------------------------------------------------------- failures


def test_max_steps_exhausted():
    scene, state = free_scene(), initial.from_omega(Q0, OMEGA0)
    long = TS * 2e4  # needs far more than the default 100_000 steps at rtol 1e-8
    with pytest.raises(SimulationError, match=r"max_steps=100000 exhausted") as info:
        simulate(scene, state, long)
    assert "t=" in str(info.value) and "raise max_steps" in str(info.value)
    traj = simulate(scene, state, long, throw=False)
    assert int(traj.result) == Result.max_steps
    stop = float(traj.t_stop)
    assert 0.0 < stop < float(long[-1])
    assert int(traj.stats["num_steps"]) == 100_000
    q = np.asarray(traj.q)
    before = np.asarray(long) <= stop
    assert np.all(np.isfinite(q[before])) and np.all(np.isnan(q[~before]))


def test_nonfinite_torque_reported():
    with pytest.raises(SimulationError, match="non-finite") as info:
        simulate(power_scene(-0.3, 0.0, 3.0), initial.from_omega(Q0, OMEGA0), TS)
    assert "t=3" in str(info.value)


def test_torque_nonfinite_from_the_start_is_reported_as_such():
    """A NaN from t = 0 made the starting step NaN: every step was rejected until max_steps
    ran out, and the solve was reported as out of steps. Now the default controller
    starts from a finite step and ends in a few rejected steps; with a user's diffrax
    controller (whose own starting step is NaN) the exhausted budget is blamed on NaN."""
    state = initial.from_omega(Q0, OMEGA0)
    scene = power_scene(-0.3, 0.0, -1.0)  # NaN everywhere from t = 0
    with pytest.raises(SimulationError, match="non-finite") as info:
        simulate(scene, state, TS)
    assert "t=0 " in str(info.value)
    traj = simulate(scene, state, TS, throw=False)
    assert int(traj.result) == Result.nonfinite and int(traj.stats["num_steps"]) < 100
    traj = simulate(scene, state, TS, throw=False, max_steps=50,
                    stepsize_controller=diffrax.PIDController(rtol=1e-8, atol=1e-10))
    assert int(traj.result) == Result.nonfinite


def test_step_size_collapse_reported():
    """N = k |ω|² ω blows up at t* = I / (2 k |ω0|²) = 2: a singular solution."""
    state = initial.from_omega(None, jnp.array([1.0, 0.0, 0.0]))
    with pytest.raises(SimulationError, match="step size collapsed") as info:
        simulate(power_scene(0.5, 1.0, np.inf), state, TS)
    assert "t=2" in str(info.value)
    traj = simulate(power_scene(0.5, 1.0, np.inf), state, TS, throw=False)
    assert int(traj.result) == Result.step_size_collapse
    assert abs(float(traj.t_stop) - 2.0) < 1e-6


def test_gimbal_lock_detected():
    # Pure rotation about body x starting tilted: θ runs through π (sin θ = 0).
    q0 = jnp.array([np.cos(0.25), np.sin(0.25), 0.0, 0.0])
    state = initial.from_omega(q0, jnp.array([1.0, 0.0, 0.0]))
    with pytest.raises(SimulationError, match="gimbal lock") as info:
        simulate(free_scene(), state, TS, formulation="euler_angles")
    assert "quaternion_acceleration" in str(info.value)
    # Passing close to the singular line: either it is reported or the result is right.
    state2 = initial.from_omega(q0, jnp.array([1.0, 0.02, 0.3]))
    traj = simulate(free_scene(), state2, TS, formulation=EulerAngles(), throw=False)
    reference = simulate(free_scene(), state2, TS, rtol=1e-10, atol=1e-12)
    if int(traj.result) != Result.gimbal_lock:
        assert int(traj.result) == Result.success
        np.testing.assert_allclose(traj.omega, reference.omega, atol=1e-6)


# --------------------------------------------------------------------------- options


def test_saveat_steps_passes_through():
    scene, state = free_scene(), initial.from_omega(Q0, OMEGA0)
    traj = simulate(scene, state, jnp.array([0.0, 2.0]), saveat=diffrax.SaveAt(steps=True),
                    max_steps=2000, rtol=1e-8, atol=1e-10)
    ts = np.asarray(traj.ts)
    n = int(traj.stats["num_accepted_steps"])
    assert np.all(np.isfinite(ts[:n])) and np.all(np.isnan(ts[n:]))
    assert ts[n - 1] == pytest.approx(2.0)
    exact = simulate(scene, state, jnp.concatenate([jnp.zeros(1), jnp.asarray(ts[:n])]),
                     solver="exact")
    np.testing.assert_allclose(traj.omega[:n], exact.omega[1:], atol=1e-7)
    with pytest.raises(ValueError, match="custom fn"):
        simulate(scene, state, TS, saveat=diffrax.SaveAt(t1=True, fn=lambda t, y, a: y.q))


def test_user_saveat_keeps_dense_and_reports_where_the_solve_stopped():
    """With a user's SaveAt, ``dense=True`` keeps the interpolation (it was dropped, and
    ``at`` asked for dense=True), and ``t_stop`` is the time the solve reached, not the
    last output time: ts[-1] on success, the last step's end after a failure."""
    scene, state = free_scene(), initial.from_omega(Q0, OMEGA0)
    ts = jnp.linspace(0.0, 4.0, 5)
    traj = simulate(scene, state, ts, saveat=diffrax.SaveAt(ts=jnp.array([1.0, 2.5])),
                    dense=True)
    assert float(traj.t_stop) == 4.0 and int(traj.result) == 0
    exact = simulate(scene, state, jnp.array([0.0, 3.3]), solver="exact")
    np.testing.assert_allclose(traj.at(3.3).omega[0], exact.omega[-1], atol=1e-7)
    short = simulate(scene, state, ts, saveat=diffrax.SaveAt(ts=jnp.array([0.5, 1.0, 3.0])),
                     max_steps=5, throw=False)
    steps = simulate(scene, state, ts, saveat=diffrax.SaveAt(steps=True), max_steps=5,
                     throw=False)
    assert int(short.result) == int(Result.max_steps)
    assert float(short.t_stop) == pytest.approx(float(np.nanmax(np.asarray(steps.ts))))
    assert 0.5 < float(short.t_stop) < 1.0
    with pytest.raises(ValueError, match="several SubSaveAt"):
        simulate(scene, state, ts, saveat=diffrax.SaveAt(
            subs=(diffrax.SubSaveAt(t0=True), diffrax.SubSaveAt(t1=True))))


def test_a_pivot_without_gravity_is_a_torque_free_body():
    """Gravity(0) on a Pivot: no direction of gravity to restore L·ĝ along (ĝ was 0/0, and
    the projection turned every step into NaN), and a sweep over g that includes 0."""
    body = RigidBody(jnp.array([1.0, 2.0, 2.5]), 2.0, jnp.array([0.0, 0.0, 0.5]))
    state = initial.from_omega(jnp.array([0.9, 0.1, -0.3, 0.2]), jnp.array([0.3, 0.2, -1.0]))
    ts = jnp.linspace(0.0, 1.0, 3)
    run = lambda g: simulate(Scene(body, Pivot(), Gravity(g)), state, ts,  # noqa: E731
                             throw=False)
    traj = run(0.0)
    assert int(traj.result) == 0
    # the same body free, with its moments about the pivot (parallel axes: M |r|² = 0.5)
    free = simulate(Scene(RigidBody(jnp.array([1.5, 2.5, 2.5]))), state, ts, solver="exact")
    np.testing.assert_allclose(traj.omega, free.omega, atol=1e-8)
    sweep = jax.vmap(run)(jnp.array([9.81, 0.0]))
    assert np.all(np.asarray(sweep.result) == 0)
    np.testing.assert_allclose(sweep.omega[1], free.omega, atol=1e-8)
    np.testing.assert_allclose(sweep.omega[0], run(9.81).omega, atol=1e-10)


def _top_loss(moments, g, omega0, com):
    state = initial.from_omega(jnp.array([0.9, 0.1, -0.3, 0.2]), omega0)
    scene = Scene(RigidBody(moments, 2.0, com), Pivot(), Gravity(g))
    return jnp.sum(simulate(scene, state, jnp.linspace(0.0, 1.0, 3)).omega[-1] ** 2)


# g, ω0 and the centre of mass are arguments: every case runs the same two compiled programs
_top_loss_jit = jax.jit(_top_loss)
_top_grad_jit = jax.jit(jax.grad(_top_loss))


@pytest.mark.parametrize("g, omega0, com", [
    (9.81, (0.0, 0.0, 0.0), (0.0, 0.0, 0.5)),   # a pendulum released from rest
    (0.0, (0.3, 0.2, -1.0), (0.0, 0.0, 0.5)),   # a pivot without gravity
    (9.81, (0.3, 0.2, -1.0), (0.0, 0.0, 0.0)),  # pivoted at the centre of mass
], ids=["from_rest", "no_gravity", "no_lever"])
def test_top_gradients_are_finite_where_a_norm_is_zero(g, omega0, com):
    """|L| at rest, |g| and |r| entered the projection through square roots, whose
    derivative at zero is infinite: the gradient was NaN (a top released from rest)."""
    args = (jnp.asarray(g, float), jnp.array(omega0), jnp.array(com))
    moments, direction, h = jnp.array([1.0, 2.0, 2.5]), jnp.array([0.3, -0.5, 0.8]), 1e-5
    grad = _top_grad_jit(moments, *args)
    central = (_top_loss_jit(moments + h * direction, *args)
               - _top_loss_jit(moments - h * direction, *args)) / (2 * h)
    assert np.all(np.isfinite(np.asarray(grad)))
    np.testing.assert_allclose(float(grad @ direction), float(central), rtol=1e-5, atol=1e-8)


def test_fixed_step_solvers_through_constant_step_size():
    scene, state = free_scene(), initial.from_omega(Q0, OMEGA0)
    ts = jnp.linspace(0.0, 2.0, 5)
    exact = simulate(scene, state, ts, solver="exact")
    errors = []
    for dt in (0.02, 0.01):
        traj = simulate(scene, state, ts, solver=diffrax.Heun(), dt0=dt,
                        stepsize_controller=diffrax.ConstantStepSize())
        errors.append(float(np.abs(np.asarray(traj.omega - exact.omega)).max()))
    assert 3.0 < errors[0] / errors[1] < 5.0  # Heun is second order
    with pytest.raises(ValueError, match="dt0"):
        simulate(scene, state, ts, solver=diffrax.Euler(),
                 stepsize_controller=diffrax.ConstantStepSize())
    # without a controller: diffrax's RuntimeError from inside its loop, now jrigid's own
    with pytest.raises(ValueError, match="Euler gives no error estimate.*ConstantStepSize"):
        simulate(scene, state, ts, solver=diffrax.Euler(), dt0=0.01)


def test_user_event_stops_without_failing():
    scene, state = free_scene(), initial.from_omega(Q0, OMEGA0)
    # stop when ω1 first crosses zero
    event = diffrax.Event(
        lambda t, y, args, **kw: 2.0 * quat.multiply(quat.conjugate(y.q), y.qdot)[1],
        optx.Bisection(rtol=1e-12, atol=1e-12),
    )
    traj = simulate(scene, state, TS, event=event)
    assert int(traj.result) == Result.event
    t_stop = float(traj.t_stop)
    assert 0.0 < t_stop < float(TS[-1])
    exact = simulate(scene, state, jnp.array([0.0, t_stop]), solver="exact")
    assert abs(float(exact.omega[-1, 0])) < 1e-6
    after = np.asarray(traj.ts) > t_stop
    assert np.isnan(np.asarray(traj.q)[after]).all()
    with pytest.raises(ValueError, match="own event"):
        simulate(scene, state, TS, formulation="euler_angles", event=event)


def test_max_steps_accepts_numpy_integers_refuses_bools():
    scene, state = free_scene(), initial.from_omega(Q0, OMEGA0)
    traj = simulate(scene, state, TS[:3], max_steps=np.int64(1000))
    assert int(traj.result) == 0
    with pytest.raises(ValueError, match="max_steps"):
        simulate(scene, state, TS[:3], max_steps=True)


def test_orientation_of_any_scale_integrates_as_the_unit_one():
    """|q| = 1e300 used to become q = 0 and burn max_steps; 1e-300 was called zero."""
    state = initial.from_omega(Q0, OMEGA0)
    ref = simulate(free_scene(), state, TS[:11])
    for scale in (1e300, 1e-300):
        traj = simulate(free_scene(), State(scale * state.q, scale * state.qdot), TS[:11])
        # the rescaled q normalises to the unit one up to rounding, and the step sizes
        # follow the error estimates' rounding: measured 1.0e-13 (1.2e-14 from q (1 + 1e-15))
        np.testing.assert_allclose(traj.q, ref.q, rtol=0, atol=1e-12)
        np.testing.assert_allclose(traj.omega, ref.omega, rtol=0, atol=1e-12)


def test_traced_dt0_is_checked():
    """A ``dt0`` traced by ``jit``/``vmap`` is checked like a concrete one: NaN read as a
    non-finite state, a negative one reached diffrax's check in unit time."""
    state = initial.from_omega(Q0, OMEGA0)
    dt0s = jnp.array([0.01, -0.1, jnp.nan, 0.0])
    trajs = jax.vmap(lambda d: simulate(free_scene(), state, TS[:11], dt0=d, throw=False))(dt0s)
    np.testing.assert_array_equal(trajs.result, [Result.success] + [Result.invalid_input] * 3)
    alone = jax.jit(lambda d: simulate(free_scene(), state, TS[:11], dt0=d).q)
    np.testing.assert_allclose(trajs.q[0], alone(0.01), rtol=0, atol=1e-13)
    assert np.isnan(np.asarray(trajs.q[1:])).all()
    with pytest.raises(Exception, match="dt0 must be finite and > 0"):
        jax.block_until_ready(alone(jnp.nan))


@pytest.mark.parametrize("adjoint", ["BacksolveAdjoint", "ImplicitAdjoint"])
def test_unsupported_adjoints_are_refused_by_name(adjoint):
    """BacksolveAdjoint failed under jax.grad with "Unexpected tangent" (or a tracer
    conversion); ImplicitAdjoint's derivatives are a steady state's."""
    import diffrax

    with pytest.raises(ValueError, match=f"adjoint={adjoint}\\(\\) is not supported"):
        simulate(free_scene(), initial.from_omega(Q0, OMEGA0), TS[:3],
                 adjoint=getattr(diffrax, adjoint)())
    direct = simulate(free_scene(), initial.from_omega(Q0, OMEGA0), TS[:3],
                      adjoint=diffrax.DirectAdjoint())
    np.testing.assert_allclose(direct.q, simulate(free_scene(), initial.from_omega(Q0, OMEGA0),
                                                  TS[:3]).q, rtol=0, atol=1e-13)


def test_tolerances_beside_a_users_controller_are_refused():
    """rtol/atol passed with a stepsize_controller were silently dropped (rtol 1e-12
    asked, the controller's 1e-3 used)."""
    import diffrax

    with pytest.raises(ValueError, match="do not reach a stepsize_controller"):
        simulate(free_scene(), initial.from_omega(Q0, OMEGA0), TS[:3], rtol=1e-12,
                 stepsize_controller=diffrax.PIDController(rtol=1e-3, atol=1e-6))


def test_invalid_members_of_a_vmap_get_their_own_code():
    """One bad member (zero quaternion, non-physical body, zero frame) never stops the
    others."""
    moments = jnp.array([[1.0, 2.0, 3.0], [1.0, 1.0, 3.0], [1.0, 2.0, 3.0], [1.0, 2.0, 3.0]])
    qs = jnp.stack([Q0, Q0, jnp.zeros(4), Q0])
    frames = jnp.stack([jnp.array([1.0, 0.0, 0.0, 0.0])] * 3 + [jnp.zeros(4)])

    def run(m, q, frame):
        state = initial.from_omega(Q0, OMEGA0)
        state = State(q, state.qdot)
        return simulate(Scene(RigidBody(m, frame=frame)), state, TS[:11], throw=False)

    trajs = jax.vmap(run)(moments, qs, frames)
    np.testing.assert_array_equal(trajs.result, [Result.success, Result.invalid_input,
                                                 Result.invalid_input, Result.invalid_input])
    assert np.isnan(np.asarray(trajs.q[1:])).all()
    alone = simulate(free_scene(), initial.from_omega(Q0, OMEGA0), TS[:11])
    np.testing.assert_allclose(trajs.q[0], alone.q, rtol=0, atol=1e-13)
    with pytest.raises(eqx.EquinoxRuntimeError, match="triangle"):
        jax.block_until_ready(
            jax.vmap(lambda m, q: simulate(Scene(RigidBody(m)), State(q, Q0 * 0), TS[:11]).q)(
                moments, qs)
        )
