"""Smoke tests of the benchmark harness and of the quick speed-against-error run."""

from __future__ import annotations

import json
import math
import pathlib
import sys

import jax.numpy as jnp
import numpy as np
import pytest

BENCH = pathlib.Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCH))

import first_call  # noqa: E402
import harness  # noqa: E402
import outputs  # noqa: E402
import speed_vs_error as sve  # noqa: E402
import splitting as sp  # noqa: E402

from jrigid import quaternion as quat  # noqa: E402
from jrigid.formulations import QuaternionOmega, QuaternionOmegaState  # noqa: E402

# --------------------------------------------------------------------------- harness


def test_time_to_error_interpolates_a_power_law_exactly():
    errors = [1e-2, 1e-4, 1e-6, 1e-8]
    times = [1e-3 * e**-0.25 for e in errors]
    t, kind = harness.time_to_error(errors, times, 1e-5)
    assert kind == "interp"
    assert t == pytest.approx(1e-3 * 1e-5**-0.25, rel=1e-12)


def test_time_to_error_bound_and_unreached():
    errors, times = [1e-5, 1e-7], [1.0, 2.0]
    assert harness.time_to_error(errors, times, 1e-4) == (1.0, "bound")
    assert harness.time_to_error(errors, times, 1e-9) == (None, "unreached")
    assert harness.time_to_error([math.nan], [1.0], 1e-4) == (None, "unreached")


def test_pareto_front_drops_dominated_and_nonfinite_points():
    errors = [1e-3, 1e-4, 2e-3, math.nan, 1e-6]
    times = [1.0, 2.0, 3.0, 0.5, 4.0]
    # (2e-3, 3.0) is beaten by (1e-3, 1.0); the NaN run is dropped.
    assert harness.pareto_front(errors, times) == [(1e-3, 1.0), (1e-4, 2.0), (1e-6, 4.0)]


def test_errors_are_relative_and_sign_invariant():
    q = np.asarray(quat.from_axis_angle(jnp.array([0.3, -0.2, 0.9]), 1.1))
    assert harness.quaternion_error(q, -q) == pytest.approx(0.0, abs=1e-15)
    small = np.asarray(quat.multiply(q, quat.from_axis_angle(jnp.array([1.0, 0.0, 0.0]), 2e-6)))
    # For a small rotation angle δ the distance is 2 sin(δ/4) ≈ δ/2.
    assert harness.quaternion_error(-small, q) == pytest.approx(1e-6, rel=1e-6)
    assert harness.omega_error([2.0, 0.0, 0.0], [1.0, 0.0, 0.0]) == pytest.approx(1.0)


def test_time_runs_counts_calls_and_reports_the_median():
    calls = []
    timing, out = harness.time_runs(lambda: calls.append(1) or len(calls), 5, warmup=2)
    assert len(calls) == 7 and out == 7
    assert len(timing.runs) == 5
    assert timing.min <= timing.median <= timing.max


def test_time_runs_repeats_fast_calls_up_to_min_time():
    calls = []
    timing, _ = harness.time_runs(lambda: calls.append(1), 3, warmup=0, min_time=10.0,
                                  max_repeats=40)
    assert len(timing.runs) == 40 == len(calls)  # fast calls: capped by max_repeats
    timing, _ = harness.time_runs(lambda: None, 3, warmup=0, min_time=0.0)
    assert len(timing.runs) == 3


def test_time_interleaved_alternates_and_respects_repeats():
    order = []
    calls = {"a": lambda: order.append("a") or "A", "b": lambda: order.append("b") or "B"}
    out = harness.time_interleaved(calls, {"a": 3, "b": 2}, warmup=1)
    assert out["a"][1] == "A" and len(out["a"][0].runs) == 3 and len(out["b"][0].runs) == 2
    # warm-up a, b; then rounds a b | b a | a (order alternates; b stops after 2 rounds)
    assert "".join(order) == "ab" + "ab" + "ba" + "a"


def test_machine_info_names_cpu_and_versions():
    info = harness.machine_info()
    assert info["cpu"] and info["cores_usable"] >= 1
    for dist in ("jax", "diffrax", "scipy"):
        assert info[dist][0].isdigit(), (dist, info[dist])
    line = harness.machine_line(info)
    assert info["cpu"] in line and "diffrax" in line


def test_writers(tmp_path):
    table = harness.markdown_table(["a", "b"], [[1, "x"], [2, "y"]])
    assert table.splitlines()[1] == "| --- | --- |" and "| 2 | y |" in table
    path = harness.write_json(tmp_path / "r.json", {"x": np.float64(math.nan), 1e-4: [np.int64(3)]})
    assert json.loads(path.read_text()) == {"x": None, "0.0001": [3]}
    png = harness.work_precision_figure(
        {"p": {"scipy A": ([1e-3, 1e-6], [1e-2, 1e-1]), "B": ([1e-4], [2e-3])}},
        tmp_path / "wp.png", targets=(1e-4,), highlight=("B",),
    )
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# --------------------------------------------------------------------------- problems


@pytest.mark.parametrize("problem", [sve.FREE_ROTOR, sve.HEAVY_TOP], ids=lambda p: p.key)
def test_numpy_equations_match_jrigid(problem):
    """The scipy right-hand side is the same ODE as jrigid's (q, ω) vector field."""
    rng = np.random.default_rng(0)
    q = rng.normal(size=4) * 0.8  # off the unit sphere on purpose
    omega = rng.normal(size=3)
    y = QuaternionOmegaState(jnp.asarray(q), jnp.asarray(omega))
    dy = QuaternionOmega().vector_field(0.0, y, problem.scene())
    expected = np.concatenate([np.asarray(dy.q), np.asarray(dy.omega)])
    got = problem.numpy_rhs()(0.0, np.concatenate([q, omega]))
    np.testing.assert_allclose(got, expected, rtol=1e-13, atol=1e-13)


def test_free_rotor_momentum_is_along_space_z():
    """Keeps the ZXZ Euler angles away from gimbal lock (the angle θ ≠ 0)."""
    state = sve.FREE_ROTOR.state()
    L_space = quat.rotate(state.q, jnp.array(sve.FREE_ROTOR.moments) * state.omega)
    np.testing.assert_allclose(np.asarray(L_space)[:2], 0.0, atol=1e-14)
    assert float(L_space[2]) > 0


# --------------------------------------------------------------------------- quick run


def test_quick_run_produces_table_plot_and_finite_errors(tmp_path):
    out = sve.main(["--quick", "--out", str(tmp_path), "--quiet"])
    md = (tmp_path / "speed_vs_error_quick.md").read_text()
    assert "| method | compile |" in md and "scipy DOP853 / jrigid default" in md
    assert "better hand-written diffrax / jrigid default" in md
    assert "Machine: " in md
    assert (tmp_path / "speed_vs_error_quick.png").read_bytes()[:4] == b"\x89PNG"
    data = json.loads((tmp_path / "speed_vs_error_quick.json").read_text())
    methods = data["problems"]["free_rotor"]["methods"]
    assert {sve.DEFAULT, sve.OLD_DEFAULT, sve.PEER, f"{sve.HAND} + Tsit5",
            f"{sve.HAND} + Dopri8"} <= set(methods)
    assert methods[sve.DEFAULT]["compile_seconds"] > 0
    for label, m in methods.items():
        pts = m["points"]
        assert pts and all(p["ok"] for p in pts), label
        errs = [p["error"] for p in pts]
        assert all(e is not None and math.isfinite(e) and e > 0 for e in errs), label
        assert all(p["time"] > 0 and len(p["times"]) >= 3 for p in pts), label
        # Tightening the tolerance from 1e-3 to 1e-12 must shrink the error a lot.
        assert errs[-1] < 1e-3 * errs[0], (label, errs)
    tte = data["problems"]["free_rotor"]["summary"]["time_to_error"][sve.DEFAULT]
    assert tte["0.0001"]["seconds"] is not None
    assert out["markdown"] == md


def test_first_call_splits_a_fresh_process_first_simulate(tmp_path):
    first_call.main(["--runs", "1", "--out", str(tmp_path)])
    assert "Largest first compile" in (tmp_path / "first_call.md").read_text()
    data = json.loads((tmp_path / "first_call.json").read_text())
    runs = data["runs"]
    assert set(runs) == {"rotor", "top"}
    for (run,) in runs.values():
        assert all(run[c] > 0 for c in first_call.COLUMNS)
        # the program's tracing, lowering and XLA compilation happen inside the first call
        assert run["compile"] < run["first_simulate"]
        assert run["second_simulate"] < 0.1 * run["first_simulate"]
        assert run["cache_hits"] == 0  # an empty cache of its own
    for (run,) in data["cached"].values():
        assert run["cache_hits"] >= 1  # the same script again: its solve loaded, not compiled


def test_outputs_quick_run_times_every_call_and_measures_its_error(tmp_path):
    outputs.main(["--quick", "--out", str(tmp_path)])
    md = (tmp_path / "outputs_quick.md").read_text()
    assert "Machine: " in md and "| T | call |" in md
    rows = json.loads((tmp_path / "outputs_quick.json").read_text())["rows"]
    assert {r["T"] for r in rows} == {2, 101} and len(rows) == 12
    assert all(r["median"] > 0 and math.isfinite(r["error"]) for r in rows)
    by = {(r["T"], r["method"]): r for r in rows}
    for T in (2, 101):
        jitted, plain = by[T, "jrigid default, jitted"], by[T, "jrigid default, plain call"]
        assert jitted["error"] == pytest.approx(plain["error"], rel=1e-6)  # the same solve
        for label in (outputs.LOOP_JIT, outputs.LOOP_PLAIN):  # timed again, in a loop
            assert by[T, label]["error"] == pytest.approx(plain["error"], rel=1e-6)
        # at equal tolerance the hand-written Dopri8 is far less accurate (no projection,
        # diffrax's per-entry error scale): what the table's tighter row is for
        loose = by[T, f"hand-written diffrax Dopri8, rtol {outputs.RTOL:g}"]
        assert jitted["error"] < 0.1 * loose["error"]


# --------------------------------------------------------------------------- ensemble


def _throughput_result(rates: dict[str, float]) -> dict:
    """A result of ``ensemble_throughput`` with the given trajectories/s per method."""
    import ensemble_throughput as et

    methods = {
        label: {"label": label, "setting": "-", "members_timed": 100, "throughput": rate,
                "compile_seconds": None, "errors": {"median": 1e-6, "max": 2e-6},
                "executor": "in process"}
        for label, rate in rates.items()
    }
    scipy = rates["scipy DOP853 loop"]
    mujoco = rates["MuJoCo RK4 rollout"]
    head, cluster = rates[et.HEADLINE], rates[et.CLUSTER]
    return {
        "n": 100, "quick": True, "machine": {"load_average": [0, 0, 0],
                                             "load_average_end": [0, 0, 0]},
        "machine_line": "test machine", "n_devices": 1, "total_seconds": 1.0,
        "reference_check": 1e-11, "reference_members": 5,
        "compile_cache": {"empty cache": {"per_worker": [9.0, 11.0]},
                          "warm cache": {"per_worker": [1.0, 1.0]}, "saved_per_worker": 9.0},
        "methods": methods,
        "verdict": {
            "default_vs_scipy_same_rtol": head / scipy,
            "default_vs_scipy_matched": head / scipy,
            "cluster_vs_scipy_same_rtol": cluster / scipy,
            "cluster_vs_scipy_matched": cluster / scipy,
            "exact_vs_scipy": rates["jrigid exact"] / scipy,
            "default_vs_mujoco": head / mujoco,
            "cluster_vs_mujoco": cluster / mujoco,
            "exact_vs_mujoco": rates["jrigid exact"] / mujoco,
            "mujoco_error": 1e-6, "jrigid_error": 1e-6,
            "default_scipy_met": head / scipy >= et.TARGET_SPEEDUP_SCIPY,
            "cluster_scipy_met": cluster / scipy >= et.TARGET_SPEEDUP_SCIPY,
        },
    }


def test_ensemble_throughput_report_and_figure(tmp_path):
    import ensemble_throughput as et

    rates = {et.HEADLINE: 4000.0, et.CLUSTER: 2500.0, "jrigid exact": 1e5,
             "scipy DOP853 loop": 10.0, "MuJoCo RK4 rollout": 30.0}
    text = et.report(_throughput_result(rates))
    assert "400× at matched error in process — met; on 2 local workers 250× (NOT met)" in text
    assert "At the same rtol, where scipy's error is larger: 400× in process" in text
    assert "| 400× |" in text  # the default call's ratio to the scipy loop in the table
    assert "9.0 s saved per worker" in text
    rates[et.HEADLINE] = 900.0
    assert "— NOT met" in et.report(_throughput_result(rates))
    png = et.figure(_throughput_result(rates), tmp_path / "fig.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_splitting_drift_report_on_a_short_run():
    """The splitting benchmark's drift part: Strang's energy band does not grow, L·ĝ is kept
    to rounding, scipy DOP853's band (its own equations) is measured on the same scene."""
    res = sp.drift(2000)
    assert res["t1"] == pytest.approx(20.0)
    methods = res["methods"]
    strang = methods["jrigid splitting strang, h = 0.01"]
    assert strang["steps"] == 2000
    assert 1e-9 < strang["energy_first_half"] < 1e-5  # O(h²), not rounding
    assert strang["energy_second_half"] < 2 * strang["energy_first_half"]
    assert strang["L_g"] < 1e-12
    dop = methods[f"scipy DOP853, rtol {sp.DRIFT_RTOL:g}"]
    assert 0 < dop["energy_second_half"] < 1e-6 and dop["L_g"] < 1e-5
    text = sp.report({"orders": {}, "drift": res,
                      "closed_form": {"seconds": {}, "max_difference_vs_dop853_100_periods": 0.0}},
                     harness.machine_info())
    assert "No drift" in text and "strang" in text
