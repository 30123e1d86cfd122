"""Rate measurements on a sampled motion: Euler angles of a body axis about a fixed
direction, unwrapped, and their least-squares rates (see :mod:`jrigid.theory`).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from jrigid import quaternion as quat
from jrigid._checks import as_floats

__all__ = [
    "angle_rate",
    "axis_angles",
    "frame_about",
    "omega_phase_rate",
    "trajectory_rates",
    "unwrap",
    "wobble_to_spin",
    "zero_crossings",
]

_TWO_PI = 2.0 * math.pi


def _check_axis(axis) -> None:
    if axis not in (0, 1, 2):
        raise ValueError(f"axis must be 0, 1 or 2, got {axis!r}")


def unwrap(angle: ArrayLike) -> jax.Array:
    """Continuous angle along the last axis: each step reduced to ``(−π, π]``.

    The ``2π`` corrections are piecewise constant, so the derivative is that of the
    raw angles (unlike zero-crossing counts).

    Args:
        angle: ``(..., T)`` angles (rad).

    Returns:
        ``(..., T)`` unwrapped angles, equal to ``angle`` at the first sample.
    """
    a = jnp.asarray(angle)
    d = jnp.diff(a, axis=-1)
    d = d - _TWO_PI * jax.lax.stop_gradient(jnp.round(d / _TWO_PI))
    zero = jnp.zeros_like(a[..., :1])
    return a[..., :1] + jnp.concatenate([zero, jnp.cumsum(d, axis=-1)], axis=-1)


def angle_rate(ts: ArrayLike, angle: ArrayLike) -> jax.Array:
    """Least-squares slope ``Σ (t − t̄)(a − ā) / Σ (t − t̄)²`` of an unwrapped angle.

    Args:
        ts: ``(T,)`` times; angle: ``(..., T)`` continuous (unwrapped) angles.

    Returns:
        ``(...)`` mean rate (rad/time).

    Example:
        >>> import jax.numpy as jnp
        >>> from jrigid import theory
        >>> ts = jnp.linspace(0.0, 2.0, 21)
        >>> print(f"{float(theory.angle_rate(ts, 3.0 * ts + 1.0)):.4f}")
        3.0000
    """
    ts, a = jnp.asarray(ts), jnp.asarray(angle)
    tc = ts - jnp.mean(ts)
    ac = a - jnp.mean(a, axis=-1, keepdims=True)
    return jnp.sum(tc * ac, axis=-1) / jnp.sum(tc * tc)


def frame_about(n: ArrayLike) -> jax.Array:
    """Right-handed rotation matrix ``(3, 3)`` whose third column is ``n / |n|``.

    The first column is the unit vector along ``n̂ × e`` with ``e`` the coordinate axis
    least aligned with ``n`` (a fixed, reproducible choice). Differentiable in ``n``.

    Args:
        n: ``(3,)`` nonzero vector.

    Raises:
        ValueError: for a concrete zero (or non-finite) ``n``.
    """
    if not isinstance(n, jax.core.Tracer) and not np.linalg.norm(np.asarray(n, float)) > 0:
        raise ValueError("frame_about: the axis vector is zero")
    n = jnp.asarray(n)
    n = n.astype(jnp.result_type(n, float))
    z = n / jnp.linalg.norm(n)
    e = jax.nn.one_hot(jnp.argmin(jnp.abs(jax.lax.stop_gradient(z))), 3, dtype=z.dtype)
    x = jnp.cross(z, e)
    x = x / jnp.linalg.norm(x)
    return jnp.stack([x, jnp.cross(z, x), z], axis=-1)


def axis_angles(
    q: ArrayLike, direction: ArrayLike, axis: int = 2, unwrapped: bool = True
) -> jax.Array:
    """Precession ``φ``, nutation ``θ`` and spin ``ψ`` of a body axis about a fixed direction.

    The chapter's ZXZ Euler angles (eq. 17.10, active form) with the space ``Z`` axis along
    ``direction``: with ``A = [x, y, n̂]`` (:func:`frame_about`) and ``P`` the cyclic
    permutation that makes body axis ``axis`` play the role of ``z``,
    ``R = A · Rz(φ) Rx(θ) Rz(ψ) · Pᵀ``. ``φ`` is the azimuth of the line of nodes (the axis
    ``u`` itself is at ``φ − π/2``), ``θ = atan2(|u × n|, u·n)`` and ``ψ`` the spin about
    ``u``. For a symmetric torque-free body about ``L`` these are straight lines
    (:func:`~jrigid.theory.plate_theory`). At ``θ = 0`` (axis along the direction) only ``φ + ψ`` is
    defined.

    Args:
        q: ``(T, 4)`` body → space orientations (principal frame).
        direction: ``(3,)`` fixed space direction (``L``, or the vertical for a top).
        axis: body axis ``0, 1, 2``; ``ψ`` is measured about it from the line of nodes,
            with the body axes ``(axis+1, axis+2, axis)`` right-handed.
        unwrapped: unwrap ``φ`` and ``ψ`` in time (:func:`unwrap`; continuous angles, for
            rates); else each in ``(−π, π]``.

    Returns:
        ``(T, 3)`` array of ``(φ, θ, ψ)`` (rad).

    Example:
        >>> import jax.numpy as jnp
        >>> from jrigid import quaternion as quat, theory
        >>> q = quat.from_axis_angle(jnp.array([1.0, 0.0, 0.0]), jnp.array([0.3]))
        >>> ang = theory.axis_angles(q, jnp.array([0.0, 0.0, 1.0]))  # tilted by 0.3 rad
        >>> print([f"{abs(a):.4f}" for a in ang[0, 1:].tolist()])
        ['0.3000', '0.0000']
    """
    _check_axis(axis)
    q = jnp.asarray(q)
    q = q.astype(jnp.result_type(q, float))
    frame = frame_about(jnp.asarray(direction, dtype=q.dtype))
    x, y, n = frame[:, 0], frame[:, 1], frame[:, 2]
    eye = jnp.eye(3, dtype=q.dtype)
    u = quat.rotate(q, jnp.broadcast_to(eye[axis], q.shape[:-1] + (3,)))
    phi = jnp.arctan2(u @ x, -(u @ y))
    theta = jnp.arctan2(jnp.linalg.norm(jnp.cross(u, n), axis=-1), u @ n)
    nb = quat.rotate_inverse(q, jnp.broadcast_to(n, q.shape[:-1] + (3,)))
    psi = jnp.arctan2(nb[..., (axis + 1) % 3], nb[..., (axis + 2) % 3])
    if unwrapped:
        phi, psi = unwrap(phi), unwrap(psi)
    return jnp.stack([phi, theta, psi], axis=-1)


def trajectory_rates(ts: ArrayLike, q: ArrayLike, direction: ArrayLike, axis: int = 2) -> dict:
    """Mean precession and spin rates and mean tilt of a body axis from sampled orientations.

    Args:
        ts: ``(T,)`` times; q: ``(T, 4)``; direction: ``(3,)``; axis: as :func:`axis_angles`.

    Returns:
        dict of ``()`` arrays: ``precession_rate``, ``spin_rate``, ``ratio``
        ``|φ̇/ψ̇|`` and ``tilt`` (the mean of ``θ``).
    """
    ang = axis_angles(q, direction, axis)
    prec = angle_rate(ts, ang[:, 0])
    spin = angle_rate(ts, ang[:, 2])
    return dict(
        precession_rate=prec,
        spin_rate=spin,
        ratio=jnp.abs(prec) / jnp.abs(spin),
        tilt=jnp.mean(ang[:, 1]),
    )


def wobble_to_spin(ts: ArrayLike, q: ArrayLike, L_space: ArrayLike, axis: int = 2) -> dict:
    """Measured precession and spin rates of body axis ``axis`` about ``L`` (line fits).

    :func:`trajectory_rates` about ``L``; compare with :func:`~jrigid.theory.plate_theory`.

    Args:
        ts: ``(T,)`` times; q: ``(T, 4)`` body → space orientations.
        L_space: ``(3,)`` or ``(T, 3)`` angular momentum in space; a series is averaged
            (it is constant for torque-free motion) to fix the reference frame.
        axis: body axis ``0, 1, 2``.

    Returns:
        dict of ``()`` arrays: ``precession_rate``, ``spin_rate``, ``ratio`` ``|φ̇/ψ̇|``
        and the mean nutation ``theta``.
    """
    L = jnp.asarray(L_space)
    if L.ndim == 2:
        L = jnp.mean(L, axis=0)
    r = trajectory_rates(ts, q, L, axis)
    return dict(
        precession_rate=r["precession_rate"],
        spin_rate=r["spin_rate"],
        ratio=r["ratio"],
        theta=r["tilt"],
    )


def omega_phase_rate(ts: ArrayLike, omega: ArrayLike, axis: int) -> jax.Array:
    """Mean rate of the phase of ``(ω_{axis+1}, ω_{axis+2})``: ``±2π/T`` when the polhode
    encircles ``axis`` (:func:`unwrap` and :func:`angle_rate`); for a symmetric body the
    rate ``Ω`` of :func:`~jrigid.theory.body_precession_rate`.

    Args:
        ts: ``(T,)``; omega: ``(T, 3)`` principal-frame angular velocity; axis: ``0, 1, 2``.

    Returns:
        ``()`` rate (rad/time).
    """
    omega = jnp.asarray(omega)
    phase = jnp.arctan2(omega[:, (axis + 2) % 3], omega[:, (axis + 1) % 3])
    return angle_rate(ts, unwrap(phase))


def zero_crossings(ts: ArrayLike, x: ArrayLike) -> jax.Array:
    """Times where the samples ``x`` change sign (linear interpolation between samples).

    A sample that is exactly zero between samples of opposite signs is a crossing at its
    own time (a run of zeros: at the run's middle); zeros between samples of one sign
    (a touch) and at either end are not crossings.

    Which intervals hold a crossing is read from the concrete samples (their number is
    data-dependent, so this does not ``jit``); the crossing times are differentiable in
    ``ts`` and ``x``.

    Args:
        ts: ``(T,)`` times; x: ``(T,)`` finite samples.

    Returns:
        ``(C,)`` crossing times, in order.

    Example:
        >>> import jax.numpy as jnp
        >>> from jrigid import theory
        >>> ts = jnp.linspace(0.0, 7.0, 701)
        >>> print([f"{t:.3f}" for t in theory.zero_crossings(ts, jnp.sin(ts)).tolist()])
        ['3.142', '6.283']
    """
    ts, x = as_floats(ts, x)
    if ts.ndim != 1 or x.shape != ts.shape:
        raise ValueError(f"ts and x must both have shape (T,); got {ts.shape} and {x.shape}")
    xs = np.asarray(jax.lax.stop_gradient(x))
    if not np.all(np.isfinite(xs)):
        raise ValueError(f"x must be finite; sample {int(np.argmin(np.isfinite(xs)))} "
                         "is not")
    # consecutive non-zero samples of opposite signs, with only zeros between them
    sign = np.sign(xs)
    nonzero = np.flatnonzero(sign)
    before, after = nonzero[:-1], nonzero[1:]
    cross = sign[before] != sign[after]
    before, after = before[cross], after[cross]
    # the interval interpolated: between the two samples, or, across one zero sample,
    # from that zero (which is the crossing, with its derivative in x); across a run of
    # zeros the crossing is the run's middle
    run = after - before - 1
    i = np.where(run == 1, before + 1, before)
    linear = ts[i] - x[i] * (ts[i + 1] - ts[i]) / (x[i + 1] - x[i])
    middle = 0.5 * (ts[before + 1] + ts[np.maximum(after - 1, before + 1)])
    return jnp.where(run > 1, middle, linear)
