"""The dynamics experiments of chapter 17 (issue 8, experiments 7-13 and 16), in quick mode.

Each experiment runs once per session through the command line (``jrigid run NAME --quick
--out DIR``); the tests read its ``numbers.json`` and check the chapter's claim against
closed-form theory (elliptic flip interval, precession rates of symmetric bodies, steady
precession roots of the heavy top) typed in or derived here. The torque-free quick runs share
one compiled :func:`jrigid.simulate` (same scene structure and 401 output samples).
Simulations run at ``rtol = 1e-8`` or tighter, so integration errors are ~1e-7 relative at
worst; the tolerances below are set by the measurement (sampling, line fits, nutation), each
justified where it is used.
"""

import math

import numpy as np
import pytest
from _experiments import quick_suite
from scipy import special as sps

NAMES = (
    "dzhanibekov",
    "body_frame",
    "symmetric_precession",
    "free_rotation",
    "thin_rod",
    "feynman_plate",
    "gyroscope",
    "euler_angle_gyroscope",
    "spinning_top",
)


results, test_listed_and_writes_outputs = quick_suite(NAMES)


# --------------------------------------------------------------------------- 16. dzhanibekov


def test_dzhanibekov_flip_interval(results):
    n, folder = results["dzhanibekov"]
    assert n["intermediate_axis_index"] == 1 and n["flips_seen"] >= 2
    # 2K/λ (theory.flip_theory) and half the closed-form period (jrigid.exact) are two
    # independent evaluations of the same number: agree to roundoff of K near m -> 1
    assert n["flip_interval_exact_solution"] == pytest.approx(n["flip_interval_theory"], rel=1e-9)
    # zero crossings are located by linear interpolation between samples spaced
    # ~0.02 s on a sine-like ω2: the error is O(dt³ ω'''/ω') ~ 1e-7 of the interval
    assert n["flip_interval_measured"] == pytest.approx(n["flip_interval_theory"], rel=1e-5)
    np.testing.assert_allclose(
        n["sweep_flip_interval_measured"], n["sweep_flip_interval_theory"], rtol=1e-5
    )
    # the simulated motion follows the closed form (rtol 1e-10 run: errors ~1e-8)
    assert n["omega_vs_exact_max_rel_error"] < 1e-6
    assert n["q_vs_exact_max_angle"] < 1e-6
    # interval ~ (2/λ0) ln(1/ε) + const near the separatrix; the fit over ε = 0.3°..3° has
    # O(ε²) corrections of a few per cent
    assert n["sweep_slope_vs_log_inverse_tilt"] == pytest.approx(
        n["slope_theory_2_over_growth"], rel=0.05
    )
    assert n["energy_rel_drift"] < 1e-8 and n["L_norm_rel_drift"] < 1e-8
    assert (folder / "t_handle.gif").is_file()


# --------------------------------------------------------------------------- 7. body_frame


def test_body_frame_stability(results):
    n, _ = results["body_frame"]
    m = n["moments"]
    assert m[0] < m[1] < m[2]
    small, middle, large = n["max_deviation_deg"]
    eps = n["tilt_deg"]
    # linear theory: about a stable axis the polhode is an ellipse whose semi-axes differ
    # by sqrt(I_j (I_k - I_j) / (I_l (I_k - I_l))) ~ 1.2 here, so ω stays within ~1.2 ε; 3 ε
    # leaves room without letting a slow instability pass
    assert small < 3 * eps and large < 3 * eps
    # the starting tilt itself is the lower bound of the wander
    assert small >= 0.99 * eps and large >= 0.99 * eps
    # about the intermediate axis ω turns over (nearly 180° after one flip interval)
    assert middle > 90.0
    assert n["duration"] > 2 * n["flip_interval_theory"]
    # rtol 1e-8 integration: E and |L| to ~1e-7
    assert n["energy_rel_drift"] < 1e-6 and n["L_norm_rel_drift"] < 1e-6


# ---------------------------------------------------------------- 9. symmetric_precession


def test_symmetric_precession_rate(results):
    n, _ = results["symmetric_precession"]
    I1, I2, I3 = n["moments"]
    assert I1 == I2
    # (17.47) typed in here: Ω = (I3/I1 − 1) |ω| cos α with the default |ω| = 6
    omega3 = 6.0 * math.cos(math.radians(n["alpha_deg"]))
    assert n["precession_rate_theory"] == pytest.approx((I3 / I1 - 1) * omega3, rel=1e-12)
    # the fitted slope of an exactly linear phase: limited by the rtol 1e-8 integration
    assert n["precession_rate_measured"] == pytest.approx(n["precession_rate_theory"], rel=1e-6)
    # ω3 constant, |ω⊥| constant, phase uniform: ω1, ω2 are sinusoids 90° apart
    assert n["omega3_spread"] < 1e-6 and n["omega_perp_rel_spread"] < 1e-6
    assert n["phase_residual_max"] < 1e-6
    r = np.asarray(n["sweep_I3_over_I1"])
    np.testing.assert_allclose(n["sweep_rate_theory"], (r - 1) * omega3, rtol=1e-12)
    np.testing.assert_allclose(n["sweep_rate_measured"], n["sweep_rate_theory"], rtol=1e-6)
    # prolate bodies (I3 < I1) precess backwards
    assert np.all(np.sign(n["sweep_rate_measured"]) == np.sign(r - 1))


# --------------------------------------------------------------------------- 10. free_rotation


def test_free_rotation(results):
    n, _ = results["free_rotation"]
    # exact spin about any principal axis is steady (ω × Iω = 0): only integration error
    # (rtol 1e-8 on |ω| = 2) remains
    assert max(n["steady_omega_max_error"]) < 1e-6
    eps = n["tilt_deg"]
    small, middle, large = n["perturbed_axis_from_L_max_deg"]
    # stable axes: the axis starts atan((I_j/I_k) tan ε) <= 2ε from L (I2/I1 = 2 for the
    # block) and the polhode ellipse widens that by < 30 %: 5ε is a safe "small"
    assert small < 5 * eps and large < 5 * eps
    # the unstable axis swings to the far side of the sphere
    assert middle > 90.0
    # the body-frame solution (Problem 17.3) and the quaternion model agree; on the
    # unstable axis integration errors (~1e-8) are amplified by e^{λt} ~ 1e2 over two flips
    assert n["body_omega_vs_quaternion_max_error"] < 1e-4
    # I1 = I2 = I3: ω constant (Problem 17.6, last part)
    assert n["sphere_omega_max_error"] < 1e-6
    # Exercise 17.12: same wobble-to-spin ratio as the Feynman plate model. Against theory:
    # rtol 1e-10 quaternion run, line fit over 2.5 wobbles (1e-8); the leapfrog has an O(dt²)
    # rate error, (ω dt)² ~ 1.6e-4 at dt = 2e-3 for ω ~ 2π
    assert n["plate_ratio_free_rotation"] == pytest.approx(n["plate_ratio_theory"], rel=1e-7)
    assert n["plate_ratio_leapfrog"] == pytest.approx(n["plate_ratio_theory"], rel=2e-4)
    assert n["plate_leapfrog_vs_free_rotation_max_angle"] < 1e-3


# --------------------------------------------------------------------------- 11. thin_rod


def test_thin_rod(results):
    n, _ = results["thin_rod"]
    I1, I2, I3 = n["moments"]
    # Table 17.1 solid cylinder typed in: ℓ = 1, r = 0.02, m = 1
    assert I1 == pytest.approx((3 * 0.02**2 + 1.0) / 12, rel=1e-12)
    assert I3 == pytest.approx(0.02**2 / 2, rel=1e-12)
    # L fixed in space, ω3 constant (rtol 1e-8 run)
    assert n["L_space_max_rel_change"] < 1e-6 and n["omega3_spread"] < 1e-6
    # ... though L is far from parallel to ω
    assert n["angle_L_omega_deg"] > 30.0
    # ω precesses about the rod's axis at (I3/I1 − 1) ω3 (ω3 = 3): nearly −ω3 for a thin
    # rod. Slope of an exactly linear phase: rtol-limited, 1e-6 is ample
    assert n["body_precession_theory"] == pytest.approx((I3 / I1 - 1) * 3.0, rel=1e-12)
    assert n["body_precession_measured"] == pytest.approx(n["body_precession_theory"], rel=1e-6)
    assert n["space_precession_measured"] == pytest.approx(n["space_precession_theory"], rel=1e-6)
    ratio = np.asarray(n["sweep_I3_over_I1"])
    np.testing.assert_allclose(n["sweep_body_theory"], (ratio - 1) * 3.0, rtol=1e-12)
    np.testing.assert_allclose(n["sweep_body_measured"], n["sweep_body_theory"], rtol=1e-6)
    np.testing.assert_allclose(n["sweep_space_measured"], n["sweep_space_theory"], rtol=1e-6)
    # a thicker rod (larger I3/I1) precesses more slowly in the body frame
    assert np.all(np.diff(np.abs(n["sweep_body_measured"])) < 0)


# --------------------------------------------------------------------------- 8. feynman_plate


def test_feynman_plate(results):
    n, folder = results["feynman_plate"]
    I1, _, I3 = n["moments"]
    th = math.radians(n["theta_deg"])
    # theory typed in: |φ̇/ψ̇| = I3/((I3 − I1) cos θ), and the thin-plate 2/cos θ
    assert n["ratio_theory"] == pytest.approx(I3 / ((I3 - I1) * math.cos(th)), rel=1e-12)
    assert n["ratio_thin_2_over_cos"] == pytest.approx(2 / math.cos(th), rel=1e-12)
    # adaptive run (rtol 1e-10): the line fits of exactly linear angles agree to ~1e-10
    assert n["ratio_adaptive"] == pytest.approx(n["ratio_theory"], rel=1e-7)
    np.testing.assert_allclose(n["sweep_ratio_measured"], n["sweep_ratio_theory"], rtol=1e-7)
    # small wobble -> 2: at θ = 3° the ratio is within 0.5 % of 2 (1/cos 3° = 1.0014 and the
    # thickness factor 1/(1 − h²/3r²) = 1.0033)
    assert n["sweep_ratio_measured"][0] == pytest.approx(2.0, rel=5e-3)
    # ... and grows as 1/cos θ: at 60° it is ~4, a physical effect, not an error
    assert n["sweep_ratio_measured"][-1] > 3.9
    # leapfrog, midpoint: orientation error O(dt²) (fit over dt = 4e-3..1e-3 gives 2.00);
    # the chapter's literal listing is first order
    assert n["leapfrog_q_error_order"]["midpoint"] == pytest.approx(2.0, abs=0.15)
    assert n["leapfrog_q_error_order"]["chapter"] == pytest.approx(1.0, abs=0.15)
    # its ratio error is O(dt²) too: (ω dt)² ~ 4e-5 at dt = 1e-3
    assert n["ratio_leapfrog_midpoint"] == pytest.approx(n["ratio_theory"], rel=1e-4)
    # conservation: the adaptive run to its tolerance; the torque-free leapfrog keeps L to
    # roundoff (every kick is zero) while its energy error shrinks at least as dt²
    assert n["adaptive_energy_drift"] < 1e-8 and n["adaptive_L_drift"] < 1e-8
    for run in n["leapfrog"].values():
        assert run["L_drift"] < 1e-12
    assert n["leapfrog_midpoint_energy_error_order"] > 1.8
    assert n["leapfrog"]["midpoint_0.001"]["energy_drift"] < 1e-6
    # the symmetric plate does not nutate
    assert n["plate_nutation_ptp_deg"] < 1e-5
    # c. a thin tray: the same 2:1 at small tilt (first-order theory for any thin flat body:
    # body-frame ω precesses at ω3 √((I3−I1)(I3−I2)/(I1 I2)) = ω3 because I3 = I1 + I2);
    # tilt ~4° gives O(θ²) ~ 1 % corrections; but θ nutates (elliptical wobble)
    assert n["tray_ratio"] == pytest.approx(2.0, rel=0.02)
    assert n["tray_nutation_ptp_deg"] > 0.5 * n["tray_theta_mean_deg"]
    # d. spun near a diameter: no 2:1 wobble; measured against the symmetric-top theory
    assert n["diameter_theta_deg"] > 45
    assert n["diameter_ratio_measured"] == pytest.approx(n["diameter_ratio_theory"], rel=1e-7)
    assert n["diameter_ratio_measured"] > 4
    assert (folder / "plate.gif").is_file()


# --------------------------------------------------------------------------- 12. gyroscope


def test_gyroscope(results):
    n, _ = results["gyroscope"]
    I1, _, I3 = n["moments_about_pivot"]
    # chapter's top typed in: ellipsoid semi-axes (1, 1, 0.1), M = 1, z0 = 1, about the pivot
    assert I1 == pytest.approx((1 + 0.01) / 5 + 1.0, rel=1e-12)
    assert I3 == pytest.approx(2 / 5, rel=1e-12)
    th, w3, mgl = math.radians(n["theta0_deg"]), n["omega3"], n["mgl"]
    for name in ("slow", "fast"):
        r = n[name]
        # the rates are roots of I1 Ω² cos θ − I3 ω3 Ω + M g l = 0
        om = r["rate_exact"]
        assert I1 * om**2 * math.cos(th) - I3 * w3 * om + mgl == pytest.approx(0, abs=1e-9)
        # started on the root: uniform precession at that rate, no nutation (only the
        # integration error, rtol 1e-8, remains: θ constant to ~1e-8 rad)
        assert r["rate_measured"] == pytest.approx(om, rel=1e-6)
        assert r["theta_ptp"] < 1e-6
        assert r["energy_drift"] < 1e-6 and r["Lz_drift"] < 1e-6
    # (17.51b) and (17.51a) approximate the roots to O(4 I1 Mgl cos θ/(I3 ω3)²) ~ 2 %
    assert n["slow"]["rate_approx"] == pytest.approx(mgl / (I3 * w3), rel=1e-12)
    assert n["fast"]["rate_approx"] == pytest.approx(I3 * w3 / (I1 * math.cos(th)), rel=1e-12)
    for name in ("slow", "fast"):
        assert n[name]["rate_exact"] == pytest.approx(n[name]["rate_approx"], rel=0.03)
    assert n["fast"]["rate_exact"] > 50 * n["slow"]["rate_exact"]
    # released with φ̇ = 0: nutation. Fast-top theory holds to O(ε), ε = Mgl I1/(I3 ω3)² ≈ 2 %
    nut = n["nutation"]
    assert nut["frequency_measured"] == pytest.approx(nut["frequency_fast_top"], rel=0.05)
    assert nut["dip_measured"] == pytest.approx(nut["dip_fast_top"], rel=0.08)
    assert nut["dip_measured"] > 1e3 * n["slow"]["theta_ptp"]
    assert nut["mean_rate_measured"] == pytest.approx(nut["mean_rate_slow"], rel=0.03)
    assert nut["energy_drift"] < 1e-6 and nut["L3_drift"] < 1e-6


# ---------------------------------------------------------------- 13. euler_angle_gyroscope


def test_euler_angle_gyroscope(results):
    n, _ = results["euler_angle_gyroscope"]
    # two formulations, each at rtol 1e-8 over ~6 nutations of a spin of 20 rad/s: they
    # agree to ~1e-6 rad in orientation (spin phase), far better in θ
    assert n["q_euler_vs_quaternion_max_angle"] < 1e-5
    assert n["theta_euler_vs_quaternion_max"] < 1e-6
    # the fast-top solution is first order in ε ≈ 0.019: amplitude and frequency off by
    # O(ε) each, so over one nutation the θ error is a few ε of the dip (measured 3.2 ε)
    eps = n["epsilon"]
    assert n["theta_vs_fast_top_max_over_dip"] < 5 * eps
    assert n["phi_vs_fast_top_max_over_advance"] < 5 * eps
    # near θ = 0: quaternions pass the vertical (sampled minimum within 0.1°) ...
    assert n["flip_quaternion_success"] and n["flip_quaternion_min_theta_deg"] < 0.1
    # ... the Euler-angle run reports gimbal lock there, not garbage
    assert n["flip_euler_result"] == 4 and n["flip_euler_result_name"] == "gimbal_lock"
    assert n["flip_euler_t_stop"] < 0.5 * n["flip_euler_t_end"]
    # it stops where the axle reaches the vertical (within a few output samples,
    # spacing t_end/400, and the |sin θ| < 1e-3 threshold)
    assert n["flip_euler_t_stop"] == pytest.approx(n["flip_quaternion_time_of_min"], abs=0.01)
    assert n["flip_euler_outputs_after_stop_nan"]
    assert "gimbal lock" in n["flip_euler_error_message"]


# --------------------------------------------------------------------------- spinning_top


def test_spinning_top_closed_form(results):
    """Problem 17.2: the closed-form top equals the integrated one; released with φ̇0 = θ̇0 = 0
    (the defaults) its axle starts at the top of its swing and traces cusps."""
    n, _ = results["spinning_top"]
    # the integrated run has rtol 1e-10: the two agree far below the 1e-7 the run asserts
    assert n["q_closed_vs_integrated_max_rad"] < 1e-7
    assert n["omega_closed_vs_integrated_max_rel"] < 1e-7
    assert n["locus"] == "cusps" and abs(n["b_minus_a_u2"]) < 1e-12
    # released at rest at θ0, u = cos θ swings between u0 and the lower root u1 of
    # β(u0 − u)(u − u1)(u3 − u) (a = I3 ω3/I1, β = 2Mgl/I1, I1 about the pivot), with
    # period 2K(m)/ω_n, m = (u0 − u1)/(u3 − u1), ω_n = ½√(β(u3 − u1)) (scipy's K)
    i1, _, i3 = n["moments_about_pivot"]
    a, beta = i3 * n["omega3"] / i1, 2.0 * n["mgl"] / i1
    u0, s2 = math.cos(math.radians(n["tilt_deg"])), math.sin(math.radians(n["tilt_deg"])) ** 2
    p = a * a - 2.0 * beta * u0
    root = math.sqrt(p * p + 4.0 * beta * beta * s2)
    drop, spread = 2.0 * beta * s2 / (p + root), root / beta  # u0 − u1, u3 − u1
    period = 2.0 * sps.ellipk(drop / spread) / (0.5 * math.sqrt(beta * spread))
    assert n["nutation_period_closed_form"] == pytest.approx(period, rel=1e-12)
    assert n["theta_min_deg_closed_form"] == pytest.approx(n["tilt_deg"], abs=1e-9)
    theta_max = math.degrees(math.acos(u0 - drop))
    assert n["theta_max_deg_closed_form"] == pytest.approx(theta_max, abs=1e-9)
    # measured on the integrated run: crossings of the mid angle (linear interpolation,
    # ~100 samples per period) and the sampled extremes (off by at most θ̈ Δt²/8 ≈ 1e-3°)
    assert n["nutation_period_measured"] == pytest.approx(period, rel=1e-6)
    assert n["theta_max_deg_measured"] == pytest.approx(theta_max, abs=2e-3)
    # the closed form keeps energy, L_z and L·e3 to rounding
    assert max(n["energy_drift_closed_form"], n["Lz_drift_closed_form"]) < 1e-13
    assert n["L3_drift_closed_form"] < 1e-13
