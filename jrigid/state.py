"""State pytrees: what a scene integrates, and the kinematic view loads receive.

:class:`State` is the formulation-independent state a user passes to
:func:`jrigid.simulate`: the orientation ``q`` (principal body frame → space), its rate
``q̇`` and, only for a scene in free flight, the centre-of-mass position ``x`` and
velocity ``v``. Formulations convert it to their own variables.

:class:`Kinematics` is what a user torque ``N(t, kin, params)`` sees: orientation, body
angular velocity and, in free flight, position and velocity.
"""

from __future__ import annotations

import equinox as eqx
import jax

from jrigid import linalg
from jrigid import quaternion as quat

__all__ = ["Kinematics", "State", "omega_from_rate"]


def omega_from_rate(q: jax.Array, qdot: jax.Array) -> jax.Array:
    """Body angular velocity ``ω = 2 vec(q* ⊗ q̇) / |q|²`` (eq. 17.42, ``ω = 2 W q̇``).

    Dividing by ``|q|²`` gives the angular velocity of the rotation ``q/|q|`` even when
    ``|q|`` has drifted from one, which keeps the vector fields consistent off the
    constraint.

    Args:
        q: ``(..., 4)`` quaternion.
        qdot: ``(..., 4)`` its rate.

    Returns:
        ``(..., 3)`` body-frame angular velocity.
    """
    return quat.angular_velocity(q, qdot) * (1.0 / linalg.dot(q, q))[..., None]


class State(eqx.Module):
    """Integrated state of a scene: ``(q, q̇)``, plus ``(x, v)`` only in free flight.

    Attributes:
        q: ``(..., 4)`` unit quaternion, principal body frame → space.
        qdot: ``(..., 4)`` its time derivative; on the constraint ``q·q̇ = 0``.
        x: ``(..., 3)`` centre-of-mass position (space frame), or ``None``.
        v: ``(..., 3)`` centre-of-mass velocity (space frame), or ``None``.

    Build one with the helpers in :mod:`jrigid.initial`.
    """

    q: jax.Array
    qdot: jax.Array
    x: jax.Array | None = None
    v: jax.Array | None = None

    @property
    def omega(self) -> jax.Array:
        """``(..., 3)`` body-frame angular velocity (eq. 17.42)."""
        return omega_from_rate(self.q, self.qdot)

    @property
    def omega_space(self) -> jax.Array:
        """``(..., 3)`` space-frame angular velocity."""
        return quat.rotate(linalg.unit(self.q), self.omega)


class Kinematics(eqx.Module):
    """The kinematic view of a state handed to loads and user torques.

    Attributes:
        q: ``(4,)`` unit orientation (principal body frame → space), or ``None`` under the
            ``body_omega`` formulation, which carries no orientation.
        omega: ``(3,)`` body-frame angular velocity.
        x: ``(3,)`` centre-of-mass position (free flight only, else ``None``).
        v: ``(3,)`` centre-of-mass velocity (free flight only, else ``None``).
        q_raw: ``(4,)`` the integrated quaternion ``q`` was normalised from (any non-zero
            norm), or ``None``. With it :meth:`to_body` and :meth:`to_space` rotate by
            ``q_raw`` and divide by ``|q_raw|²`` afterwards, which inside an integrator's
            loop costs less than normalising first (the quaternion-acceleration field of a
            heavy top: about a quarter less per evaluation on a CPU).
    """

    q: jax.Array | None
    omega: jax.Array
    x: jax.Array | None = None
    v: jax.Array | None = None
    q_raw: jax.Array | None = None

    @property
    def omega_space(self) -> jax.Array:
        """``(3,)`` space-frame angular velocity (needs ``q``)."""
        return self.to_space(self.omega)

    def to_body(self, v: jax.Array) -> jax.Array:
        """``(3,)`` the space-frame vector ``v (3,)`` in body coordinates, ``Rᵀ v`` (needs q)."""
        if self.q_raw is None:
            return quat.rotate_inverse(self.q, v)
        return quat.rotate_inverse(self.q_raw, v) * (1.0 / linalg.dot(self.q_raw, self.q_raw))

    def to_space(self, v: jax.Array) -> jax.Array:
        """``(3,)`` the body-frame vector ``v (3,)`` in space coordinates, ``R v`` (needs ``q``)."""
        if self.q_raw is None:
            return quat.rotate(self.q, v)
        return quat.rotate(self.q_raw, v) * (1.0 / linalg.dot(self.q_raw, self.q_raw))
