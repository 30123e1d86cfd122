"""A small solve on XLA:CPU's fast path (``jrigid._dispatch``): synchronous dispatch set on
import, the default solve compiled into one kernel, and derivatives through it."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jrigid import initial, simulate
from jrigid._dispatch import one_kernel
from jrigid.body import RigidBody
from jrigid.inertia._checks import _sorted3
from jrigid.scene import Gravity, Pivot, Scene


def _run(code: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=env,
                          capture_output=True, text=True, timeout=300)


_READ = "from jax._src import xla_bridge; print(xla_bridge._CPU_ENABLE_ASYNC_DISPATCH.value)"


_JAX_FIRST = """
import jax
import jrigid
import jax.numpy as jnp
jnp.zeros(1).block_until_ready()
"""

_JRIGID_FIRST = """
import sys
import jrigid
assert "jax" not in sys.modules  # importing jrigid alone still does not import JAX
import jax.numpy as jnp
jnp.zeros(1).block_until_ready()
"""


@pytest.mark.parametrize("code", [_JAX_FIRST, _JRIGID_FIRST], ids=["jax-first", "jrigid-first"])
def test_importing_jrigid_turns_asynchronous_cpu_dispatch_off(code):
    out = _run(code + _READ)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False"]


def test_a_users_setting_after_import_wins():
    out = _run(f"""
        import jrigid, jax
        jax.config.update("jax_cpu_enable_async_dispatch", True)
        {_READ}
    """)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["True"]


def _f(x, y):
    return {"a": jnp.sin(x) * y[0], "b": jnp.cumsum(x * x) + y[1], "n": jnp.argmax(x)}


def test_one_kernel_gives_the_functions_values_and_derivatives():
    x, y = jnp.array([0.3, -1.2, 2.0]), jnp.array([1.5, -0.5])
    g = one_kernel(_f)
    for k in ("a", "b", "n"):
        np.testing.assert_array_equal(g(x, y)[k], _f(x, y)[k])

    def loss(h):
        return lambda x, y: jnp.sum(h(x, y)["a"] * h(x, y)["b"])

    want = jax.grad(loss(_f), argnums=(0, 1))(x, y)
    for got in (
        jax.grad(loss(g), argnums=(0, 1))(x, y),
        jax.jit(jax.grad(loss(g), argnums=(0, 1)))(x, y),
        jax.grad(jax.jit(loss(g)), argnums=(0, 1))(x, y),
        jax.jacfwd(loss(g), argnums=(0, 1))(x, y),
    ):
        for a, b in zip(got, want, strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-12)
    xs = jnp.stack([x, 2 * x])
    batched = jax.vmap(g, in_axes=(0, None))(xs, y)
    np.testing.assert_allclose(batched["b"][1], _f(xs[1], y)["b"], rtol=1e-12)


def test_one_kernel_in_reverse_mode_differentiates_under_vmap():
    """``one_kernel(fn, reverse=True)`` (a ``custom_vjp``, for a solve whose adjoint is
    itself one): values and reverse-mode derivatives of ``fn``, also of a loss summed
    over ``vmap``; forward mode is refused."""
    x, y = jnp.array([0.3, -1.2, 2.0]), jnp.array([1.5, -0.5])
    g = one_kernel(_f, reverse=True)
    for k in ("a", "b", "n"):
        np.testing.assert_array_equal(g(x, y)[k], _f(x, y)[k])

    def loss(h):
        return lambda x, y: jnp.sum(h(x, y)["a"] * h(x, y)["b"])

    want = jax.grad(loss(_f), argnums=(0, 1))(x, y)
    for got in (jax.grad(loss(g), argnums=(0, 1))(x, y),
                jax.jit(jax.grad(loss(g), argnums=(0, 1)))(x, y)):
        for a, b in zip(got, want, strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-12)
    xs = jnp.stack([x, 2 * x])

    def summed(h):
        return lambda xs: jnp.sum(jax.vmap(loss(h), in_axes=(0, None))(xs, y))

    np.testing.assert_allclose(jax.grad(summed(g))(xs), jax.grad(summed(_f))(xs), rtol=1e-12)
    with pytest.raises(TypeError, match="custom_vjp"):
        jax.jacfwd(loss(g))(x, y)


def test_gradient_of_a_loss_over_vmapped_simulate():
    """``jax.grad`` of a loss summed over ``jax.vmap(simulate)`` (the default, reverse-mode
    adjoint) equals each member's own gradient (it raised a forward-mode error)."""
    scene = Scene(RigidBody(jnp.array([1.0, 2.0, 3.0])))
    ts = jnp.linspace(0.0, 1.0, 3)
    spins = jnp.array([[1.0, 0.3, 0.7], [0.5, 1.0, 0.2]])

    def one(w):
        traj = simulate(scene, initial.from_omega(None, w), ts)
        return traj.omega[-1, 0] + traj.q[-1, 1]

    got = jax.grad(lambda ws: jnp.sum(jax.vmap(one)(ws)))(spins)
    member = jax.jit(jax.grad(one))  # one program for every member (not one per call)
    np.testing.assert_allclose(got, jnp.stack([member(w) for w in spins]), rtol=1e-12)
    assert np.all(np.abs(got) > 1e-3)


def test_one_kernel_compiles_into_a_single_kernel():
    text = jax.jit(one_kernel(_f)).lower(jnp.ones(3), jnp.ones(2)).compile().as_text()
    entry = text[text.index("ENTRY"):]
    assert "xla_cpu_small_call" in entry
    assert " while(" not in entry


def _scenes():
    rotor = Scene(RigidBody(jnp.array([1.0, 2.0, 3.0])))
    top = Scene(RigidBody(jnp.array([1.0, 1.0, 0.5]), mass=1.0, com=jnp.array([0.0, 0.0, 1.0])),
                holder=Pivot(), loads=(Gravity(1.0),))
    return [rotor, top]


@pytest.mark.parametrize("n_out", [2, 11])
@pytest.mark.parametrize("scene", _scenes(), ids=["rotor", "top"])
def test_the_default_solve_is_one_kernel(scene, n_out):
    # Anything XLA:CPU cannot put in a kernel (a sort, a scatter, a runtime error such as
    # diffrax's checks of SaveAt(ts=...)) in the default path would put ~100 operations
    # back at the top of the program.
    state = initial.from_omega(jnp.array([1.0, 0.1, 0.0, 0.0]), jnp.array([0.3, 0.2, 5.0]))
    ts = jnp.linspace(0.0, 1.0, n_out)
    solve = jax.jit(lambda s: simulate(scene, s, ts, throw=False).q)
    entry = solve.lower(state).compile().as_text()
    entry = entry[entry.index("ENTRY"):]
    assert entry.count("xla_cpu_small_call") == 1
    assert " while(" not in entry and "custom-call(" not in entry


@pytest.mark.parametrize("scene", _scenes(), ids=["rotor", "top"])
def test_outputs_saved_by_the_controller_match_diffrax_saving_them(scene):
    # The default saves through its step-size controller; a user's SaveAt(ts=...) makes
    # diffrax save. Same steps, same interpolation: the same outputs.
    state = initial.from_omega(jnp.array([1.0, 0.1, 0.0, 0.0]), jnp.array([0.3, 0.2, 5.0]))
    ts = jnp.concatenate([jnp.array([0.0, 1e-3]), jnp.linspace(0.5, 7.0, 40)])
    ours = simulate(scene, state, ts)
    theirs = simulate(scene, state, ts, saveat=diffrax.SaveAt(ts=ts))
    assert int(ours.stats["num_steps"]) == int(theirs.stats["num_steps"])
    np.testing.assert_allclose(ours.q, theirs.q, atol=1e-13)
    np.testing.assert_allclose(ours.omega, theirs.omega, atol=1e-12)


def test_two_output_times_give_the_end_state_of_a_longer_output():
    scene = _scenes()[1]
    state = initial.from_omega(jnp.array([1.0, 0.1, 0.0, 0.0]), jnp.array([0.3, 0.2, 5.0]))
    two = simulate(scene, state, jnp.array([0.0, 5.0]))
    three = simulate(scene, state, jnp.array([0.0, 2.5, 5.0]))
    assert int(two.stats["num_steps"]) == int(three.stats["num_steps"])
    np.testing.assert_allclose(two.q[-1], three.q[-1], atol=1e-13)
    np.testing.assert_allclose(two.omega[-1], three.omega[-1], atol=1e-13)
    np.testing.assert_array_equal(two.q[0], three.q[0])
    np.testing.assert_array_equal(three.q[0], state.q)  # the initial state, as given


@pytest.mark.parametrize("n_out", [2, 21])
def test_an_exhausted_budget_leaves_the_outputs_after_the_stop_nan(n_out):
    scene = _scenes()[0]
    state = initial.from_omega(omega=jnp.array([1.0, 0.3, 0.7]))
    ts = jnp.linspace(0.0, 100.0, n_out)
    traj = simulate(scene, state, ts, max_steps=5, throw=False)
    assert int(traj.result) != 0 and float(traj.t_stop) < 100.0
    reached = np.asarray(ts) <= float(traj.t_stop)
    assert np.all(np.isfinite(np.asarray(traj.q)[reached]))
    assert np.all(np.isnan(np.asarray(traj.q)[~reached]))


def test_sorted3_sorts_exactly():
    rng = np.random.default_rng(0)
    m = rng.normal(size=(500, 3)) * 10.0 ** rng.integers(-8, 8, size=(500, 1))
    m[:50, 1] = m[:50, 0]  # ties
    m[50:60] = 1.0
    np.testing.assert_array_equal(_sorted3(jnp.asarray(m)), np.sort(m, axis=-1))


def test_saving_controller_and_saved_refuse_what_they_cannot_use():
    from jrigid.solve import SavingController, saved
    from jrigid.solvers import TightDop853

    interp = TightDop853.interpolation_cls
    kw = dict(rtol=1e-6, atol=1e-8)
    with pytest.raises(ValueError, match="output_ts"):
        SavingController(**kw, interpolation_cls=interp)
    with pytest.raises(ValueError, match="output_ts"):
        SavingController(**kw, output_ts=jnp.ones((2, 2)), interpolation_cls=interp)
    with pytest.raises(ValueError, match="interpolation_cls"):
        SavingController(**kw, output_ts=jnp.array([0.0, 1.0]))
    with pytest.raises(ValueError, match="loop_kind"):
        SavingController(**kw, output_ts=jnp.array([0.0, 1.0]), interpolation_cls=interp,
                         loop_kind="bounded")
    sol = diffrax.diffeqsolve(diffrax.ODETerm(lambda t, y, a: -y), diffrax.Tsit5(), 0.0, 1.0,
                              0.1, jnp.ones(2))
    with pytest.raises(ValueError, match="controller_state"):
        saved(sol, jnp.array([0.0, 1.0]))


def test_a_plain_call_returns_its_inputs_and_computes_quantities_when_read():
    # What a plain call's program returns is what it costs (each output is initialised
    # and copied outside the kernel): the states, q, ω and the outcome only.
    scene = _scenes()[1]
    state = initial.from_omega(jnp.array([1.0, 0.1, 0.0, 0.0]), jnp.array([0.3, 0.2, 5.0]))
    ts = jnp.linspace(0.0, 1.0, 3)
    traj = simulate(scene, state, ts)
    assert traj.scene is scene and traj.ts is ts
    assert not {"L", "L_space", "axes", "kinetic_energy"} & set(vars(traj))
    np.testing.assert_allclose(traj.q, traj.y.q / np.linalg.norm(traj.y.q, axis=-1)[:, None],
                               rtol=1e-15)
    inertia = np.asarray(scene.inertia())
    np.testing.assert_allclose(traj.L, np.asarray(traj.omega) @ inertia.T, rtol=1e-13)
    assert "L" in vars(traj)
