"""The projects of chapter 17 on motion with translation (17.1 and 17.3), in quick mode.

Each experiment runs once through the command line (``jrigid run NAME --quick``); the
tests read its ``numbers.json`` and check it against closed forms derived in the
experiment's docstring (the rotating-frame path and the Coriolis deflection) and against
the conservation laws an impulse must obey. Tolerances are justified where used.
"""

import numpy as np
import pytest
from _experiments import quick_suite

NAMES = ("rotating_frame", "falling_box")


results, test_listed_and_writes_outputs = quick_suite(NAMES)


# --------------------------------------------------------------------------- 17.1


def test_rotating_frame_deflection_matches_theory(results):
    n, _ = results["rotating_frame"]
    # Tsit5 (order 5) integrates the parabola exactly up to roundoff and the frame change
    # is a rotation: the simulated landing offset equals the closed form to ~1e-14 m;
    # 1e-9 relative leaves room for rtol = 1e-10 step control without hiding a sign error
    assert n["deflection_simulated"] == pytest.approx(n["deflection_exact"], rel=1e-9)
    np.testing.assert_allclose(
        n["sweep_deflection_simulated"], n["sweep_deflection_exact"], rtol=1e-9
    )
    assert n["deflection_exact"] > 0  # counter-clockwise platform: to the thrower's right
    assert n["path_vs_exact_max"] < 1e-9
    # the rotating-frame equation of motion (Coriolis + centrifugal) by scipy DOP853 at
    # rtol 1e-11 over ~1 s of flight: path errors ~1e-10 m
    assert n["path_vs_rotating_eom_max"] < 1e-8
    assert n["affine_vs_quaternion_max"] < 1e-12
    assert abs(n["landing_height"]) < 1e-9


def test_rotating_frame_small_omega_limit(results):
    n, _ = results["rotating_frame"]
    T, R, u = n["flight_time"], n["radius"], n["speed"]
    for om, exact, small in zip(
        n["sweep_omega"], n["sweep_deflection_exact"], n["sweep_deflection_small_omega"],
        strict=True,
    ):
        theta = om * T
        assert small == pytest.approx(om * u * T**2, rel=1e-12)
        if theta < 0.1:
            # Ω u T² / exact − 1 = θ² (1/6 + R/(3uT)) + O(θ⁴): at θ < 0.1 the O(θ⁴) part is
            # below 3 % of the θ² part for these R, u, T
            second = theta**2 * (1 / 6 + R / (3 * u * T))
            assert small / exact - 1 == pytest.approx(second, rel=0.03)
    # at the default Ω the second-order estimate is within 10 % of the actual error
    assert n["small_omega_rel_error"] == pytest.approx(n["second_order_rel_prediction"], rel=0.1)


# --------------------------------------------------------------------------- 17.3


@pytest.mark.parametrize("dim", ["2d", "3d"])
def test_falling_box_elastic_conserves_energy(results, dim):
    n = results["falling_box"][0][f"{dim}_elastic"]
    assert n["status"] == "t_end" and n["bounces"] >= 3
    # e = 1, μ = 0: each impulse conserves kinetic energy exactly (roundoff ~1e-15 J);
    # between bounces rtol = 1e-10 integration and a 1e-10 floor lift per bounce
    assert n["bounce_energy_change_max"] < 1e-12
    assert n["energy_rel_drift"] < 1e-7
    # frictionless impulses are vertical: horizontal momentum unchanged
    assert n["horizontal_momentum_change_max"] < 1e-13
    assert n["Lz_drift"] < 1e-8  # no torque about the vertical
    # contacts are found at contact_tol = 1e-10 below the floor by bisection (to ± 5e-11,
    # or a few 1e-10 when it runs out of iterations); the body is then lifted back
    assert n["max_depth"] < 1e-9


@pytest.mark.parametrize("case", ["2d_elastic", "3d_elastic", "2d_dissipative", "3d_dissipative"])
def test_falling_box_impulses_obey_restitution_and_momentum_balance(results, case):
    n = results["falling_box"][0][case]
    assert n["single_impulse_bounces"] >= 3
    # normal velocity of the contact corner reversed and scaled by e (exact algebra)
    assert n["restitution_ratio_max_error"] < 1e-9
    # angular momentum about the contact point is unchanged by an impulse there
    assert n["L_contact_change_max"] < 1e-12


@pytest.mark.parametrize("dim", ["2d", "3d"])
def test_falling_box_dissipative_loses_energy(results, dim):
    n = results["falling_box"][0][f"{dim}_dissipative"]
    assert n["energy_lost_per_bounce_mean"] > 0
    assert n["energy_end"] < 0.5 * n["energy_start"]
    assert n["horizontal_momentum_change_max"] > 1e-3  # friction acts
    assert n["status"] in ("resting", "t_end")
    assert not list(results["falling_box"][1].glob("*.gif"))  # no GIF in quick mode
