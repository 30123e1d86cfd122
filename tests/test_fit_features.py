"""jrigid.fit.features: closed-form rates against theory and independent integration,
loss gradients against finite differences, recovery of a plate's thickness, bad input."""

import math

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation
from scipy.special import ellipk

from jrigid import fit, inertia, initial
from jrigid.body import RigidBody
from jrigid.scene import Gravity, Pivot, Scene

# --------------------------------------------------------------------------- references


def symmetric_theory(moments, omega):
    """Symmetric body (I1 = I2): φ̇ = |L|/I1 about L; ψ̇ about the axis a = sign(ω3) e3."""
    i1, _, i3 = moments
    L = np.linalg.norm(np.asarray(moments) * np.asarray(omega))
    w3 = omega[2]
    prec = L / i1
    spin = abs(w3) * (i1 - i3) / i1
    theta = math.acos(i3 * abs(w3) / L)
    return prec, spin, theta


def landau_period(moments, omega):
    """``4K(m)/λ`` from Landau & Lifshitz §37 with scipy's ``ellipk`` (``L² > 2E I2``)."""
    i1, i2, i3 = np.sort(moments)
    w = np.asarray(omega)[np.argsort(moments)]
    L2 = np.sum((np.array([i1, i2, i3]) * w) ** 2)
    E2 = np.sum(np.array([i1, i2, i3]) * w * w)
    assert L2 > E2 * i2
    lam = math.sqrt((i3 - i2) * (L2 - E2 * i1) / (i1 * i2 * i3))
    m = (i2 - i1) * (E2 * i3 - L2) / ((i3 - i2) * (L2 - E2 * i1))
    return 4 * ellipk(m) / lam


def integrate_angles(moments, omega, t_end, axis):
    """scipy ``solve_ivp`` (DOP853, rtol 1e-12) of Euler's equations and q̇ = ½ q ⊗ ω;
    returns the total advance of φ and ψ of ``axis`` about L, and min/max of θ."""
    mom = np.asarray(moments, float)

    def rhs(t, y):
        w, q = y[:3], y[3:]
        dw = np.cross(mom * w, w) / mom
        qw, qv = q[0], q[1:]
        dq = 0.5 * np.concatenate([[-qv @ w], qw * w + np.cross(qv, w)])
        return np.concatenate([dw, dq])

    ts = np.linspace(0.0, t_end, 4001)
    sol = solve_ivp(rhs, (0, t_end), np.r_[omega, 1.0, 0, 0, 0], t_eval=ts, rtol=1e-12,
                    atol=1e-14, method="DOP853")  # fmt: skip
    R = Rotation.from_quat(sol.y[3:].T, scalar_first=True)
    n = mom * np.asarray(omega)
    n = n / np.linalg.norm(n)  # L in space (q0 = identity)
    u = R.apply(np.eye(3)[axis])
    x = np.cross(n, np.eye(3)[np.argmin(np.abs(n))])
    x /= np.linalg.norm(x)
    y = np.cross(n, x)
    phi = np.unwrap(np.arctan2(u @ y, u @ x))
    nb = R.inv().apply(n)
    psi = np.unwrap(0.5 * np.pi - np.arctan2(nb[:, (axis + 2) % 3], nb[:, (axis + 1) % 3]))
    theta = np.arccos(np.clip(u @ n, -1, 1))
    return phi[-1] - phi[0], psi[-1] - psi[0], theta.min(), theta.max()


# --------------------------------------------------------------------------- closed form


@pytest.mark.parametrize(
    "moments, omega",
    [
        ((0.25, 0.25, 0.5), (0.3, 0.0, 5.0)),  # plate (oblate)
        ((0.25, 0.25, 0.5), (0.2, -0.1, -5.0)),  # spinning the other way
        ((0.5, 0.5, 0.2), (0.3, 0.4, 2.0)),  # prolate
        ((1.0, 1.0, 1.9), (1.0, 0.0, 0.05)),  # large tilt
    ],
)
def test_free_rates_symmetric_body_matches_theory(moments, omega):
    r = fit.free_rates(jnp.asarray(moments), jnp.asarray(omega))
    prec, spin, theta = symmetric_theory(moments, omega)
    np.testing.assert_allclose(r.precession_rate, prec, rtol=1e-12)
    np.testing.assert_allclose(r.spin_rate, spin, rtol=1e-12)
    np.testing.assert_allclose(r.ratio, abs(prec / spin), rtol=1e-12)
    np.testing.assert_allclose([r.tilt_min, r.tilt_max], [theta, theta], rtol=1e-12)
    np.testing.assert_allclose(r.omega_period, 2 * np.pi / abs(spin), rtol=1e-12)
    assert int(r.axis) == 2


def test_free_rates_thin_plate_ratio_is_two_over_cos():
    tilt = 0.3
    m = np.asarray(inertia.disk(1.0, 1.0, 1e-4))
    w3 = 4.0
    w = np.array([w3 * math.tan(tilt) * m[2] / m[0], 0.0, w3])
    r = fit.free_rates(jnp.asarray(m), jnp.asarray(w))
    np.testing.assert_allclose(r.tilt_min, tilt, rtol=1e-12)
    np.testing.assert_allclose(r.ratio, 2 / math.cos(tilt), rtol=1e-8)


@pytest.mark.parametrize(
    "moments, omega, axis",
    [
        ((0.24, 0.26, 0.5), (0.3, 0.2, 5.0), 2),  # nearly symmetric plate
        ((1.0, 2.0, 2.5), (0.05, 2.0, 0.3), 2),  # near the separatrix, L² > 2E I2
        ((1.0, 2.0, 2.5), (0.3, 2.0, 0.05), 0),  # L² < 2E I2: the polhode circles axis 0
        ((2.5, 1.0, 2.0), (0.02, 0.3, 2.0), 1),  # permuted axes
    ],
)
def test_free_rates_asymmetric_against_scipy_integration(moments, omega, axis):
    """Mean rates over exactly two periods of ω (where the periodic parts cancel)."""
    r = fit.free_rates(jnp.asarray(moments), jnp.asarray(omega))
    assert int(r.axis) == axis
    T = float(r.omega_period)
    if moments[2] == max(moments) and axis == 2:
        np.testing.assert_allclose(T, landau_period(moments, omega), rtol=1e-10)
    dphi, dpsi, th_min, th_max = integrate_angles(moments, omega, 2 * T, axis)
    np.testing.assert_allclose(float(r.precession_rate) * 2 * T, dphi, rtol=1e-8)
    np.testing.assert_allclose(float(r.spin_rate) * 2 * T, dpsi, rtol=1e-8)
    np.testing.assert_allclose(float(r.nutation_rate), 4 * np.pi / T, rtol=1e-12)
    # θ extremes: the sampled min/max approach them from inside (4001 samples)
    assert float(r.tilt_min) <= th_min + 1e-9 and th_min - float(r.tilt_min) < 1e-4
    assert float(r.tilt_max) >= th_max - 1e-9 and float(r.tilt_max) - th_max < 1e-4


def test_free_rates_steady_and_float32(float32):
    r = fit.free_rates(jnp.array([1.0, 2.0, 3.0]), jnp.array([0.0, 0.0, 1.0]))
    assert np.isnan(float(r.ratio)) and np.isinf(float(r.omega_period))
    m = jnp.array([0.25, 0.25, 0.5], jnp.float32)
    w = jnp.array([0.3, 0.0, 5.0], jnp.float32)
    r = fit.free_rates(m, w)
    assert r.ratio.dtype == jnp.float32
    prec, spin, _ = symmetric_theory(np.asarray(m, float), np.asarray(w, float))
    np.testing.assert_allclose(float(r.ratio), abs(prec / spin), rtol=1e-5)


# --------------------------------------------------------------------------- trajectory tools


def test_unwrap_and_angle_rate():
    ts = jnp.linspace(0.0, 3.0, 50)
    raw = jnp.angle(jnp.exp(1j * (2.5 * ts + 0.3)))
    np.testing.assert_allclose(fit.unwrap(raw), np.unwrap(np.asarray(raw)), atol=1e-12)
    np.testing.assert_allclose(fit.angle_rate(ts, fit.unwrap(raw)), 2.5, rtol=1e-12)
    # the 2π corrections are constant: the Jacobian of unwrap is the identity
    np.testing.assert_allclose(jax.jacfwd(fit.unwrap)(raw), np.eye(50))


def test_trajectory_rates_match_closed_form_for_symmetric_body():
    m = jnp.array([0.25, 0.25, 0.5])
    w = jnp.array([0.4, 0.1, 5.0])
    ts = jnp.linspace(0.0, 3.0, 301)
    from jrigid import exact

    q, _ = exact.solve(m, jnp.array([1.0, 0, 0, 0]), w, ts)
    tr = fit.trajectory_rates(ts, q, m * w, axis=2)
    prec, spin, theta = symmetric_theory(np.asarray(m), np.asarray(w))
    np.testing.assert_allclose([tr["precession_rate"], tr["spin_rate"]], [prec, spin], rtol=1e-9)
    np.testing.assert_allclose(tr["tilt"], theta, rtol=1e-9)


# --------------------------------------------------------------------------- losses: gradients

TS = jnp.linspace(0.0, 4.0, 41)


def build_free(theta):
    body = RigidBody(fit.moment_ratios(theta["shape"]))
    return Scene(body), initial.from_omega(None, theta["omega0"])


THETA = {
    "shape": fit.moment_ratios_raw(jnp.array([0.3, 0.33, 0.37])),
    "omega0": jnp.array([0.4, 0.3, 3.0]),
}


def feature_observations(method):
    kw = dict(method=method)
    return [
        fit.WobbleRatio(TS, 1.5, 0.01, **kw),
        fit.PrecessionRate(TS, 3.0, 0.1, **kw),
        fit.SpinRate(TS, -0.5, 0.1, **kw),
        fit.Tilt(TS, 0.1, 0.01, **kw),
        fit.NutationRate(TS, 1.0, 0.1, **kw),
        fit.FlipPeriod(TS, 5.0, 0.1, **kw),
    ]


def _central_fd(f, flat, h):
    cols = [(f(flat + h * e) - f(flat - h * e)) / (2 * h) for e in jnp.eye(flat.shape[0])]
    return jnp.stack(cols, axis=-1)


@pytest.mark.parametrize(
    "method, model, jac",
    [
        ("closed", fit.Exact(build_free), jax.jacrev),
        # forward mode through simulate (half the compile time of reverse mode, which
        # tests/test_fit.py checks for the other losses)
        (
            "trajectory",
            fit.Simulated(build_free, rtol=1e-12, atol=1e-14, adjoint=diffrax.ForwardMode()),
            jax.jacfwd,
        ),
    ],
    ids=["closed-exact-reverse", "trajectory-simulate-forward"],
)
def test_every_feature_loss_gradient_matches_finite_differences(method, model, jac):
    problem = fit.Problem(model, feature_observations(method))
    flat, unravel = jax.flatten_util.ravel_pytree(THETA)

    def losses(x):
        pred = problem.predict(unravel(x))
        out = []
        for obs, idx in zip(problem.observations, problem.index, strict=True):
            out.append(obs.loss(pred._replace(q=pred.q[idx], omega=pred.omega[idx])))
        return jnp.stack(out)

    grad = jax.jit(jac(losses))(flat)
    fd = _central_fd(jax.jit(losses), flat, 1e-5)
    assert bool(jnp.all(jnp.isfinite(grad)))
    assert bool(jnp.all(jnp.max(jnp.abs(grad), axis=1) > 0))  # every loss depends on θ
    scale = np.asarray(jnp.max(jnp.abs(fd), axis=1, keepdims=True))
    np.testing.assert_allclose(grad / scale, fd / scale, rtol=1e-6, atol=1e-6)


# --------------------------------------------------------------------------- plate recovery


def plate_build(theta):
    """A plate of radius 1 and thickness ``positive(theta['h'])``, axis tilted from L by
    ``theta['tilt']``, spinning at ω3 = 2π."""
    h = fit.positive(theta["h"])
    m = inertia.disk(1.0, 1.0, h)
    w3 = 2 * jnp.pi
    w = jnp.stack([w3 * jnp.tan(theta["tilt"]) * m[2] / m[0], jnp.zeros(()), w3 * jnp.ones(())])
    return Scene(RigidBody(m)), initial.from_omega(None, w)


def plate_ratio(h, tilt):
    """Independent: |φ̇/ψ̇| = 2/((1 − h²/3) cos θ) for a plate of radius 1."""
    return 2.0 / ((1 - h * h / 3) * math.cos(tilt))


def plate_problem(ratio, tilt, s_ratio, s_tilt):
    ts = [0.0, 1.0]
    return fit.Problem(
        fit.Invariants(plate_build),
        [fit.WobbleRatio(ts, ratio, s_ratio), fit.Tilt(ts, tilt, s_tilt)],
    )


START = {"h": fit.positive_raw(0.5), "tilt": jnp.asarray(0.15)}


def test_plate_thickness_noise_free_recovery():
    h, tilt = 0.3, 0.2
    problem = plate_problem(plate_ratio(h, tilt), tilt, 1e-3, 1e-3)
    res = fit.fit(problem, START, max_iter=200, gtol=1e-12)
    assert res.converged, res.reason
    assert abs(float(fit.positive(res.params["h"])) - h) < 1e-6
    assert abs(float(res.params["tilt"]) - tilt) < 1e-6


def test_plate_thickness_truth_within_three_sigma_seeded():
    h, tilt, s_r, s_t = 0.4, 0.25, 2e-3, 2e-3
    rng = np.random.default_rng(7)
    hits = 0
    for _ in range(5):
        r_obs = plate_ratio(h, tilt) + s_r * rng.standard_normal()
        t_obs = tilt + s_t * rng.standard_normal()
        problem = plate_problem(r_obs, t_obs, s_r, s_t)
        res = fit.fit(problem, START, max_iter=200, gtol=1e-12)
        lap = fit.laplace(problem, res.params)
        h_est, h_sig = fit.propagate(lambda p: fit.positive(p["h"]), lap)
        # delta method by hand: h = sqrt(3 (1 − 2/(R cos θ)))
        dh_dr = 3 / (h_est * r_obs**2 * math.cos(t_obs))
        dh_dt = -3 * math.tan(t_obs) / (h_est * r_obs * math.cos(t_obs))
        np.testing.assert_allclose(h_sig, math.hypot(dh_dr * s_r, dh_dt * s_t), rtol=1e-6)
        hits += abs(float(h_est) - h) < 3 * float(h_sig)
    assert hits == 5


# --------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: fit.WobbleRatio([0.0, 1.0], np.nan, 0.1), "NaN"),
        (lambda: fit.WobbleRatio([0.0, 1.0], [2.0, 2.1], 0.1), "single number"),
        (lambda: fit.WobbleRatio([0.0, 1.0], 2.0, 0.0), "sigma"),
        (lambda: fit.WobbleRatio([0.0, 1.0], 2.0, np.inf), "sigma"),
        (lambda: fit.Tilt([0.0], 0.1, 0.1), "too few samples"),
        (lambda: fit.Tilt(np.arange(5.0), 0.1, 0.1, method="trajectory"), "too few samples"),
        (lambda: fit.Tilt([0.0, np.nan], 0.1, 0.1), "non-finite"),
        (lambda: fit.SpinRate([0.0, 1.0], 0.1, 0.1, method="fourier"), "method"),
        (lambda: fit.SpinRate([0.0, 1.0], 0.1, 0.1, axis=3), "axis"),
        (lambda: fit.SpinRate(np.arange(9.0), 0.1, method="trajectory", about=[0, 0, 0]), "about"),
    ],
)
def test_bad_feature_observations_raise_clear_errors(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def top_build(theta):
    body = RigidBody(jnp.array([0.25, 0.25, 0.4]), 1.0, jnp.array([0.0, 0.0, 0.5]))
    return Scene(body, Pivot(), Gravity(9.81)), initial.from_omega(None, theta["omega0"])


def test_closed_form_needs_torque_free_model_and_the_encircled_axis():
    top = {"omega0": jnp.array([0.5, 0.0, 20.0])}
    ts = jnp.linspace(0.0, 0.5, 21)
    with pytest.raises(ValueError, match="torque-free"):
        fit.Problem(fit.Simulated(top_build), fit.WobbleRatio(ts, 2.0, 0.1)).residuals(top)
    with pytest.raises(ValueError, match="about"):
        obs = fit.WobbleRatio(ts, 2.0, 0.1, method="trajectory")
        fit.Problem(fit.Simulated(top_build), obs).residuals(top)
    # with a fixed direction (the vertical) the trajectory route traces for the top
    obs = fit.PrecessionRate(ts, 1.0, 0.1, method="trajectory", about=[0.0, 0.0, 1.0])
    problem = fit.Problem(fit.Simulated(top_build), obs)
    assert jax.eval_shape(problem.residuals, top).shape == (1,)
    # the closed form describes the encircled axis (here 2), not axis 0
    wrong = fit.Problem(fit.Invariants(build_free), fit.WobbleRatio(TS, 2.0, 0.1, axis=0))
    with pytest.raises(ValueError, match="encircles axis 2"):
        wrong.residuals(THETA)
    with pytest.raises(Exception, match="encircle"):
        eqx.filter_jit(lambda p, th: p.residuals(th))(wrong, THETA)


def test_models_predict_moments_only_when_torque_free():
    ts = jnp.linspace(0.0, 1.0, 5)
    free = jax.eval_shape(lambda th: fit.Simulated(build_free)(th, ts), THETA)
    assert free.moments is not None and free.moments.shape == (3,)
    top = jax.eval_shape(lambda th: fit.Simulated(top_build)(th, ts), {"omega0": jnp.ones(3)})
    assert top.moments is None
    with pytest.raises(ValueError, match="Invariants predicts no trajectory"):
        fit.Problem(fit.Invariants(build_free), fit.Gyroscope(ts, np.zeros((5, 3))))
    with pytest.raises(ValueError, match="Invariants predicts no trajectory"):
        fit.Problem(fit.Invariants(build_free), fit.Tilt(TS, 0.1, method="trajectory"))
