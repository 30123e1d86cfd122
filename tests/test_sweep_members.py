"""One bad member never stops a sweep: invalid inputs and failures in simulate_many.

An invalid member (zero quaternion, NaN angular velocity) gets ``invalid_input`` and NaN
outputs and the others come out as without it; a member that fails inside a shared-step
group (its step budget) does not take its group mates with it (the group is solved again
member by member); the sweep names how many and the first. The same holds for
``jax.vmap(simulate(..., throw=False))``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jrigid import RigidBody, Scene, ensemble, initial, simulate
from jrigid.state import State
from jrigid.trajectory import Result

SCENE = Scene(RigidBody(jnp.asarray([1.0, 2.0, 3.0])))
TS = np.linspace(0.0, 10.0, 3)


def final(traj):
    return {"q": traj.q[-1], "omega": traj.omega[-1], "steps": traj.stats["num_steps"]}


def states_of(omegas) -> State:
    return jax.vmap(lambda w: initial.from_omega(None, w))(jnp.asarray(omegas))


def spoil(states: State, zero_q: int, nan_omega: int) -> State:
    q, qdot = np.array(states.q), np.array(states.qdot)
    q[zero_q] = 0.0
    qdot[nan_omega, 1] = np.nan
    return State(jnp.asarray(q), jnp.asarray(qdot))


def at_rest(states: State, members) -> State:
    """``states`` with ``members`` replaced by the identity orientation at rest."""
    q, qdot = np.array(states.q), np.array(states.qdot)
    q[members] = [1.0, 0.0, 0.0, 0.0]
    qdot[members] = 0.0
    return State(jnp.asarray(q), jnp.asarray(qdot))


def test_invalid_members_are_named_and_leave_the_others_alone():
    """Members 0 (zero quaternion) and 4 (NaN ω) are invalid. The others come out bit for
    bit as in the sweep where those two are valid bodies at rest (which add nothing to a
    shared step's error), per member and in a shared step alike."""
    omegas = np.random.default_rng(0).normal(size=(6, 3))
    bad = spoil(states_of(omegas), zero_q=0, nan_omega=4)
    rest = at_rest(states_of(omegas), [0, 4])
    keep = [1, 2, 3, 5]
    outs = {}
    for shared_step in (False, True):
        kwargs = dict(summary=final, chunk_size=6, progress=False, shared_step=shared_step)
        info: dict = {}
        with pytest.warns(ensemble.SweepWarning,
                          match=r"2 of 6 members have invalid input \(first: member 0\)"):
            out = ensemble.simulate_many(SCENE, bad, TS, info=info, **kwargs)
        assert out["result"].tolist() == [Result.invalid_input, 0, 0, 0, Result.invalid_input, 0]
        assert np.all(np.isnan(out["omega"][[0, 4]])) and np.all(np.isnan(out["q"][[0, 4]]))
        assert info["invalid_input"] == 2 and info["first_invalid"] == 0
        assert info["failed"] == 0 and info["shared_step"] == shared_step
        reference = ensemble.simulate_many(SCENE, rest, TS, **kwargs)
        for k in ("q", "omega", "steps", "result"):
            np.testing.assert_array_equal(out[k][keep], reference[k][keep], err_msg=k)
        outs[shared_step] = out
    # the two step controls agree within the tolerance (rtol 1e-8 over 10 time units)
    np.testing.assert_allclose(outs[True]["omega"][keep], outs[False]["omega"][keep],
                               atol=1e-6)



def body_of(moments):
    return Scene(RigidBody(moments))


def test_member_with_a_non_physical_body_is_named():
    """A per-member body violating the triangle inequality ((1, 1, 3)) is invalid input;
    the other members come out as they do on their own."""
    omegas = np.random.default_rng(1).normal(size=(4, 3))
    moments = np.array([[1.0, 2.0, 3.0], [1.0, 2.0, 2.5], [1.0, 1.0, 3.0], [2.0, 2.0, 3.0]])
    states = states_of(omegas)
    for shared_step in (False, True):
        info: dict = {}
        with pytest.warns(ensemble.SweepWarning,
                          match=r"1 of 4 members have invalid input \(first: member 2\)"):
            out = ensemble.simulate_many(body_of, states, TS, params=jnp.asarray(moments),
                                         summary=final, chunk_size=4, progress=False,
                                         info=info, shared_step=shared_step)
        assert out["result"].tolist() == [0, 0, Result.invalid_input, 0]
        assert np.all(np.isnan(out["omega"][2])) and info["first_invalid"] == 2
        for i in (0, 1, 3):
            alone = simulate(Scene(RigidBody(jnp.asarray(moments[i]))),
                             initial.from_omega(None, jnp.asarray(omegas[i])), TS)
            np.testing.assert_allclose(out["omega"][i], alone.omega[-1], rtol=0, atol=1e-6)

def test_failed_member_does_not_take_its_group_with_it(tmp_path):
    """One fast member exhausts max_steps in a shared-step group: the group is solved
    again per member; the slow members succeed as they do on their own."""
    omegas = np.array([[0.3, 0.1, 0.2], [0.1, 0.3, -0.2], [30.0, 10.0, 20.0], [0.2, -0.1, 0.3]])
    states = states_of(omegas)
    kwargs = dict(summary=final, chunk_size=4, progress=False, max_steps=200)
    info: dict = {}
    with pytest.warns(ensemble.SweepWarning,
                      match=r"1 of 4 members failed \(first: member 2, result max_steps\)"):
        shared = ensemble.simulate_many(SCENE, states, TS, info=info, out_dir=tmp_path, **kwargs)
    assert info["shared_step"] and info["failed"] == 1 and info["first_failed"] == 2
    assert info["solved_again"] == 4 and (tmp_path / "per_member" / "chunk_00000.npz").exists()
    assert shared["result"].tolist() == [0, 0, Result.max_steps, 0]
    # the chunk file holds what the call returned (it held the group's failure), and a
    # resumed run returns the same
    with np.load(tmp_path / "chunk_00000.npz") as stored:
        for k in shared:
            np.testing.assert_array_equal(stored[k], shared[k])
    with pytest.warns(ensemble.SweepWarning):
        again = ensemble.simulate_many(SCENE, states, TS, info=info, out_dir=tmp_path, **kwargs)
    assert info["chunks_loaded"] == 1
    for k in shared:
        np.testing.assert_array_equal(again[k], shared[k])
    with pytest.warns(ensemble.SweepWarning):
        per_member = ensemble.simulate_many(SCENE, states, TS, shared_step=False, **kwargs)
    slow = [0, 1, 3]
    np.testing.assert_array_equal(shared["steps"][slow], per_member["steps"][slow])
    np.testing.assert_allclose(shared["omega"][slow], per_member["omega"][slow], rtol=1e-12)
    # without the fast member (a slow one twice instead) the shared step succeeds
    alone = ensemble.simulate_many(SCENE, states_of(omegas[[0, 1, 0, 3]]), TS, info=info,
                                   **kwargs)
    assert alone["result"].tolist() == [0, 0, 0, 0] and info["failed"] == 0


def test_vmap_simulate_throw_false_isolates_an_invalid_member():
    omegas = np.random.default_rng(1).normal(size=(3, 3))
    good = states_of(omegas)
    bad = spoil(good, zero_q=1, nan_omega=1)

    @jax.jit
    def sweep(states):
        traj = jax.vmap(lambda s: simulate(SCENE, s, TS, throw=False))(states)
        return traj.omega[:, -1], traj.result

    w_bad, r_bad = sweep(bad)
    w_good, r_good = sweep(good)
    assert np.asarray(r_bad).tolist() == [0, Result.invalid_input, 0]
    assert np.asarray(r_good).tolist() == [0, 0, 0]
    assert np.all(np.isnan(np.asarray(w_bad)[1]))
    np.testing.assert_array_equal(np.asarray(w_bad)[[0, 2]], np.asarray(w_good)[[0, 2]])


def test_failed_groups_follow_chunks_groups_and_order():
    """Groups are consecutive runs of ``group`` members within each chunk, in computing order."""
    codes = np.zeros(10, dtype=np.int32)
    codes[7] = Result.max_steps
    # chunks of 4 in input order: [0-3], [4-7], [8, 9]; groups of 2: member 7 is in {6, 7}
    assert ensemble.many.failed_groups(codes, None, 4, 2).tolist() == [6, 7]
    assert ensemble.many.failed_groups(codes, None, 4, 4).tolist() == [4, 5, 6, 7]
    # an invalid member or an event is not a failure of its group
    codes[1], codes[9] = Result.invalid_input, Result.event
    assert ensemble.many.failed_groups(codes, None, 4, 4).tolist() == [4, 5, 6, 7]
    # computed in the order 9, 8, ..., 0: member 7 sits at position 2, with 9, 8, 6
    order = np.arange(10)[::-1]
    assert ensemble.many.failed_groups(codes, order, 4, 4).tolist() == [9, 8, 7, 6]
    assert ensemble.many.failed_groups(np.zeros(10, np.int32), order, 4, 4).size == 0


@pytest.mark.parametrize("ts", [TS[::-1], np.array([0.0, 1.0, 1.0, 2.0])])
def test_output_times_not_increasing_are_refused_up_front(ts):
    """Every member shares ``ts``: decreasing or repeated times are the sweep's error, not
    every member's (they all came back invalid, with NaN outputs and a warning to run
    one member alone)."""
    with pytest.raises(ValueError, match="strictly increasing"):
        ensemble.simulate_many(SCENE, states_of(np.eye(3)), ts, progress=False)


@pytest.mark.parametrize("option, message", [
    (dict(rtol=-1.0), "rtol must be finite"), (dict(rtol=1e-30), "below 10 machine"),
    (dict(atol=-1.0), "atol must be finite"), (dict(dt0=-0.1), "dt0 must be finite and > 0"),
])
def test_settings_every_member_shares_are_refused_up_front(option, message):
    """A bad tolerance made every member invalid (N warnings' worth, after the whole
    sweep), and a negative dt0 ended in an internal runtime error."""
    with pytest.raises(ValueError, match=message):
        ensemble.simulate_many(SCENE, states_of(np.eye(3)), TS, progress=False, **option)


def test_a_scene_with_a_member_axis_is_refused_with_the_remedy():
    moments = jnp.asarray([[1.0, 2.0, 3.0], [1.0, 2.0, 2.5], [2.0, 2.0, 3.0]])
    scenes = jax.vmap(lambda m: Scene(RigidBody(m)))(moments)
    states = states_of(np.eye(3))
    with pytest.raises(ValueError, match="member axis.*function params -> Scene"):
        ensemble.simulate_many(scenes, states, TS, progress=False)
    with pytest.raises(ValueError, match="scene has a batch axis"):
        simulate(scenes, jax.tree_util.tree_map(lambda a: a[0], states), TS)
    with pytest.raises(ValueError, match="pass batched_scene=True"):
        ensemble.simulate_lockstep(scenes, states, TS)
    with pytest.raises(ValueError, match="batched_scene=True but"):
        ensemble.simulate_lockstep(SCENE, states, TS, batched_scene=True)
    with pytest.raises(ValueError, match="no members"):
        ensemble.simulate_lockstep(SCENE, states_of(np.zeros((0, 3))), TS)
    # and the scene function built from the same moments runs, member for member
    traj = ensemble.simulate_lockstep(scenes, states, TS, batched_scene=True)
    for k in range(3):
        one = simulate(Scene(RigidBody(moments[k])), initial.from_omega(None, np.eye(3)[k]), TS,
                       formulation="quaternion_acceleration")
        np.testing.assert_allclose(traj.omega[k], one.omega, atol=1e-7)


def test_resuming_with_another_scene_function_or_summary_is_refused(tmp_path):
    """Two lambdas have the same name: the second run returned the first one's numbers."""
    params = jnp.asarray([[1.0, 2.0, 3.0], [1.0, 2.0, 2.5]])
    states = states_of(np.eye(3)[:2])
    kwargs = dict(params=params, out_dir=tmp_path, progress=False)
    first = ensemble.simulate_many(lambda p: Scene(RigidBody(p)), states, TS, **kwargs)
    with pytest.raises(ValueError, match="different run"):
        ensemble.simulate_many(lambda p: Scene(RigidBody(2.0 * p)), states, TS, **kwargs)
    with pytest.raises(ValueError, match="different run"):
        ensemble.simulate_many(lambda p: Scene(RigidBody(p)), states, TS,
                               summary=lambda t: {"omega": t.omega[0]}, **kwargs)
    same = ensemble.simulate_many(lambda p: Scene(RigidBody(p)), states, TS, **kwargs)
    np.testing.assert_array_equal(same["omega"], first["omega"])


def test_an_ensemble_run_under_a_transformation_names_the_remedy():
    def loss(omegas):
        return ensemble.simulate_many(SCENE, states_of(omegas), TS, progress=False)["omega"].sum()

    with pytest.raises(ValueError, match="is traced.*simulate_lockstep"):
        jax.grad(loss)(jnp.eye(3))


def test_an_out_dir_that_cannot_be_created_is_a_value_error(tmp_path):
    """It was the operating system's NotADirectoryError."""
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    with pytest.raises(ValueError, match="cannot be created"):
        ensemble.simulate_many(SCENE, states_of(np.eye(3)), TS, progress=False,
                               out_dir=a_file / "below")


def test_resuming_refuses_closures_and_options_that_repr_does_not_tell_apart(tmp_path):
    """``repr`` shows a long array with an ellipsis, 8 digits of a JAX scalar, and an
    equinox module's arrays as their shapes: a summary closing over another window, a
    scene scaled by 3e-9 more, or a SaveAt at other times of the same count came back
    with the first run's numbers."""
    states = states_of(np.eye(3)[:2])
    weights = np.ones(1001)

    def summary_of(w):
        return lambda t: {"omega": t.omega[-1] * w[500]}

    kwargs = dict(out_dir=tmp_path / "summary", progress=False)
    ensemble.simulate_many(SCENE, states, TS, summary=summary_of(weights), **kwargs)
    other = weights.copy()
    other[500] = 0.0  # repr(other) == repr(weights)
    assert repr(other) == repr(weights)
    with pytest.raises(ValueError, match="different run"):
        ensemble.simulate_many(SCENE, states, TS, summary=summary_of(other), **kwargs)

    def scene_of(scale):
        return lambda p: Scene(RigidBody(scale * p))

    params = jnp.asarray([[1.0, 2.0, 3.0], [1.0, 2.0, 2.5]])
    kwargs = dict(params=params, out_dir=tmp_path / "scene", progress=False)
    ensemble.simulate_many(scene_of(jnp.float64(1.0)), states, TS, **kwargs)
    with pytest.raises(ValueError, match="different run"):
        ensemble.simulate_many(scene_of(jnp.float64(1.0 + 3e-9)), states, TS, **kwargs)


def test_options_are_fingerprinted_by_their_arrays():
    import diffrax

    from jrigid.ensemble import many

    a = diffrax.SaveAt(ts=jnp.array([0.5, 1.0]))
    b = diffrax.SaveAt(ts=jnp.array([1.5, 2.0]))
    assert many._describe(a) == many._describe(b)  # repr shows f64[2] for both
    assert many._value_identity(a) != many._value_identity(b)
    assert many._value_identity(a) == many._value_identity(diffrax.SaveAt(ts=jnp.array([0.5, 1.0])))


def test_float32_sweeps_warn_as_simulate_does(float32):
    """simulate warned that float32 cannot resolve t = 3000 to rtol; the sweeps, whose
    members ended 7e-4 rad off, did not."""
    from jrigid import PrecisionWarning

    scene = Scene(RigidBody(jnp.asarray([1.0, 2.0, 3.0])))
    states = jax.vmap(lambda w: initial.from_omega(None, w))(
        jnp.asarray([[1.0, 0.3, 0.2], [0.1, 2.0, 0.3]]))
    ts = np.array([0.0, 3000.0], np.float32)
    with pytest.warns(PrecisionWarning, match="float32 resolves times"):
        ensemble.simulate_many(scene, states, ts, progress=False, max_steps=4)
    with pytest.warns(PrecisionWarning, match="float32 resolves times"):
        ensemble.simulate_lockstep(scene, states, ts, max_steps=4, throw=False)


def test_a_grid_of_states_is_named_as_states():
    """A (2, 3) grid was blamed on `initial_states` / `initial_state.q` with jax.vmap
    advice that does not apply to simulate_many."""
    grid = jax.vmap(states_of)(jnp.ones((2, 3, 3)))
    with pytest.raises(ValueError, match=r"states must have one leading member axis.*\(2, 3, 4\)"):
        ensemble.simulate_many(SCENE, grid, TS, progress=False)
