"""Small-vector linear algebra written out component by component.

Dot products (of 3- and 4-vectors), unit vectors, cross products and ``3 × 3`` solves of rigid-body
mechanics, as sums of products rather than reductions or library calls: inside an
integrator's loop XLA fuses them with their neighbours on a CPU, where each reduction or
LAPACK call would start a kernel of its own (a step of the quaternion-acceleration
field costs about 4× less this way). All functions take any leading batch shape.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax

__all__ = ["cross", "dot", "matvec", "norm2", "solve3", "unit"]


def dot(a: jax.Array, b: jax.Array) -> jax.Array:
    """``a · b`` over the last axis (a short one: 3 or 4; statically unrolled).

    Args:
        a, b: ``(..., n)`` with broadcastable batch shapes.

    Returns:
        ``(...)``.
    """
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
    """``a × b`` of ``(..., 3)`` vectors (batch shapes broadcast), shape ``(..., 3)``."""
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    bx, by, bz = b[..., 0], b[..., 1], b[..., 2]
    return jnp.stack([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx], axis=-1)


def matvec(m: jax.Array, v: jax.Array) -> jax.Array:
    """``m @ v`` for small ``(..., n, k)`` matrices and ``(..., k)`` vectors, shape ``(..., n)``."""
    return jnp.stack([dot(m[..., i, :], v) for i in range(m.shape[-2])], axis=-1)


def solve3(m: jax.Array, b: jax.Array) -> jax.Array:
    """``m⁻¹ b`` for ``(..., 3, 3)`` matrices by the adjugate (cheap and differentiable).

    Args:
        m: ``(..., 3, 3)`` invertible matrix.
        b: ``(..., 3)`` right-hand side.

    Returns:
        ``(..., 3)``; non-finite where ``det m = 0``.
    """
    c0 = cross(m[..., :, 1], m[..., :, 2])
    c1 = cross(m[..., :, 2], m[..., :, 0])
    c2 = cross(m[..., :, 0], m[..., :, 1])
    det = dot(m[..., :, 0], c0)
    return jnp.stack([dot(c0, b), dot(c1, b), dot(c2, b)], axis=-1) / det[..., None]
