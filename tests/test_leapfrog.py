"""leapfrog: the chapter's kick–drift–kick stepper (17.45–17.46), its order and its norm.

References: the closed-form torque-free motion (:mod:`jrigid.exact`) and a Dopri8 solve
of the heavy top at rtol 1e-12.
"""

import jax.numpy as jnp
import numpy as np
import pytest
from _simulate import OMEGA0, Q0, TS, same_rotation, top_scene
from _simulate import top_reference as _top_reference
from scipy.stats import linregress

from jrigid import exact, initial
from jrigid.body import RigidBody
from jrigid.leapfrog import leapfrog
from jrigid.scene import Scene


@pytest.fixture(scope="module")
def top_reference():
    return _top_reference()


# --------------------------------------------------------------------------- order


def _leapfrog_errors(variant, top_reference):
    state, ref = top_reference
    ts = TS[:41]  # t ∈ [0, 2]
    errors, dts = [], []
    for k in (2, 4, 8, 16):
        dt = 0.05 / k  # divides the output spacing
        traj = leapfrog(top_scene(), state, ts, dt=dt, variant=variant)
        assert int(traj.stats["num_steps"]) == 40 * k
        errors.append(np.max(np.abs(np.asarray(traj.omega[-1]) - np.asarray(ref.omega[40]))))
        dts.append(dt)
    return linregress(np.log(dts), np.log(errors)).slope


def test_leapfrog_order_two(top_reference):
    slope = _leapfrog_errors("midpoint", top_reference)
    assert 1.9 < slope < 2.1


def test_leapfrog_chapter_listing_is_first_order(top_reference):
    """The listing evaluates q̇ at q(t) instead of q(t + Δt/2): first order."""
    slope = _leapfrog_errors("chapter", top_reference)
    assert 0.9 < slope < 1.1


def test_leapfrog_renormalises(top_reference):
    state, _ = top_reference
    traj = leapfrog(top_scene(), state, TS, dt=0.05)
    assert np.max(np.abs(np.asarray(traj.norm_error))) < 1e-14


def test_free_rotor_error_falls_fourfold_when_the_step_halves():
    """Second order against the closed form (jrigid.exact): e(Δt) / e(Δt/2) ≈ 4."""
    moments = jnp.array([1.0, 2.0, 2.5])
    state = initial.from_omega(Q0, OMEGA0)
    ts = jnp.array([0.0, 1.0, 2.0])
    q_exact, w_exact = exact.solve(moments, Q0, OMEGA0, ts)
    errors = []
    for dt in (0.02, 0.01):
        traj = leapfrog(Scene(RigidBody(moments)), state, ts, dt=dt)
        same_rotation(traj.q, q_exact, 1e-2)  # close, and in the same sign convention
        errors.append(float(np.max(np.abs(np.asarray(traj.omega - w_exact)))))
    assert 3.6 < errors[0] / errors[1] < 4.4, errors


def test_jit_over_the_step_alone_runs_and_checks_the_other_inputs():
    """With only dt traced, the (concrete) inputs' checks ended in a
    TracerBoolConversionError."""
    import jax

    scene = Scene(RigidBody(jnp.array([1.0, 2.0, 3.0])))
    state = initial.from_omega(None, jnp.array([1.0, 0.3, 0.7]))
    ts = jnp.linspace(0.0, 1.0, 3)
    jitted = jax.jit(lambda dt: leapfrog(scene, state, ts, dt=dt).omega)
    np.testing.assert_allclose(jitted(0.01), leapfrog(scene, state, ts, dt=0.01).omega,
                               rtol=1e-12)
    from jrigid.state import State

    bad = State(state.q, state.qdot.at[1].set(jnp.nan))
    with pytest.raises(ValueError, match="not finite"):
        jax.jit(lambda dt: leapfrog(scene, bad, ts, dt=dt).omega)(0.01)


@pytest.mark.parametrize("ts", [np.linspace(0.0, 1.0, 5), np.array([0.0, 0.013, 0.5, 1.0, 2.7])],
                         ids=["even", "uneven"])
def test_reverse_mode_through_the_steps(ts):
    """``jax.grad`` through the leapfrog (concrete ``ts`` and ``dt``: loops of known length)
    matches central differences and forward mode; it was refused ("Reverse-mode
    differentiation does not work for lax.while_loop")."""
    import jax

    state = initial.from_omega(None, jnp.array([1.0, 0.3, 0.7]))
    ts = jnp.asarray(ts)

    def f(m):
        return leapfrog(Scene(RigidBody(m)), state, ts, dt=0.01).q[-1, 1]

    m = jnp.array([1.5, 2.0, 3.0])
    grad = jax.grad(f)(m)
    eps = 1e-6
    central = [(f(m + eps * e) - f(m - eps * e)) / (2 * eps) for e in jnp.eye(3)]
    np.testing.assert_allclose(grad, central, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(grad, jax.jacfwd(f)(m), rtol=1e-12, atol=1e-14)
    # the same steps as with dt traced (each interval's count computed in the program)
    traced = jax.jit(lambda dt: leapfrog(Scene(RigidBody(m)), state, ts, dt=dt))(0.01)
    fixed = leapfrog(Scene(RigidBody(m)), state, ts, dt=0.01)
    assert int(traced.stats["num_steps"]) == int(fixed.stats["num_steps"])
    np.testing.assert_allclose(traced.q, fixed.q, rtol=0, atol=1e-14)


def test_a_step_too_small_to_count_is_refused():
    """dt=1e-300 ended in OverflowError ('Python int too large to convert to C long')."""
    from jrigid.integrate import simulate
    from jrigid.splitting import Splitting

    scene = Scene(RigidBody(jnp.array([1.0, 2.0, 3.0])))
    state = initial.from_omega(Q0, OMEGA0)
    ts = jnp.linspace(0.0, 1.0, 3)
    with pytest.raises(ValueError, match="dt=1e-300 needs 5e.299 steps.*raise dt"):
        leapfrog(scene, state, ts, dt=1e-300)
    with pytest.raises(ValueError, match="dt=1e-300 needs 5e.299 steps.*raise dt"):
        simulate(scene, state, ts, solver=Splitting(dt=1e-300))
