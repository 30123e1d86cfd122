"""Shared scenes, initial state and reference solves of the integrator tests.

``test_integrate``, ``test_formulations``, ``test_leapfrog``, ``test_trajectory``,
``test_scene`` and ``test_solve`` integrate the same free body and heavy top from the
same initial state; the references are computed once per test process (Dopri8 at rtol
1e-12, checked against scipy DOP853 in ``test_dynamics_analytic``).
"""

import functools

import diffrax
import jax.numpy as jnp
import numpy as np
from scipy.spatial.transform import Rotation

from jrigid import initial
from jrigid.body import RigidBody
from jrigid.integrate import simulate
from jrigid.scene import Gravity, Pivot, Scene, Torque

N_OUT = 201  # shared with test_dynamics_analytic so compiled solves are reused
MOMENTS = jnp.array([1.0, 2.0, 3.0])

# Q0 tilts body axis 3 well away from space z so ZXZ Euler angles stay regular.
Q0 = jnp.array(Rotation.from_euler("ZXZ", [0.2, 1.2, -0.4]).as_quat(scalar_first=True))
OMEGA0 = jnp.array([0.2, 0.3, 1.5])  # near the stable axis 3: θ stays away from 0 and π
TS = jnp.linspace(0.0, 10.0, N_OUT)


def scipy_rot(q):
    return Rotation.from_quat(np.array(q, dtype=float), scalar_first=True)


def same_rotation(q1, q2, atol):
    sign = np.sign(np.sum(np.asarray(q1) * np.asarray(q2), axis=-1))[..., None]
    np.testing.assert_allclose(sign * np.asarray(q1), np.asarray(q2), atol=atol)


def free_scene():
    return Scene(RigidBody(MOMENTS))


def top_scene():
    body = RigidBody(jnp.array([0.5, 0.5, 0.8]), com=jnp.array([0.0, 0.0, 1.0]))
    return Scene(body, Pivot(), Gravity(1.0))


@functools.cache
def free_reference():
    """Dopri8 at rtol 1e-12 from ``(Q0, OMEGA0)`` at ``TS``."""
    return simulate(free_scene(), initial.from_omega(Q0, OMEGA0), TS,
                    solver=diffrax.Dopri8(), rtol=1e-12, atol=1e-14)


@functools.cache
def top_reference():
    """``(state, trajectory)`` of the heavy top, Dopri8 at rtol 1e-12 at ``TS``."""
    state = initial.from_euler_rates([0.0, 0.6, 0.0], [0.3, 0.0, 5.0])
    traj = simulate(top_scene(), state, TS, solver=diffrax.Dopri8(), rtol=1e-12, atol=1e-14)
    return state, traj


def _power_torque(t, kin, params):
    """c |ω|^(2 power) ω, turning NaN after t_nan (one function: one compiled solve)."""
    w2 = jnp.dot(kin.omega, kin.omega)
    nan_after = jnp.where(t > params["t_nan"], jnp.nan, 1.0)
    return params["c"] * w2 ** params["power"] * kin.omega * nan_after


def power_scene(c, power, t_nan):
    """A spherical body (I = 2) under the torque ``c |ω|^(2 power) ω``, NaN after
    ``t_nan``."""
    params = {"c": c, "power": power, "t_nan": t_nan}  # floats become traced arrays
    return Scene(RigidBody(jnp.full(3, 2.0)), loads=(Torque(_power_torque, params),))
