"""Stability maps (jrigid.stability) against closed-form theory, scipy and mpmath.

Anchors: the polhode is the intersection of ``ω·Iω = 2E`` and ``|Iω|² = L²``; the axis
the polhode encircles is the largest when ``L² > 2E I_mid`` (Landau & Lifshitz §37); the
time between flips is ``2K(m)/λ_m`` (computed here with mpmath) and tends to
``(2/λ) ln(C/ε)``; rotations of body axes are compared with scipy's ``Rotation``.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import mpmath
import numpy as np
import pytest
from _experiments import quick_suite
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

from jrigid import stability, theory

# Bodies (I1, I2, I3) with distinct moments: a box of sides 1, 2, 3, a T-handle-like body
# and a near-symmetric one (I1 ≈ I2).
BODIES = {
    "box": np.array([13.0, 10.0, 5.0]) / 12.0,
    "t_handle": np.array([0.3, 0.8, 1.0]),
    "near_symmetric": np.array([0.62, 0.66, 1.0]),
}


def _tilted(k: int, other: int, sign: float, deg: float) -> np.ndarray:
    w = np.zeros(3)
    w[k] = math.cos(math.radians(deg))
    w[other] = sign * math.sin(math.radians(deg))
    return w


# --------------------------------------------------------------------------- directions


def test_fibonacci_directions_are_unit_and_uniform():
    n = 4000
    d = np.asarray(stability.fibonacci_sphere(n))
    assert d.shape == (n, 3)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-14)
    # a spherical cap of half-angle θ holds the fraction (1 − cos θ)/2 of a uniform sample
    rng = np.random.default_rng(0)
    for axis in rng.normal(size=(6, 3)):
        axis /= np.linalg.norm(axis)
        for theta in (0.3, 1.0, 2.0):
            frac = np.mean(d @ axis > math.cos(theta))
            assert frac == pytest.approx((1 - math.cos(theta)) / 2, abs=3e-3)
    assert np.linalg.norm(d.mean(axis=0)) < 1e-3
    with pytest.raises(ValueError, match="positive int"):
        stability.fibonacci_sphere(0)
    with pytest.raises(ValueError, match="positive int"):
        stability.fibonacci_sphere(True)  # a bool is not a count
    np.testing.assert_array_equal(stability.fibonacci_sphere(np.int64(5)),
                                  stability.fibonacci_sphere(5))


@pytest.mark.parametrize("t", [0.0, -5.0, float("nan")])
def test_ftle_exact_refuses_a_horizon_that_is_not_positive(t):
    """t = 0 gave NaN, and t < 0 a negative exponent that read as stable."""
    from jrigid.ftle import ftle_exact

    with pytest.raises(ValueError, match="horizon > 0"):
        ftle_exact(jnp.array([1.0, 2.0, 3.0]), jnp.array([0.1, 1.0, 0.1]), t)


def test_omega_at_energy_has_the_energy_and_direction():
    d = np.asarray(stability.fibonacci_sphere(50))
    mom = BODIES["box"]
    w = np.asarray(stability.omega_at_energy(d, np.broadcast_to(mom, d.shape), np.full(50, 0.7)))
    np.testing.assert_allclose(np.sum(mom * w * w, axis=1), 1.4, rtol=1e-14)
    np.testing.assert_allclose(w / np.linalg.norm(w, axis=1, keepdims=True), d, atol=1e-14)


# --------------------------------------------------------------------------- per trajectory


def test_flip_summary_and_interval_of_a_sine():
    ts = np.linspace(0.0, 10.0, 2001)
    x = np.sin(2 * math.pi * (ts - 0.3) / 4.0)  # zeros at 0.3, 2.3, 4.3, 6.3, 8.3
    count, first = stability.flip_summary(ts, x)
    assert int(count) == 5 and float(first) == pytest.approx(0.3, abs=1e-6)
    interval, count = stability.flip_interval(ts, x)
    assert int(count) == 5 and float(interval) == pytest.approx(2.0, abs=1e-6)
    count, first = stability.flip_summary(ts, 1.0 + 0.5 * np.sin(ts))
    assert int(count) == 0 and math.isinf(float(first))
    assert math.isnan(float(stability.flip_interval(ts, np.cos(ts / 5))[0]))  # one zero only


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(0, 2))
def test_axis_angle_matches_scipy(seed, axis):
    rot = Rotation.random(5, random_state=seed)
    q = jnp.asarray(rot.as_quat(scalar_first=True))
    got = np.asarray(stability.axis_angle(q, q[0], axis))
    e = np.eye(3)[axis]
    a = rot.apply(e)
    want = np.arccos(np.clip(a @ a[0], -1.0, 1.0))
    np.testing.assert_allclose(got, want, atol=1e-7)


def _euler_fd_ftle(mom, w0, t, h=1e-6):
    """FTLE from central differences of scipy's DOP853 solution of Euler's equations."""
    i1, i2, i3 = mom

    def rhs(_, w):
        return [
            (i2 - i3) * w[1] * w[2] / i1,
            (i3 - i1) * w[2] * w[0] / i2,
            (i1 - i2) * w[0] * w[1] / i3,
        ]

    def final(w):
        return solve_ivp(rhs, (0.0, t), w, method="DOP853", rtol=1e-13, atol=1e-15).y[:, -1]

    jac = np.stack([(final(w0 + h * e) - final(w0 - h * e)) / (2 * h) for e in np.eye(3)], 1)
    return math.log(np.linalg.svd(jac, compute_uv=False)[0]) / t


@pytest.fixture(scope="module")
def ftle_solver():
    """``ftle_simulate`` (jacfwd through diffrax) for six (body, ω, T), one compiled program."""
    box, th = BODIES["box"], BODIES["t_handle"]
    cases = [
        (th, _tilted(1, 2, 1.0, 2.0), 15.0),  # near the separatrix
        (th, _tilted(2, 0, 1.0, 20.0), 15.0),  # stable, largest axis
        (box, _tilted(0, 1, 1.0, 5.0), 50.0),  # 5° from the largest axis of the box ...
        (box, _tilted(0, 1, 1.0, 5.0), 500.0),
        (box, _tilted(0, 1, 1.0, 5.0), 3000.0),
        (box, _tilted(1, 0, 1.0, 1e-4), 10.0),  # 1e-4 rad from its intermediate axis
    ]
    mom, w, t = (jnp.asarray(np.stack([c[k] for c in cases])) for k in range(3))
    run = jax.jit(
        jax.vmap(lambda m, w, t: stability.ftle_simulate(m, w, t, rtol=1e-11, atol=1e-13))
    )
    return cases, np.asarray(run(mom, w, t))


def test_ftle_through_the_solver_matches_scipy_finite_differences(ftle_solver):
    cases, ftle = ftle_solver
    for (mom, w, t), got in list(zip(cases, ftle, strict=True))[:2]:
        assert got == pytest.approx(_euler_fd_ftle(mom, w, t), rel=1e-5, abs=1e-7)


def test_ftle_stable_near_zero_separatrix_positive(ftle_solver):
    _, ftle = ftle_solver
    s = np.sort(BODIES["box"])
    lam = math.sqrt((s[2] - s[1]) * (s[1] - s[0]) / (s[0] * s[2]))
    # stable: |J| grows at most linearly, so the FTLE decays like log(t)/t
    assert 0.0 <= ftle[4] < ftle[3] < ftle[2] < 0.1 * lam
    assert ftle[4] * 3000.0 < 2.0 * ftle[3] * 500.0  # logarithmic growth of log σ, not linear
    # near the separatrix, before the first flip (≈ (1/λ) ln(1/ε) ≈ 19): the saddle rate
    assert 0.8 * lam < ftle[5] < 1.05 * lam


# --------------------------------------------------------------------------- closed form


@settings(max_examples=30, deadline=None)
@given(
    st.floats(0.2, 0.95),
    st.floats(0.02, 0.95),
    st.integers(0, 2**31 - 1),
)
def test_polhode_lies_on_the_ellipsoid_and_the_sphere(i1, frac, seed):
    i2 = i1 + frac * (1.0 - i1)  # i1 < i2 < 1 = i3, and i1 + i2 > 1 not needed here
    mom = np.random.default_rng(seed).permutation([i1, i2, 1.0])
    w0 = np.random.default_rng(seed + 1).normal(size=3)
    curve = np.asarray(stability.polhode(mom, w0, 400))
    two_e, l2 = np.sum(mom * w0 * w0), np.sum((mom * w0) ** 2)
    np.testing.assert_allclose(np.sum(mom * curve**2, axis=1), two_e, rtol=1e-11)
    np.testing.assert_allclose(np.sum((mom * curve) ** 2, axis=1), l2, rtol=1e-11)
    # it passes through ω0 (up to the spacing of the points) and keeps the sign of ω_c
    assert np.min(np.linalg.norm(curve - w0, axis=1)) < 0.05 * np.linalg.norm(w0)
    c = int(stability.encircled_axis(mom, w0))
    assert np.all(np.sign(curve[:, c]) == np.sign(w0[c]))
    # ... and goes round axis c: both other components change sign along the curve
    for k in {0, 1, 2} - {c}:
        assert curve[:, k].min() < 0 < curve[:, k].max()


def test_polhode_family_covers_both_regions():
    mom = BODIES["box"]
    curves = np.asarray(stability.polhode_family(mom, levels=4, n=100))
    assert curves.shape == (18, 100, 3)
    two_e = np.sum(mom * curves**2, axis=2)
    np.testing.assert_allclose(two_e, 1.0, rtol=1e-12)
    l2 = np.sum((mom * curves) ** 2, axis=2)
    assert np.ptp(l2, axis=1).max() < 1e-12
    i_mid = np.median(mom)
    # curves 0..3 round the smallest axis, 4..7 the largest, 8 the separatrix
    assert np.all(l2[:4, 0] < i_mid) and np.all(l2[4:8, 0] > i_mid)
    assert l2[8, 0] == pytest.approx(i_mid, rel=1e-12)


@pytest.mark.parametrize("toward", ["largest", "smallest"])
@pytest.mark.parametrize("name", list(BODIES))
def test_flip_time_asymptote_against_mpmath(name, toward):
    mom = BODIES[name]
    a, b, c = np.sort(mom)
    mpmath.mp.dps = 40
    for eps in (1e-2, 1e-4):
        # exact 2K(m)/λ_m for ω = (sin ε or 0, cos ε, 0 or sin ε) in sorted axes, |ω| = 1
        e_ = mpmath.mpf(eps)
        w1, w2, w3 = (
            (0, mpmath.cos(e_), mpmath.sin(e_))
            if toward == "largest"
            else (mpmath.sin(e_), mpmath.cos(e_), 0)
        )
        A, B, C = (mpmath.mpf(float(x)) for x in (a, b, c))
        two_e = A * w1**2 + B * w2**2 + C * w3**2
        l2 = (A * w1) ** 2 + (B * w2) ** 2 + (C * w3) ** 2
        if l2 > two_e * B:
            lam = mpmath.sqrt((C - B) * (l2 - two_e * A) / (A * B * C))
            m = (B - A) * (two_e * C - l2) / ((C - B) * (l2 - two_e * A))
        else:
            lam = mpmath.sqrt((B - A) * (two_e * C - l2) / (A * B * C))
            m = (C - B) * (l2 - two_e * A) / ((B - A) * (two_e * C - l2))
        exact_t = float(2 * mpmath.ellipk(m) / lam)
        t, rate, const = stability.flip_time_asymptotic(mom, 1.0, eps, toward)
        assert float(rate) == pytest.approx(math.sqrt((c - b) * (b - a) / (a * c)), rel=1e-14)
        assert abs(float(t) / exact_t - 1) < 5 * eps**2 * (1 + abs(math.log(eps)))


def test_closed_form_helpers_in_float32(float32):
    d = stability.fibonacci_sphere(100)
    assert d.dtype == jnp.float32
    np.testing.assert_allclose(np.linalg.norm(np.asarray(d), axis=1), 1.0, atol=1e-6)
    mom = jnp.asarray(BODIES["box"], dtype=jnp.float32)
    w0 = jnp.asarray([0.3, 0.2, 0.9], dtype=jnp.float32)
    curve = np.asarray(stability.polhode(mom, w0, 64))
    assert curve.dtype == np.float32
    two_e = float(np.sum(np.asarray(mom) * np.asarray(w0) ** 2))
    np.testing.assert_allclose(np.sum(np.asarray(mom) * curve**2, axis=1), two_e, rtol=1e-5)


# --------------------------------------------------------------------------- lockstep


def test_lockstep_names_are_the_ensemble_schedules():
    """``lockstep_efficiency`` and ``difficulty_order`` live in ``jrigid.ensemble.schedule``
    (tests/test_ensemble_schedule.py); the old ``jrigid.stability`` names still work."""
    from jrigid.ensemble import schedule

    assert stability.lockstep_efficiency is schedule.lockstep_efficiency
    assert stability.difficulty_order is schedule.difficulty_order


def test_ftle_and_polhode_names_are_their_modules():
    from jrigid import ftle, polhode

    assert stability.ftle_exact is ftle.ftle_exact
    assert stability.ftle_simulate is ftle.ftle_simulate
    for name in polhode.__all__:
        assert getattr(stability, name) is getattr(polhode, name)


# --------------------------------------------------------------------------- experiments

NAMES = ("stability_map", "stability_bodies")


results, test_listed_and_writes_outputs = quick_suite(NAMES)


def test_stability_map_quick_shows_the_unstable_middle_axis(results):
    num, folder = results["stability_map"]
    assert num["all_succeeded"]
    assert num["classification_agreement"] == 1.0
    caps = num["cap_fraction_unstable"]
    assert caps["smallest"] == 0.0 and caps["largest"] == 0.0 and caps["intermediate"] == 1.0
    ftle = num["cap_ftle"]
    assert ftle["intermediate"]["median"] > 3 * max(
        ftle["smallest"]["median"], ftle["largest"]["median"]
    )
    assert list((folder / "chunks").rglob("chunk_*.npz")), "ensemble chunks not written"


def test_stability_map_quick_ftle_near_axes(results):
    num, _ = results["stability_map"]
    lam, ftle = num["saddle_rate_lambda"], num["cap_ftle"]
    # one rotation period: near the stable axes log(σ)/T stays small, near the middle
    # axis perturbations grow at close to the saddle rate λ
    assert ftle["smallest"]["max"] < 0.25 * lam and ftle["largest"]["max"] < 0.25 * lam
    assert 0.6 * lam < ftle["intermediate"]["median"] < 1.05 * lam


def test_bodies_quick_classify_the_axes_of_three_bodies(results):
    num, _ = results["stability_bodies"]
    bodies = np.asarray(num["bodies"])
    assert len(bodies) == 3 and np.min(np.diff(bodies[:, :2], axis=1)) < 0.05  # near-symmetric
    assert num["axis_checks"] == 36 and num["all_checks_succeeded"]
    assert num["axis_checks_middle_flips"] and num["axis_checks_others_never_flip"]
    assert num["axis_checks_agree_with_closed_form"]


def test_grouping_raises_lockstep_efficiency(results):
    num, _ = results["stability_bodies"]
    # members of very different length (step counts from a few hundred to ~10⁴), chunks of 8
    assert num["lockstep_efficiency_grouped"] > num["lockstep_efficiency_random_order"] + 0.15


def test_stability_bodies_quick_flip_period(results):
    num, _ = results["stability_bodies"]
    assert num["all_succeeded"] and num["min_crossings"] >= 2
    assert num["max_rel_error_simulated_vs_exact"] < 1e-5
    assert 1.7 < num["asymptotic_error_slope_vs_log_eps"] < 2.3
    assert num["max_rel_error_asymptotic_vs_exact"]["0.001"] < 1e-4


def test_encircled_axis_and_flips_expected_per_member():
    """A batch of ω gives one axis per member (the closed form L² − 2E I_mid of each)."""
    moments = jnp.array([1.0, 2.0, 3.0])
    omegas = jnp.array([[1.0, 0.0, 0.1], [0.1, 0.0, 1.0], [0.1, 1.0, 0.05]])
    axes = stability.encircled_axis(moments, omegas)
    np.testing.assert_array_equal(axes, [int(stability.encircled_axis(moments, w))
                                         for w in omegas])
    np.testing.assert_array_equal(axes, [0, 2, 0])  # L² − 2E I_mid: −0.99, 3.0, −0.0025
    np.testing.assert_array_equal(stability.flips_expected(moments, omegas),
                                  [False, False, True])
    with pytest.raises(ValueError, match="omega"):
        stability.encircled_axis(moments, jnp.ones(2))


def test_polhode_of_a_steady_rotation_is_its_point():
    """A sphere, or a symmetric body spun in the plane of its two largest (equal) moments,
    rotates steadily: the polhode is ω0 itself, not NaN."""
    for moments, w in (([1.0, 1.0, 1.0], [1.0, 0.3, 0.2]), ([1.0, 2.0, 2.0], [0.0, 0.3, 0.2])):
        curve = stability.polhode(jnp.array(moments), jnp.array(w), n=5)
        np.testing.assert_array_equal(curve, np.broadcast_to(w, (5, 3)))


def test_polhode_inputs_are_checked():
    good = jnp.array([1.0, 2.0, 3.0])
    w = jnp.array([1.0, 0.3, 0.2])
    with pytest.raises(ValueError, match="moments"):
        stability.polhode(jnp.array([1.0, 2.0]), w[:2])
    with pytest.raises(ValueError, match="one polhode"):
        stability.polhode(good, jnp.stack([w, w]))
    with pytest.raises(ValueError, match="not positive definite"):
        stability.polhode(jnp.array([-1.0, 2.0, 3.0]), w)
    with pytest.raises(ValueError, match="n must be"):
        stability.polhode(good, w, n=1)
    with pytest.raises(ValueError, match="spherical"):
        stability.polhode_family(jnp.ones(3))
    with pytest.raises(ValueError, match="direction must not be zero"):
        stability.omega_at_energy(jnp.zeros(3), good, 1.0)
    with pytest.raises(ValueError, match="energy"):
        stability.omega_at_energy(w, good, -1.0)


def test_ftle_of_a_failed_solve_is_nan_and_bad_horizons_are_refused():
    """A solve out of steps gave FTLE = -inf (its zero tangents): the most stable direction
    on a map. A horizon t <= 0 gave ±inf."""
    moments, w = jnp.array([1.0, 2.0, 3.0]), jnp.array([0.1, 1.0, 0.05])
    assert np.isnan(float(stability.ftle_simulate(moments, w, 10.0, max_steps=5)))
    for f in (stability.ftle_simulate, stability.ftle_exact):
        for t in (0.0, -10.0, float("nan")):
            with pytest.raises(ValueError, match="t must be a finite horizon"):
                f(moments, w, t)
        with pytest.raises(ValueError, match="triangle inequality"):
            f(jnp.array([1.0, 2.0, 4.0]), w, 1.0)
    # under vmap a bad member is NaN and its neighbours are computed (a sweep goes on): the
    # good member equals its value in a batch without the bad one (one compiled program,
    # the horizon an argument)
    ftle = jax.jit(jax.vmap(stability.ftle_exact, in_axes=(None, 0, None)))
    out = ftle(moments, jnp.stack([w, jnp.array([jnp.nan, 1.0, 0.0])]), 10.0)
    clean = ftle(moments, jnp.stack([w, jnp.array([0.05, 1.0, 0.1])]), 10.0)
    assert np.isnan(float(out[1])) and np.isfinite(float(clean[1]))
    assert float(out[0]) == pytest.approx(float(clean[0]), rel=1e-12)
    # an integer ω0 no longer truncates the horizon (0.5 became 0)
    tilted = jnp.array([[0, 1, 0], [1, 2, 0]])
    assert np.asarray(ftle(moments, tilted, 0.5)) == pytest.approx(
        np.asarray(ftle(moments, tilted.astype(float), 0.5)))


def test_flips_expected_of_steady_spins_and_degenerate_bodies_matches_simulation():
    """A sphere, an exact spin about the intermediate axis and a symmetric body spun in its
    equatorial plane rotate steadily (L² = 2E I_mid exactly): no flips expected, and the
    solver counts none; a symmetric body spun off its equator turns its equatorial axes
    over, which the closed form and the solver both see."""
    ts = jnp.linspace(0.0, 100.0, 1001)
    cases = [  # moments, ω0, flips expected
        ((1.0, 1.0, 1.0), (1.0, 0.01, 0.02), False),
        ((1.0, 2.0, 3.0), (0.0, 1.0, 0.0), False),
        ((1.0, 1.0, 2.0), (1.0, 0.0, 0.0), False),
        ((1.0, 1.0, 2.0), (1.0, 0.0, 0.1), True),
        ((1.0, 2.0, 3.0), (0.05, 1.0, 0.05), True),
    ]
    for moments, w, expected in cases:
        moments, w = jnp.array(moments), jnp.array(w)
        assert bool(stability.flips_expected(moments, w)) is expected, (moments, w)
        flips = int(stability.map_member(moments, w, ts, 1.0)["flips"])
        assert (flips > 0) is expected, (moments, w, flips)
    assert float(stability.separatrix_offset(jnp.array([1.0, 2.0, 3.0]),
                                             jnp.array([0.0, 1.0, 0.0]))) == 0.0


def test_a_failed_member_is_not_counted_stable_and_bad_settings_raise():
    """A solve that fails reported 0 flips (a stable direction on the map); settings no
    solve can run with were flagged per member instead of refused."""
    moments, w = jnp.array([1.0, 2.0, 3.0]), jnp.array([0.1, 1.0, 0.05])
    ts = jnp.linspace(0.0, 50.0, 101)
    out = stability.map_member(moments, w, ts, 1.0, max_steps=5)
    assert int(out["result"]) != 0 and int(out["flips"]) == -1
    assert np.isnan(float(out["first_flip"])) and np.isnan(float(out["max_axis_angle"]))
    for rtol in (-1.0, 0.0, 2.0):
        with pytest.raises(ValueError, match="rtol must be finite"):
            stability.map_member(moments, w, ts, 1.0, rtol=rtol)


@pytest.mark.parametrize("moments", [(1.0, 1.0, 2.0), (1.0, 2.0, 2.0), (1.0, 1.0, 1.0)])
def test_flip_intervals_need_distinct_moments(moments):
    """Two equal moments: no intermediate axis, no flip interval (was ±inf or NaN)."""
    with pytest.raises(ValueError, match="moments must be distinct"):
        stability.flip_time_asymptotic(jnp.array(moments), 1.0, 0.01)
    with pytest.raises(ValueError, match="moments must be distinct"):
        theory.flip_interval(jnp.array(moments), jnp.array([0.01, 1.0, 0.0]))


def test_a_non_finite_spin_encircles_no_axis():
    """A NaN ω gave axis 0 (the comparison with the separatrix was False) and so
    "flips expected": a plausible classification of no motion at all."""
    m = jnp.array([1.0, 2.0, 3.0])
    bad = jnp.array([jnp.nan, 1.0, 0.0])
    with pytest.raises(ValueError, match="omega must be finite"):
        stability.encircled_axis(m, bad)
    assert int(jax.jit(stability.encircled_axis)(m, bad)) == -1
    both = jnp.stack([bad, jnp.array([0.01, 1.0, 0.0])])
    flips = jax.vmap(lambda w: stability.flips_expected(m, w))(both)
    assert flips.tolist() == [False, True]
