"""Small array utilities shared by the quaternion modules (not public API)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from jrigid import linalg
from jrigid._checks import is_traced  # noqa: F401  (re-exported for the quaternion modules)


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


def safe_norm(v: jax.Array, axis: int = -1) -> jax.Array:
    """Euclidean norm with a finite (zero) gradient at the zero vector (double ``where``)."""
    n2 = jnp.sum(v * v, axis=axis)
    positive = n2 > 0
    n2_safe = jnp.where(positive, n2, jnp.ones_like(n2))
    return jnp.where(positive, jnp.sqrt(n2_safe), jnp.zeros_like(n2))


def cross(a: jax.Array, b: jax.Array) -> jax.Array:
    """Cross product of ``(..., 3)`` arrays (:func:`jrigid.linalg.cross`)."""
    return linalg.cross(a, b)


def dot(a: jax.Array, b: jax.Array) -> jax.Array:
    """Dot product over the last axis (:func:`jrigid.linalg.dot`, no reduction op)."""
    return linalg.dot(a, b)
