"""Reductions over short axes written out elementwise: ``all``, ``any``, ``max``,
``argmax``, sums and the RMS norm.

XLA:CPU gives each reduction in a program buffers of its own (its reducer's scalars),
and every call of the program pays for them, whether the reduction runs once, in every
step of a loop, or not at all: about 0.2 µs per reduction per call on this project's
machines (measured in a one-kernel program: 40 reductions of 7 entries added 8 µs to a
call, 0.67 µs to each of its loop's iterations). A default solve held 26 (free rotor)
to 29 (heavy top) of them (its input checks, the step-size control, the projection, the
outcome), nearly all over 2–16 entries. Written out as ``&``, ``|``, ``max`` and ``+``
of slices, they join their neighbours' fused loops and cost nothing per call. Longer
axes (more than ``SMALL`` entries, e.g. many output times) keep the reduction.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

__all__ = ["SMALL", "every", "first_true", "largest", "rms_norm", "some", "total"]

#: Reductions over at most this many entries are written out elementwise.
SMALL = 64


def _fold(op, a: jax.Array, axis) -> jax.Array:
    a = jnp.moveaxis(a, axis, -1)
    out = a[..., 0]
    for i in range(1, a.shape[-1]):
        out = op(out, a[..., i])
    return out


def _small(a: jax.Array, axis) -> bool:
    return a.ndim > 0 and 0 < a.shape[axis] <= SMALL


def every(a, axis: int | None = None) -> jax.Array:
    """``jnp.all(a, axis)``; over at most ``SMALL`` entries written out as ``&``."""
    a = jnp.asarray(a, bool)
    if axis is None:
        a, axis = a.reshape(-1), -1
    return _fold(jnp.logical_and, a, axis) if _small(a, axis) else jnp.all(a, axis=axis)


def some(a, axis: int | None = None) -> jax.Array:
    """``jnp.any(a, axis)``, written out over at most ``SMALL`` entries (:func:`every`)."""
    a = jnp.asarray(a, bool)
    if axis is None:
        a, axis = a.reshape(-1), -1
    return _fold(jnp.logical_or, a, axis) if _small(a, axis) else jnp.any(a, axis=axis)


def largest(a: jax.Array) -> jax.Array:
    """``jnp.max(a)`` of a 1-D array, written out over at most ``SMALL`` entries."""
    return _fold(jnp.maximum, a, -1) if _small(a, -1) else jnp.max(a)


def first_true(a: jax.Array) -> jax.Array:
    """``jnp.argmax(a)`` of a 1-D bool array (0 if none is true), as ``int32``; written
    out over at most ``SMALL`` entries."""
    if not _small(a, -1):
        return jnp.argmax(a).astype(jnp.int32)
    index = jnp.zeros(a.shape[:-1], jnp.int32)
    for i in range(a.shape[-1] - 1, -1, -1):
        index = jnp.where(a[..., i], jnp.int32(i), index)
    return index


def total(a: jax.Array, axis: int = -1) -> jax.Array:
    """``jnp.sum(a, axis)``, written out over at most ``SMALL`` entries."""
    a = jnp.asarray(a)
    return _fold(jnp.add, a, axis) if _small(a, axis) else jnp.sum(a, axis=axis)


@jax.custom_jvp
def rms_norm(x) -> jax.Array:
    """``sqrt(Σ xᵢ² / n)`` over every entry of the pytree ``x`` (``optimistix.rms_norm``,
    diffrax's default norm), summed elementwise over at most ``SMALL`` entries; ``0``
    for no entries. Its derivative is ``0`` where the norm is ``0`` or infinite."""
    leaves = [jnp.ravel(a) for a in jax.tree_util.tree_leaves(x)]
    size = sum(a.shape[0] for a in leaves)
    if size == 0:
        return jnp.zeros((), jnp.result_type(*leaves) if leaves else float)
    flat = jnp.concatenate(leaves) if len(leaves) > 1 else leaves[0]
    return jnp.sqrt(total(flat * flat) / size)


@rms_norm.defjvp
def _rms_norm_jvp(primals, tangents):
    (x,), (tx,) = primals, tangents
    out = rms_norm(x)
    size = sum(jnp.size(a) for a in jax.tree_util.tree_leaves(x))
    pred = (out == 0) | jnp.isinf(out)
    denominator = jnp.where(pred, 1, out) * max(size, 1)
    dot = sum((total(jnp.ravel(a * b)) for a, b in zip(jax.tree_util.tree_leaves(x),
                                                        jax.tree_util.tree_leaves(tx),
                                                        strict=True)), jnp.zeros_like(out))
    return out, jnp.where(pred, 0, dot / denominator)
