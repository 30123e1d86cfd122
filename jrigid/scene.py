"""Scenes: a body, how it is held, and what acts on it.

"Model only what a scene needs": a :class:`Scene` names one :class:`~jrigid.body.RigidBody`,
a holder

- :class:`FreeRotation` — the body turns about its centre of mass, which stays put;
- :class:`Pivot` — a fixed frictionless pivot at the body's support point (heavy top,
  gyroscope). The centre of mass sits at ``body.com`` from the pivot, and the dynamics
  use the inertia about the pivot, ``diag(moments) + M (|r|² 1 − r rᵀ)`` with
  ``r = body.com`` (parallel-axis theorem): ``body.moments`` are always central moments;
- :class:`FreeFlight` — the centre of mass translates (``x, v`` join the state) and the
  body turns about it;

and a tuple of loads: :class:`Gravity` (uniform field), :class:`Torque` (a user
function ``N(t, kin, params)`` in the body or space frame) and the impulsive
:class:`jrigid.contact.Floor`. Every part is an
``equinox.Module``, so scenes are pytrees: ``jit``, ``vmap`` and ``grad`` reach the
moments, mass, lever arm, field strength and torque parameters alike.

All methods here act on one (unbatched) state; batch with ``jax.vmap``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from jrigid import linalg
from jrigid import quaternion as quat
from jrigid._folds import first_true, largest, total
from jrigid.body import RigidBody
from jrigid.state import Kinematics

__all__ = [
    "AbstractHolder",
    "Conserved",
    "AbstractLoad",
    "FreeFlight",
    "FreeRotation",
    "Gravity",
    "Pivot",
    "Scene",
    "TopConstants",
    "Torque",
]


# --------------------------------------------------------------------------- holders


class AbstractHolder(eqx.Module):
    """How a body is held. Subclasses set ``translates`` and ``pivoted``."""

    translates: ClassVar[bool] = False
    pivoted: ClassVar[bool] = False


class FreeRotation(AbstractHolder):
    """Rotation about the centre of mass, which stays fixed (``body.com`` is ignored)."""


class Pivot(AbstractHolder):
    """A fixed frictionless pivot at the support point; the centre of mass is at ``body.com``.

    The dynamics use the inertia about the pivot (parallel-axis shift of the central
    moments); gravity exerts the torque ``r × M g`` about it, computed in the body frame.
    """

    pivoted: ClassVar[bool] = True


class FreeFlight(AbstractHolder):
    """Free flight: the centre of mass moves (state gains ``x, v``); rotation about it."""

    translates: ClassVar[bool] = True


# --------------------------------------------------------------------------- loads


class AbstractLoad(eqx.Module):
    """Something acting on the body.

    Subclasses implement :meth:`wrench` and may implement :meth:`potential` and
    :meth:`uses_orientation` (formulations without an orientation, such as
    ``body_omega``, reject loads that use it). An ``impulsive`` load (the floor of
    :mod:`jrigid.contact`) acts by impulses that :func:`jrigid.simulate` cannot apply.
    """

    impulsive: ClassVar[bool] = False

    def wrench(self, t, kin: Kinematics, scene: Scene) -> tuple[jax.Array, jax.Array]:
        """``(force (3,), space frame; torque (3,) about the rotation centre, body frame)``."""
        raise NotImplementedError

    def potential(self, kin: Kinematics, scene: Scene) -> jax.Array:
        """Potential energy ``()``; zero unless the load is conservative."""
        return jnp.zeros((), dtype=kin.omega.dtype)

    def uses_orientation(self, scene: Scene) -> bool:
        """Whether this load needs the orientation in ``scene`` (static); default yes."""
        return True


def _gravity_vector(g) -> jax.Array:
    """``g`` as a ``(3,)`` space-frame vector; a scalar means ``(0, 0, -g)``.

    Raises ``ValueError`` for any other shape (always, also under ``jit``) and for
    non-finite values (concrete values only).
    """
    g = jnp.asarray(g)
    dtype = g.dtype if jnp.issubdtype(g.dtype, jnp.floating) else jnp.result_type(float)
    g = jnp.asarray(g, dtype=jax.dtypes.canonicalize_dtype(dtype))
    if g.shape not in ((), (3,)):
        raise ValueError(
            "Gravity: g must be a scalar (meaning (0, 0, -g)) or a vector of shape (3,), "
            f"got shape {g.shape}"
        )
    if not isinstance(g, jax.core.Tracer) and not bool(jnp.all(jnp.isfinite(g))):
        raise ValueError(f"Gravity: g must be finite, got {g}")
    if g.ndim == 0:
        zero = jnp.zeros_like(g)
        return jnp.stack([zero, zero, -g])
    return g


class Gravity(AbstractLoad):
    """Uniform gravity.

    Attributes:
        g: ``(3,)`` gravitational acceleration in the space frame; a scalar ``g`` means
            ``(0, 0, −g)``. Default ``9.81`` (the chapter's gyroscope uses ``g = 1``).

    For a :class:`Pivot` scene the torque about the pivot is ``r × (M g_body)`` with
    ``g_body = q* ⊗ g ⊗ q`` (the field projected into the body frame) and ``r = body.com``;
    the potential energy is ``−M g · (R r)``. For :class:`FreeFlight` the force ``M g``
    acts on the centre of mass (potential ``−M g · x``) and there is no torque. For
    :class:`FreeRotation` gravity does nothing (the support carries the weight).
    """

    g: jax.Array = eqx.field(converter=_gravity_vector, default=9.81)

    def uses_orientation(self, scene: Scene) -> bool:
        return scene.holder.pivoted

    def wrench(self, t, kin, scene):
        m = scene.body.mass
        zero = jnp.zeros(3, dtype=kin.omega.dtype)
        if scene.holder.pivoted:
            g_body = kin.to_body(self.g)
            return zero, linalg.cross(scene.body.com, m * g_body)
        if scene.holder.translates:
            return m * self.g, zero
        return zero, zero

    def potential(self, kin, scene):
        m = scene.body.mass
        if scene.holder.pivoted:
            return -m * linalg.dot(self.g, kin.to_space(scene.body.com))
        if scene.holder.translates:
            return -m * linalg.dot(self.g, kin.x)
        return jnp.zeros((), dtype=kin.omega.dtype)


def _float_leaves(params):
    """Python floats → arrays, so that changing them does not recompile."""
    return jax.tree_util.tree_map(
        lambda x: jnp.asarray(x, dtype=jnp.result_type(float)) if isinstance(x, float) else x,
        params,
    )


class Torque(AbstractLoad):
    """A user torque ``N = fn(t, kin, params)``.

    Attributes:
        fn: static callable ``(t, kin: Kinematics, params) -> (3,)`` torque about the
            rotation centre (pivot or centre of mass). Keep the same function object
            between calls: it is part of the compiled program's identity.
        params: pytree of parameters (traced: ``grad`` and ``vmap`` reach them; Python
            floats are converted to arrays, other non-array leaves stay static).
        frame: static, ``"body"`` or ``"space"``, the frame ``fn`` returns its torque
            in. A space-frame torque is projected into the body frame with ``q``.

    Under the ``body_omega`` formulation only body-frame torques are allowed and
    ``kin.q`` is ``None``.
    """

    fn: Callable[..., Any] = eqx.field(static=True)
    params: Any = eqx.field(default=None, converter=_float_leaves)
    frame: str = eqx.field(static=True, default="body")

    def __check_init__(self):
        if self.frame not in ("body", "space"):
            raise ValueError(f"Torque frame must be 'body' or 'space', got {self.frame!r}")
        if not callable(self.fn):
            raise ValueError("Torque fn must be callable as fn(t, kin, params)")

    def uses_orientation(self, scene: Scene) -> bool:
        return self.frame == "space"

    def wrench(self, t, kin, scene):
        n = jnp.asarray(self.fn(t, kin, self.params), dtype=kin.omega.dtype)
        if n.shape != (3,):
            raise ValueError(f"Torque fn must return shape (3,), got {n.shape}")
        if self.frame == "space":
            n = kin.to_body(n)
        return jnp.zeros(3, dtype=kin.omega.dtype), n


# --------------------------------------------------------------------------- scene


def _as_loads(loads) -> tuple:
    if isinstance(loads, AbstractLoad):
        return (loads,)
    return tuple(loads)


class Conserved(NamedTuple):
    """Conserved quantities of a state (see :meth:`Scene.conserved`).

    Attributes:
        values: ``(4,)`` the quantities.
        scales: ``(4,)`` positive sizes of the terms each is made of (for relative
            residuals).
        active: ``(4,)`` bool, the slots to enforce at this state.
    """

    values: jax.Array
    scales: jax.Array
    active: jax.Array


def _length(square: jax.Array) -> jax.Array:
    """``√square`` with a zero derivative, not an infinite one, at zero (``|L|`` of a top
    at rest, ``|g|`` without gravity, ``|r|`` pivoted at the centre of mass)."""
    positive = square > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, square, 1.0)), 0.0)


class TopConstants(eqx.Module):
    """What a conservative top's invariants (:meth:`Scene.conserved`) need of its scene.

    Attributes:
        tensor: ``(3, 3)`` inertia ``I_p`` about the pivot, body frame.
        g_hat: ``(3,)`` direction of gravity (space frame; zero when ``g = 0``).
        lever_weight: ``(3,)`` ``M |g| r`` (``r`` the centre of mass from the pivot).
        r_hat: ``(3,)`` ``r / |r|`` (zero without a lever arm).
        weight: ``()`` ``M |g| |r|``.
        momentum_floor: ``()`` ``√(I_max M |g| |r|)``, a top's momentum scale at rest.
        pendulum2: ``()`` ``M |g| |r| / I_max``, its pendulum frequency squared.
        symmetric: ``()`` bool, :meth:`Scene.symmetric_about_lever`.
    """

    tensor: jax.Array
    g_hat: jax.Array
    lever_weight: jax.Array
    r_hat: jax.Array
    weight: jax.Array
    momentum_floor: jax.Array
    pendulum2: jax.Array
    symmetric: jax.Array

    def conserved(self, q: jax.Array, omega: jax.Array) -> Conserved:
        """:meth:`Scene.conserved` of the top at unit ``q (4,)`` and body ``omega (3,)``."""
        return self.conserved_at(quat.rotate_inverse(q, self.g_hat), omega)

    def conserved_at(self, g_body: jax.Array, omega: jax.Array) -> Conserved:
        """:meth:`conserved` from the body-frame direction of gravity ``g_body (3,)``
        (``Rᵀ ĝ``) and body ``omega (3,)``.

        Written with sums over whole vectors (few operations, quick to compile: a
        projection evaluates it at every step), written out (``jrigid._folds``).
        """
        dtype = omega.dtype
        L = total(self.tensor * omega[None, :])
        kinetic = 0.5 * linalg.dot(omega, L)
        potential = -linalg.dot(g_body, self.lever_weight)  # −M g·(R r)
        momentum = _length(linalg.norm2(L)) + self.momentum_floor
        values = jnp.stack([kinetic + potential, linalg.dot(L, g_body), linalg.dot(L, self.r_hat),
                            jnp.zeros((), dtype)])
        scales = jnp.stack([kinetic + self.weight, momentum, momentum, jnp.ones((), dtype)])
        # without gravity (|g| = 0, ĝ = 0) L·ĝ says nothing; a slot whose scale is zero (a
        # body at rest with no weight) has nothing to restore
        pulled = linalg.norm2(self.g_hat) > 0
        active = jnp.stack([jnp.array(True), pulled, self.symmetric, jnp.array(False)])
        return Conserved(values, scales, active & (scales > 0))


class Scene(eqx.Module):
    """One body, how it is held, and what acts on it.

    Attributes:
        body: the :class:`~jrigid.body.RigidBody`.
        holder: :class:`FreeRotation` (default), :class:`Pivot` or :class:`FreeFlight`.
        loads: tuple of loads (:class:`Gravity`, :class:`Torque`); default none.

    The state of a scene is ``(q, q̇)``, plus ``(x, v)`` when ``holder`` is
    :class:`FreeFlight` (see :class:`jrigid.state.State`).
    """

    body: RigidBody
    holder: AbstractHolder = FreeRotation()
    loads: tuple = eqx.field(default=(), converter=_as_loads)

    def __check_init__(self):
        if not isinstance(self.body, RigidBody):
            raise ValueError(f"Scene body must be a RigidBody, got {type(self.body).__name__}")
        if not isinstance(self.holder, AbstractHolder):
            raise ValueError(
                "Scene holder must be FreeRotation(), Pivot() or FreeFlight(), "
                f"got {self.holder!r}"
            )
        for load in self.loads:
            if not isinstance(load, AbstractLoad):
                raise ValueError(f"Scene loads must be Gravity, Torque or Floor, got {load!r}")

    @property
    def translates(self) -> bool:
        """Whether the state carries ``x, v`` (static)."""
        return self.holder.translates

    @property
    def torque_free(self) -> bool:
        """Whether no torque acts about the rotation centre (static).

        True for :class:`FreeRotation` and :class:`FreeFlight` holders whose loads are
        all :class:`Gravity` (a uniform field exerts no torque about the centre of mass).
        """
        return not self.holder.pivoted and all(isinstance(load, Gravity) for load in self.loads)

    @property
    def conservative_top(self) -> bool:
        """Whether this is a body on a :class:`Pivot` under :class:`Gravity` only (static)."""
        return (
            self.holder.pivoted
            and bool(self.loads)
            and all(isinstance(load, Gravity) for load in self.loads)
        )

    def conserved(self, kin: Kinematics) -> Conserved | None:
        """What the exact motion conserves, as a :class:`Conserved` (or ``None``).

        The scene says what its motion conserves, so that integrators can restore it
        (:func:`jrigid.invariants.project`). Four slots:

        - torque free (:attr:`torque_free`): ``|L|²`` and, for ``k = 1, 2, 3``,
          ``Δ_k = 2 E I_k − |L|² = Σ_j I_j (I_k − I_j) ω_j²`` (eq. 17.30b; ``E`` the
          rotational kinetic energy). Energy and ``|L|`` fix all four; only ``|L|²`` and
          the ``Δ_k`` of the axis nearest the momentum are marked active: written as a
          sum without that axis's term, it is exact to rounding even for a spin close to
          that axis, where the energy and ``|L|²`` alone are nearly dependent;
        - a body on a pivot under gravity only (:attr:`conservative_top`): the total
          energy ``½ ω·I_p ω − M g·(R r)``, the momentum component along gravity
          ``L_space·ĝ`` (active only when ``g ≠ 0``), and — active only when the body
          is symmetric about the line from the pivot to its centre of mass — the
          momentum component ``L·r̂`` along that line (the Lagrange top's ``L₃``); the
          fourth slot is unused; a slot whose scale is zero (at rest, with no weight)
          is not active;
        - anything else (a user torque, no load on a pivot): ``None``.

        Args:
            kin: one state's :class:`~jrigid.state.Kinematics` (``q`` unit).
        """
        omega = kin.omega
        if self.torque_free:
            m = self.body.moments
            L = m * omega
            L2 = linalg.dot(L, L)
            w2 = omega * omega
            deltas = [
                sum(m[j] * (m[k] - m[j]) * w2[j] for j in range(3) if j != k) for k in range(3)
            ]
            size = jnp.abs(L)
            nearest = first_true(size == largest(size))  # argmax, written out
            active = jnp.stack([jnp.array(True), nearest == 0, nearest == 1, nearest == 2])
            return Conserved(jnp.stack([L2, *deltas]), jnp.full(4, L2), active)
        if not self.conservative_top:
            return None
        return self.top_constants().conserved(kin.q, omega)

    def top_constants(self) -> TopConstants:
        """The parts of a conservative top's invariants that do not change along its
        motion (:class:`TopConstants`), for :meth:`conserved` and for projections that
        evaluate the invariants at every step (computed once per solve).

        Raises:
            ValueError: the scene is not a :attr:`conservative_top`.
        """
        if not self.conservative_top:
            raise ValueError("top_constants: the scene is not a body on a Pivot under Gravity only")
        dtype = jnp.result_type(self.body.moments)
        tensor = self.inertia()
        g = sum((load.g for load in self.loads), jnp.zeros(3, dtype))
        g_norm = _length(linalg.dot(g, g))
        r = self.body.com
        r_norm = _length(linalg.dot(r, r))
        r_hat = r / jnp.where(r_norm > 0, r_norm, 1.0)
        weight = self.body.mass * g_norm * r_norm
        widest = largest(jnp.diagonal(tensor))
        return TopConstants(
            tensor=tensor,
            g_hat=g / jnp.where(g_norm > 0, g_norm, 1.0),  # zero without gravity
            lever_weight=self.body.mass * g_norm * r,
            r_hat=r_hat,
            weight=weight,
            momentum_floor=_length(widest * weight),
            pendulum2=weight / widest,
            symmetric=self.symmetric_about_lever(),
        )

    def symmetric_about_lever(self) -> jax.Array:
        """``()`` bool: the body is symmetric about the pivot–centre-of-mass line.

        True when the centre of mass lies on a principal axis ``k`` and the two other
        central moments agree to within 64 machine epsilons (then ``L·r̂`` is conserved
        on a pivot under gravity: the Lagrange top). False without a lever arm.
        """
        m = self.body.moments
        r = self.body.com
        eps = 64 * jnp.finfo(m.dtype).eps
        flags = []
        for k in range(3):
            i, j = [a for a in range(3) if a != k]
            on_axis = (r[i] == 0) & (r[j] == 0) & (r[k] != 0)
            equal = jnp.abs(m[i] - m[j]) <= eps * jnp.maximum(m[i], m[j])
            flags.append(on_axis & equal)
        return flags[0] | flags[1] | flags[2]

    @property
    def needs_orientation(self) -> bool:
        """Whether some load depends on the orientation (static)."""
        return any(load.uses_orientation(self) for load in self.loads)

    def lever(self) -> jax.Array:
        """``(3,)`` centre of mass relative to the rotation centre, body frame."""
        if self.holder.pivoted:
            return self.body.com
        return jnp.zeros_like(self.body.com)

    def inertia(self) -> jax.Array:
        """``(3, 3)`` inertia about the rotation centre in the body frame (parallel axis)."""
        tensor = self.body.tensor()
        if self.holder.pivoted:
            r = self.body.com
            eye = jnp.eye(3, dtype=r.dtype)
            tensor = tensor + self.body.mass * (linalg.dot(r, r) * eye - r[:, None] * r[None, :])
        return tensor

    def omega_dot(self, omega: jax.Array, torque: jax.Array) -> jax.Array:
        """Euler's equations ``I ω̇ = N − ω × (I ω)`` (eq. 17.34; 17.35 for diagonal ``I``).

        Args:
            omega: ``(3,)`` body angular velocity.
            torque: ``(3,)`` body-frame torque about the rotation centre.

        Returns:
            ``(3,)`` body angular acceleration.
        """
        if self.holder.pivoted:
            tensor = self.inertia()
            return linalg.solve3(tensor, torque - linalg.cross(omega, linalg.matvec(tensor, omega)))
        return linalg.euler_diagonal(self.body.moments, omega, torque)

    def wrench(self, t, kin: Kinematics) -> tuple[jax.Array, jax.Array]:
        """Total ``(force (3,) space frame, torque (3,) body frame)`` of all loads."""
        force = jnp.zeros(3, dtype=kin.omega.dtype)
        torque = jnp.zeros(3, dtype=kin.omega.dtype)
        for load in self.loads:
            f, n = load.wrench(t, kin, self)
            force = force + f
            torque = torque + n
        return force, torque

    def omega_from_momentum(self, L: jax.Array) -> jax.Array:
        """``(3,)`` body angular velocity ``ω = I⁻¹ L`` from the body-frame momentum (17.30b).

        Args:
            L: ``(3,)`` body-frame angular momentum about the rotation centre.
        """
        if self.holder.pivoted:
            return linalg.solve3(self.inertia(), L)
        return L / self.body.moments

    def angular_momentum(self, omega: jax.Array) -> jax.Array:
        """``(3,)`` body-frame angular momentum ``L = I ω`` about the rotation centre (17.30b)."""
        if self.holder.pivoted:
            return linalg.matvec(self.inertia(), omega)
        return self.body.moments * omega

    def kinetic_energy(self, omega: jax.Array, v: jax.Array | None = None) -> jax.Array:
        """``½ ω·Iω`` (+ ``½ M |v|²`` in free flight)."""
        energy = 0.5 * linalg.dot(omega, self.angular_momentum(omega))
        if v is not None:
            energy = energy + 0.5 * self.body.mass * linalg.dot(v, v)
        return energy

    def potential_energy(self, kin: Kinematics) -> jax.Array:
        """Total potential energy ``()`` of the conservative loads."""
        energy = jnp.zeros((), dtype=kin.omega.dtype)
        for load in self.loads:
            energy = energy + load.potential(kin, self)
        return energy
