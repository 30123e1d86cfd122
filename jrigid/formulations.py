"""Equations of motion as pure vector fields, one class per choice of variables.

Every formulation turns the user's :class:`~jrigid.state.State` into its own variables
(:meth:`~AbstractFormulation.from_state`), evaluates ``dy/dt`` for one scene
(:meth:`~AbstractFormulation.vector_field`, the diffrax ``f(t, y, args)`` with
``args = scene``), and reports the kinematics of a state
(:meth:`~AbstractFormulation.kinematics`). All act on one unbatched state.

- ``quaternion_acceleration`` (default): variables ``(q, q̇[, x, v])``; ω from (17.42),
  ω̇ from Euler's equations (17.34/17.35), q̈ from (17.50);
- ``quaternion_omega``: ``(q, ω[, x, v])``; q̇ from (17.44), ω̇ from (17.34/17.35);
- ``body_omega``: ``ω`` alone, (17.35); no orientation (Problem 17.3);
- ``euler_angles``: ``((φ, θ, ψ), ω[, x, v])`` ZXZ; angle rates by inverting (17.36),
  ω̇ from (17.35).

**Quaternion acceleration (17.50).** With ``q̇ = ½ q ⊗ (0, ω)``,
``q̈ = ½ q̇ ⊗ (0, ω) + ½ q ⊗ (0, ω̇)``; on ``|q| = 1`` this is the chapter's
``q̈ = ½ Wᵀ (ω̇, −2 Σ q̇ₘ²) = ½ q ⊗ (0, ω̇) − |q̇|² q``. The stages of a Runge–Kutta step
lie off that sphere, where the ways of writing (17.50) differ. What is integrated is
``q̈ = q̇ ⊗ p + ½ q ⊗ (0, ω̇)`` with ``p = q⁻¹ ⊗ q̇ = (s, ω/2)``: ω as in (17.42),
``2 vec(q* ⊗ q̇)/|q|²``, and ``s = q·q̇/|q|²``. For any state ``q̇ = q ⊗ p``, and this
field gives ``ṗ = ½ (0, ω̇)``: off the constraint the motion is the unit motion scaled by
``exp(s t)``, ``s`` constant, so a stage's error in ``|q|`` or in ``q·q̇`` never reaches
the rotation ``q/|q|`` or ω. The chapter's cubic ``−|q̇|² q`` (``centripetal=True``)
turns a stage's error in ``|q|`` into an error in its rate of turning, that is in the
phase. Measured on the hard cases of ``benchmarks/hard_cases.py`` (rtol 1e-6 … 1e-10,
DOP853 with projection), the orientation error is 8–16× smaller on the fast tops, the
thin rod and near the separatrix at ε = 1e-6 (2.3–3× at ε = 1e-4), at the same steps.
The constraint manifold ``|q|² = 1, q·q̇ = 0`` is invariant; off it ``|q|`` changes at
the constant rate ``s``, so without a remedy step errors make ``|q|`` drift (the rotation
and ω do not see it). Two remedies: projection after each step (:meth:`AbstractFormulation.project`,
used by :func:`jrigid.simulate` through :class:`jrigid.solve.ProjectedSolver`) and the
stabilising term ``−(2k c + ½ k² e) q / |q|²`` added to ``q̈`` (``e = |q|² − 1``,
``c = q·q̇``, ``stabilization = γ``, ``k = γ |ω|``), which turns the residual dynamics
into ``ë + 2k ė + k² e = 0`` to first order: a decay at rate ``k`` without stiffness.
Over 10⁴ periods of a free rotor (``benchmarks/constraint_drift.py``) both hold ``|q| − 1``
and ``q·q̇`` near rtol or below; the projection also restores the energy and ``|L|`` to
rounding, which is why it is the default.

**Euler angles.** Inverting (17.36): ``φ̇ = (ω1 sin ψ + ω2 cos ψ)/sin θ``,
``θ̇ = ω1 cos ψ − ω2 sin ψ``, ``ψ̇ = ω3 − φ̇ cos θ``. The rates blow up as
``sin θ → 0`` (gimbal lock): the formulation supplies a terminating diffrax event at
``|sin θ| < min_sin_theta`` or at a change of sign of ``sin θ`` within a step, which
:func:`jrigid.simulate` reports as a failure (an initial state at gimbal lock is
rejected).
"""

from __future__ import annotations

import functools
from typing import ClassVar

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from jrigid import linalg
from jrigid import quaternion as quat
from jrigid._checks import check_number
from jrigid.invariants import Invariants, restore
from jrigid.scene import Scene
from jrigid.state import Kinematics, State, omega_from_rate

__all__ = [
    "AbstractFormulation",
    "BodyOmega",
    "EulerAngles",
    "EulerState",
    "FORMULATIONS",
    "QuaternionAcceleration",
    "QuaternionOmega",
    "QuaternionOmegaState",
    "check_scene",
    "get_formulation",
]


def _translation_rates(scene: Scene, v, force):
    if not scene.translates:
        return None, None
    return v, force / scene.body.mass


def _traced_once(method):
    """``method`` as an ``equinox.filter_jit`` function: traced once per input structure
    and then reused (by every stage of a Runge–Kutta step, by the projection after it, and
    again by each autodiff transformation of the solve) and inlined into the program that
    calls it. This halves the tracing of a solve and cuts that of its gradient by more;
    the compiled program, and so its speed, are unchanged."""
    return eqx.filter_jit(method)


class AbstractFormulation(eqx.Module):
    """Interface of a formulation (all methods act on one unbatched state).

    Class attributes: ``name`` (str) and ``has_orientation`` (bool).
    """

    name: ClassVar[str]
    has_orientation: ClassVar[bool] = True
    carries_quaternion: ClassVar[bool] = False

    def check_scene(self, scene: Scene) -> None:
        """Raise ``ValueError`` if the formulation cannot represent ``scene``."""

    def from_state(self, scene: Scene, state: State):
        """Formulation variables from a :class:`~jrigid.state.State` (``q`` unit)."""
        raise NotImplementedError

    def kinematics(self, scene: Scene, y) -> Kinematics:
        """:class:`~jrigid.state.Kinematics` of a state (``q`` normalised)."""
        raise NotImplementedError

    def vector_field(self, t, y, scene: Scene):
        """``dy/dt`` (the diffrax vector field with ``args = scene``)."""
        raise NotImplementedError

    def project(self, y, scene: Scene, invariants: Invariants | None = None):
        """Nearest point of the constraint manifold (identity if there is none).

        With ``invariants`` (:class:`~jrigid.invariants.Invariants`), formulations that
        carry ``(q, ω)`` also restore the scene's conserved quantities
        (:func:`jrigid.invariants.project`).
        """
        return y

    def raw_quaternion(self, y) -> jax.Array | None:
        """The integrated, unnormalised ``q`` (``None`` if not a variable)."""
        return None

    def tangent_error(self, y) -> jax.Array | None:
        """``q·q̇`` for a formulation that carries ``q̇`` (else ``None``)."""
        return None

    def event(self) -> diffrax.Event | None:
        """A terminating diffrax event signalling a breakdown, or ``None``."""
        return None

    def step_tolerances(self, rtol, atol, eps):
        """The ``(rtol, atol)`` jrigid's step-size controller works to when ``(rtol, atol)``
        are asked for (scalars; ``eps`` the machine epsilon of the solve's dtype): the
        same, unless the formulation's result errs more per local error than its
        variables show (:class:`QuaternionAcceleration`)."""
        return rtol, atol

    def step_acceptance(self) -> float:
        """The scaled error below which jrigid's step-size controller keeps a step, the
        error it steps to unchanged
        (:attr:`~jrigid.solve.stepping.VectorPIDController.acceptance`): 1, as in
        diffrax, unless the formulation says otherwise (:class:`QuaternionAcceleration`)."""
        return 1.0

    def domain_error(self, scene: Scene, state: State) -> tuple[jax.Array, str] | None:
        """``(bad, message)`` if an initial state can lie outside the formulation's domain."""
        return None


def _check_number(name: str, value, low: float) -> None:
    check_number(f"QuaternionAcceleration {name}", value, low)


class QuaternionAcceleration(AbstractFormulation):
    """State ``(q, q̇)``: ω from (17.42), ω̇ from Euler's equations, q̈ from (17.50).

    Attributes:
        stabilization: ``γ ≥ 0``, gain of the constraint-stabilising term
            ``−(2k (q·q̇) + ½ k² (|q|² − 1)) q / |q|²`` with ``k = γ |ω|`` (0 = off).
        centripetal: ``False`` (default): ``q̈ = q̇ ⊗ p + ½ q ⊗ (0, ω̇)``,
            ``p = q⁻¹ ⊗ q̇``;
            ``True``: the chapter's ``½ Wᵀ (ω̇, −2 Σ q̇ₘ²) = ½ q ⊗ (0, ω̇) − |q̇|² q``
            (jrigid 0.1's field). Equal on ``|q| = 1``; off it (inside a Runge–Kutta
            step) the second is less accurate (module docstring). For comparison and
            teaching.
        tolerance_scale: ``s ≥ 1``: jrigid's step-size controller works to ``rtol / s``
            and ``atol / s``, but not below ``100 eps`` of the solve's dtype (or ``rtol``,
            if that is smaller: float32 at its default rtol is not tightened). In this
            form ω is ``2 q* ⊗ q̇``, so it carries the orientation's error, where the
            ``(q, ω)`` form integrates ω by an equation of its own; at the same tolerance
            its error was 1.7–7.9× that form's on the nearly symmetric body, near the
            separatrix and on Hairer's rigid body (``docs/benchmarks.md``). ``s = 6``
            (with the default ``acceptance``) brings it within 1.9× of it on every hard
            case at rtol 1e-4, 1e-6, …, 1e-12 (but not at every tolerance near the
            separatrix at ε = 1e-6, where around rtol 1e-10 the error jumps between
            0.04 and 0.5·rtol), for ``6^(1/9) ≈ 1.2×`` the steps at a given
            rtol; the steps at a given error are unchanged (the error is proportional to
            the tolerance). 1 turns it off.
        acceptance: ``c ≥ 1``: jrigid's step-size controller keeps a step whose
            scaled error is below ``c`` instead of 1, choosing every step as before
            (:attr:`~jrigid.solve.stepping.VectorPIDController.acceptance`): fewer
            steps are redone. With ``c = 4.6`` (the default) the steps (rejected ones
            included) to reach a given error from 1e-4 to 1e-10 fell 12–16 % on a free
            rotor, 2–8 % near the intermediate axis, 6–16 % on a general body and up to
            9 % near the separatrix, and stayed within 1 % on the heavy tops (which
            redo no steps). The error per tolerance grew by up to 4.4× (the thin rod at
            rtol 1e-4: 0.00025 → 0.0011·rtol) and stayed within 0.13·rtol to 1e-10
            (``docs/benchmarks.md``). The ``(q, ω)`` form took up to
            22 % more steps near the separatrix with the same setting, so it keeps 1.
    """

    name: ClassVar[str] = "quaternion_acceleration"
    carries_quaternion: ClassVar[bool] = True
    stabilization: float = eqx.field(static=True, default=0.0)
    centripetal: bool = eqx.field(static=True, default=False)
    tolerance_scale: float = eqx.field(static=True, default=6.0)
    acceptance: float = eqx.field(static=True, default=4.6)

    def __check_init__(self):
        _check_number("stabilization", self.stabilization, 0)
        flag = self.centripetal
        if not isinstance(flag, bool):
            raise ValueError(
                f"QuaternionAcceleration centripetal must be True or False, got {flag!r}"
            )
        _check_number("tolerance_scale", self.tolerance_scale, 1)
        _check_number("acceptance", self.acceptance, 1)

    def step_acceptance(self):
        """:attr:`acceptance`."""
        return self.acceptance

    def step_tolerances(self, rtol, atol, eps):
        """``(rtol, atol) / s`` with ``s = tolerance_scale``, the relative one kept
        at or above ``min(rtol, 100 eps)`` and the absolute one scaled alike."""
        if self.tolerance_scale == 1:
            return rtol, atol
        floor = jnp.minimum(rtol, 100 * eps)
        tight = jnp.maximum(rtol / self.tolerance_scale, floor)
        ratio = jnp.where(rtol > 0, tight / jnp.where(rtol > 0, rtol, 1.0),
                          1.0 / self.tolerance_scale)
        return tight, atol * ratio

    def from_state(self, scene, state):
        return self.project(state, scene)

    def kinematics(self, scene, y):
        return Kinematics(linalg.unit(y.q), omega_from_rate(y.q, y.qdot), y.x, y.v)

    @_traced_once
    def vector_field(self, t, y, scene):
        q, qd = y.q, y.qdot
        n2 = linalg.dot(q, q)
        # q̈ = turning + ½ q ⊗ (0, ω̇) (17.50); the module docstring says why the turning
        # term is q̇ ⊗ p by default and not the chapter's −|q̇|² q
        if self.centripetal:
            omega = quat.angular_velocity(q, qd) * (1.0 / n2)  # (17.42) off |q| = 1 too
            turning = -linalg.dot(qd, qd) * q
        else:
            # q̇ = q ⊗ p with p = q⁻¹ ⊗ q̇ = (s, ω/2): ω from (17.42) off |q| = 1 too, and s
            # the rate at which |q| changes (zero on the constraint)
            p = quat.multiply(quat.conjugate(q), qd) * (1.0 / n2)
            omega = 2.0 * p[..., 1:]
            turning = quat.multiply(qd, p)
        kin = Kinematics(linalg.unit(q), omega, y.x, y.v, q_raw=q)
        force, torque = scene.wrench(t, kin)
        omega_dot = scene.omega_dot(omega, torque)
        qdd = turning + quat.derivative(q, omega_dot)
        if self.stabilization:
            k = self.stabilization * jnp.sqrt(linalg.dot(omega, omega))
            c = linalg.dot(q, qd)
            e = n2 - 1.0
            qdd = qdd - ((2.0 * k * c + 0.5 * k * k * e) / n2) * q
        xd, vd = _translation_rates(scene, y.v, force)
        return State(qd, qdd, xd, vd)

    @_traced_once
    def project(self, y, scene, invariants=None):
        q = linalg.unit(y.q)
        q, omega = restore(scene, invariants, q, omega_from_rate(y.q, y.qdot))
        return State(q, quat.derivative(q, omega), y.x, y.v)

    def raw_quaternion(self, y):
        return y.q

    def tangent_error(self, y):
        return linalg.dot(y.q, y.qdot)


class QuaternionOmegaState(eqx.Module):
    """Variables of :class:`QuaternionOmega`: ``q (4,)``, ``omega (3,)``, ``x, v``."""

    q: jax.Array
    omega: jax.Array
    x: jax.Array | None = None
    v: jax.Array | None = None


class QuaternionOmega(AbstractFormulation):
    """First-order state ``(q, ω)``: ``q̇ = ½ q ⊗ (0, ω)`` (17.44), ω̇ from (17.34/17.35)."""

    name: ClassVar[str] = "quaternion_omega"
    carries_quaternion: ClassVar[bool] = True

    def from_state(self, scene, state):
        return QuaternionOmegaState(state.q, state.omega, state.x, state.v)

    def kinematics(self, scene, y):
        return Kinematics(linalg.unit(y.q), y.omega, y.x, y.v)

    @_traced_once
    def vector_field(self, t, y, scene):
        kin = Kinematics(linalg.unit(y.q), y.omega, y.x, y.v, q_raw=y.q)
        force, torque = scene.wrench(t, kin)
        qd = quat.derivative(y.q, y.omega)
        xd, vd = _translation_rates(scene, y.v, force)
        return QuaternionOmegaState(qd, scene.omega_dot(y.omega, torque), xd, vd)

    @_traced_once
    def project(self, y, scene, invariants=None):
        q, omega = restore(scene, invariants, linalg.unit(y.q), y.omega)
        return QuaternionOmegaState(q, omega, y.x, y.v)

    def raw_quaternion(self, y):
        return y.q


class BodyOmega(AbstractFormulation):
    """Body-frame ``ω`` alone, Euler's equations (17.35): the chapter's body-frame solution.

    Carries no orientation (Problem 17.3: "we do not know the location of the xyz-axis
    system"), so it accepts only scenes without translation and without loads that
    depend on the orientation (gravity about a pivot, space-frame torques). A body-frame
    :class:`~jrigid.scene.Torque` receives ``kin.q = None``.
    """

    name: ClassVar[str] = "body_omega"
    has_orientation: ClassVar[bool] = False

    def check_scene(self, scene):
        if scene.translates:
            raise ValueError("body_omega cannot represent free flight; use quaternion_acceleration")
        if scene.needs_orientation:
            raise ValueError(
                "body_omega carries no orientation, but a load of this scene depends on it "
                "(gravity about a pivot or a space-frame torque); use quaternion_acceleration"
            )

    def from_state(self, scene, state):
        return state.omega

    def kinematics(self, scene, y):
        return Kinematics(None, y)

    @_traced_once
    def vector_field(self, t, y, scene):
        _, torque = scene.wrench(t, Kinematics(None, y))
        return scene.omega_dot(y, torque)


class EulerState(eqx.Module):
    """Variables of :class:`EulerAngles`: ``angles (3,) = (φ, θ, ψ)`` ZXZ, ``omega (3,)``."""

    angles: jax.Array
    omega: jax.Array
    x: jax.Array | None = None
    v: jax.Array | None = None


class EulerAngles(AbstractFormulation):
    """ZXZ Euler angles ``(φ, θ, ψ)`` with rates from (17.36) and ω̇ from (17.35).

    Singular at ``sin θ = 0`` (gimbal lock): the solve terminates at the end of the first
    step in which ``|sin θ| < min_sin_theta`` (or ``sin θ`` changes sign) and
    :func:`jrigid.simulate` reports it (error, or ``Result.gimbal_lock`` with
    ``throw=False``). The event has no root finder, so ``t_stop`` is that step's end,
    up to a step past the crossing (measured: 0.185 for a crossing at 0.05); the outputs
    before ``t_stop`` are as accurate as elsewhere. Use a quaternion formulation there.

    Attributes:
        min_sin_theta: static threshold on ``|sin θ|``; default ``1e-3``.
    """

    name: ClassVar[str] = "euler_angles"
    min_sin_theta: float = eqx.field(static=True, default=1e-3)

    def from_state(self, scene, state):
        return EulerState(quat.to_euler("ZXZ", state.q), state.omega, state.x, state.v)

    def kinematics(self, scene, y):
        return Kinematics(quat.from_euler("ZXZ", y.angles), y.omega, y.x, y.v)

    def angle_rates(self, angles: jax.Array, omega: jax.Array) -> jax.Array:
        """``(φ̇, θ̇, ψ̇)`` from the body ω, inverting (17.36) (guarded near ``sin θ = 0``)."""
        th, ps = angles[1], angles[2]
        st, ct, sp, cp = jnp.sin(th), jnp.cos(th), jnp.sin(ps), jnp.cos(ps)
        floor = 0.5 * self.min_sin_theta
        st = jnp.where(jnp.abs(st) < floor, jnp.where(st < 0, -floor, floor), st)
        dphi = (omega[0] * sp + omega[1] * cp) / st
        dtheta = omega[0] * cp - omega[1] * sp
        dpsi = omega[2] - dphi * ct
        return jnp.stack([dphi, dtheta, dpsi])

    @_traced_once
    def vector_field(self, t, y, scene):
        q = quat.from_euler("ZXZ", y.angles) if (scene.needs_orientation) else None
        kin = Kinematics(q, y.omega, y.x, y.v)
        force, torque = scene.wrench(t, kin)
        xd, vd = _translation_rates(scene, y.v, force)
        return EulerState(
            self.angle_rates(y.angles, y.omega), scene.omega_dot(y.omega, torque), xd, vd
        )

    def locked(self, y) -> jax.Array:
        """Whether ``|sin θ| < min_sin_theta`` (boolean, any batch shape)."""
        return jnp.abs(jnp.sin(y.angles[..., 1])) < self.min_sin_theta

    def domain_error(self, scene, state):
        return (
            self.locked(self.from_state(scene, state)),
            "the initial orientation is at Euler-angle gimbal lock (|sin θ| < min_sin_theta); "
            "use formulation='quaternion_acceleration'",
        )

    def event(self):
        # Terminate when |sin θ| is small, or when sin θ changes sign within a step
        # (a step may jump across the singular line when the rates happen to stay finite).
        return diffrax.Event(
            (
                lambda t, y, args, **kwargs: self.locked(y),
                lambda t, y, args, **kwargs: jnp.sin(y.angles[1]),
            )
        )


FORMULATIONS = {
    cls.name: cls for cls in (QuaternionAcceleration, QuaternionOmega, BodyOmega, EulerAngles)
}


@functools.cache
def _default_instance(name: str) -> AbstractFormulation:
    return FORMULATIONS[name]()


def check_scene(formulation: str | AbstractFormulation, scene: Scene) -> None:
    """``formulation.check_scene(scene)``, called through the class.

    Reading a method off an equinox module builds a bound-method module (about 30 µs
    here, measured with equinox 0.13.8), which a plain ``simulate`` call would pay on
    every call; the class's function is the same method without that wrapper.

    Args:
        formulation: a formulation object or name (:func:`get_formulation`).
        scene: the :class:`~jrigid.scene.Scene`.

    Raises:
        ValueError: an unknown formulation, or a scene it cannot represent.
    """
    formulation = get_formulation(formulation)
    type(formulation).check_scene(formulation, scene)


def get_formulation(formulation: str | AbstractFormulation) -> AbstractFormulation:
    """A formulation from its name (see :data:`FORMULATIONS`) or the object itself."""
    if isinstance(formulation, AbstractFormulation):
        return formulation
    try:
        return _default_instance(formulation)
    except (KeyError, TypeError):
        raise ValueError(
            f"unknown formulation {formulation!r}; choose one of {sorted(FORMULATIONS)} "
            "or pass a formulation object"
        ) from None
