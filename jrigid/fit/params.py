"""Parametrisations that stay physical for every unconstrained input.

An optimiser moves freely in ``R^n``; these maps take such *raw* vectors to physical
quantities, so no step can leave the physical domain:

- :func:`moment_ratios` — principal moments of a torque-free body **up to scale**
  (2 raw numbers). Torque-free motion is unchanged when every moment is multiplied by
  the same factor (Euler's equations ``I ω̇ = −ω × I ω`` are homogeneous in ``I``), so
  an observation of the motion fixes only the ratios. The scale is therefore fixed
  explicitly: the moments sum to ``trace`` (default 1).
- :func:`moments` — principal moments including their scale (3 raw numbers), for
  scenes where the scale matters (a top under gravity, a user torque).
- :func:`inertia_tensor` — a full symmetric tensor ``R diag(I) Rᵀ``: moments plus the
  orientation ``R`` of the principal axes (a raw 4-vector, normalised).
- :func:`unit_quaternion` — an orientation from a raw 4-vector.
- :func:`positive` — a positive scalar (pivot distance, field strength) from a raw number.

Why the moments are physical. Write ``I1 = b + c``, ``I2 = a + c``, ``I3 = a + b``. Then
``I1 + I2 − I3 = 2c`` and so on: the triangle inequality holds iff ``a, b, c ≥ 0``, and
every physical triple has the unique representation ``a = (I2 + I3 − I1)/2`` etc. Here
``(a, b, c)`` are the fractions ``floor + (1 − 3 floor) softmax(r1, r2, 0)``: positive,
summing to one, and with every interior point reached. The ``floor`` (default ``1e-6``)
keeps the smallest moment at least ``2 floor`` times the trace, so the tensor is
positive definite (``jrigid.inertia.validate`` passes) even for raw inputs of ``±1e308``;
flat bodies (``a = 0``) are approached but not reached.

The inverses (``*_raw`` functions) give the raw vector of a physical value, for
starting points and for tests.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from jrigid import inertia as _inertia
from jrigid import quaternion as quat
from jrigid._checks import as_float, fail_if

__all__ = [
    "inertia_tensor",
    "moment_ratios",
    "moment_ratios_raw",
    "moments",
    "moments_raw",
    "positive",
    "positive_raw",
    "unit_quaternion",
]

DEFAULT_FLOOR = 1e-6


def _check_last(x: jax.Array, n: int, name: str) -> None:
    if x.ndim < 1 or x.shape[-1] != n:
        raise ValueError(f"{name} must have shape (..., {n}), got {x.shape}")


def _fractions(raw: jax.Array, floor: float) -> jax.Array:
    """``(..., 2)`` raw → ``(..., 3)`` positive fractions summing to one, each ≥ ``floor``."""
    logits = jnp.concatenate([raw, jnp.zeros_like(raw[..., :1])], axis=-1)
    return floor + (1.0 - 3.0 * floor) * jax.nn.softmax(logits, axis=-1)


def _from_fractions(p: jax.Array, trace: jax.Array) -> jax.Array:
    a, b, c = p[..., 0], p[..., 1], p[..., 2]
    # I1 = b + c etc., summed directly (no 1 - a cancellation); the sum of the moments
    # is 2 (a + b + c) = 2, hence the factor trace / 2.
    return 0.5 * trace[..., None] * jnp.stack([b + c, a + c, a + b], axis=-1)


def moment_ratios(
    raw: ArrayLike, trace: ArrayLike = 1.0, *, floor: float = DEFAULT_FLOOR
) -> jax.Array:
    """Principal moments with a fixed sum, from 2 unconstrained numbers.

    Torque-free motion fixes only the ratios of the moments: this map fixes their
    scale to ``I1 + I2 + I3 = trace`` so that an optimiser cannot wander along the
    unobservable direction (and the Gauss–Newton covariance stays regular).

    Args:
        raw: ``(..., 2)`` any finite reals.
        trace: ``()`` or ``(...)`` the fixed sum of the moments (> 0).
        floor: smallest fraction ``(Ia + Ib − Ic) / trace`` allowed (see module docstring).

    Returns:
        ``(..., 3)`` moments ``(I1, I2, I3)``: positive, triangle inequality strict.
    """
    raw = as_float(raw)
    _check_last(raw, 2, "raw")
    trace = jnp.broadcast_to(as_float(trace), raw.shape[:-1])
    return _from_fractions(_fractions(raw, floor), trace)


def moment_ratios_raw(moments_: ArrayLike, *, floor: float = DEFAULT_FLOOR) -> jax.Array:
    """Inverse of :func:`moment_ratios` (the scale is dropped).

    Args:
        moments_: ``(..., 3)`` physical principal moments (triangle inequality strict
            enough that every fraction exceeds ``floor``).

    Returns:
        ``(..., 2)`` raw vector with ``moment_ratios(raw, sum(moments_)) == moments_``.

    Raises:
        ValueError: non-physical moments (concrete input), via ``jrigid.inertia.validate``,
            or moments whose fractions do not all exceed ``floor`` (a flat body).
    """
    m = _inertia.validate(as_float(moments_), kind="moments")
    i1, i2, i3 = m[..., 0], m[..., 1], m[..., 2]
    half = jnp.stack([i2 + i3 - i1, i1 + i3 - i2, i1 + i2 - i3], axis=-1) / 2.0
    p = half / jnp.sum(half, axis=-1, keepdims=True)
    p = fail_if(p, ~jnp.all(p > floor, axis=-1),
                f"moments too close to a flat body: every fraction (I_j + I_k - I_i) / ΣI "
                f"must exceed floor = {floor:g}, where the parametrisation ends",
                lambda: f"fractions {np.asarray(p)}")
    s = (p - floor) / (1.0 - 3.0 * floor)
    s = jnp.maximum(s, jnp.finfo(s.dtype).tiny)
    return jnp.log(s[..., :2]) - jnp.log(s[..., 2:])


def _scale_bound(dtype) -> float:
    return 0.25 * math.log(float(jnp.finfo(dtype).max))


def positive(raw: ArrayLike, unit: ArrayLike = 1.0) -> jax.Array:
    """A positive number ``unit · exp(raw)``, with ``raw`` clipped so nothing overflows.

    The clip at ``±log(max float)/4`` (±177 in float64, ±22 in float32) only matters for
    absurd inputs; it keeps the result finite and positive for every finite ``raw``.

    Args:
        raw: ``(...)`` any reals.
        unit: ``()`` the value at ``raw = 0``.

    Returns:
        ``(...)`` positive values.
    """
    raw = as_float(raw)
    bound = _scale_bound(raw.dtype)
    return as_float(unit) * jnp.exp(jnp.clip(raw, -bound, bound))


def positive_raw(value: ArrayLike, unit: ArrayLike = 1.0) -> jax.Array:
    """Inverse of :func:`positive`: ``log(value / unit)``."""
    return jnp.log(as_float(value) / as_float(unit))


def moments(raw: ArrayLike, unit: ArrayLike = 1.0, *, floor: float = DEFAULT_FLOOR) -> jax.Array:
    """Principal moments including their scale, from 3 unconstrained numbers.

    ``raw[..., :2]`` sets the ratios (as :func:`moment_ratios`), ``raw[..., 2]`` the
    sum of the moments, ``unit · exp(raw[..., 2])`` (see :func:`positive`). Use this only
    when the scale is observable (gravity, a known torque); for torque-free motion use
    :func:`moment_ratios`.

    Args:
        raw: ``(..., 3)`` any finite reals.
        unit: ``()`` the sum of the moments at ``raw[..., 2] = 0``.
        floor: as in :func:`moment_ratios`.

    Returns:
        ``(..., 3)`` physical principal moments.
    """
    raw = as_float(raw)
    _check_last(raw, 3, "raw")
    return moment_ratios(raw[..., :2], positive(raw[..., 2], unit), floor=floor)


def moments_raw(
    moments_: ArrayLike, unit: ArrayLike = 1.0, *, floor: float = DEFAULT_FLOOR
) -> jax.Array:
    """Inverse of :func:`moments`: ``(..., 3)`` moments → ``(..., 3)`` raw."""
    m = as_float(moments_)
    ratios = moment_ratios_raw(m, floor=floor)
    return jnp.concatenate([ratios, positive_raw(jnp.sum(m, axis=-1), unit)[..., None]], axis=-1)


def unit_quaternion(raw: ArrayLike) -> jax.Array:
    """Unit quaternion ``raw / |raw|`` (scalar first).

    ``raw`` and ``c · raw`` (``c > 0``) give the same rotation, and ``q ≡ −q``: the
    norm is a direction the data cannot see, so the Gauss–Newton matrix has one zero
    eigenvalue per raw quaternion (:func:`jrigid.fit.laplace` uses a pseudo-inverse and
    reports the rank). Start from a raw vector of norm about one. The zero vector has
    no direction; its gradient is set to zero (double-``where``) and the result is the
    identity.

    Args:
        raw: ``(..., 4)`` any reals.

    Returns:
        ``(..., 4)`` unit quaternion.
    """
    raw = as_float(raw)
    _check_last(raw, 4, "raw")
    ok = jnp.max(jnp.abs(raw), axis=-1, keepdims=True) > 0
    safe = jnp.where(ok, raw, quat.identity(dtype=raw.dtype))
    # Rescale by a power of two so that |raw|² neither over- nor underflows (a division
    # by the largest entry would be compiled as a product with its reciprocal, which
    # underflows for entries near the largest float).
    maxexp = jnp.finfo(raw.dtype).maxexp
    big = jnp.max(jnp.abs(safe), axis=-1, keepdims=True)
    factor = jnp.where(
        big > 2.0 ** (maxexp // 2),
        2.0 ** -(maxexp * 7 // 8),
        jnp.where(big < 2.0 ** -(maxexp // 2), 2.0 ** (maxexp * 7 // 8), 1.0),
    ).astype(raw.dtype)
    safe = safe * factor
    q = safe / jnp.sqrt(jnp.sum(safe * safe, axis=-1, keepdims=True))
    return jnp.where(ok, q, quat.identity(dtype=raw.dtype))


def inertia_tensor(
    raw_moments: ArrayLike,
    raw_axes: ArrayLike,
    unit: ArrayLike = 1.0,
    *,
    ratios_only: bool = False,
    floor: float = DEFAULT_FLOOR,
) -> jax.Array:
    """Full inertia tensor ``R diag(I) Rᵀ`` (eq. 17.32) from unconstrained numbers.

    Args:
        raw_moments: ``(..., 3)`` (see :func:`moments`), or ``(..., 2)`` with
            ``ratios_only=True`` (see :func:`moment_ratios`, ``unit`` is then the trace).
        raw_axes: ``(..., 4)`` raw quaternion of the principal axes: column ``i`` of
            ``R`` is principal axis ``i + 1`` in the reference frame.
        unit: scale (see :func:`moments` / :func:`moment_ratios`).
        ratios_only: fix the trace (torque-free fits).
        floor: as in :func:`moment_ratios`.

    Returns:
        ``(..., 3, 3)`` symmetric positive-definite tensor satisfying the triangle
        inequality. Build the body with ``RigidBody(moments, frame=unit_quaternion(raw_axes))``
        to simulate in the principal frame without diagonalising.
    """
    if ratios_only:
        m = moment_ratios(raw_moments, unit, floor=floor)
    else:
        m = moments(raw_moments, unit, floor=floor)
    q = unit_quaternion(raw_axes)
    return _inertia.rotate_tensor(_inertia.to_tensor(m), q)
