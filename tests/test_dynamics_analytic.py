"""Analytic anchors: free rotors, symmetric precession (17.47), the heavy top (17.51).

Every simulation of a free rotor here uses the same compiled solve (default formulation,
Tsit5, 201 output times); the heavy-top ones share another. Tolerances are traced, so
tightening them does not recompile.
"""

import diffrax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp
from scipy.spatial.transform import Rotation

from jrigid import initial
from jrigid.body import RigidBody
from jrigid.integrate import simulate
from jrigid.scene import Gravity, Pivot, Scene

N_OUT = 201


def scipy_rot(q):
    return Rotation.from_quat(np.array(q, dtype=float), scalar_first=True)


# --------------------------------------------------------------------------- independent reference


def _qmul(p, q):
    w1, x1, y1, z1 = p
    w2, x2, y2, z2 = q
    return np.array(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def reference_free_rotor(moments, omega0, q0, ts):
    """scipy DOP853 at rtol 1e-13 on Euler's equations + q̇ = ½ q ⊗ (0, ω), in numpy."""
    I1, I2, I3 = moments

    def rhs(t, y):
        w1, w2, w3 = y[:3]
        wdot = [
            (I2 - I3) * w2 * w3 / I1,
            (I3 - I1) * w3 * w1 / I2,
            (I1 - I2) * w1 * w2 / I3,
        ]
        qdot = 0.5 * _qmul(y[3:], np.array([0.0, w1, w2, w3]))
        return np.concatenate([wdot, qdot])

    sol = solve_ivp(
        rhs, (ts[0], ts[-1]), np.concatenate([omega0, q0]), method="DOP853",
        t_eval=ts, rtol=1e-13, atol=1e-13,
    )
    assert sol.success
    return sol.y[:3].T, sol.y[3:].T


def free_scene(moments, **kw):
    return Scene(RigidBody(jnp.asarray(moments, dtype=float), **kw))


# --------------------------------------------------------------------------- free rotors


def test_spherical_body_omega_constant():
    """I1 = I2 = I3: ω is constant and q(t) = q0 ⊗ exp(ω t / 2) (Problem 17.6)."""
    omega0 = np.array([0.3, -1.2, 0.8])
    q0 = scipy_rot([0.9, 0.1, -0.3, 0.2]).as_quat(scalar_first=True)
    ts = np.linspace(0.0, 20.0, N_OUT)
    traj = simulate(free_scene([2.0, 2.0, 2.0]), initial.from_omega(q0, omega0), ts,
                    rtol=1e-11, atol=1e-12)
    assert int(traj.result) == 0
    np.testing.assert_allclose(traj.omega, np.broadcast_to(omega0, (N_OUT, 3)), atol=1e-10)
    expected = scipy_rot(q0) * Rotation.from_rotvec(ts[:, None] * omega0[None, :])
    np.testing.assert_allclose(scipy_rot(traj.q).as_matrix(), expected.as_matrix(), atol=1e-9)


def test_symmetric_body_precession_17_47():
    """I1 = I2: ω1, ω2 sinusoidal and out of phase, rate Ω = (I3/I1 − 1) ω3."""
    I1, I3 = 1.0, 1.7
    w_perp, w3 = 0.4, 2.0
    ts = np.linspace(0.0, 50.0, N_OUT)
    traj = simulate(free_scene([I1, I1, I3]), initial.from_omega(None, [w_perp, 0.0, w3]), ts,
                    rtol=1e-12, atol=1e-13)
    Omega = (I3 / I1 - 1.0) * w3
    np.testing.assert_allclose(traj.omega[:, 0], w_perp * np.cos(Omega * ts), atol=1e-9)
    np.testing.assert_allclose(traj.omega[:, 1], w_perp * np.sin(Omega * ts), atol=1e-9)
    np.testing.assert_allclose(traj.omega[:, 2], w3, atol=1e-11)
    # The measured rate of the ω vector about body axis 3, from the unwrapped phase.
    phase = np.unwrap(np.arctan2(np.asarray(traj.omega[:, 1]), np.asarray(traj.omega[:, 0])))
    slope = np.polyfit(ts, phase, 1)[0]
    assert abs(slope - Omega) < 1e-8 * abs(Omega)
    # The chapter's form: Ω = (I3/Is − 1) ω cos α with cos α = ω3/|ω|.
    w = np.hypot(w_perp, w3)
    assert abs((I3 / I1 - 1.0) * w * (w3 / w) - slope) < 1e-8


@pytest.mark.parametrize("solver", [diffrax.Tsit5(), diffrax.Dopri8()], ids=["Tsit5", "Dopri8"])
def test_asymmetric_body_matches_scipy_dop853(solver):
    moments = np.array([1.0, 2.0, 3.0])
    omega0 = np.array([1.0, 0.3, 0.7])
    q0 = scipy_rot([0.7, -0.2, 0.4, 0.1]).as_quat(scalar_first=True)
    ts = np.linspace(0.0, 100.0, N_OUT)
    traj = simulate(free_scene(moments), initial.from_omega(q0, omega0), ts, solver=solver,
                    rtol=1e-10, atol=1e-12)
    w_ref, q_ref = reference_free_rotor(moments, omega0, q0, ts)
    np.testing.assert_allclose(traj.omega, w_ref, atol=1e-8)
    sign = np.sign(np.sum(np.asarray(traj.q) * q_ref, axis=-1))[:, None]
    np.testing.assert_allclose(sign * np.asarray(traj.q), q_ref, atol=1e-8)


def test_energy_and_momentum_conserved_to_tolerance():
    moments = np.array([1.0, 2.0, 3.0])
    omega0 = np.array([0.2, 1.1, -0.6])
    ts = np.linspace(0.0, 100.0, N_OUT)
    state = initial.from_omega(scipy_rot([0.3, 0.3, 0.1, 0.9]).as_quat(scalar_first=True), omega0)
    for rtol in (1e-7, 1e-10):
        traj = simulate(free_scene(moments), state, ts, rtol=rtol, atol=1e-2 * rtol)
        e0 = 0.5 * omega0 @ (moments * omega0)
        L0 = scipy_rot(state.q).apply(moments * omega0)
        energy_err = np.max(np.abs(np.asarray(traj.kinetic_energy) - e0)) / e0
        l_err = np.max(np.abs(np.asarray(traj.L_space) - L0)) / np.linalg.norm(L0)
        assert energy_err < 50 * rtol
        assert l_err < 50 * rtol
        np.testing.assert_allclose(traj.potential_energy, 0.0)
        # norm and tangent residuals stay at the tolerance (projection)
        assert np.max(np.abs(np.asarray(traj.norm_error))) < 10 * rtol
        assert np.max(np.abs(np.asarray(traj.tangent_error))) < 10 * rtol


@pytest.mark.parametrize("axis, stable", [(0, True), (1, False), (2, True)])
def test_stability_about_principal_axes(axis, stable):
    """Problem 17.3: stable about the largest and smallest axes, flips about the middle one."""
    moments = np.array([1.0, 2.0, 3.0])
    eps = 0.01
    ts = np.linspace(0.0, 60.0, N_OUT)
    traj = simulate(free_scene(moments), initial.tilted(axis, eps, 1.0), ts,
                    rtol=1e-9, atol=1e-11)
    omega = np.asarray(traj.omega)
    deviation = np.arccos(np.clip(np.abs(omega[:, axis]) / np.linalg.norm(omega, axis=-1), 0, 1))
    L_hat = np.asarray(traj.L_space[0]) / np.linalg.norm(traj.L_space[0])
    alignment = np.asarray(traj.axes[:, :, axis]) @ L_hat  # body axis · L
    if stable:
        assert np.max(deviation) < 3 * eps
        assert np.min(alignment) > 0.99
    else:
        assert np.max(deviation) > 1.0
        assert np.min(alignment) < -0.9  # the body has flipped over
        assert np.min(omega[:, axis]) < -0.9  # ω along the axis reverses


# --------------------------------------------------------------------------- heavy top

M, G, ELL = 1.0, 1.0, 1.0
I1C, I3 = 0.5, 0.8  # central moments; about the pivot I1 = I1C + M l²
I1 = I1C + M * ELL**2


def top_scene():
    body = RigidBody(jnp.array([I1C, I1C, I3]), mass=M, com=jnp.array([0.0, 0.0, ELL]))
    return Scene(body, Pivot(), Gravity(G))


def top_constants(theta0, phidot0, omega3):
    """Goldstein's a, b, α, β for θ̇0 = 0, and the roots of the cubic f(u)."""
    u0 = np.cos(theta0)
    a = I3 * omega3 / I1
    b = (I1 * phidot0 * np.sin(theta0) ** 2 + I3 * omega3 * u0) / I1
    beta = 2 * M * G * ELL / I1
    energy = 0.5 * I1 * phidot0**2 * np.sin(theta0) ** 2 + M * G * ELL * u0
    alpha = 2 * energy / I1
    # f(u) = (1 − u²)(α − βu) − (b − au)² = βu³ − (α + a²)u² + (2ab − β)u + (α − b²)
    roots = np.sort(np.roots([beta, -(alpha + a**2), 2 * a * b - beta, alpha - b**2]).real)
    return a, b, beta, roots


def top_period_and_precession(theta0, phidot0, omega3):
    """Nutation period and mean precession rate by quadrature over u ∈ [u1, u2].

    With u = u1 + (u2 − u1) sin² s, du/√f = 2 ds/√(β(u3 − u)), which is smooth.
    """
    a, b, beta, (u1, u2, u3) = top_constants(theta0, phidot0, omega3)

    def u_of(s):
        return u1 + (u2 - u1) * np.sin(s) ** 2

    def dt(s):
        return 2.0 / np.sqrt(beta * (u3 - u_of(s)))

    def dphi(s):
        u = u_of(s)
        return (b - a * u) / (1 - u * u) * dt(s)

    opts = dict(epsabs=1e-14, epsrel=1e-13, limit=200)
    period = 2 * quad(dt, 0, np.pi / 2, **opts)[0]
    advance = 2 * quad(dphi, 0, np.pi / 2, **opts)[0]
    return period, advance / period, (u1, u2)


def simulate_top(theta0, phidot0, omega3, t_end, rtol=1e-11):
    # θ̇0 = 0; ω3 = ψ̇ + φ̇ cos θ.
    psidot0 = omega3 - phidot0 * np.cos(theta0)
    state = initial.from_euler_rates([0.0, theta0, 0.0], [phidot0, 0.0, psidot0])
    ts = np.linspace(0.0, t_end, N_OUT)
    return simulate(top_scene(), state, ts, rtol=rtol, atol=1e-2 * rtol)


def precession_advance(traj):
    phi = np.unwrap(np.asarray(traj.euler("ZXZ")[:, 0]))
    return phi[-1] - phi[0]


@pytest.mark.parametrize("phidot0", [0.0, 0.8])
def test_heavy_top_nutation_matches_cubic(phidot0):
    theta0, omega3 = 0.5, 4.0
    period, mean_rate, (u1, u2) = top_period_and_precession(theta0, phidot0, omega3)
    traj = simulate_top(theta0, phidot0, omega3, period)
    u = np.asarray(traj.axes[:, 2, 2])  # cos θ: z component of the symmetry axis
    # Starting at a turning point, u reaches the other root at T/2 and returns at T.
    u0 = np.cos(theta0)
    start, other = (u2, u1) if abs(u0 - u2) < abs(u0 - u1) else (u1, u2)
    assert abs(u[0] - start) < 1e-12
    assert abs(u[N_OUT // 2] - other) < 1e-8
    assert abs(u[-1] - start) < 1e-8
    assert u.min() > u1 - 1e-8 and u.max() < u2 + 1e-8
    # u̇ = (ω_space × axis3)_z vanishes at the turning points: the period is right to ~1e-8.
    udot = np.cross(np.asarray(traj.omega_space), np.asarray(traj.axes[:, :, 2]))[:, 2]
    scale = np.max(np.abs(udot))
    assert abs(udot[N_OUT // 2]) < 1e-7 * scale
    assert abs(udot[-1]) < 1e-7 * scale
    # Precession over one nutation period matches the quadrature.
    np.testing.assert_allclose(precession_advance(traj) / period, mean_rate, rtol=1e-8)
    # Energy and the vertical angular momentum are conserved.
    energy = np.asarray(traj.energy)
    assert np.max(np.abs(energy - energy[0])) < 1e-9 * abs(energy[0])
    Lz = np.asarray(traj.L_space[:, 2])
    assert np.max(np.abs(Lz - Lz[0])) < 1e-9 * np.max(np.abs(traj.L_space))


def test_heavy_top_precession_rates_fast_top_limit():
    """Mean precession → Mgl/(I3 ω3) (17.51b) and → I3 ω3/(I1 cos θ0) (17.51a) as ω3 grows.

    (17.51a)'s "I_s" is I1, the transverse moment about the pivot. Both follow from the
    steady-precession condition I1 cos θ φ̇² − I3 ω3 φ̇ + Mgl = 0 for large ω3.
    """
    theta0 = 0.5
    slow_err, fast_err = [], []
    for omega3 in (10.0, 20.0, 40.0):
        slow = M * G * ELL / (I3 * omega3)
        fast = I3 * omega3 / (I1 * np.cos(theta0))
        for phidot0, approx, errs in ((0.0, slow, slow_err), (fast, fast, fast_err)):
            period, mean_rate, _ = top_period_and_precession(theta0, phidot0, omega3)
            traj = simulate_top(theta0, phidot0, omega3, period, rtol=1e-10)
            measured = precession_advance(traj) / period
            np.testing.assert_allclose(measured, mean_rate, rtol=1e-7)
            errs.append(abs(measured - approx) / approx)
    # The approximations become exact in the limit: errors shrink like 1/ω3².
    for errs in (slow_err, fast_err):
        assert errs[0] > errs[1] > errs[2]
        assert errs[2] < 0.3 * errs[1]
    assert slow_err[-1] < 2e-2 and fast_err[-1] < 2e-3
