"""Tests of jrigid.ensemble.simulate_lockstep and simulate_many(shared_step=True).

References: the closed-form motion (:mod:`jrigid.exact`), the per-member solve
``jax.vmap(simulate)`` (agreement within the tolerance, and bit for bit for a batch of
one), energy conservation for the gradient, and the single-device run for the sharded
one (in a subprocess with four forced host devices).
"""

from __future__ import annotations

import json

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _ensemble import python as _python

from jrigid import RigidBody, Scene, SimulationError, State, ensemble, exact, initial, simulate
from jrigid.ensemble import simulate_lockstep

MOMENTS = jnp.array([1.0, 2.0, 3.0])
SCENE = Scene(RigidBody(MOMENTS))
PERIODS = 8
TS = np.linspace(0.0, PERIODS * 2 * np.pi, 5)


def directions(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    w = rng.normal(size=(n, 3))
    return w / np.linalg.norm(w, axis=1, keepdims=True)


def states_of(omegas) -> State:
    return jax.vmap(lambda w: initial.from_omega(None, w))(jnp.asarray(omegas))


def take(tree, index):
    return jax.tree_util.tree_map(lambda a: a[index], tree)


@pytest.fixture(scope="module")
def batch():
    omegas = directions(24)
    return omegas, states_of(omegas)


@pytest.mark.parametrize("formulation", ["quaternion_acceleration", "quaternion_omega"])
def test_against_exact(batch, formulation):
    omegas, states = batch
    traj = simulate_lockstep(SCENE, states, TS, formulation=formulation)
    q_ref, w_ref = jax.vmap(lambda w: exact.solve(MOMENTS, jnp.array([1.0, 0, 0, 0]), w, TS))(
        jnp.asarray(omegas)
    )
    assert traj.omega.shape == (24, 5, 3) and traj.q.shape == (24, 5, 4)
    assert traj.ts.shape == (24, 5) and traj.result.shape == (24,)
    assert np.all(np.asarray(traj.result) == 0)
    err_q = np.minimum(np.linalg.norm(traj.q - q_ref, axis=-1),
                       np.linalg.norm(traj.q + q_ref, axis=-1))
    assert err_q.max() < 3e-6
    assert np.abs(traj.omega - w_ref).max() < 3e-6
    # one shared step count, about the hardest member's
    steps = np.asarray(traj.stats["num_steps"])
    assert np.all(steps == steps[0])


def test_agrees_with_per_member_solve(batch):
    _, states = batch
    lock = simulate_lockstep(SCENE, states, TS, formulation="quaternion_omega")
    each = jax.jit(jax.vmap(lambda s: simulate(SCENE, s, TS, formulation="quaternion_omega",
                                               throw=False)))(states)
    assert np.abs(lock.omega - each.omega).max() < 3e-6
    hardest = int(np.max(each.stats["num_steps"]))
    shared = int(lock.stats["num_steps"][0])
    # Shared steps follow the envelope of the members' errors: measured 1.22x the hardest
    # member's count with the default DOP853 pair (within 1.2x with Tsitouras 5(4)).
    assert hardest <= shared * 1.05 and shared <= 1.3 * hardest, (shared, hardest)


def test_batch_of_one_is_simulate_to_rounding(batch):
    """The batched and unbatched programs differ by rounding only. The error estimates
    carry a relative rounding of ~1e-6 (a difference of nearly equal sums at rtol 1e-8),
    so the two step sequences part after a few dozen steps: measured over the 24 members,
    up to 5 steps of 140 apart and states up to 2.2e-10 apart after 5 time units."""
    _, states = batch
    for i in (3, 7):
        one = simulate_lockstep(SCENE, take(states, slice(i, i + 1)), TS)
        ref = simulate(SCENE, take(states, i), TS)
        a, b = int(one.stats["num_steps"][0]), int(ref.stats["num_steps"])
        assert abs(a - b) <= 0.05 * b, (a, b)
        np.testing.assert_allclose(one.q[0], ref.q, rtol=0, atol=1e-9)
        np.testing.assert_allclose(one.omega[0], ref.omega, rtol=0, atol=1e-9)


def test_member_order_does_not_matter(batch):
    """The max-norm is symmetric in the members: a permuted batch gives permuted results."""
    _, states = batch
    perm = np.random.default_rng(1).permutation(24)
    a = simulate_lockstep(SCENE, states, TS)
    b = simulate_lockstep(SCENE, take(states, perm), TS)
    np.testing.assert_array_equal(np.asarray(a.q)[perm], b.q)
    np.testing.assert_array_equal(np.asarray(a.omega)[perm], b.omega)


def test_batched_scene(batch):
    """Per-member moments (a scene with a member axis) against per-member solves."""
    _, states = batch
    moments = np.tile([1.0, 2.0, 2.5], (24, 1))
    moments[:, 1] = np.linspace(1.6, 2.4, 24)
    scenes = jax.vmap(lambda m: Scene(RigidBody(m)))(jnp.asarray(moments))
    lock = simulate_lockstep(scenes, states, TS, batched_scene=True)
    for k in (0, 11, 23):
        ref = simulate(Scene(RigidBody(jnp.asarray(moments[k]))), take(states, k), TS,
                       rtol=1e-11, atol=1e-13)
        assert np.abs(lock.omega[k] - ref.omega).max() < 3e-6
        assert np.abs(lock.kinetic_energy[k] - ref.kinetic_energy).max() < 1e-8


def test_gradient_through_lockstep_is_energy_gradient():
    """E(T) = E(0) = ½ ω0·Iω0, so d(Σ E(T))/dω0 = I ω0 per member."""
    omegas = jnp.asarray(directions(4, seed=2))

    @jax.jit
    def total_energy(w):
        traj = simulate_lockstep(SCENE, states_of(w), TS[:2], formulation="quaternion_omega",
                                 rtol=1e-10, atol=1e-12)
        return jnp.sum(traj.kinetic_energy[:, -1])

    grad = jax.grad(total_energy)(omegas)
    np.testing.assert_allclose(grad, MOMENTS[None, :] * omegas, atol=1e-7)


def test_bad_input_names_member(batch):
    _, states = batch
    q = np.array(states.q)
    q[5] = 0.0
    bad = State(jnp.asarray(q), states.qdot)
    with pytest.raises(ValueError, match=r"zero quaternion.*member 5 of 24"):
        simulate_lockstep(SCENE, bad, TS)
    with pytest.raises(eqx.EquinoxRuntimeError, match="zero quaternion"):
        jax.block_until_ready(eqx.filter_jit(lambda s: simulate_lockstep(SCENE, s, TS).omega)(bad))
    with pytest.raises(ValueError, match="event"):
        simulate_lockstep(SCENE, states, TS, formulation="euler_angles")
    with pytest.raises(ValueError, match="leading member axis"):
        simulate_lockstep(SCENE, take(states, 0), TS)
    with pytest.raises(ValueError, match="leading member axis"):
        simulate_lockstep(SCENE, State(states.q, states.qdot[:3]), TS)
    with pytest.raises(ValueError, match="diffrax solver"):
        simulate_lockstep(SCENE, states, TS, solver="exact")


def test_failure_stops_every_member(batch):
    _, states = batch
    with pytest.raises(SimulationError, match=r"member 0 of 24 \(24 failed\).*max_steps=50"):
        simulate_lockstep(SCENE, states, TS, max_steps=50)
    traj = simulate_lockstep(SCENE, states, TS, max_steps=50, throw=False)
    assert np.all(np.asarray(traj.result) == 1)
    assert np.all(np.isnan(np.asarray(traj.omega)[:, -1]))
    assert np.all(np.asarray(traj.t_stop) < TS[-1])


def test_simulate_many_shared_step(tmp_path, batch):
    omegas, states = batch
    summary = lambda tr: {"omega": tr.omega[-1], "steps": tr.stats["num_steps"]}  # noqa: E731
    kwargs = dict(chunk_size=10, summary=summary, progress=False, formulation="quaternion_omega")
    info: dict = {}
    out = ensemble.simulate_many(SCENE, states, TS, shared_step=True, out_dir=tmp_path / "r",
                                 info=info, **kwargs)
    assert info["n_chunks"] == 3 and out["omega"].shape == (24, 3)
    # each chunk is one lockstep solve (the last one padded by repeating its last member)
    for lo in (0, 10, 20):
        idx = np.minimum(np.arange(lo, lo + 10), 23)
        ref = simulate_lockstep(SCENE, take(states, idx), TS, formulation="quaternion_omega")
        real = min(10, 24 - lo)
        np.testing.assert_array_equal(out["omega"][lo:lo + real], ref.omega[:real, -1])
        assert len(set(out["steps"][lo:lo + real].tolist())) == 1
    w_ref = jax.vmap(lambda w: exact.solve(MOMENTS, jnp.array([1.0, 0, 0, 0]), w, TS))(
        jnp.asarray(omegas))[1][:, -1]
    assert np.abs(out["omega"] - w_ref).max() < 3e-6
    meta = json.loads((tmp_path / "r" / "meta.json").read_text())
    assert meta["batched"] == {"group": 10} and meta["metadata"]["simulate"]["shared_step"]
    # resume loads everything, bit for bit; a per-member run may not reuse the folder
    info = {}
    again = ensemble.simulate_many(SCENE, states, TS, shared_step=True, out_dir=tmp_path / "r",
                                   info=info, **kwargs)
    assert info["chunks_loaded"] == 3 and info["chunks_computed"] == 0
    np.testing.assert_array_equal(again["omega"], out["omega"])
    with pytest.raises(ValueError, match="different run"):
        ensemble.simulate_many(SCENE, states, TS, out_dir=tmp_path / "r", shared_step=False,
                               **kwargs)


def test_run_batched_checks_output_axis():
    with pytest.raises(ValueError, match="leading member axis"):
        ensemble.run(lambda m: {"total": jnp.sum(m["x"])}, {"x": np.ones((5, 2))},
                     batched=True, progress=False)


def test_sharded_lockstep_groups_are_device_shares(tmp_path, batch):
    """Over 4 devices each device integrates its quarter of a chunk as one lockstep group."""
    _, states = batch
    code = f"""
    import jax.numpy as jnp
    from jrigid import RigidBody, Scene, initial
    assert len(jax.devices()) == 4
    w = np.load({str(tmp_path / "w.npy")!r})
    states = jax.vmap(lambda x: initial.from_omega(None, x))(jnp.asarray(w))
    info = {{}}
    out = ensemble.simulate_many(Scene(RigidBody(jnp.array([1.0, 2.0, 3.0]))), states,
                                 np.linspace(0.0, {PERIODS} * 2 * np.pi, 5), chunk_size=12,
                                 shared_step=True, progress=False, info=info)
    assert info["group"] == 3 and info["n_devices"] == 4, info
    np.savez({str(tmp_path / "sharded.npz")!r}, **out)
    """
    np.save(tmp_path / "w.npy", directions(24))
    proc = _python(code, XLA_FLAGS="--xla_force_host_platform_device_count=4")
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    with np.load(tmp_path / "sharded.npz") as data:
        sharded = {k: data[k] for k in data.files}
    for k in range(8):
        group = simulate_lockstep(SCENE, take(states, slice(3 * k, 3 * k + 3)), TS,
                                  formulation=ensemble.SWEEP_DEFAULTS["formulation"])
        # the same group and steps; the sharded program rounds alike to about an ulp
        np.testing.assert_allclose(sharded["q"][3 * k:3 * k + 3], group.q, rtol=0, atol=1e-13)
        np.testing.assert_array_equal(sharded["num_steps"][3 * k:3 * k + 3],
                                      group.stats["num_steps"])
    single = ensemble.simulate_many(SCENE, states, TS, chunk_size=12, shared_step=True,
                                    progress=False)
    assert np.abs(sharded["omega"] - single["omega"]).max() < 3e-6


def test_solver_choice_is_used(batch):
    _, states = batch
    a = simulate_lockstep(SCENE, take(states, slice(0, 4)), TS, solver=diffrax.Tsit5(),
                          formulation="quaternion_omega")
    b = simulate_lockstep(SCENE, take(states, slice(0, 4)), TS, formulation="quaternion_omega")
    assert int(a.stats["num_steps"][0]) > 2 * int(b.stats["num_steps"][0])  # 5th vs 8th order
