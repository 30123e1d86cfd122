"""Exact-flow splitting (jrigid.splitting): orders, long-run invariants, reversibility, gradients.

References are independent of the method: the heavy symmetric top in closed form
(``jrigid.lagrange_top``) and scipy DOP853 at rtol 1e-13 on a numpy (q, ω) right-hand side
written here. Compiling a splitting program takes seconds (the closed-form free flow is
large), so runs share programs: every run uses 101 output times (``TS`` or a rescaling of
it: the times are traced) and the step bound ``BOUND``, one program per composition.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation
from scipy.stats import linregress

from jrigid import initial, lagrange_top
from jrigid import quaternion as quat
from jrigid.body import RigidBody
from jrigid.integrate import simulate
from jrigid.scene import FreeFlight, FreeRotation, Gravity, Pivot, Scene, Torque
from jrigid.splitting import COMPOSITIONS, Splitting
from jrigid.state import State
from jrigid.trajectory import Result, SimulationError

T = 30.0
TS = jnp.linspace(0.0, T, 101)
SHORT = TS / 5  # the asymmetric top is chaotic: against DOP853 over T/5 or T/2 only
MEDIUM = TS / 2
BOUND = 2**12  # at least the 2500 steps per interval of the long run
G = 1.0
Q0 = quat.from_rotvec(jnp.array([0.5, 0.0, 0.0]))


def top(moments, com, mass=1.0):
    return Scene(RigidBody(jnp.asarray(moments), mass=mass, com=jnp.asarray(com)), Pivot(),
                 Gravity(G))


SYMMETRIC = top((1.0, 1.0, 1.5), (0.0, 0.0, 1.0))
SYMMETRIC_W0 = jnp.array([0.2, 0.0, 4.0])
# Asymmetric about the pivot, centre of mass off every principal axis.
ASYMMETRIC = top((1.0, 1.5, 2.0), (0.1, -0.2, 0.5))
ASYMMETRIC_W0 = jnp.array([0.3, -0.4, 3.0])


def split(method, dt):
    return Splitting(method, dt=dt, max_steps=BOUND)


def errors(q, w, q_ref, w_ref):
    """Worst relative ω error and sign-invariant q error over the outputs."""
    q, w, q_ref, w_ref = (np.asarray(a) for a in (q, w, q_ref, w_ref))
    e_w = np.max(np.linalg.norm(w - w_ref, axis=-1)) / np.linalg.norm(w_ref[0])
    e_q = np.max(np.minimum(np.abs(q - q_ref).max(-1), np.abs(q + q_ref).max(-1)))
    return max(e_w, e_q)


def lagrange_reference(scene, q0, w0, ts):
    b = scene.body
    return lagrange_top.solve(b.moments, b.mass, b.com, jnp.array([0.0, 0.0, -G]), q0, w0, ts)


def _rhs(tensor, torque):
    """numpy (q, ω) right-hand side: q̇ = ½ q ⊗ (0, ω), I ω̇ = N − ω × Iω (body frame)."""
    inv = np.linalg.inv(tensor)

    def rhs(t, y):
        q, w = y[:4], y[4:]
        rot = Rotation.from_quat(q / np.linalg.norm(q), scalar_first=True)
        a, b, c, d = q
        qdot = 0.5 * np.array([-b * w[0] - c * w[1] - d * w[2], a * w[0] + c * w[2] - d * w[1],
                               a * w[1] - b * w[2] + d * w[0], a * w[2] + b * w[1] - c * w[0]])
        return np.concatenate([qdot, inv @ (torque(t, rot) - np.cross(w, tensor @ w))])

    return rhs


def dop853(scene, torque, q0, w0, ts):
    sol = solve_ivp(_rhs(np.asarray(scene.inertia()), torque), (float(ts[0]), float(ts[-1])),
                    np.concatenate([np.asarray(q0), np.asarray(w0)]), method="DOP853",
                    rtol=1e-13, atol=1e-15, t_eval=np.asarray(ts))
    q = sol.y[:4].T
    return q / np.linalg.norm(q, axis=-1, keepdims=True), sol.y[4:].T


def gravity_torque(scene):
    """Body-frame torque r × M g_body about the pivot."""
    r, m = np.asarray(scene.body.com), float(scene.body.mass)
    return lambda t, rot: np.cross(r, m * rot.inv().apply([0.0, 0.0, -G]))


def measured_order(scene, w0, method, dts, ts, reference):
    """Slope of log error against log step, and the errors."""
    state = initial.from_omega(Q0, w0)
    span = float(ts[1] - ts[0])
    hs, errs = [], []
    for dt in dts:
        traj = simulate(scene, state, ts, solver=split(method, dt))
        assert int(traj.result) == Result.success
        hs.append(span / math.ceil(span / dt - 1e-9))
        errs.append(errors(traj.q, traj.omega, *reference))
    return linregress(np.log(hs), np.log(errs)).slope, errs


# --------------------------------------------------------------------------- the compositions


@pytest.mark.parametrize("name", sorted(COMPOSITIONS))
def test_compositions_are_symmetric_and_satisfy_the_moment_conditions(name):
    order, gammas, _ = COMPOSITIONS[name]
    g = np.asarray(gammas)
    np.testing.assert_array_equal(g, g[::-1])
    assert math.fsum(gammas) == pytest.approx(1.0, abs=1e-15)
    # Necessary conditions of a symmetric composition of a symmetric method (HLW V.3):
    # Σ γ^k = 0 for odd k = 3, 5, … below the order.
    for k in range(3, order, 2):
        assert abs(np.sum(g**k)) < 1e-14 * np.sum(np.abs(g) ** k), (name, k)


STEPS = {  # errors between ~1e-4 and ~1e-11, above the reference's rounding
    "strang": (0.04, 0.02, 0.01, 0.005),
    "yoshida4": (0.1, 0.05, 0.025, 0.0125),
    "suzuki4": (0.1, 0.05, 0.03, 0.015),
    "kahan_li6": (0.3, 0.15, 0.1, 0.05),
    "kahan_li8": (0.3, 0.15, 0.1),
}


@pytest.mark.parametrize("method", sorted(COMPOSITIONS))
def test_order_on_the_symmetric_top_against_the_closed_form(method):
    ref = lagrange_reference(SYMMETRIC, Q0, SYMMETRIC_W0, TS)
    slope, errs = measured_order(SYMMETRIC, SYMMETRIC_W0, method, STEPS[method], TS, ref)
    assert abs(slope - COMPOSITIONS[method].order) < 0.3, (slope, errs)
    assert min(errs) > 3e-13  # above the reference's rounding: a real slope


@pytest.mark.parametrize("method", ["strang", "yoshida4", "kahan_li6"])
def test_order_on_an_asymmetric_top_against_dop853(method):
    """Off-axis centre of mass: the pivot tensor is not diagonal in the body frame."""
    ref = dop853(ASYMMETRIC, gravity_torque(ASYMMETRIC), Q0, ASYMMETRIC_W0, MEDIUM)
    dts = {"strang": (0.02, 0.01, 0.005), "yoshida4": (0.05, 0.025, 0.0125),
           "kahan_li6": (0.15, 0.075, 0.05)}[method]
    slope, errs = measured_order(ASYMMETRIC, ASYMMETRIC_W0, method, dts, MEDIUM, ref)
    assert abs(slope - COMPOSITIONS[method].order) < 0.3, (slope, errs)


@pytest.mark.parametrize(
    "moments, com",
    [((1.0, 1.0, 1.0), (0.0, 0.0, 0.5)),  # spherical body
     ((1.25, 1.25, 1.5), (0.0, 0.0, 0.5))],  # spherical about the pivot: every flow steady
    ids=["spherical_body", "spherical_about_pivot"],
)
def test_degenerate_inertia_against_the_closed_form(moments, com):
    scene = top(moments, com)
    w0 = jnp.array([0.3, -0.1, 2.0])
    ref = lagrange_reference(scene, Q0, w0, SHORT)
    traj = simulate(scene, initial.from_omega(Q0, w0), SHORT, solver=split("kahan_li6", 0.02))
    assert errors(traj.q, traj.omega, *ref) < 1e-9


def test_time_dependent_user_torque_keeps_the_order():
    """A space-frame torque of time and orientation on a free body: the kick holds t, the
    free flow advances it (extended phase space)."""

    def fn(t, kin, p):
        axis = quat.rotate(kin.q, jnp.array([0.0, 0.0, 1.0]))
        return p[0] * jnp.cos(p[1] * t) * jnp.array([1.0, 0.0, 0.0]) + p[2] * jnp.cross(
            axis, jnp.array([0.0, 0.0, 1.0]))

    params = (0.7, 1.3, 0.5)
    scene = Scene(RigidBody(jnp.array([1.0, 2.0, 2.5])), FreeRotation(),
                  Torque(fn, jnp.asarray(params), frame="space"))

    def torque(t, rot):
        axis = rot.apply([0.0, 0.0, 1.0])
        n_space = (params[0] * np.cos(params[1] * t) * np.array([1.0, 0.0, 0.0])
                   + params[2] * np.cross(axis, [0.0, 0.0, 1.0]))
        return rot.inv().apply(n_space)

    w0 = jnp.array([0.5, 1.0, -0.7])
    ref = dop853(scene, torque, Q0, w0, SHORT)
    slope, errs = measured_order(scene, w0, "yoshida4", (0.06, 0.03, 0.015), SHORT, ref)
    assert abs(slope - 4) < 0.3, (slope, errs)


# --------------------------------------------------------------------------- structure


def test_energy_and_vertical_momentum_do_not_drift_over_long_runs():
    """Asymmetric top on a pivot, Strang at h = 0.01: 2.5·10⁵ steps over 2500 time units
    (about 1200 spin periods)."""
    ts = TS * (2.5e3 / T)
    traj = simulate(ASYMMETRIC, initial.from_omega(Q0, ASYMMETRIC_W0), ts,
                    solver=split("strang", 0.01))
    assert int(traj.result) == Result.success
    assert int(traj.stats["num_steps"]) == 250_000
    energy = np.asarray(traj.energy)
    de = np.abs(energy - energy[0]) / float(traj.kinetic_energy[0])
    half = len(de) // 2
    # Bounded, O(h²), and no drift: the second half wanders no further than the first.
    assert de.max() < 1e-3
    assert de[half:].max() < 1.5 * de[:half].max()
    # L·ĝ: both the kicks (torque ⊥ g) and the free flows (L_space fixed) conserve it.
    lg = np.asarray(traj.L_space[:, 2])
    assert np.max(np.abs(lg - lg[0])) < 1e-11 * np.linalg.norm(np.asarray(traj.L[0]))
    np.testing.assert_allclose(np.linalg.norm(np.asarray(traj.q), axis=-1), 1.0, atol=1e-13)


def test_time_reversible_to_rounding():
    solver = split("yoshida4", 0.02)
    there = simulate(ASYMMETRIC, initial.from_omega(Q0, ASYMMETRIC_W0), SHORT, solver=solver)
    back = simulate(ASYMMETRIC, initial.from_omega(there.q[-1], -there.omega[-1]), SHORT,
                    solver=solver)
    assert np.max(np.abs(np.asarray(there.omega[-1] - ASYMMETRIC_W0))) > 0.1  # it moved
    d = np.asarray(back.q[-1]) * np.sign(np.dot(back.q[-1], Q0)) - np.asarray(Q0)
    assert np.max(np.abs(d)) < 1e-12
    np.testing.assert_allclose(back.omega[-1], -ASYMMETRIC_W0, atol=1e-12)


# --------------------------------------------------------------------------- transformations


def test_vmapped_gradients_match_finite_differences():
    """Reverse mode through the scan, under vmap: d/d(com, moments, ω0) of a final-state
    functional for an asymmetric top and a Lagrange top (tied moments about the pivot)."""
    c, d = jnp.array([0.3, -0.8, 0.5]), jnp.array([0.2, 0.4, -0.1, 0.7])

    def loss(com, moments, w0):
        traj = simulate(top(moments, com), initial.from_omega(Q0, w0), SHORT,
                        solver=split("yoshida4", 0.05))
        return jnp.dot(traj.omega[-1], c) + jnp.dot(traj.q[-1], d) ** 2

    com = jnp.array([[0.1, -0.2, 0.5], [0.0, 0.0, 0.7]])
    moments = jnp.array([[1.0, 1.5, 2.0], [1.0, 1.0, 1.5]])
    w0 = jnp.stack([ASYMMETRIC_W0, SYMMETRIC_W0])
    values, grads = jax.jit(jax.vmap(jax.value_and_grad(loss, argnums=(0, 1, 2))))(
        com, moments, w0
    )
    rng = np.random.default_rng(0)
    eps = 1e-5
    for k in range(2):
        args = (com[k], moments[k], w0[k])
        np.testing.assert_allclose(values[k], loss(*args), rtol=1e-13)
        for _ in range(2):
            dirs = [jnp.asarray(rng.normal(size=3)) for _ in args]
            plus = loss(*(a + eps * u for a, u in zip(args, dirs, strict=True)))
            minus = loss(*(a - eps * u for a, u in zip(args, dirs, strict=True)))
            fd = (plus - minus) / (2 * eps)
            ad = sum(jnp.dot(g[k], u) for g, u in zip(grads, dirs, strict=True))
            np.testing.assert_allclose(ad, fd, rtol=1e-6, atol=1e-9)


def test_float32(float32):
    scene = top((1.0, 1.0, 1.5), (0.0, 0.0, 1.0))
    ts = jnp.asarray(SHORT, jnp.float32)
    q0 = quat.from_rotvec(jnp.array([0.5, 0.0, 0.0], jnp.float32))
    w0 = jnp.array([0.2, 0.0, 4.0], jnp.float32)
    traj = simulate(scene, initial.from_omega(q0, w0), ts, solver=Splitting("yoshida4", dt=0.02))
    assert traj.q.dtype == jnp.float32 and int(traj.result) == Result.success
    with jax.enable_x64(True):
        ref = lagrange_reference(SYMMETRIC, Q0, SYMMETRIC_W0, SHORT)
    assert errors(traj.q, traj.omega, *ref) < 1e-4


# --------------------------------------------------------------------------- selection and errors


def test_a_torque_that_turns_nan_is_a_result_code_and_an_error():
    """The closed-form free flow checked its own input, so a NaN the torque produced
    raised 'exact: omega0 has non-finite entries' even with throw=False (and under vmap
    stopped the batch)."""
    scene = Scene(RigidBody(jnp.array([1.0, 2.0, 3.0])), FreeRotation(),
                  (Torque(lambda t, kin, p: p * jnp.ones(3), float("nan")),))
    state = initial.from_omega(None, jnp.array([0.1, 0.2, 5.0]))
    ts = jnp.linspace(0.0, 1.0, 3)
    traj = simulate(scene, state, ts, solver=Splitting(dt=0.1), throw=False)
    assert int(traj.result) == Result.nonfinite
    assert np.all(np.isfinite(np.asarray(traj.omega[0])))
    assert np.all(np.isnan(np.asarray(traj.omega[1:])))
    with pytest.raises(SimulationError, match="non-finite"):
        simulate(scene, state, ts, solver=Splitting(dt=0.1))


def test_too_many_steps_is_a_result_code_and_an_error():
    state = initial.from_omega(Q0, SYMMETRIC_W0)
    ts = TS.at[60:].add(1e4)  # interval 59 needs more than BOUND steps of 0.1
    solver = split("yoshida4", 0.1)
    traj = simulate(SYMMETRIC, state, ts, solver=solver, throw=False)
    assert int(traj.result) == Result.max_steps
    assert float(traj.t_stop) == float(ts[59])
    assert np.all(np.isfinite(np.asarray(traj.q[:60])))
    assert np.all(np.isnan(np.asarray(traj.q[60:])))
    assert int(traj.stats["num_steps"]) == 59 * 3
    # the splitting's own bound and remedy, not the adaptive solver's (which quoted
    # rtol/atol, which a splitting ignores, and simulate's max_steps)
    with pytest.raises(SimulationError, match=r"output interval needs more than "
                       r"Splitting\(max_steps=\d+\).*raise the Splitting's") as info:
        simulate(SYMMETRIC, state, ts, solver=solver)
    assert "rtol" not in str(info.value)
    with pytest.raises(Exception, match="Splitting's max_steps"):
        jax.jit(lambda s: simulate(SYMMETRIC, s, ts, solver=solver).q)(state).block_until_ready()


def test_invalid_input_names_the_problem():
    good = initial.from_omega(Q0, SYMMETRIC_W0)
    bad = State(jnp.zeros(4), good.qdot)
    with pytest.raises(ValueError, match="zero quaternion"):
        simulate(SYMMETRIC, bad, TS, solver=split("yoshida4", 0.05))
    traj = simulate(SYMMETRIC, bad, TS, solver=split("yoshida4", 0.05), throw=False)
    assert int(traj.result) == Result.invalid_input


@pytest.mark.parametrize(
    "kwargs, match",
    [(dict(method="rk4", dt=0.1), "method"), (dict(), "exactly one"),
     (dict(dt=0.1, steps=3), "exactly one"), (dict(steps=0), "positive int"),
     (dict(dt=-0.1), "finite and > 0"), (dict(dt=0.1, max_steps=2.5), "positive int")],
)
def test_bad_settings(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Splitting(**kwargs)


def test_scenes_and_options_it_cannot_do():
    state = initial.from_omega(Q0, SYMMETRIC_W0)
    damped = Scene(SYMMETRIC.body, Pivot(),
                   (Gravity(G), Torque(lambda t, kin, p: -p * kin.omega, 0.1)))
    with pytest.raises(ValueError, match="reads kin.omega"):
        simulate(damped, state, TS, solver=split("strang", 0.1))
    flying = Scene(SYMMETRIC.body, FreeFlight(), Gravity(G))
    flying_state = initial.from_omega(Q0, SYMMETRIC_W0, x=jnp.zeros(3), v=jnp.zeros(3))
    with pytest.raises(ValueError, match="FreeFlight"):
        simulate(flying, flying_state, TS, solver=split("strang", 0.1))
    with pytest.raises(ValueError, match="dense"):
        simulate(SYMMETRIC, state, TS, solver=split("strang", 0.1), dense=True)
    with pytest.raises(ValueError, match="dt0"):
        simulate(SYMMETRIC, state, TS, solver="splitting")
    with pytest.raises(ValueError, match="max_steps"):
        jax.jit(lambda dt: simulate(SYMMETRIC, state, TS, solver=Splitting(dt=dt)).q)(0.1)
