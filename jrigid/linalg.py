"""Small-vector linear algebra written out component by component.

Dot products (of 3- and 4-vectors), unit vectors, cross products, ``3 × 3`` solves and
scale-safe norms (:func:`rescale`, :func:`safe_norm`) of rigid-body mechanics, as sums of
products rather than reductions or library calls: inside an integrator's loop XLA fuses
them with their neighbours on a CPU, where each reduction or LAPACK call would start a
kernel of its own (a step of the quaternion-acceleration field costs several times less
this way). All functions take any leading batch shape.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
from jax import lax

from jrigid._checks import check_shape

__all__ = [
    "cross", "dot", "euler_diagonal", "matvec", "norm2", "rescale", "safe_norm", "solve3", "unit",
]


def dot(a: jax.Array, b: jax.Array) -> jax.Array:
    """``a · b`` over the last axis (a short one: 3 or 4; statically unrolled).

    Args:
        a, b: ``(..., n)`` with broadcastable batch shapes.

    Returns:
        ``(...)``.

    Raises:
        ValueError: last axes of different lengths.
    """
    a = jnp.asarray(a)
    if a.ndim < 1:
        raise ValueError(f"dot: a must have shape (..., n); got shape {a.shape}")
    b = check_shape(b, "dot: b", a.shape[-1:], why=" to match a")
    total = a[..., 0] * b[..., 0]
    for i in range(1, a.shape[-1]):
        total = total + a[..., i] * b[..., i]
    return total


def norm2(a: jax.Array) -> jax.Array:
    """``|a|²`` of ``(..., n)`` vectors, shape ``(...)``."""
    return dot(a, a)


def unit(a: jax.Array) -> jax.Array:
    """``a / |a|`` of ``(..., n)`` vectors with one ``rsqrt``, shape ``(..., n)``.

    The lean normalisation of the integrators' loops (a handful of fused elementwise
    operations, no reduction): ``|a|²`` must be a normal float, i.e. ``|a|`` within
    about ``1e±150`` in float64 and ``1e±18`` in float32; a zero ``a`` gives NaN. For
    input of any scale use :func:`jrigid.quaternion.normalize`.

    One ``rsqrt``, not a division by ``sqrt``: XLA rewrites ``a / sqrt(s)`` into
    ``a * rsqrt(s)`` only where the ``sqrt`` has no other use, so the same step rounded
    differently when recomputed inside a reverse pass (where the ``sqrt`` is reused),
    and checkpointed gradients through projected solves drifted (up to 1e-3).
    """
    return a * lax.rsqrt(norm2(a))[..., None]


def cross(a: jax.Array, b: jax.Array) -> jax.Array:
    """``a × b`` of ``(..., 3)`` vectors (batch shapes broadcast), shape ``(..., 3)``.

    ``ValueError`` if a last axis is not of length 3."""
    a, b = check_shape(a, "cross: a", (3,)), check_shape(b, "cross: b", (3,))
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    bx, by, bz = b[..., 0], b[..., 1], b[..., 2]
    return jnp.stack([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx], axis=-1)


def euler_diagonal(moments: jax.Array, omega: jax.Array, torque: jax.Array) -> jax.Array:
    """``ω̇`` from Euler's equations for principal moments (eq. 17.35):
    ``ω̇₁ = ((I₂ − I₃)/I₁) ω₂ ω₃ + N₁/I₁`` and cyclically.

    Written with the ratios of the moments, which depend on the body alone: inside an
    integrator's loop XLA computes them once, before the loop, and fuses the rest with
    its neighbours (``(N − ω × Iω) / I`` as vectors took a third more time per evaluation
    of the quaternion-acceleration field on a CPU).

    Args:
        moments: ``(..., 3)`` principal moments ``(I₁, I₂, I₃)``.
        omega: ``(..., 3)`` body angular velocity.
        torque: ``(..., 3)`` body-frame torque.

    Returns:
        ``(..., 3)`` body angular acceleration; batch shapes broadcast.

    Raises:
        ValueError: an argument whose last axis is not of length 3.
    """
    for name, a in (("moments", moments), ("omega", omega), ("torque", torque)):
        if jnp.shape(a)[-1:] != (3,):
            raise ValueError(f"euler_diagonal: {name} must have shape (..., 3), got {jnp.shape(a)}")
    moments, omega, torque = jnp.broadcast_arrays(moments, omega, torque)
    i1, i2, i3 = moments[..., 0], moments[..., 1], moments[..., 2]
    w1, w2, w3 = omega[..., 0], omega[..., 1], omega[..., 2]
    n1, n2, n3 = torque[..., 0], torque[..., 1], torque[..., 2]
    return jnp.stack([
        ((i2 - i3) / i1) * w2 * w3 + n1 * (1.0 / i1),
        ((i3 - i1) / i2) * w3 * w1 + n2 * (1.0 / i2),
        ((i1 - i2) / i3) * w1 * w2 + n3 * (1.0 / i3),
    ], axis=-1)


def matvec(m: jax.Array, v: jax.Array) -> jax.Array:
    """``m @ v`` for small ``(..., n, k)`` matrices and ``(..., k)`` vectors, shape ``(..., n)``.

    ``ValueError`` if ``v``'s last axis is not ``m``'s."""
    m = jnp.asarray(m)
    if m.ndim < 2:
        raise ValueError(f"matvec: m must have shape (..., n, k); got shape {m.shape}")
    v = check_shape(v, "matvec: v", m.shape[-1:], why=" to match m")
    return jnp.stack([dot(m[..., i, :], v) for i in range(m.shape[-2])], axis=-1)


def solve3(m: jax.Array, b: jax.Array) -> jax.Array:
    """``m⁻¹ b`` for ``(..., 3, 3)`` matrices by the adjugate (cheap and differentiable).

    Args:
        m: ``(..., 3, 3)`` invertible matrix.
        b: ``(..., 3)`` right-hand side.

    Returns:
        ``(..., 3)``; non-finite where ``det m = 0``.

    Raises:
        ValueError: ``m`` not ``(..., 3, 3)`` or ``b`` not ``(..., 3)``.
    """
    m, b = check_shape(m, "solve3: m", (3, 3)), check_shape(b, "solve3: b", (3,))
    c0 = cross(m[..., :, 1], m[..., :, 2])
    c1 = cross(m[..., :, 2], m[..., :, 0])
    c2 = cross(m[..., :, 0], m[..., :, 1])
    det = dot(m[..., :, 0], c0)
    # times 1/det rather than divided by det: for a constant ``m`` (an inertia inside an
    # integrator's loop) XLA computes the adjugate and 1/det once, before the loop
    return jnp.stack([dot(c0, b), dot(c1, b), dot(c2, b)], axis=-1) * (1.0 / det)[..., None]


def rescale(x: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Split ``x (..., n)`` into ``(x / s, s)`` so that squaring ``x / s`` is safe.

    ``s (..., 1)`` is ``1`` (and ``x`` is returned unchanged, bit for bit) unless the
    largest ``|component|`` ``m`` lies outside ``[sqrt(tiny)/eps, sqrt(max)/(2n)]``, where
    the sum of squares would overflow or lose precision; then ``s`` is a power of two,
    ``2^e`` for ``m`` below that range and ``2^(e−2)`` above it (``m = f 2^e``,
    ``½ ≤ f < 1``), so ``x / s`` has entries below 1 (or 4) in size, divided exactly. Its
    reciprocal is a normal number even for ``m`` near the largest float: XLA computes
    ``x / s`` as ``x · (1/s)``, and a reciprocal below the smallest normal number
    (``s > 4.5e307`` in float64) is flushed to zero on a CPU. A zero ``x`` keeps ``s = 1``. An
    ``x`` with a NaN or infinite entry has no direction: ``x / s`` is all NaN there, so
    every function built on it returns NaN for that element. ``s`` carries no gradient:
    functions of ``x`` that are homogeneous (``normalize``, ``norm``, the conversions)
    then still get exact derivatives. The largest component is found by elementwise
    maxima over the (short) last axis, not a reduction, so that XLA fuses it with its
    neighbours (see the module docstring).
    """
    info = jnp.finfo(x.dtype)
    lo = math.sqrt(float(info.tiny)) / float(info.eps)
    hi = math.sqrt(float(info.max)) / (2.0 * x.shape[-1])
    m = jnp.abs(x[..., :1])
    for i in range(1, x.shape[-1]):
        m = jnp.maximum(m, jnp.abs(x[..., i : i + 1]))
    finite = jnp.isfinite(m)
    keep = ((m >= lo) & (m <= hi)) | (m == 0) | ~finite
    ones = jnp.ones_like(m)
    _, e = jnp.frexp(jnp.where(keep, ones, m))
    power = jnp.ldexp(ones, jnp.where(m > hi, e - 2, e))
    s = lax.stop_gradient(jnp.where(keep, ones, power))
    return jnp.where(finite, x / s, jnp.nan), s


def safe_norm(v: jax.Array) -> jax.Array:
    """Euclidean norm of ``(..., n)`` vectors, shape ``(...)``, safe for any finite scale
    (see :func:`rescale`), with a finite (zero) gradient at the zero vector (double
    ``where``); NaN for a vector with a NaN or infinite entry.

    The norm has no derivative at zero, so ``safe_norm(v)**2`` has a zero Hessian there
    (not ``2 I``): differentiate :func:`norm2` for the squared norm."""
    v, s = rescale(v)
    n2 = norm2(v)
    zero = n2 == 0
    n2_safe = jnp.where(zero, jnp.ones_like(n2), n2)
    return s[..., 0] * jnp.where(zero, jnp.zeros_like(n2), jnp.sqrt(n2_safe))
