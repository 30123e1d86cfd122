"""trajectory: derived quantities of a Trajectory, dense output, Result codes and the
error a failed solve raises."""


import jax
import jax.numpy as jnp
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
from jrigid.body import RigidBody
from jrigid.integrate import simulate
from jrigid.scene import Gravity, Pivot, Scene
from jrigid.state import State
from jrigid.trajectory import CAUSES, Result, SimulationError, replace


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


def _top_members():
    """Three heavy tops (different bodies, spins and gravity) and their states."""
    moments = jnp.array([[0.5, 0.5, 0.8], [0.6, 0.5, 0.9], [0.4, 0.45, 0.7]])
    scenes = [Scene(RigidBody(m, com=jnp.array([0.0, 0.0, 1.0])), Pivot(), Gravity(g))
              for m, g in zip(moments, (1.0, 2.0, 0.5), strict=True)]
    states = [initial.from_euler_rates([0.0, 0.6, 0.0], [0.3, 0.0, w]) for w in (5.0, 3.0, 8.0)]
    return scenes, states


_QUANTITIES = ("q", "omega", "omega_space", "L", "L_space", "kinetic_energy",
               "potential_energy", "energy", "norm_error", "tangent_error", "axes")


def test_quantities_of_a_vmapped_solve_are_those_of_its_members():
    """Computed on access from the states: per member, with each member's own scene."""
    scenes, states = _top_members()
    ts = jnp.linspace(0.0, 2.0, 5)
    stack = lambda *xs: jax.tree_util.tree_map(lambda *a: jnp.stack(a), *xs)  # noqa: E731
    batch = jax.vmap(lambda sc, s: simulate(sc, s, ts))(stack(*scenes), stack(*states))
    assert batch.L.shape == (3, 5, 3) and batch.axes.shape == (3, 5, 3, 3)
    for k, (scene, state) in enumerate(zip(scenes, states, strict=True)):
        alone = simulate(scene, state, ts)
        member = jax.tree_util.tree_map(lambda a, k=k: a[k], batch)
        for name in _QUANTITIES:
            np.testing.assert_allclose(getattr(batch, name)[k], getattr(alone, name),
                                       rtol=1e-10, atol=1e-12, err_msg=name)
            np.testing.assert_allclose(getattr(member, name), getattr(alone, name),
                                       rtol=1e-10, atol=1e-12, err_msg=name)
    # the energy of each member is its own: different gravity, different energy
    assert len({round(float(e), 6) for e in batch.energy[:, 0]}) == 3


def test_quantities_are_kept_and_the_same_inside_jit():
    scenes, states = _top_members()
    traj = simulate(scenes[1], states[1], jnp.linspace(0.0, 1.0, 4))
    assert traj.L is traj.L  # computed once
    inside = jax.jit(lambda t: (t.L_space, t.potential_energy, t.q))(traj)
    for got, name in zip(inside, ("L_space", "potential_energy", "q"), strict=True):
        np.testing.assert_allclose(got, getattr(traj, name), rtol=1e-14, atol=1e-15)
    # L from the states by hand: the pivot inertia (parallel axes) times ω
    inertia = np.diag([0.6, 0.5, 0.9]) + np.diag([1.0, 1.0, 0.0])
    np.testing.assert_allclose(traj.L, np.asarray(traj.omega) @ inertia.T, rtol=1e-12)


def test_an_invalid_member_keeps_its_scene_and_times():
    # a zero quaternion: solved with stand-in inputs, returned with the given ones
    scene, state = free_scene(), State(jnp.zeros(4), jnp.zeros(4))
    ts = jnp.linspace(2.0, 3.0, 4)
    traj = simulate(scene, state, ts, throw=False)
    assert int(traj.result) == Result.invalid_input
    np.testing.assert_array_equal(traj.ts, ts)
    np.testing.assert_array_equal(traj.scene.body.moments, MOMENTS)
    assert np.isnan(np.asarray(traj.q)).all() and np.isnan(np.asarray(traj.energy)).all()


def test_replace_changes_fields_and_refuses_what_is_not_one():
    traj = simulate(free_scene(), initial.from_omega(Q0, OMEGA0), jnp.linspace(0.0, 1.0, 3))
    moved = replace(traj, ts=traj.ts + 1.0)
    np.testing.assert_allclose(moved.ts, np.asarray(traj.ts) + 1.0)
    np.testing.assert_allclose(moved.L, traj.L)  # computed again, from the same states
    with pytest.raises(ValueError, match="no field"):
        replace(traj, L=traj.omega)
    with pytest.raises(ValueError, match="needs a Trajectory"):
        replace(traj.y, ts=traj.ts)


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
    with pytest.raises(ValueError, match=r"scalar or a \(K,\) array"):
        traj.at(np.ones((2, 2)))
    batch = jax.vmap(lambda w: simulate(free_scene(), initial.from_omega(Q0, w), TS,
                                        dense=True))(jnp.stack([OMEGA0, 2 * OMEGA0]))
    with pytest.raises(ValueError, match=r"batch.*jax.vmap"):
        batch.at(t_mid)
    each = jax.vmap(lambda tr: tr.at(t_mid).omega)(batch)
    np.testing.assert_allclose(each[0], at.omega, atol=1e-8)


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
