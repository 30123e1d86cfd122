"""Inertia tensors: from moments and point masses (17.31), the parallel-axis shift, rotation
(17.32) and principal axes."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jrigid import quaternion as quat
from jrigid._checks import as_float, as_floats, check_shape, fail_if

from ._checks import _check_moments, _check_tensor, _mass, _size

__all__ = [
    "to_tensor",
    "from_point_masses",
    "parallel_axis",
    "rotate_tensor_by_matrix",
    "rotate_tensor",
    "principal_axes",
]


def _eye(like: jax.Array) -> jax.Array:
    """Identity ``(..., 3, 3)`` with the batch shape and dtype of ``like (..., 3)``."""
    return jnp.broadcast_to(jnp.eye(3, dtype=like.dtype), like.shape[:-1] + (3, 3))


def to_tensor(moments) -> jax.Array:
    """Diagonal tensor ``diag(I1, I2, I3)`` from principal moments.

    Args:
        moments: ``(..., 3)``.

    Returns:
        ``(..., 3, 3)``.
    """
    moments = as_float(moments)
    _check_moments(moments)
    return moments[..., :, None] * _eye(moments)


def from_point_masses(masses, positions, origin=None) -> jax.Array:
    """Inertia tensor of point masses about ``origin`` (the sums behind 17.31).

    ``I = Σ_k m_k (|r_k|² 1 − r_k r_kᵀ)`` with ``r_k = position_k − origin``; its diagonal
    is 17.31a–c with the integrals replaced by sums, the off-diagonal entries are the
    products of inertia.

    Args:
        masses: ``(..., N)``, finite and ``>= 0``.
        positions: ``(..., N, 3)``, finite.
        origin: ``(..., 3)``, finite; default the centre of mass (then the total mass
            must be ``> 0``).

    Returns:
        ``(..., 3, 3)``.
    """
    masses, positions = as_floats(masses, positions)
    if positions.ndim < 2 or positions.shape[-1] != 3:
        raise ValueError(f"positions must have shape (..., N, 3); got shape {positions.shape}")
    n = positions.shape[-2]
    check_shape(masses, "masses", (n,), why=f" to match positions of shape {positions.shape}")
    masses = _size(masses, "masses")
    positions = fail_if(positions, ~jnp.isfinite(positions), "positions must be finite")
    if origin is None:
        masses = fail_if(
            masses,
            ~(jnp.sum(masses, axis=-1) > 0),
            "masses must not all be zero (the centre of mass is undefined)",
        )
    batch = jnp.broadcast_shapes(masses.shape[:-1], positions.shape[:-2])
    masses = jnp.broadcast_to(masses, batch + (n,))
    positions = jnp.broadcast_to(positions, batch + (n, 3))
    if origin is None:
        origin = jnp.einsum("...n,...ni->...i", masses, positions) / jnp.sum(
            masses, axis=-1, keepdims=True
        )
    else:
        origin = as_float(origin)
        check_shape(origin, "origin", (3,))
        origin = fail_if(origin, ~jnp.isfinite(origin), "origin must be finite")
        batch = jnp.broadcast_shapes(batch, origin.shape[:-1])
        masses = jnp.broadcast_to(masses, batch + (n,))
        positions = jnp.broadcast_to(positions, batch + (n, 3))
        origin = jnp.broadcast_to(origin, batch + (3,))
    r = positions - origin[..., None, :]
    second = jnp.einsum("...n,...ni,...nj->...ij", masses, r, r)
    trace = jnp.trace(second, axis1=-2, axis2=-1)
    return trace[..., None, None] * _eye(second[..., 0]) - second


def parallel_axis(I_cm, mass, d) -> jax.Array:
    """Shift a centre-of-mass tensor to a point displaced by ``d`` (parallel-axis theorem).

    ``I_O = I_cm + M (|d|² 1 − d dᵀ)``; the sign of ``d`` does not matter.

    Args:
        I_cm: ``(..., 3, 3)`` about the centre of mass.
        mass: total mass ``(...)``, finite and ``> 0``.
        d: displacement between the centre of mass and the new origin ``(..., 3)``.

    Returns:
        ``(..., 3, 3)``.
    """
    I_cm, mass, d = as_floats(I_cm, _mass(mass), d)
    _check_tensor(I_cm, "I_cm")
    check_shape(d, "d", (3,))
    d = fail_if(d, ~jnp.all(jnp.isfinite(d)), "d must be finite", lambda: f"{d}")
    batch = jnp.broadcast_shapes(I_cm.shape[:-2], mass.shape, d.shape[:-1])
    I_cm = jnp.broadcast_to(I_cm, batch + (3, 3))
    mass = jnp.broadcast_to(mass, batch)
    d = jnp.broadcast_to(d, batch + (3,))
    dd = d[..., :, None] * d[..., None, :]
    shift = jnp.sum(d * d, axis=-1)[..., None, None] * _eye(d) - dd
    return I_cm + mass[..., None, None] * shift


def rotate_tensor_by_matrix(inertia, R) -> jax.Array:
    """Frame change ``R I Rᵀ`` (17.32, where the chapter writes ``M I M⁻¹``).

    With ``R`` the active body → space matrix (``v_space = R v_body``), this turns a
    body-frame tensor into the space-frame one.

    Args:
        inertia: ``(..., 3, 3)``.
        R: ``(..., 3, 3)`` rotation matrix: orthogonal within
            :func:`~jrigid.quaternion.default_atol` (``max |RᵀR − 1|``), else
            ``ValueError`` (under ``jit``, at run time): another matrix would not change
            the frame but the body. A non-finite ``R`` gives a non-finite result.

    Returns:
        ``(..., 3, 3)``.
    """
    inertia, R = as_floats(inertia, R)
    _check_tensor(inertia)
    _check_tensor(R, "R")
    gram = jnp.swapaxes(R, -1, -2) @ R
    error = jnp.max(jnp.abs(gram - _eye(R[..., 0])), axis=(-2, -1))
    R = fail_if(R, error > quat.default_atol(R.dtype),  # (NaN in, NaN out)
                "R must be a rotation matrix (orthogonal; max |RᵀR - 1| exceeds the "
                "tolerance)", lambda: f"max |RᵀR - 1| = {jnp.max(error):.3g}")
    return _rotated(inertia, R)


def _rotated(inertia: jax.Array, R: jax.Array) -> jax.Array:
    """``R I Rᵀ``, unchecked."""
    return R @ inertia @ jnp.swapaxes(R, -1, -2)


def rotate_tensor(inertia, q) -> jax.Array:
    """Body → space frame change of an inertia tensor, ``R I Rᵀ`` with ``R`` from ``q`` (17.32).

    Args:
        inertia: ``(..., 3, 3)`` in the body frame (use :func:`to_tensor` for moments).
        q: ``(..., 4)`` unit quaternion, body → space.

    Returns:
        ``(..., 3, 3)`` in the space frame. ``rotate_tensor(I, quat.conjugate(q))`` goes back.
    """
    inertia = as_float(inertia)
    _check_tensor(inertia)
    return _rotated(inertia, quat.to_matrix(q))


@jax.custom_jvp
def _eigh(sym):
    """``(w, V)`` of ``jnp.linalg.eigh``, with a derivative that is finite at repeated ``w``."""
    w, v = jnp.linalg.eigh(sym)
    return w, v


@_eigh.defjvp
def _eigh_jvp(primals, tangents):
    # A V = V Λ gives dΛ = diag(P) and dV = V (F ∘ P), P = Vᵀ dA V, F_ij = 1/(λ_j − λ_i).
    # For λ_i = λ_j (to within rounding: 64 eps of the largest) the pair's rotation within
    # the eigenspace is arbitrary; it is taken as zero (jnp.linalg.eigh's own rule divides
    # by the rounding-level gap there and returns NaN or noise).
    (sym,), (dsym,) = primals, tangents
    w, v = _eigh(sym)
    proj = jnp.swapaxes(v, -1, -2) @ dsym @ v
    gap = w[..., None, :] - w[..., :, None]
    tol = 64 * jnp.finfo(w.dtype).eps * jnp.max(jnp.abs(w), axis=-1)[..., None, None]
    apart = jnp.abs(gap) > tol
    f = jnp.where(apart, 1.0 / jnp.where(apart, gap, 1.0), 0.0)
    dw = jnp.diagonal(proj, axis1=-2, axis2=-1)
    return (w, v), (dw, v @ (f * proj))


def principal_axes(inertia) -> tuple[jax.Array, jax.Array]:
    """Principal moments and a right-handed principal frame of a symmetric tensor.

    ``I = R diag(moments) Rᵀ`` with ``R = quaternion.to_matrix(q)``: the columns of ``R``
    are the principal axes in the frame of ``I``, and ``q`` is the body → frame rotation.

    For repeated moments (equal to within 64 machine epsilons of the largest) any
    orthonormal basis of the eigenspace is equally valid and one is returned; the moments
    and their gradients stay well defined there, and the frame's gradient is finite: it
    leaves out the (arbitrary) rotation within the eigenspace, so that any function of
    ``R diag(moments) Rᵀ`` gets its derivative except for perturbations that mix two axes
    of equal moment.

    Args:
        inertia: ``(..., 3, 3)`` symmetric (the symmetric part is used).

    Returns:
        ``(moments, q)``: ``moments (..., 3)`` in ascending order, ``q (..., 4)``.
    """
    inertia = as_float(inertia)
    _check_tensor(inertia)
    sym = 0.5 * (inertia + jnp.swapaxes(inertia, -1, -2))
    moments, V = _eigh(sym)
    sign = jnp.sign(jnp.linalg.det(V))
    sign = jnp.where(sign == 0, 1.0, sign).astype(V.dtype)
    V = jnp.concatenate([V[..., :2], V[..., 2:] * sign[..., None, None]], axis=-1)
    return moments, quat.from_matrix(V)
