"""Small array utilities shared by the quaternion modules (not public API)."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
from jax import lax
from jax.typing import ArrayLike

from jrigid import linalg
from jrigid._checks import (
    check_shape,
    is_traced,  # noqa: F401  (re-exported for the quaternion modules)
)


def as_float(x: ArrayLike) -> jax.Array:
    """Convert to a JAX array with a floating dtype (ints become the default float)."""
    x = jnp.asarray(x)
    if not jnp.issubdtype(x.dtype, jnp.inexact):
        x = x.astype(jnp.result_type(float))
    return x


def as_float_pair(a: ArrayLike, b: ArrayLike) -> tuple[jax.Array, jax.Array]:
    """Convert two inputs to arrays of one common floating dtype."""
    return as_float_all(a, b)


def as_float_all(*xs: ArrayLike) -> tuple[jax.Array, ...]:
    """Convert any number of inputs to arrays of one common floating dtype."""
    arrays = [as_float(x) for x in xs]
    dtype = jnp.result_type(*arrays)
    return tuple(a.astype(dtype) for a in arrays)


def quaternion_arg(q: ArrayLike, name: str = "q") -> jax.Array:
    """``q`` as a float array, after checking its trailing shape is ``(4,)`` (static)."""
    return check_shape(as_float(q), name, (4,), why=", a quaternion (w, x, y, z)")


def vector_arg(v: ArrayLike, name: str) -> jax.Array:
    """``v`` as a float array, after checking its trailing shape is ``(3,)`` (static)."""
    return check_shape(as_float(v), name, (3,))


def matrix_arg(m: ArrayLike, name: str = "matrix") -> jax.Array:
    """``m`` as a float array, after checking its trailing shape is ``(3, 3)`` (static)."""
    return check_shape(as_float(m), name, (3, 3))


def rescale(x: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Split ``x (..., n)`` into ``(x / s, s)`` so that squaring ``x / s`` is safe.

    ``s (..., 1)`` is ``1`` (and ``x`` is returned unchanged, bit for bit) unless the
    largest ``|component|`` lies outside ``[sqrt(tiny)/eps, sqrt(max)/(2n)]``, where the
    sum of squares would overflow or lose precision; then ``s`` is that largest
    component, so ``x / s`` has entries in ``[-1, 1]``. A zero ``x`` keeps ``s = 1``. An
    ``x`` with a NaN or infinite entry has no direction: ``x / s`` is all NaN there, so
    every function built on it returns NaN for that element. ``s`` carries no gradient:
    functions of ``x`` that are homogeneous (``normalize``, ``norm``, the conversions)
    then still get exact derivatives. The largest component is found by elementwise
    maxima over the (short) last axis, not a reduction, so that XLA fuses it with its
    neighbours (see :mod:`jrigid.linalg`).
    """
    info = jnp.finfo(x.dtype)
    lo = math.sqrt(float(info.tiny)) / float(info.eps)
    hi = math.sqrt(float(info.max)) / (2.0 * x.shape[-1])
    m = jnp.abs(x[..., :1])
    for i in range(1, x.shape[-1]):
        m = jnp.maximum(m, jnp.abs(x[..., i : i + 1]))
    finite = jnp.isfinite(m)
    keep = ((m >= lo) & (m <= hi)) | (m == 0) | ~finite
    s = lax.stop_gradient(jnp.where(keep, jnp.ones_like(m), m))
    return jnp.where(finite, x / s, jnp.nan), s


def unit(x: jax.Array) -> jax.Array:
    """``x / |x|`` along the last axis, safe for any finite non-zero scale (``0`` gives NaN).

    :func:`jrigid.linalg.unit` after :func:`rescale`; where no rescaling is needed the
    result is bit for bit that of ``linalg.unit`` (the integrators' lean version).
    """
    return linalg.unit(rescale(x)[0])


def batch_shape(x: jax.Array, core_ndim: int) -> tuple[int, ...]:
    """Leading (batch) shape of ``x`` once its ``core_ndim`` trailing axes are removed."""
    return x.shape[: x.ndim - core_ndim]


def broadcast_batch(a: jax.Array, a_core: int, b: jax.Array, b_core: int):
    """Broadcast the leading batch dimensions of ``a`` and ``b`` explicitly.

    ``a_core`` / ``b_core`` are the numbers of trailing core axes (e.g. 1 for a
    quaternion ``(..., 4)``, 0 for an angle ``(...)``, 2 for a matrix).
    """
    shape = jnp.broadcast_shapes(batch_shape(a, a_core), batch_shape(b, b_core))
    a = jnp.broadcast_to(a, shape + a.shape[a.ndim - a_core :])
    b = jnp.broadcast_to(b, shape + b.shape[b.ndim - b_core :])
    return a, b


def epsilon(dtype) -> float:
    """Threshold on a squared angle below which Taylor branches are used."""
    return 1e-5 if jnp.finfo(dtype).bits <= 32 else 1e-10


def safe_norm(v: jax.Array) -> jax.Array:
    """Euclidean norm over the last axis, safe for any finite scale (see :func:`rescale`),
    with a finite (zero) gradient at the zero vector (double ``where``); NaN for a
    vector with a NaN or infinite entry."""
    v, s = rescale(v)
    n2 = linalg.norm2(v)
    zero = n2 == 0
    n2_safe = jnp.where(zero, jnp.ones_like(n2), n2)
    return s[..., 0] * jnp.where(zero, jnp.zeros_like(n2), jnp.sqrt(n2_safe))


def cross(a: jax.Array, b: jax.Array) -> jax.Array:
    """Cross product of ``(..., 3)`` arrays (:func:`jrigid.linalg.cross`)."""
    return linalg.cross(a, b)


def dot(a: jax.Array, b: jax.Array) -> jax.Array:
    """Dot product over the last axis (:func:`jrigid.linalg.dot`, no reduction op)."""
    return linalg.dot(a, b)
