"""Precession, nutation and spin of a body axis about the angular momentum.

For torque-free motion ``L`` is fixed in space, so the natural Euler angles use ``L̂`` as
the space ``Z`` axis: with ``A = [u, v, L̂]`` (a right-handed frame, ``u ⊥ L̂``) and
``R = A · Rz(φ) Rx(θ) Rz(ψ) · Pᵀ`` (scipy's intrinsic ``"ZXZ"``, the chapter's 17.10
angles, active form), ``φ`` is the precession of the chosen body axis about ``L``, ``θ``
its nutation (angle to ``L``) and ``ψ`` the spin about the axis itself. ``P`` is the
cyclic permutation that makes body axis ``axis`` play the role of ``z``.

For a symmetric top (``I1 = I2``, symmetry axis 3) these are exact straight lines:
``φ̇ = |L| / I1`` and ``ψ̇ = ω3 (I1 − I3) / I1``, ``θ`` constant with ``cos θ = I3 ω3 / |L|``.

No matplotlib here: the plots and the demo's measurements both use it. The rotation
algebra is :mod:`jrigid.quaternion` (one jitted kernel); the frame ``A`` is plain numpy.
At ``θ = 0`` (axis along ``L``) only ``φ + ψ`` is defined; there the spin is set to 0
(as :func:`jrigid.quaternion.to_euler` does).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from jrigid import quaternion as quat

from ._jit import bucket, float_dtype, pad

__all__ = ["euler_about", "fit_rate", "frame_about"]


def frame_about(n) -> np.ndarray:
    """Right-handed rotation matrix ``(3, 3)`` whose third column is ``n / |n|``.

    The first column is the unit vector along ``n̂ × e`` with ``e`` the coordinate axis
    least aligned with ``n`` (a fixed, reproducible choice).

    Args:
        n: ``(3,)`` nonzero vector.
    """
    n = np.asarray(n, dtype=float)
    nrm = np.linalg.norm(n)
    if not nrm > 0:
        raise ValueError("frame_about: the axis vector is zero")
    z = n / nrm
    e = np.eye(3)[np.argmin(np.abs(z))]
    x = np.cross(z, e)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=-1)


@functools.partial(jax.jit, static_argnames=("axis", "unwrap"))
def _euler_about(q, A, axis: int, unwrap: bool):
    qa = quat.from_matrix(A)
    eye = jnp.eye(3, dtype=q.dtype)
    P = jnp.stack([eye[(axis + 1) % 3], eye[(axis + 2) % 3], eye[axis]], axis=-1)
    qp = quat.from_matrix(P)
    q_rel = quat.multiply(quat.multiply(quat.conjugate(qa)[None], q), qp[None])
    ang = quat.to_euler("ZXZ", q_rel)
    if unwrap:
        ang = jnp.stack([jnp.unwrap(ang[:, 0]), ang[:, 1], jnp.unwrap(ang[:, 2])], axis=-1)
    return ang


def euler_about(q, L_space, axis: int = 2, unwrap: bool = True) -> np.ndarray:
    """Precession ``φ``, nutation ``θ`` and spin ``ψ`` of body axis ``axis`` about ``L``.

    Args:
        q: ``(T, 4)`` body → space quaternions.
        L_space: ``(3,)`` or ``(T, 3)`` angular momentum in space; a series is averaged
            (it is constant for torque-free motion) to fix the reference frame.
        axis: body axis (0, 1, 2) whose motion about ``L`` is measured.
        unwrap: unwrap ``φ`` and ``ψ`` in time (continuous angles, for rates).

    Returns:
        ``(T, 3)`` numpy array of ``(φ, θ, ψ)`` in radians.
    """
    if axis not in (0, 1, 2):
        raise ValueError(f"axis must be 0, 1 or 2, got {axis!r}")
    q = np.asarray(q, dtype=float)
    if q.ndim != 2 or q.shape[-1] != 4:
        raise ValueError(f"q must have shape (T, 4), got {q.shape}")
    L = np.asarray(L_space, dtype=float)
    if L.ndim == 2:
        L = L.mean(axis=0)
    A = frame_about(L)
    n, dt = bucket(len(q)), float_dtype()
    ang = _euler_about(
        jnp.asarray(pad(q, n, q[-1]), dtype=dt), jnp.asarray(A, dtype=dt), axis, unwrap
    )
    return np.asarray(ang, dtype=float)[: len(q)]


def fit_rate(ts, angle) -> float:
    """Least-squares slope of ``angle(t)`` (rad/time); the mean rate of an unwrapped angle.

    Args:
        ts: ``(T,)``; angle: ``(T,)``.
    """
    ts = np.asarray(ts, dtype=float)
    angle = np.asarray(angle, dtype=float)
    tc = ts - ts.mean()
    return float(np.sum(tc * (angle - angle.mean())) / np.sum(tc * tc))
