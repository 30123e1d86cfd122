"""Small array utilities shared by the quaternion modules (not public API)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from jrigid import linalg
from jrigid._checks import as_float, check_shape
from jrigid.linalg import rescale


def as_float_pair(a: ArrayLike, b: ArrayLike) -> tuple[jax.Array, jax.Array]:
    """Convert two inputs to arrays of one common floating dtype."""
    return as_float_all(a, b)


def as_float_all(*xs: ArrayLike) -> tuple[jax.Array, ...]:
    """Convert any number of inputs to arrays of one common floating dtype."""
    arrays = [as_float(x, weak=True) for x in xs]
    dtype = jnp.result_type(*arrays)
    return tuple(a.astype(dtype) for a in arrays)


def quaternion_arg(q: ArrayLike, name: str = "q", order: str = "(w, x, y, z)") -> jax.Array:
    """``q`` as a float array, after checking its trailing shape is ``(4,)`` (static);
    ``order`` names its components in the message."""
    return check_shape(as_float(q, weak=True), name, (4,), why=f", a quaternion {order}")


def vector_arg(v: ArrayLike, name: str) -> jax.Array:
    """``v`` as a float array, after checking its trailing shape is ``(3,)`` (static)."""
    return check_shape(as_float(v, weak=True), name, (3,))


def matrix_arg(m: ArrayLike, name: str = "matrix") -> jax.Array:
    """``m`` as a float array, after checking its trailing shape is ``(3, 3)`` (static)."""
    return check_shape(as_float(m, weak=True), name, (3, 3))


def unit(x: jax.Array) -> jax.Array:
    """``x / |x|`` along the last axis, safe for any finite non-zero scale (``0`` gives NaN).

    :func:`jrigid.linalg.unit` after :func:`jrigid.linalg.rescale`; where no rescaling is needed the
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
