"""Quaternion kinematics: the rate ``q̇`` of an orientation and the angular velocity (17.37-17.44).

Body frame unless a name says ``space``: ``q̇ = ½ q ⊗ (0, ω_body)`` (eq. 17.44) and
``ω_body = 2 W q̇`` (eq. 17.42, the chapter's matrix ``W`` of eq. 17.43); in the space
frame ``q̇ = ½ (0, ω_space) ⊗ q``. Conventions, broadcasting and shape checks as in
:mod:`jrigid.quaternion.core`.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from ._utils import as_float_pair, broadcast_batch, quaternion_arg, vector_arg
from .core import conjugate, multiply

__all__ = [
    "angular_velocity",
    "angular_velocity_space",
    "derivative",
    "derivative_space",
    "w_matrix",
    "w_matrix_space",
]


def w_matrix(q: ArrayLike) -> jax.Array:
    """The chapter's matrix ``W`` (eq. 17.43, first three rows), body frame.

    ``ω_body = 2 W q̇`` (eq. 17.42) and, for unit ``q``, ``q̇ = ½ Wᵀ ω_body`` (eq. 17.44)
    because the rows of ``W`` are orthonormal. ``2 W q̇`` is the vector part of
    ``2 q* ⊗ q̇``. The chapter's fourth row ``(q0, q1, q2, q3)`` gives ``q·q̇ = 0``.

    Args:
        q: ``(..., 4)`` unit quaternion.

    Returns:
        ``(..., 3, 4)``::

            [[-q1,  q0,  q3, -q2],
             [-q2, -q3,  q0,  q1],
             [-q3,  q2, -q1,  q0]]
    """
    q = quaternion_arg(q)
    q0, q1, q2, q3 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    rows = [
        jnp.stack([-q1, q0, q3, -q2], axis=-1),
        jnp.stack([-q2, -q3, q0, q1], axis=-1),
        jnp.stack([-q3, q2, -q1, q0], axis=-1),
    ]
    return jnp.stack(rows, axis=-2)


def w_matrix_space(q: ArrayLike) -> jax.Array:
    """Space-frame counterpart of :func:`w_matrix`: ``ω_space = 2 W_s q̇``.

    ``2 W_s q̇`` is the vector part of ``2 q̇ ⊗ q*`` (the chapter's eq. 17.41).

    Args:
        q: ``(..., 4)`` unit quaternion.

    Returns:
        ``(..., 3, 4)``::

            [[-q1,  q0, -q3,  q2],
             [-q2,  q3,  q0, -q1],
             [-q3, -q2,  q1,  q0]]
    """
    q = quaternion_arg(q)
    q0, q1, q2, q3 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    rows = [
        jnp.stack([-q1, q0, -q3, q2], axis=-1),
        jnp.stack([-q2, q3, q0, -q1], axis=-1),
        jnp.stack([-q3, -q2, q1, q0], axis=-1),
    ]
    return jnp.stack(rows, axis=-2)


def _pure(v: jax.Array) -> jax.Array:
    return jnp.concatenate([jnp.zeros_like(v[..., :1]), v], axis=-1)


def derivative(q: ArrayLike, omega_body: ArrayLike) -> jax.Array:
    """Quaternion rate ``q̇ = ½ q ⊗ (0, ω_body)`` (eq. 17.44, ``= ½ Wᵀ ω``).

    Args:
        q: ``(..., 4)`` unit quaternion (body → space).
        omega_body: ``(..., 3)`` body-frame angular velocity; batch dimensions broadcast.

    Returns:
        ``(..., 4)`` time derivative of ``q``.
    """
    q, omega = as_float_pair(quaternion_arg(q), vector_arg(omega_body, "omega_body"))
    q, omega = broadcast_batch(q, 1, omega, 1)
    # The product with the pure quaternion written out (no multiplications by its zero
    # scalar part, which XLA keeps): fewer operations in an integrator's loop.
    q0, q1, q2, q3 = (q[..., i] for i in range(4))
    w1, w2, w3 = (omega[..., i] for i in range(3))
    return 0.5 * jnp.stack(
        [
            -q1 * w1 - q2 * w2 - q3 * w3,
            q0 * w1 + q2 * w3 - q3 * w2,
            q0 * w2 - q1 * w3 + q3 * w1,
            q0 * w3 + q1 * w2 - q2 * w1,
        ],
        axis=-1,
    )


def derivative_space(q: ArrayLike, omega_space: ArrayLike) -> jax.Array:
    """Quaternion rate from the space-frame angular velocity: ``q̇ = ½ (0, ω_space) ⊗ q``.

    Args:
        q: ``(..., 4)`` unit quaternion.
        omega_space: ``(..., 3)`` space-frame angular velocity.

    Returns:
        ``(..., 4)``.
    """
    q, omega = as_float_pair(quaternion_arg(q), vector_arg(omega_space, "omega_space"))
    return 0.5 * multiply(_pure(omega), q)


def angular_velocity(q: ArrayLike, qdot: ArrayLike) -> jax.Array:
    """Body-frame angular velocity ``ω = 2 W q̇`` = vector part of ``2 q* ⊗ q̇`` (eq. 17.42).

    Args:
        q: ``(..., 4)`` unit quaternion.
        qdot: ``(..., 4)`` its time derivative.

    Returns:
        ``(..., 3)`` body-frame angular velocity.
    """
    return 2.0 * multiply(conjugate(q), quaternion_arg(qdot, "qdot"))[..., 1:]


def angular_velocity_space(q: ArrayLike, qdot: ArrayLike) -> jax.Array:
    """Space-frame angular velocity = vector part of ``2 q̇ ⊗ q*`` (eq. 17.41).

    Args:
        q: ``(..., 4)`` unit quaternion.
        qdot: ``(..., 4)`` its time derivative.

    Returns:
        ``(..., 3)`` space-frame angular velocity.
    """
    return 2.0 * multiply(quaternion_arg(qdot, "qdot"), conjugate(q))[..., 1:]
