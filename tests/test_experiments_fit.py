"""The parameter-inference experiments (issue 5, experiments 1-4), in quick mode.

Each experiment runs once per session through the command line (``jrigid run NAME --quick
--out DIR``); the tests read its ``numbers.json`` and check its claim: recovery within 3σ
(a seeded run), noise-free recovery, Laplace σ against the delta-method formula, how the
error scales with noise and record length, and the agreement of reverse-mode,
forward-mode, finite-difference and exact derivatives.
"""

import math

import numpy as np
import pytest
from _experiments import quick_suite

NAMES = ("fit_spin", "fit_tumbling", "fit_plate", "autodiff_sensitivity")


results, test_listed_and_writes_outputs = quick_suite(NAMES)


def test_fit_spin_recovers_tilt_and_spin_within_three_sigma(results):
    n, _ = results["fit_spin"]
    assert n["reason"] in ("gtol", "ftol")
    est, true, sig = (np.asarray(n[k]) for k in ("estimate", "truth", "sigma"))
    assert np.all(sig > 0)
    assert n["within_3_sigma"] and np.all(np.abs(est - true) < 3 * sig)
    # χ² of a right model with the true noise: dof ± 5 standard deviations
    assert abs(n["chi2"] - n["dof"]) < 5 * math.sqrt(2 * n["dof"])


def test_fit_tumbling_error_shrinks_with_length_and_grows_with_noise(results):
    n, _ = results["fit_tumbling"]
    est, true, sig = (np.asarray(n[k]) for k in ("estimate", "truth", "sigma"))
    assert n["within_3_sigma"] and np.all(np.abs(est - true) < 3 * sig)
    assert np.sum(true[:3]) == pytest.approx(1.0) and np.sum(est[:3]) == pytest.approx(1.0)
    sweep = n["sweep"]
    assert all(x["converged"] and x["within_3_sigma"] for x in sweep)
    lengths = sorted({x["duration"] for x in sweep})
    noises = sorted({x["sigma"] for x in sweep})
    assert len(lengths) >= 2 and len(noises) >= 2
    by = {(x["duration"], x["sigma"]): x["max_moment_sigma"] for x in sweep}
    for s in noises:  # a longer record constrains the ratios better
        assert by[lengths[-1], s] < by[lengths[0], s]
    for d in lengths:  # Laplace σ is linear in the noise (same data geometry)
        ratio = by[d, noises[-1]] / by[d, noises[0]]
        assert ratio == pytest.approx(noises[-1] / noises[0], rel=0.15)


def test_fit_plate_recovers_thickness_and_loses_it_when_thin(results):
    n, _ = results["fit_plate"]
    assert n["noise_free_error"] < 1e-6
    # Laplace σ equals the delta method of x = sqrt(3 (1 − 2/(R cos θ)))
    assert n["noise_free_sigma"] == pytest.approx(n["noise_free_sigma_theory"], rel=1e-6)
    sweep = sorted(n["sweep"], key=lambda s: s["thickness"])
    for s in sweep:
        assert s["noise_free_estimate"] == pytest.approx(s["thickness"], rel=1e-6)
        assert s["sigma_laplace"] == pytest.approx(s["sigma_theory"], rel=1e-6)
    # thin plates: the ratio flattens to 2/cos θ and σ_x grows like 1/x
    thin, next_ = sweep[0], sweep[1]
    assert thin["ratio"] == pytest.approx(n["ratio_thin_2_over_cos"], rel=1e-4)
    x1, x2 = thin["thickness"], next_["thickness"]
    scaled = (thin["sigma_laplace"] * x1) / (next_["sigma_laplace"] * x2)
    assert scaled == pytest.approx(1.0, rel=0.02)
    assert thin["sigma_laplace"] > thin["thickness"]  # unconstrained below the floor
    assert sweep[-1]["sigma_laplace"] < 0.01 * sweep[-1]["thickness"]
    assert x1 < n["thickness_floor"] < sweep[-1]["thickness"]
    assert n["resolvable_runs"] >= 3
    assert n["resolvable_within_3_sigma"] == n["resolvable_runs"]


def test_autodiff_sensitivity_methods_agree_and_sensitivity_grows(results):
    n, _ = results["autodiff_sensitivity"]
    worst = n["worst_rel_error_vs_exact"]
    # forward mode and finite differences against the exact solver's derivative
    assert worst["forward"] < 1e-3 and worst["finite differences"] < 1e-3
    assert worst["reverse, checkpoint every step"] < 1e-3 and worst["reverse"] < 1e-3
    sweep = sorted(n["sweep"], key=lambda s: -s["eps"])
    sens = np.array([s["sensitivity_exact"] for s in sweep])
    period = np.array([s["period"] for s in sweep])
    assert np.all(np.diff(period) > 0) and np.all(np.diff(sens) > 0)
    # the growth is linear in T(ε) ∝ log(1/ε)
    slopes = np.diff(sens) / np.diff(period)
    assert np.ptp(slopes) < 0.2 * np.mean(slopes)
    for s in sweep:
        assert s["scale_invariance_exact"] < 1e-8  # Σ I_k ∂q/∂I_k = 0
        assert s["scale_invariance_forward"] < 1e-6
    rows = n["tolerance_study"]["rows"]
    for r in rows:  # reverse, with or without recomputation, is forward mode's transpose
        assert r["reverse_every_step_vs_forward"] < 1e-8
        # Known defect: below rtol 1e-8 the default reverse pass recomputes some steps
        # with other rounding and differentiates a slightly different path (7e-7 at
        # rtol 1e-11; see the experiment's docstring). Held here so it cannot grow.
        assert r["reverse_vs_forward"] < (1e-8 if r["rtol"] >= 1e-8 else 2e-6)
    # both converge to the exact derivative as the tolerance shrinks
    assert rows[-1]["forward_vs_exact"] < 1e-2 * rows[0]["forward_vs_exact"]
    assert rows[-1]["reverse_every_step_vs_exact"] < 1e-2 * rows[0]["reverse_every_step_vs_exact"]
