"""jrigid.theory: the chapter's closed-form results against independent references
(analytic limits, scipy's elliptic integrals, scipy integration of Euler's equations,
finite differences) and the rate measurements on simulated and analytic motions."""

import math
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation
from scipy.special import ellipk, ellipkm1

from jrigid import demo, exact, fit, inertia, stability, theory
from jrigid.viz import angles as viz_angles


def _euler(moments):
    mom = np.asarray(moments, float)

    def rhs(t, y):
        w, q = y[:3], y[3:]
        dw = np.cross(mom * w, w) / mom
        dq = 0.5 * np.concatenate([[-q[1:] @ w], q[0] * w + np.cross(q[1:], w)])
        return np.concatenate([dw, dq])

    return rhs


def _integrate(moments, omega0, ts):
    """scipy DOP853 of Euler's equations and q̇ = ½ q ⊗ ω (q0 = identity)."""
    sol = solve_ivp(_euler(moments), (ts[0], ts[-1]), np.r_[omega0, 1.0, 0, 0, 0], t_eval=ts,
                    rtol=1e-12, atol=1e-14, method="DOP853")  # fmt: skip
    return sol.y[:3].T, sol.y[3:].T


def _fd(f, x, h=1e-6):
    """Central differences of a scalar function of a vector."""
    x = np.asarray(x, float)
    out = np.zeros_like(x)
    for k in range(x.size):
        e = np.zeros_like(x)
        e[k] = h
        out[k] = (float(f(x + e)) - float(f(x - e))) / (2 * h)
    return out


# --------------------------------------------------------------------------- one home


def test_import_does_not_load_matplotlib():
    code = "import sys, jrigid.theory; assert 'matplotlib' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True)


def test_old_import_paths_are_the_theory_functions():
    assert demo.plate_theory is theory.plate_theory
    assert demo.flip_theory is theory.flip_theory
    assert demo.wobble_to_spin is theory.wobble_to_spin
    assert demo.zero_crossings is theory.zero_crossings
    assert demo.t_handle_moments is inertia.t_handle_moments
    assert fit.axis_angles is theory.axis_angles
    assert fit.free_rates is theory.free_rates
    assert fit.unwrap is theory.unwrap
    assert fit.angle_rate is theory.angle_rate
    assert fit.trajectory_rates is theory.trajectory_rates


# --------------------------------------------------------------------------- symmetric body


def test_body_precession_rate_against_integration():
    """17.47: ω turns about axis 3 at (I3/I1 − 1) ω3, for oblate and prolate bodies."""
    for moments in ((1.0, 1.0, 1.7), (1.0, 1.0, 0.4)):
        w0 = np.array([0.3, -0.2, 2.0])
        ts = np.linspace(0.0, 6.0, 1201)
        w, _ = _integrate(moments, w0, ts)
        measured = float(theory.omega_phase_rate(ts, w, axis=2))
        assert float(theory.body_precession_rate(moments, w0)) == pytest.approx(measured, rel=1e-9)


def test_plate_theory_limits():
    # thin plate (I3 = 2 I1): the ratio is 2/cos θ exactly, for any tilt
    for tilt in (0.01, 0.3, 1.0):
        w = np.array([math.sin(tilt), 0.0, math.cos(tilt)])
        th = theory.plate_theory([1.0, 1.0, 2.0], w)
        assert float(th["ratio"]) == pytest.approx(float(th["ratio_thin"]), rel=1e-12)
        assert float(th["ratio"]) == pytest.approx(2.0 / math.cos(float(th["theta"])), rel=1e-12)
    # a thick disk: 2/((1 − h²/3r²) cos θ)
    r, h = 1.0, 0.4
    m = np.asarray(inertia.disk(1.0, r, h))
    w = np.array([0.2, 0.0, 3.0])
    th = theory.plate_theory(m, w)
    thick = 2.0 / ((1.0 - h * h / (3 * r * r)) * math.cos(float(th["theta"])))
    assert float(th["ratio"]) == pytest.approx(thick, rel=1e-12)
    # no tilt: φ̇ = |L|/I1 = I3 ω3/I1, θ = 0
    th = theory.plate_theory([1.0, 1.0, 2.0], [0.0, 0.0, 3.0])
    assert float(th["precession_rate"]) == pytest.approx(6.0)
    assert float(th["theta"]) == 0.0


def test_plate_theory_gradient_matches_finite_differences():
    moments = np.array([1.0, 1.0, 1.8])

    def ratio(w):
        return theory.plate_theory(moments, w)["ratio"]

    w = np.array([0.3, 0.1, 2.0])
    np.testing.assert_allclose(jax.grad(ratio)(jnp.asarray(w)), _fd(ratio, w), rtol=1e-6)


def test_free_rates_reduce_to_plate_theory_for_a_symmetric_body():
    m, w = np.array([0.25, 0.25, 0.45]), np.array([0.3, 0.1, 4.0])
    r, th = theory.free_rates(m, w), theory.plate_theory(m, w)
    assert float(r.ratio) == pytest.approx(float(th["ratio"]), rel=1e-10)
    assert float(r.precession_rate) == pytest.approx(float(th["precession_rate"]), rel=1e-10)
    assert float(r.tilt_min) == pytest.approx(float(th["theta"]), rel=1e-10)


# --------------------------------------------------------------------------- the flip


@pytest.mark.parametrize("toward", [0, 2])
def test_flip_interval_against_scipy_ellipk_and_exact(toward):
    moments = np.array([0.7, 1.3, 2.1])
    eps = 0.02
    w0 = np.zeros(3)
    w0[1], w0[toward] = math.cos(eps), math.sin(eps)
    th = theory.flip_theory(moments, w0)
    # reference: λ and m from energy and momentum (Landau & Lifshitz §37), K from scipy
    a, b, c = moments
    e2, l2 = np.sum(moments * w0**2), np.sum(moments**2 * w0**2)
    if l2 > e2 * b:
        lam2 = (c - b) * (l2 - e2 * a) / (a * b * c)
        m = (b - a) * (e2 * c - l2) / ((c - b) * (l2 - e2 * a))
    else:
        lam2 = (b - a) * (e2 * c - l2) / (a * b * c)
        m = (c - b) * (l2 - e2 * a) / ((b - a) * (e2 * c - l2))
    ref = 2 * ellipk(m) / math.sqrt(lam2)
    assert float(th["flip_interval"]) == pytest.approx(ref, rel=1e-10)
    assert float(th["m"]) == pytest.approx(m, rel=1e-12)
    assert int(th["axis"]) == 1
    assert float(theory.flip_interval(moments, w0)) == pytest.approx(ref, rel=1e-10)
    # the closed-form motion has the same period
    consts = exact.prepare(moments, jnp.array([1.0, 0, 0, 0]), w0)
    assert float(exact.omega_period(consts)) == pytest.approx(2 * ref, rel=1e-10)


def test_flip_interval_near_the_separatrix_uses_the_complement():
    """1 − m ≈ 1e-14: K through ellipkm1 (the naive K(m) would lose all digits)."""
    moments = np.array([1.0, 2.0, 3.0])
    eps = 1e-7
    w0 = np.array([0.0, math.cos(eps), math.sin(eps)])
    th = theory.flip_theory(moments, w0)
    m1 = float(th["m1"])
    assert 0 < m1 < 1e-12
    assert float(th["flip_interval"]) == pytest.approx(
        2 * ellipkm1(m1) / float(th["lam"]), rel=1e-12
    )
    # and the asymptote (2/λ) ln(C/ε) agrees to O(ε²)
    t, _, _ = theory.flip_interval_asymptotic(moments, 1.0, eps)
    assert float(t) == pytest.approx(float(th["flip_interval"]), rel=1e-9)


def test_flip_interval_against_integration():
    moments = np.array([1.0, 2.0, 3.0])
    w0 = np.array([0.05, 1.0, 0.0])
    half = float(theory.flip_interval(moments, w0))
    ts = np.linspace(0.0, 4.2 * half, 40001)
    w, _ = _integrate(moments, w0, ts)
    crossings = np.asarray(theory.zero_crossings(ts, w[:, 1]))
    assert len(crossings) >= 4
    assert np.mean(np.diff(crossings)) == pytest.approx(half, rel=1e-7)


def test_flip_interval_gradient_matches_finite_differences():
    w0 = np.array([0.03, 1.0, 0.02])

    def f(m):
        return theory.flip_interval(m, w0)

    m = np.array([1.0, 2.0, 3.0])
    np.testing.assert_allclose(jax.grad(f)(jnp.asarray(m)), _fd(f, m), rtol=1e-6)

    def g(w):
        return theory.flip_interval(m, w)

    np.testing.assert_allclose(jax.grad(g)(jnp.asarray(w0)), _fd(g, w0, 1e-7), rtol=1e-5)


@pytest.mark.parametrize("toward", ["largest", "smallest"])
def test_flip_asymptote_converges_to_the_exact_interval(toward):
    moments = np.array([0.6, 1.1, 1.5])
    big = 2 if toward == "largest" else 0
    errors = []
    for eps in (1e-2, 1e-3, 1e-4):
        w0 = np.zeros(3)
        w0[1], w0[big] = math.cos(eps), math.sin(eps)
        exact_t = float(theory.flip_interval(moments, w0))
        t, lam, _ = theory.flip_interval_asymptotic(moments, 1.0, eps, toward)
        errors.append(abs(float(t) / exact_t - 1))
    # O(ε²): a factor of about 100 per decade of ε
    assert errors[0] < 1e-3 and errors[1] < errors[0] / 30 and errors[2] < errors[1] / 30
    lam_ref = math.sqrt((1.5 - 1.1) * (1.1 - 0.6) / (0.6 * 1.5))
    assert float(lam) == pytest.approx(lam_ref, rel=1e-12)
    with pytest.raises(ValueError, match="toward"):
        theory.flip_interval_asymptotic(moments, 1.0, 0.1, "middle")


def test_stability_asymptote_is_the_theory_one():
    a = stability.flip_time_asymptotic([1.0, 2.0, 3.0], 2.0, 1e-3, "smallest")
    b = theory.flip_interval_asymptotic([1.0, 2.0, 3.0], 2.0, 1e-3, "smallest")
    assert [float(x) for x in a] == [float(x) for x in b]


# --------------------------------------------------------------------------- heavy top


def test_gyroscope_rates_are_the_roots_and_tend_to_17_51():
    i1, i3, mgl, theta = 2.0, 0.8, 1.3, 0.9
    for omega3 in (10.0, 100.0, 1000.0):
        r = theory.gyroscope_rates(i1, i3, mgl, theta, omega3)
        for root in (float(r["slow"]), float(r["fast"])):
            residual = i1 * root**2 * math.cos(theta) - i3 * omega3 * root + mgl
            assert abs(residual) < 1e-12 * i3 * omega3 * abs(root) + 1e-12
        small = mgl / (i3 * omega3) ** 2  # the relative size of the correction
        assert float(r["slow"]) == pytest.approx(mgl / (i3 * omega3), rel=10 * small)
        assert float(r["slow"]) < float(r["fast"])
    # the fast-top limits: relative corrections of order 4 I1 mgl cos θ/(I3 ω3)²
    r = theory.gyroscope_rates(i1, i3, mgl, theta, 1000.0)
    assert float(r["fast"]) == pytest.approx(float(r["fast_approx"]), rel=1e-5)
    # too slow to precess steadily: no real roots
    assert np.isnan(float(theory.gyroscope_rates(i1, i3, mgl, theta, 0.5)["slow"]))


def test_gyroscope_slow_rate_gradient():
    def slow(x):
        return theory.gyroscope_rates(x[0], x[1], x[2], x[3], x[4])["slow"]

    x = np.array([2.0, 0.8, 1.3, 0.9, 12.0])
    np.testing.assert_allclose(jax.grad(slow)(jnp.asarray(x)), _fd(slow, x), rtol=1e-6)


def test_fast_top_nutation_against_the_lagrange_top():
    """Released with φ̇ = θ̇ = 0, a fast top nutates at I3 ω3/I1 by 2 mgl I1 sin θ/(I3 ω3)²."""
    from jrigid import lagrange_top
    from jrigid import quaternion as quat

    i1c, i3, mass, lever, g = 0.3, 0.5, 1.0, 1.0, 1.0
    theta, omega3 = 0.8, 60.0
    q0 = quat.from_axis_angle(jnp.array([1.0, 0.0, 0.0]), jnp.asarray(theta))
    consts = lagrange_top.prepare(
        jnp.array([i1c, i1c, i3]), mass, jnp.array([0.0, 0.0, lever]), jnp.array([0.0, 0.0, -g]),
        q0, jnp.array([0.0, 0.0, omega3]),
    )  # fmt: skip
    i1 = i1c + mass * lever**2
    r = theory.fast_top_nutation(i1, i3, mass * g * lever, theta, omega3)
    period = float(lagrange_top.nutation_period(consts))
    # corrections of relative order mgl I1/(I3 ω3)² ≈ 1.4e-3
    assert 2 * math.pi / period == pytest.approx(float(r["frequency"]), rel=5e-3)
    u1, u2 = (float(u) for u in lagrange_top.nutation_range(consts))
    assert math.acos(u1) - math.acos(u2) == pytest.approx(float(r["dip"]), rel=1e-2)


# --------------------------------------------------------------------------- measurement


def test_axis_angles_are_scipy_zxz_angles():
    """About the z axis with frame_about's x along space y: R = A Rz(φ) Rx(θ) Rz(ψ)."""
    rng = np.random.default_rng(3)
    ang = np.stack([rng.uniform(-3, 3, 50), rng.uniform(0.1, 3.0, 50), rng.uniform(-3, 3, 50)], -1)
    a = np.asarray(theory.frame_about([0.0, 0.0, 2.0]))
    q = (Rotation.from_matrix(a) * Rotation.from_euler("ZXZ", ang)).as_quat(scalar_first=True)
    got = np.asarray(theory.axis_angles(q, jnp.array([0.0, 0.0, 2.0]), unwrapped=False))
    np.testing.assert_allclose(np.angle(np.exp(1j * (got - ang))), 0.0, atol=1e-10)


def test_frame_about_is_a_rotation_and_refuses_zero():
    for n in ([0.0, 0.0, 2.0], [0.3, -0.5, 0.8], [1.0, 1e-9, 0.0]):
        a = np.asarray(theory.frame_about(n))
        np.testing.assert_allclose(a.T @ a, np.eye(3), atol=1e-14)
        assert np.linalg.det(a) == pytest.approx(1.0)
        np.testing.assert_allclose(a[:, 2], np.asarray(n) / np.linalg.norm(n), atol=1e-15)
    with pytest.raises(ValueError, match="zero"):
        theory.frame_about([0.0, 0.0, 0.0])


def test_trajectory_rates_on_an_integrated_asymmetric_body_match_free_rates():
    """A nearly symmetric body over many wobbles: line fits → the closed-form mean rates."""
    moments = np.array([1.0, 1.05, 1.9])
    w0 = np.array([0.3, 0.0, 3.0])
    r = theory.free_rates(moments, w0)
    ts = np.linspace(0.0, 40 * float(r.omega_period), 20001)
    _, q = _integrate(moments, w0, ts)
    tr = theory.wobble_to_spin(ts, q, moments * w0, axis=2)
    assert float(tr["precession_rate"]) == pytest.approx(float(r.precession_rate), rel=2e-3)
    assert float(tr["spin_rate"]) == pytest.approx(float(r.spin_rate), rel=2e-3)
    assert float(r.tilt_min) <= float(tr["theta"]) <= float(r.tilt_max)


def test_rates_are_differentiable_in_the_samples():
    ts = jnp.linspace(0.0, 2.0, 41)

    def rate(c):
        angle = jnp.angle(jnp.exp(1j * (c * ts + 0.2 * jnp.sin(3 * ts))))
        return theory.angle_rate(ts, theory.unwrap(angle))

    assert float(jax.grad(rate)(4.0)) == pytest.approx(1.0, rel=1e-12)


def test_zero_crossings_interpolate_and_differentiate():
    ts = jnp.linspace(0.0, 10.0, 2001)
    expected = [math.pi, 2 * math.pi, 3 * math.pi]
    np.testing.assert_allclose(theory.zero_crossings(ts, jnp.sin(ts)), expected, atol=1e-5)
    # d t*/d shift of sin(t − s) is 1 for every crossing; at s = 0.5 there are four, the
    # first on the sample t = 0.5, where sin(t − s) is exactly zero
    grad = jax.grad(lambda s: jnp.sum(theory.zero_crossings(ts, jnp.sin(ts - s))))(0.5)
    assert float(grad) == pytest.approx(4.0, rel=1e-4)


def test_viz_wrappers_return_numpy_from_the_theory_functions():
    ts = np.linspace(0.0, 1.0, 30)
    q = Rotation.from_euler("ZXZ", np.stack([2 * ts, np.full(30, 0.4), -3 * ts], -1))
    q = q.as_quat(scalar_first=True)
    ang = viz_angles.euler_about(q, [0.0, 0.0, 1.0])
    assert isinstance(ang, np.ndarray)
    direct = theory.axis_angles(q, jnp.array([0.0, 0.0, 1.0]))
    np.testing.assert_array_equal(ang, np.asarray(direct))
    assert isinstance(viz_angles.fit_rate(ts, ang[:, 0]), float)


def test_gyroscope_rates_for_either_sense_of_spin():
    """A top spinning the other way (ω3 < 0) has the same roots, negated (the quadratic's
    roots from numpy), and the slow one is still the one near M g l / (I3 ω3)."""
    i1, i3, mgl, theta = 1.0, 0.5, 1.0, 1.0
    for omega3 in (20.0, -20.0, 3.0, -3.0):
        r = theory.gyroscope_rates(i1, i3, mgl, theta, omega3)
        roots = np.roots([i1 * math.cos(theta), -i3 * omega3, mgl])
        slow, fast = sorted(roots, key=abs)
        assert float(r["slow"]) == pytest.approx(slow, rel=1e-12)
        assert float(r["fast"]) == pytest.approx(fast, rel=1e-12)
        assert np.sign(float(r["slow"])) == np.sign(omega3)


def test_zero_crossings_through_exact_zeros():
    ts = jnp.arange(7.0)
    # a crossing on a sample, a touch, a run of zeros, a zero at the end
    x = jnp.array([1.0, 0.0, -1.0, 0.0, -2.0, 0.0, 0.0])
    np.testing.assert_array_equal(theory.zero_crossings(ts[:3], x[:3]), [1.0])
    np.testing.assert_array_equal(theory.zero_crossings(ts, x), [1.0])
    x = jnp.array([1.0, 0.0, 0.0, 0.0, -1.0, 2.0, 2.0])
    np.testing.assert_allclose(theory.zero_crossings(ts, x), [2.0, 4 + 1 / 3])
    # sin sampled so that every crossing is a sample, after rounding
    ts = jnp.linspace(0.0, 2 * math.pi, 9)
    np.testing.assert_allclose(theory.zero_crossings(ts, jnp.round(jnp.sin(ts), 12)),
                               [math.pi], atol=1e-12)
    # the crossing on a zero sample moves with the sample after it, as the interpolation
    grad = jax.grad(lambda v: jnp.sum(theory.zero_crossings(
        jnp.arange(3.0), jnp.array([1.0, v, -1.0]))))(0.0)
    assert float(grad) == pytest.approx(1.0)  # t* = 1 + v for v near 0
    with pytest.raises(ValueError, match="x must be finite"):
        theory.zero_crossings(jnp.arange(3.0), jnp.array([1.0, jnp.nan, -1.0]))
    with pytest.raises(ValueError, match=r"shape \(T,\)"):
        theory.zero_crossings(jnp.arange(3.0), jnp.ones((3, 2)))


def test_flip_theory_on_a_batch_is_each_member():
    moments = np.array([1.0, 2.0, 3.0])
    omegas = np.array([[0.01, 1.0, 0.0], [0.1, 1.0, 0.05], [1.0, 0.1, 0.2]])
    batch = theory.flip_theory(moments, omegas)
    for k, w in enumerate(omegas):
        one = theory.flip_theory(moments, w)
        for key in ("flip_interval", "period", "m1", "axis"):
            assert float(batch[key][k]) == pytest.approx(float(one[key]), rel=1e-14)
    # each flip interval against the closed form's ω period
    np.testing.assert_allclose(batch["period"],
                               [float(theory.free_rates(moments, w).omega_period) for w in omegas],
                               rtol=1e-12)
    # batched bodies, in any order of the moments
    bodies = np.array([[1.0, 2.0, 3.0], [3.0, 1.0, 2.0]])
    both = theory.flip_interval(bodies, np.array([[0.01, 1.0, 0.0], [0.0, 0.01, 1.0]]))
    assert float(both[1]) == pytest.approx(float(both[0]), rel=1e-14)
    t, lam, c = theory.flip_interval_asymptotic(bodies, 1.0, 0.01)
    assert t.shape == (2,) and float(t[1]) == pytest.approx(float(t[0]), rel=1e-14)


@pytest.mark.parametrize("call", [
    lambda m: theory.flip_interval(m, [0.01, 1.0]),
    lambda m: theory.plate_theory(m, [0.3, 0.1]),
    lambda m: theory.body_precession_rate(m, [0.3, 0.1]),
    lambda m: theory.flip_interval_asymptotic(m, 1.0, 0.01),
])
def test_closed_forms_refuse_two_moments_or_negative_ones(call):
    with pytest.raises(ValueError, match=r"moments.*\(\.\.\., 3\)"):
        call([1.0, 2.0])
    with pytest.raises(ValueError, match="not positive definite|shape"):
        call([-1.0, 1.0, 2.0])


def test_symmetric_body_formulas_refuse_an_asymmetric_body():
    """plate_theory and body_precession_rate hold for I1 = I2 only: for (1, 2, 3) the
    plate's ratio would be 1.50 where the exact rates give 2.01."""
    for f in (theory.plate_theory, theory.body_precession_rate):
        with pytest.raises(ValueError, match="I1 = I2"):
            f([1.0, 2.0, 3.0], [0.3, 0.1, 2.0])
        f([1.0, 1.0 + 1e-12, 2.0], [0.3, 0.1, 2.0])  # equal to rounding: accepted
    with pytest.raises(Exception, match="I1 = I2"):
        jax.jit(theory.body_precession_rate)(jnp.array([1.0, 2.0, 3.0]),
                                             jnp.array([0.3, 0.1, 2.0])).block_until_ready()
