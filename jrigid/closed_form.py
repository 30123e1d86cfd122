"""``simulate(..., solver="exact")``: closed-form motion instead of an integration.

Two scenes have their motion in closed form: a torque-free body (:mod:`jrigid.exact`,
plus the ballistic parabola of the centre of mass under uniform gravity in free flight),
and the heavy symmetric top on a pivot (:mod:`jrigid.lagrange_top`, the chapter's
Problem 17.2). :func:`solve` evaluates the motion at the output times and builds the same
:class:`~jrigid.trajectory.Trajectory` a numerical solve returns: the closed-form
``q`` and ``ω`` are converted to the formulation's variables with
``formulation.from_state``; the step counts are zero. It works under ``jit``, ``vmap``
and ``grad``, and invalid inputs get the same checks and codes as :func:`jrigid.simulate`.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from jrigid import exact, lagrange_top
from jrigid import quaternion as quat
from jrigid.formulations import AbstractFormulation
from jrigid.scene import Gravity, Scene
from jrigid.solve import finish_sampled, input_checks, normalised, screen
from jrigid.state import State

__all__ = ["ExactMotion", "TopMotion", "check_scene", "solve"]


def check_scene(scene: Scene) -> None:
    """Raise ``ValueError`` unless ``scene`` has a closed form (``solver="exact"``).

    Allowed: a torque-free scene (:attr:`jrigid.scene.Scene.torque_free`: a
    :class:`~jrigid.scene.FreeRotation` or :class:`~jrigid.scene.FreeFlight` holder
    whose loads are only :class:`~jrigid.scene.Gravity`), or a Lagrange top
    (:func:`jrigid.lagrange_top.applies`: a symmetric body, ``I1 == I2``, with its centre
    of mass on the symmetry axis, on a :class:`~jrigid.scene.Pivot` under gravity only).
    """
    if scene.torque_free or lagrange_top.applies(scene):
        return
    names = ", ".join(type(load).__name__ for load in scene.loads)
    holder = type(scene.holder).__name__
    if scene.holder.pivoted:
        try:
            lagrange_top.check_scene(scene)
        except ValueError as error:
            why = str(error)
        if not any(isinstance(load, Gravity) for load in scene.loads):
            why += (" (a body on a Pivot without gravity is torque free, but it turns about"
                    " the pivot, whose inertia tensor is not diagonal in the body's principal"
                    " frame unless the centre of mass lies on a principal axis)")
        raise ValueError(
            f"solver='exact' needs a torque-free scene or a heavy symmetric top; {why}: "
            "use a diffrax solver"
        )
    raise ValueError(
        f"solver='exact' needs a torque-free scene; this scene has a {holder} with "
        f"{names} load(s): use a diffrax solver"
    )


class ExactMotion(eqx.Module):
    """Closed-form motion of a torque-free scene as a dense output (``evaluate(t)``).

    ``evaluate(t)`` returns the formulation's state at time ``t``: ``q, ω`` from
    :func:`jrigid.exact.evaluate` and, in free flight, ``x = x0 + v0 Δt + ½ g Δt²``,
    ``v = v0 + g Δt`` with ``Δt = t − t0`` and ``g`` the sum of the scene's gravity fields.
    """

    consts: exact.ExactConstants
    t0: jax.Array
    x0: jax.Array | None
    v0: jax.Array | None
    scene: Scene
    formulation: AbstractFormulation = eqx.field(static=True)

    def evaluate(self, t):
        dt = t - self.t0
        q, omega = exact.evaluate(self.consts, dt)
        x = v = None
        if self.scene.translates:
            g = jnp.zeros(3, dtype=dt.dtype)
            for load in self.scene.loads:
                g = g + load.g
            x = self.x0 + dt * self.v0 + (0.5 * dt * dt) * g
            v = self.v0 + dt * g
        state = State(q, quat.derivative(q, omega), x, v)
        return self.formulation.from_state(self.scene, state)


class TopMotion(eqx.Module):
    """Closed-form motion of a heavy symmetric top as a dense output (``evaluate(t)``)."""

    consts: lagrange_top.TopConstants
    t0: jax.Array
    scene: Scene
    formulation: AbstractFormulation = eqx.field(static=True)

    def evaluate(self, t):
        q, omega = lagrange_top.evaluate(self.consts, t - self.t0)
        state = State(q, quat.derivative(q, omega))
        return self.formulation.from_state(self.scene, state)


def _without_rounding_noise(omega: jax.Array) -> jax.Array:
    """``omega (3,)`` with the components below ``8 eps |ω|`` set to zero (their
    derivatives kept).

    ``ω`` comes back from ``(q, q̇)``, and in a compiled program a spin about a body axis,
    ``(0, 2, 0)``, comes back as ``(4e-17, 2, 4e-18)``: no longer a spin. The closed form
    of that motion differs from the spin's where it matters: about the intermediate axis
    the rounding grows as ``e^{rt}`` and flips the body after some 40/r, and the
    derivatives of the near-spin's elliptic constants lose ``eps / δ`` (O(1) at
    ``δ = 1e-17``), where the spin's are exact.
    """
    eps = jnp.finfo(omega.dtype).eps
    noise = jnp.abs(omega) <= 8 * eps * jnp.max(jnp.abs(omega))
    return jnp.where(noise, omega - jax.lax.stop_gradient(omega), omega)


@eqx.filter_jit
def solve(scene, state, ts, rtol, atol, formulation, dense):
    """The closed-form :class:`~jrigid.trajectory.Trajectory` at ``ts``, and the check cause.

    Args:
        scene, state, ts, rtol, atol: as prepared by :func:`jrigid.solve.prepare`
            (``rtol``/``atol`` only take part in the input checks).
        formulation: the formulation whose variables fill ``Trajectory.y``.
        dense: keep the closed form for :meth:`~jrigid.trajectory.Trajectory.at`.

    Returns:
        ``(trajectory, cause, messages)``: ``cause ()`` the index of the first failed
        input check (meaningful where the result is ``invalid_input``) and the checks'
        messages.
    """
    checks = input_checks(formulation, scene, state, ts, rtol, atol)
    if not scene.torque_free:  # (a concrete body was checked by check_scene)
        checks.extend(lagrange_top.value_checks(scene))
    messages = tuple(m for _, m in checks)
    invalid, cause, scene, state, ts, rtol, atol = screen(checks, scene, state, ts, rtol, atol)
    state = normalised(state)
    omega = _without_rounding_noise(state.omega)
    if scene.torque_free:
        consts = exact.prepare(scene.body.moments, state.q, omega)
        motion = ExactMotion(consts, ts[0], state.x, state.v, scene, formulation)
    else:
        consts = lagrange_top.prepare_scene(scene, state.q, omega)
        motion = TopMotion(consts, ts[0], scene, formulation)
    ys = jax.vmap(motion.evaluate)(ts)
    traj = finish_sampled(scene, formulation, ts, ys, invalid, motion if dense else None)
    return traj, cause, messages
