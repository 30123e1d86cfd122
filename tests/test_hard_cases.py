"""The hard cases of ``benchmarks/hard_cases.py`` at small size, each asserting its check.

References are independent of the code under test: a 30-digit closed form
(``MpRigidBody`` of ``tests/test_exact.py``), classical formulae evaluated with scipy's
elliptic functions (periods, the top's nutation), scipy ``solve_ivp`` on the published
equations written out literally, and ``scipy.special.ellipj``.
"""

from __future__ import annotations

import pathlib
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import special as sps
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

BENCH = pathlib.Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCH))
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

import hard_cases as hc  # noqa: E402
import harness  # noqa: E402
import work_precision as wp  # noqa: E402
from test_exact import MpRigidBody  # noqa: E402

from jrigid import exact  # noqa: E402
from jrigid.integrate import SimulationError, simulate  # noqa: E402
from jrigid.leapfrog import leapfrog  # noqa: E402
from jrigid.state import Kinematics  # noqa: E402

N = 1001  # output times of every sampled solve here (one compilation per scene kind)
EPS = np.finfo(np.float64).eps


def _ts(case, t1=None):
    t1 = hc.horizon(case, "small") if t1 is None else t1
    return np.linspace(0.0, t1, N)


def _simulate(case, ts, formulation="quaternion_acceleration", rtol=1e-10):
    prob = hc.problem(case, "small")
    traj = simulate(prob.scene(), prob.state(), jnp.asarray(ts), formulation=formulation,
                    rtol=rtol, atol=1e-2 * rtol, max_steps=1_000_000)
    return np.asarray(traj.q, float), np.asarray(traj.omega, float)


def _exact(case, ts):
    """``jrigid.exact`` at ``ts`` (at most N times; padded to N, so one compilation)."""
    state = hc.initial_state(case)
    ts = np.asarray(ts)
    k = ts.shape[0]
    padded = np.concatenate([ts, np.zeros(N - k, ts.dtype)])
    q, w = exact.solve(jnp.asarray(case.moments), state.q, jnp.asarray(case.omega0),
                       jnp.asarray(padded, dtype=state.q.dtype))
    return np.asarray(q, float)[:k], np.asarray(w, float)[:k]


def _rot_error(q, rot):
    return np.max(np.abs(Rotation.from_quat(q, scalar_first=True).as_matrix() - rot))


# --------------------------------------------------------------------------- the suite


def test_suite_has_every_case_at_two_sizes():
    numbers = {c.number for c in hc.CASES.values()}
    assert numbers == {"1", "2", "3", "4", "5", "6", "7", "8", "B5", "HNW"}
    assert sorted(c.eps for c in hc.CASES.values() if c.number == "2") == [1e-6, 1e-4, 1e-2]
    assert {c.spin_ratio for c in hc.CASES.values() if c.number == "5"} == {20.0, 100.0}
    assert {c.key for c in hc.CASES.values() if c.dtype == "float32"} == {
        "general_f32", "separatrix_1e-2_f32", "long_horizon_f32"}
    near = hc.CASES["nearly_symmetric"].moments
    assert near[0] == pytest.approx(near[1] * (1 - 1e-10), rel=1e-15, abs=0)
    long = hc.CASES["long_horizon"]
    assert hc.horizon(long) == pytest.approx(1e4 * hc.free_period(long.moments, long.omega0))
    for case in hc.CASES.values():
        assert 0 < hc.horizon(case, "small") <= hc.horizon(case, "full")
        if case.torque_free:  # L along space z keeps ZXZ angles off gimbal lock
            state = hc.initial_state(case)
            L = Rotation.from_quat(np.asarray(state.q), scalar_first=True).apply(
                np.asarray(case.moments) * np.asarray(case.omega0))
            np.testing.assert_allclose(L[:2], 0.0, atol=1e-13 * np.linalg.norm(L))
    with pytest.raises(ValueError, match="size"):
        hc.horizon(long, "huge")


@pytest.mark.parametrize("key", [k for k, c in hc.CASES.items() if c.torque_free])
def test_classical_period_matches_exact_solver(key):
    case = hc.CASES[key]
    state = hc.initial_state(case)
    consts = exact.prepare(jnp.asarray(case.moments), state.q, jnp.asarray(case.omega0))
    assert float(exact.omega_period(consts)) == pytest.approx(
        hc.free_period(case.moments, case.omega0), rel=1e-12)


# --------------------------------------------------------------------------- cases 1–4


@pytest.mark.parametrize("key", ["general", "separatrix_1e-2", "separatrix_1e-4",
                                 "separatrix_1e-6", "nearly_symmetric", "thin_rod"])
def test_exact_solver_meets_1e_12_on_cases_1_to_4(key):
    case = hc.CASES[key]
    state = hc.initial_state(case)
    mp_body = MpRigidBody(case.moments, np.asarray(state.q), case.omega0)
    t1 = hc.horizon(case, "small")
    ts = np.array([0.31, 0.77, 1.0]) * t1
    q, w = _exact(case, ts)
    ref = hc.reference(case, "small")  # the suite's reference at the horizon
    for k, t in enumerate(ts):
        rot, w_ref = mp_body.at(t)
        assert _rot_error(q[k], rot) < 1e-12
        assert np.max(np.abs(w[k] - w_ref)) < 1e-12 * np.linalg.norm(case.omega0)
    # the suite's reference starts from the state's own ω (2 q* ⊗ q̇, rounded), as the
    # methods under test do: near the separatrix it differs from omega0 enough to matter
    rot, w_ref = MpRigidBody(case.moments, np.asarray(state.q), np.asarray(state.omega)).at(t1)
    assert _rot_error(ref["q"], rot) < 1e-12
    assert np.max(np.abs(ref["omega"] - w_ref)) < 1e-12 * np.linalg.norm(case.omega0)


@pytest.mark.parametrize("key", ["separatrix_1e-2", "separatrix_1e-4", "separatrix_1e-6"])
def test_time_between_flips_matches_exact_value(key):
    """Case 2: ω2 of the exact solver flips every 2K(m)/λ (classical formula, scipy K)."""
    case = hc.CASES[key]
    half = 0.5 * hc.free_period(case.moments, case.omega0)
    t1 = hc.horizon(case, "small")
    flips = hc.flip_times(lambda t: _exact(case, t)[1][:, 1], t1, n=N)
    assert len(flips) >= 2
    np.testing.assert_allclose(np.diff(flips), half, rtol=1e-11)
    if case.eps == 1e-2:  # a numerical solve finds the same flips
        ts = _ts(case)
        _, w = _simulate(case, ts, rtol=1e-11)
        num = hc.flips_from_samples(case.moments, ts, w)
        np.testing.assert_allclose(num, flips, rtol=1e-6)


# --------------------------------------------------------------------------- case 5


@pytest.mark.parametrize("key", ["top_fast_20", "top_fast_100"])
def test_fast_top_nutation_matches_analytic(key):
    case = hc.CASES[key]
    an = hc.top_analytic(case)
    assert an["slow_precession"] * case.spin_ratio == pytest.approx(case.top_spin, rel=1e-14)
    ts = _ts(case)
    q, w = _simulate(case, ts, rtol=1e-11)
    u, _ = hc.u_and_rate(q, w)
    assert np.max(np.abs(u - hc.top_u(case, ts))) < 1e-8
    measured = hc.nutation_from_samples(ts, q, w)
    assert measured["count"] >= 3
    assert measured["period"] == pytest.approx(an["period"], rel=1e-6)
    assert measured["amplitude"] == pytest.approx(an["amplitude"], rel=1e-6)
    ref = hc.reference(case, "small")  # the suite's reference at the horizon
    assert hc.u_and_rate(ref["q"], ref["omega"])[0] == pytest.approx(
        float(hc.top_u(case, ts[-1])), abs=1e-11)
    assert ref["floor"] < 1e-11


# --------------------------------------------------------------------------- case 6


def test_top_long_horizon_is_the_fast_top_over_ten_thousand_nutation_periods():
    case, fast = hc.CASES["top_long_horizon"], hc.CASES["top_fast_20"]
    period = hc.top_analytic(fast)["period"]
    assert hc.horizon(case) == pytest.approx(1e4 * period, rel=1e-14)
    assert hc.time_scale(case) == pytest.approx(hc.time_scale(fast), rel=1e-14)
    ref = hc.reference(case, "small")  # 100 nutation periods: DOP853 cross-check runs
    assert ref["t1"] == pytest.approx(100 * period, rel=1e-14)
    assert ref["floor"] < 1e-10
    assert hc.u_and_rate(ref["q"], ref["omega"])[0] == pytest.approx(
        float(hc.top_u(case, ref["t1"])), abs=1e-11)


def _drift_ratio(case, q, w):
    """Drift in the second half of the samples over that in the first half (secular: ~2)."""
    half = len(q) // 2
    a = hc.drift(case, q[: half + 1], w[: half + 1])
    b = hc.drift(case, q, w)
    return a, b


def test_long_horizon_drift_bounds():
    case = hc.CASES["long_horizon"]
    ts = _ts(case)  # 100 periods at small size
    n_periods = case.small_periods
    exact_drift = hc.drift(case, *_exact(case, ts))
    assert max(exact_drift.values()) < 1e-13
    q, w = _simulate(case, ts, rtol=1e-8)
    d = hc.drift(case, q, w)
    # projection keeps |q| on the sphere; energy and |L| drift by about rtol per period
    assert d["q_norm"] < 1e-12
    assert d["energy"] < 1e-8 * n_periods and d["L"] < 1e-8 * n_periods
    prob = hc.problem(case, "small")
    traj = leapfrog(prob.scene(), prob.state(), jnp.asarray(ts),
                    dt=hc.free_period(case.moments, case.omega0) / 100)
    q, w = np.asarray(traj.q), np.asarray(traj.omega)
    first, full = _drift_ratio(case, q, w)
    assert full["L"] < 1e-12 and full["q_norm"] < 1e-12  # |L| is kept exactly by the kicks
    # the renormalised leapfrog is not symplectic: its energy drifts, at most linearly
    assert 1e-3 < full["energy"] < 0.2 and full["energy"] < 2.5 * first["energy"]


# --------------------------------------------------------------------------- case 7


F32_BOUNDS = {  # final error of the default at rtol 1e-5 (phase error grows with time)
    "general_f32": 2e-3,  # 3 periods
    "separatrix_1e-2_f32": 0.1,  # 1.2 periods, next to the separatrix
    "long_horizon_f32": None,  # 100 periods: the phase is lost; drift bounds instead
}


@pytest.mark.parametrize("key", list(F32_BOUNDS))
def test_float32_error_bounds(key, float32):
    case = hc.CASES[key]
    t1 = hc.horizon(case, "small")
    with jax.enable_x64(True):
        ref = hc.reference(case, "small")
    eps32 = float(np.finfo(np.float32).eps)
    ts = np.linspace(0.0, t1, 3)
    q, w = _exact(case, ts.astype(np.float32))
    assert q.dtype == np.float64 and jnp.asarray(ts).dtype == jnp.float32  # x64 is off
    # the closed form loses only the rounding of t: λ t eps32 (λ ~ |ω|)
    scale = eps32 * (10 + 4 * t1 * float(np.linalg.norm(case.omega0)))
    err = max(harness.omega_error(w[-1], ref["omega"]), harness.quaternion_error(q[-1], ref["q"]))
    assert err < scale
    prob = hc.problem(case, "small")
    traj = simulate(prob.scene(), prob.state(), jnp.asarray(ts, jnp.float32), rtol=1e-5,
                    atol=1e-7, max_steps=1_000_000)
    assert traj.omega.dtype == jnp.float32
    err = max(harness.omega_error(traj.omega[-1], ref["omega"]),
              harness.quaternion_error(traj.q[-1], ref["q"]))
    if F32_BOUNDS[key] is not None:
        assert err < F32_BOUNDS[key]
    periods = t1 / hc.free_period(case.moments, case.omega0)
    d = hc.drift(case, np.asarray(traj.q), np.asarray(traj.omega))
    assert d["q_norm"] < 10 * eps32
    assert d["energy"] < 5e-5 * periods and d["L"] < 5e-5 * periods, d  # ~ rtol a period


# --------------------------------------------------------------------------- case 8


def test_gimbal_lock_reported_by_euler_angles_only():
    case = hc.CASES["gimbal_lock"]
    prob = hc.problem(case, "small")
    ts = jnp.asarray(_ts(case))
    with pytest.raises((ValueError, SimulationError), match="gimbal lock"):
        simulate(prob.scene(), prob.state(), ts, formulation="euler_angles")
    ref = hc.reference(case, "small")
    for formulation in ("quaternion_acceleration", "quaternion_omega"):
        q, w = _simulate(case, np.asarray(ts), formulation=formulation)
        assert np.all(np.isfinite(q)) and np.all(np.isfinite(w))
        err = max(harness.omega_error(w[-1], ref["omega"]),
                  harness.quaternion_error(q[-1], ref["q"]))
        assert err < 1e-7
        tilt = np.arccos(np.clip(hc.u_and_rate(q, w)[0], -1, 1))
        assert np.max(tilt) < 5 * case.tilt  # sleeping: stays near the vertical


# --------------------------------------------------------------------------- published


@pytest.mark.parametrize("key", ["detest_b5", "hairer_rigid_body"])
def test_published_equations_are_euler_equations_scaled(key):
    case = hc.CASES[key]
    body, coeffs, y0 = hc.published(case.published)
    d = hc.published_map(case)
    assert case.moments == body
    np.testing.assert_allclose(case.omega0, d * np.asarray(y0), rtol=1e-15)
    rng = np.random.default_rng(1)
    for y in rng.normal(size=(5, 3)):
        w = d * y
        euler = hc.euler_coeffs(body) * np.array([w[1] * w[2], w[2] * w[0], w[0] * w[1]])
        np.testing.assert_allclose(euler, d * hc.published_rhs(coeffs)(0.0, y), rtol=1e-13)
    with pytest.raises(ValueError, match="signs"):
        hc.diagonal_map(body, -np.asarray(coeffs))


def test_detest_b5_against_sn_cn_dn():
    case = hc.CASES["detest_b5"]
    d = hc.published_map(case)
    ts = np.linspace(0.0, 20.0, 9)
    _, w = _exact(case, ts)
    y = w / d
    sn, cn, dn, _ = sps.ellipj(ts, 0.51)
    expected = np.stack([sn, cn, dn], axis=-1)
    np.testing.assert_allclose(y, expected, rtol=0, atol=1e-13)
    np.testing.assert_allclose(hc.b5_exact(ts), expected, rtol=0, atol=1e-14)
    ref = hc.reference(case, "small")
    np.testing.assert_allclose(ref["omega"] / d, expected[-1], atol=1e-13)
    # the published equations written out, integrated by scipy, agree with sn, cn, dn
    sol = solve_ivp(hc.published_rhs(hc.B5_COEFFS), (0, 20), hc.B5_Y0, method="DOP853",
                    rtol=1e-12, atol=1e-14, t_eval=ts)
    np.testing.assert_allclose(sol.y.T, expected, atol=1e-9)


def test_hairer_norsett_wanner_solution_and_invariants():
    case = hc.CASES["hairer_rigid_body"]
    d = hc.published_map(case)
    ts = _ts(case)
    _, w = _exact(case, ts)
    y = w / d
    sol = solve_ivp(hc.published_rhs(hc.HNW_COEFFS), (0, 20), hc.HNW_Y0, method="DOP853",
                    rtol=1e-13, atol=1e-15, t_eval=ts)
    np.testing.assert_allclose(y, sol.y.T, atol=1e-10)
    inv0 = hc.hnw_invariants(hc.HNW_Y0)
    # HNW's invariants are conserved by its equations: check on them, then on solutions
    y_rand = np.random.default_rng(2).normal(size=3)
    f = hc.published_rhs(hc.HNW_COEFFS)(0.0, y_rand)
    np.testing.assert_allclose(
        [np.sum(np.array(hc.HNW_MOMENTS) ** p * y_rand * f) for p in (1, 2)], 0, atol=1e-14)
    np.testing.assert_allclose(hc.hnw_invariants(y), np.broadcast_to(inv0, (N, 2)), rtol=1e-14)
    _, w_num = _simulate(case, ts, rtol=1e-10)
    np.testing.assert_allclose(hc.hnw_invariants(w_num / d), np.broadcast_to(inv0, (N, 2)),
                               rtol=1e-8)
    assert np.max(np.abs(w_num / d - y)) < 1e-7


# --------------------------------------------------------------------------- report


def test_mujoco_conventions_match_jrigid():
    """Free joint: qpos quaternion body → world scalar first, qvel ω in the body frame.

    MuJoCo is a test dependency (the ``test`` extra), so this always runs in CI.
    """
    case = hc.CASES["thin_rod"]
    run = wp.mujoco_runner(case, "small", "RK4")
    ref = hc.reference(case, "small")
    out = run(hc.time_scale(case) / 3000)
    err = max(harness.omega_error(out["omega"], ref["omega"]),
              harness.quaternion_error(out["q"], ref["q"]))
    assert err < 1e-10
    top = hc.CASES["top_fast_20"]
    out = wp.mujoco_runner(top, "small", "RK4")(hc.time_scale(top) / 1000)
    ref = hc.reference(top, "small")
    assert max(harness.omega_error(out["omega"], ref["omega"]),
               harness.quaternion_error(out["q"], ref["q"])) < 1e-9


def test_splitting_runner_and_top_drift():
    """On a top the report runs the splitting methods; its drifts are the scene's invariants."""
    case = hc.CASES["top_fast_20"]
    ref = hc.reference(case, "small")
    error = wp.errors_against(ref, case)
    run, seconds = wp.splitting_runner(case, "small", "kahan_li6", wp.Compiled(lambda *a: None))
    assert seconds > 0
    out = run(hc.time_scale(case) / 30)
    errs, extra = error(out)
    assert max(errs.values()) < 1e-8
    assert abs(extra["energy_drift"]) < 1e-12 and abs(extra["L_drift"]) < 1e-12
    # MuJoCo's RK4 at a coarse step drifts; the drift is E(t1)/E0 − 1 measured independently
    out = wp.mujoco_runner(case, "small", "RK4")(hc.time_scale(case) / 10)
    _, extra = error(out)
    prob = hc.problem(case, "small")
    scene = prob.scene()
    state = prob.state()
    q = jnp.asarray(out["q"] / np.linalg.norm(out["q"]))

    def energy(q, w):
        w = jnp.asarray(w)
        return float(scene.kinetic_energy(w) + scene.potential_energy(Kinematics(q, w)))

    e0 = energy(state.q, state.omega)
    scale = float(scene.conserved(Kinematics(state.q, state.omega)).scales[0])
    assert extra["energy_drift"] == pytest.approx((energy(q, out["omega"]) - e0) / scale,
                                                  rel=1e-6)
    assert abs(extra["energy_drift"]) > 1e-9


def test_work_precision_machinery_on_a_tiny_case(tmp_path):
    """The report's sweep, summary, markdown and figure on one small case (no compiling)."""
    case = hc.CASES["hairer_rigid_body"]
    cache = wp.Compiled(lambda *a: None)
    peers = ("scipy DOP853", "MuJoCo RK4")
    res = wp.run_case(case, "small", quick=True, cache=cache, log=lambda *a: None,
                      only=lambda label: label in peers)
    methods = res["methods"]
    assert set(methods) == set(peers) and not cache.seconds  # nothing compiled
    for label in peers:
        pts = methods[label]["points"]
        assert methods[label]["compile_seconds"] is None
        assert all(p["ok"] and p["time"] > 0 and len(p["times"]) >= 1 for p in pts), label
        errs = [p["error"] for p in pts]
        assert errs[-1] < 1e-3 * errs[0], (label, errs)  # tighter settings, smaller errors
        # drift of the invariants is recorded for torque-free cases
        assert abs(pts[-1]["extra"]["energy_drift"]) < 1e-6
    tte = res["summary"]["time_to_error"]
    best = res["summary"]["best_peer"][1e-4]
    assert best["label"] in peers
    assert tte[best["label"]][1e-4]["ratio_to_best_peer"] == pytest.approx(1.0)
    assert all(r[1e-4]["ratio_to_best_peer"] >= 1.0 for r in tte.values()
               if r[1e-4]["ratio_to_best_peer"] is not None)
    text = wp.report([res], harness.machine_info(), cache, None, quick=True, seconds=1.0)
    assert "| case |" in text and "scipy DOP853" in text and "Compile times" in text
    png = harness.work_precision_grid(wp.panels_of([res]), tmp_path / "g.png", ncols=2,
                                      targets=wp.TARGETS)
    assert png.read_bytes()[:4] == b"\x89PNG"
    assert res["reference"]["floor"] < 1e-12
