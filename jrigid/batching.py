"""Batched constants of a closed-form motion, evaluated at arrays of times.

The closed-form motions (:mod:`jrigid.exact`, :mod:`jrigid.lagrange_top`) compute a
pytree of per-body constants once, with a batch shape ``B``, and evaluate it at times of
any shape ``S``; the results have shape ``B + S + (…)``. :func:`over_times` lines up the
two, :func:`power_of_two_scale` picks the exact power-of-two unit both rescale their inputs
by (so that nothing under- or overflows), and :func:`sign` is the derivative-free sign both
use for branch choices.
"""

from __future__ import annotations

from typing import TypeVar

import jax
import jax.numpy as jnp

__all__ = ["over_times", "power_of_two_scale", "sign"]

C = TypeVar("C")


def over_times(consts: C, t: jax.Array, batch_ndim: int) -> tuple[C, jax.Array]:
    """Broadcast a pytree of constants (batch shape ``B``) against times ``t`` (shape ``S``).

    Args:
        consts: pytree whose leaves have shape ``B + (…)`` (``len(B) = batch_ndim``).
        t: ``S``-shaped times.
        batch_ndim: the number of batch axes of ``consts``.

    Returns:
        ``(consts, t)``: every leaf broadcast to ``B + S + (…)``, and ``t`` to ``B + S``.

    Example:
        >>> import jax.numpy as jnp
        >>> from jrigid import batching
        >>> c, t = batching.over_times({"rate": jnp.ones((2,))}, jnp.zeros((5,)), 1)
        >>> c["rate"].shape, t.shape
        ((2, 5), (2, 5))
    """
    extra = t.ndim

    def expand(x):
        return x.reshape(x.shape[:batch_ndim] + (1,) * extra + x.shape[batch_ndim:])

    c = jax.tree_util.tree_map(expand, consts)
    t = t.reshape((1,) * batch_ndim + t.shape)
    leaves = jax.tree_util.tree_leaves(c)
    shape = jnp.broadcast_shapes(leaves[0].shape[: batch_ndim + extra], t.shape)
    t = jnp.broadcast_to(t, shape)
    c = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, shape + x.shape[len(shape) :]), c)
    return c, t


def power_of_two_scale(x: jax.Array) -> jax.Array:
    """``2^-e`` with ``x = f 2^e``, ``f`` in ``[0.5, 1)`` (``x > 0``); no derivative.

    Multiplying by it is exact, so rescaled inputs carry no rounding error.
    """
    _, e = jnp.frexp(jax.lax.stop_gradient(x))
    return jnp.ldexp(jnp.ones_like(x), -e)


def sign(x: jax.Array) -> jax.Array:
    """``+1`` for ``x ≥ 0``, ``-1`` otherwise (a constant: no derivative)."""
    return jnp.where(x >= 0, 1.0, -1.0)
