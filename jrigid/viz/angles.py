"""Precession, nutation and spin of a body axis about the angular momentum, as numpy.

The angles and rates are measured by :mod:`jrigid.theory` (:func:`jrigid.theory.axis_angles`,
:func:`jrigid.theory.angle_rate`, :func:`jrigid.theory.frame_about`); these wrappers take
and return numpy arrays and Python floats for the plots and reports. For torque-free motion
``L`` is fixed in space, so the natural Euler angles use ``L̂`` as the space ``Z`` axis:
``φ`` is the precession of the chosen body axis about ``L``, ``θ`` its nutation (angle to
``L``) and ``ψ`` the spin about the axis itself (the chapter's ZXZ angles, eq. 17.10).
For a symmetric top (``I1 = I2``, symmetry axis 3) these are straight lines
(:func:`jrigid.theory.plate_theory`).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from jrigid import theory

__all__ = ["euler_about", "fit_rate", "frame_about"]


def frame_about(n) -> np.ndarray:
    """Right-handed rotation matrix ``(3, 3)`` whose third column is ``n / |n|``
    (:func:`jrigid.theory.frame_about`, as numpy).

    Args:
        n: ``(3,)`` nonzero vector.
    """
    return np.asarray(theory.frame_about(np.asarray(n, dtype=float)), dtype=float)


def euler_about(q, L_space, axis: int = 2, unwrap: bool = True) -> np.ndarray:
    """Precession ``φ``, nutation ``θ`` and spin ``ψ`` of body axis ``axis`` about ``L``.

    :func:`jrigid.theory.axis_angles` about ``L``, as numpy.

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
    ang = theory.axis_angles(jnp.asarray(q), jnp.asarray(L), axis, unwrapped=unwrap)
    return np.asarray(ang, dtype=float)


def fit_rate(ts, angle) -> float:
    """Least-squares slope of ``angle(t)`` (rad/time); the mean rate of an unwrapped angle
    (:func:`jrigid.theory.angle_rate`).

    Args:
        ts: ``(T,)``; angle: ``(T,)``.
    """
    return float(theory.angle_rate(np.asarray(ts, dtype=float), np.asarray(angle, dtype=float)))
