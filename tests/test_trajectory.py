"""trajectory: derived quantities of a Trajectory, dense output, Result codes and the
error a failed solve raises."""


import numpy as np
import pytest
from _simulate import (
    MOMENTS,
    OMEGA0,
    Q0,
    TS,
    free_scene,
    same_rotation,
    scipy_rot,
)
from _simulate import free_reference as _free_reference

from jrigid import initial
from jrigid.integrate import simulate
from jrigid.trajectory import CAUSES, Result, SimulationError


@pytest.fixture(scope="module")
def free_reference():
    return _free_reference()


# --------------------------------------------------------------------------- derived quantities


def test_trajectory_quantities_are_consistent(free_reference):
    traj = free_reference
    R = scipy_rot(traj.q).as_matrix()
    np.testing.assert_allclose(traj.axes, R, atol=1e-12)
    np.testing.assert_allclose(traj.omega_space, np.einsum("tij,tj->ti", R, traj.omega),
                               atol=1e-12)
    np.testing.assert_allclose(traj.L, np.asarray(traj.omega) * np.asarray(MOMENTS), atol=1e-12)
    np.testing.assert_allclose(
        traj.euler("zyx"), scipy_rot(traj.q).as_euler("zyx"), atol=1e-10
    )
    np.testing.assert_allclose(
        traj.kinetic_energy, 0.5 * np.sum(np.asarray(traj.omega) * np.asarray(traj.L), -1),
        rtol=1e-12,
    )
    assert traj.x is None and traj.v is None


def test_dense_output():
    from test_dynamics_analytic import reference_free_rotor

    state = initial.from_omega(Q0, OMEGA0)
    traj = simulate(free_scene(), state, TS, rtol=1e-10, atol=1e-12, dense=True)
    t_mid = np.asarray(TS[1:]) - 0.0123
    at = traj.at(t_mid)
    w_ref, q_ref = reference_free_rotor(np.asarray(MOMENTS), np.asarray(OMEGA0),
                                        np.asarray(Q0), np.concatenate([[0.0], t_mid]))
    np.testing.assert_allclose(at.ts, t_mid)
    np.testing.assert_allclose(at.omega, w_ref[1:], atol=1e-8)
    same_rotation(at.q, q_ref[1:], 1e-8)
    with pytest.raises(ValueError, match="dense"):
        simulate(free_scene(), state, TS).at(t_mid)


# --------------------------------------------------------------------------- result codes


def test_result_codes_and_their_causes():
    """Every failure code has a cause and a remedy; success and event are not failures."""
    assert [int(r) for r in Result] == list(range(len(Result)))
    assert Result.success == 0 and not Result.success.failed and not Result.event.failed
    failures = {r for r in Result if r.failed}
    assert failures == set(Result) - {Result.success, Result.event}
    assert set(CAUSES) == failures
    for cause, remedy in CAUSES.values():
        assert cause and remedy and cause != remedy
    assert "max_steps=7 exhausted" in CAUSES[Result.max_steps][0].format(max_steps=7)


def test_failed_solve_raises_with_cause_time_and_remedy():
    """max_steps=5 cannot reach t = 10: the message names where the solve stopped."""
    scene, state = free_scene(), initial.from_omega(Q0, OMEGA0)
    stopped = simulate(scene, state, TS, max_steps=5, throw=False)
    assert int(stopped.result) == Result.max_steps and Result(int(stopped.result)).failed
    assert int(stopped.stats["num_steps"]) == 5
    t_stop = float(stopped.t_stop)
    assert 0.0 < t_stop < float(TS[-1])
    with pytest.raises(SimulationError) as info:
        simulate(scene, state, TS, max_steps=5)
    text = str(info.value)
    cause, remedy = CAUSES[Result.max_steps]
    assert text.startswith(f"jrigid.simulate failed at t={t_stop:.6g} ")
    assert cause.format(max_steps=5) in text and f"remedy: {remedy}." in text
    assert "integrating 0 → 10" in text
    assert isinstance(info.value, RuntimeError)
