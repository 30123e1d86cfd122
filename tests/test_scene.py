"""scene: holders and loads move the body as the closed forms say (free flight, user
torque), and a pivot adds the parallel-axis inertia."""


import jax.numpy as jnp
import numpy as np
from _simulate import (
    OMEGA0,
    Q0,
    TS,
    power_scene,
)

from jrigid import initial
from jrigid.body import RigidBody
from jrigid.integrate import simulate
from jrigid.scene import FreeFlight, Gravity, Pivot, Scene

# --------------------------------------------------------------------------- holders


def test_free_flight_parabola_and_torque_free_rotation():
    g = jnp.array([0.0, 0.0, -9.81])
    I1, I3 = 1.0, 1.6
    body = RigidBody(jnp.array([I1, I1, I3]), mass=2.0)
    scene = Scene(body, FreeFlight(), Gravity(g))
    x0, v0 = jnp.array([0.0, 1.0, 2.0]), jnp.array([3.0, 0.0, 10.0])
    w_perp, w3 = 0.5, 3.0
    state = initial.from_omega(None, [w_perp, 0.0, w3], x=x0, v=v0)
    ts = jnp.linspace(0.0, 2.0, 41)
    traj = simulate(scene, state, ts, rtol=1e-11, atol=1e-12)
    t = np.asarray(ts)[:, None]
    x0, v0, g = (np.asarray(a)[None, :] for a in (x0, v0, g))
    np.testing.assert_allclose(traj.x, x0 + v0 * t + 0.5 * g * t**2, atol=1e-9)
    np.testing.assert_allclose(traj.v, v0 + g * t, atol=1e-9)
    Omega = (I3 / I1 - 1) * w3  # torque-free symmetric precession (17.47)
    np.testing.assert_allclose(traj.omega[:, 0], w_perp * np.cos(Omega * t[:, 0]), atol=1e-9)
    np.testing.assert_allclose(traj.omega[:, 1], w_perp * np.sin(Omega * t[:, 0]), atol=1e-9)
    np.testing.assert_allclose(traj.energy, traj.energy[0], rtol=1e-10)


# --------------------------------------------------------------------------- loads


def test_user_torque_damping_is_exponential():
    """Spherical body, N = −c ω: ω(t) = ω0 exp(−c t / I)."""
    traj = simulate(power_scene(-0.3, 0.0, np.inf), initial.from_omega(Q0, OMEGA0), TS,
                    rtol=1e-10, atol=1e-12)
    decay = np.exp(-0.3 * np.asarray(TS) / 2.0)[:, None]
    np.testing.assert_allclose(traj.omega, np.asarray(OMEGA0)[None, :] * decay, atol=1e-9)


# ---------------------------------------------------------------- inertia about the support


def test_pivot_uses_the_parallel_axis_inertia():
    """About a pivot: J = diag(I) + M (|r|² 1 − r rᵀ), L = J ω, T = ½ ω·Jω and Euler's
    equations J ω̇ = N − ω × Jω (17.34), here with r off every principal axis."""
    moments, mass, r = np.array([1.0, 1.5, 2.0]), 3.0, np.array([0.2, -0.1, 0.6])
    scene = Scene(RigidBody(jnp.asarray(moments), mass, jnp.asarray(r)), Pivot(), Gravity(9.81))
    J = np.diag(moments) + mass * (r @ r * np.eye(3) - np.outer(r, r))
    omega, torque = np.array([0.3, -1.2, 2.0]), np.array([0.1, 0.4, -0.2])
    np.testing.assert_allclose(scene.inertia(), J, rtol=1e-14)
    np.testing.assert_allclose(scene.angular_momentum(jnp.asarray(omega)), J @ omega, rtol=1e-14)
    np.testing.assert_allclose(scene.kinetic_energy(jnp.asarray(omega)), 0.5 * omega @ J @ omega,
                               rtol=1e-14)
    np.testing.assert_allclose(scene.omega_dot(jnp.asarray(omega), jnp.asarray(torque)),
                               np.linalg.solve(J, torque - np.cross(omega, J @ omega)),
                               rtol=1e-12)
    # Free rotation ignores the centre of mass: the central moments.
    free = Scene(RigidBody(jnp.asarray(moments), mass, jnp.asarray(r)))
    np.testing.assert_allclose(free.inertia(), np.diag(moments), rtol=1e-14)
    np.testing.assert_allclose(free.omega_dot(jnp.asarray(omega), jnp.asarray(torque)),
                               (torque - np.cross(omega, moments * omega)) / moments, rtol=1e-12)
