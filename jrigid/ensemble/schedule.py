"""Scheduling ensemble members into chunks: how much lockstep work a grouping wastes.

Under ``vmap`` an adaptive solve runs until the slowest member of its chunk is done, so
a chunk of members of mixed difficulty executes many steps that nobody needs.
:func:`lockstep_efficiency` measures the useful fraction of the steps a chunking
executes; :func:`difficulty_order` groups members of similar predicted cost, the
permutation to pass as :func:`jrigid.ensemble.run`'s ``order`` (``benchmarks/lockstep.py``
measures both on a stability map).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from jrigid._checks import is_traced

__all__ = ["difficulty_order", "lockstep_efficiency"]


def lockstep_efficiency(
    steps: ArrayLike, chunk_size: int, order: ArrayLike | None = None
) -> jax.Array:
    """Useful fraction of the steps a chunked ``vmap`` of adaptive solves executes.

    Under ``vmap`` diffrax's loop runs until the slowest member of a chunk is done, so a
    chunk of ``n`` members needing ``s_i`` steps executes ``n · max s_i`` member-steps.
    Efficiency ``= Σ s_i / Σ_chunks (n_chunk · max_chunk s_i)`` (a padded last chunk's
    padding is not counted).

    Args:
        steps: ``(N,)`` steps each member needs (``Trajectory.stats["num_steps"]``).
        chunk_size: static members per chunk.
        order: ``(N,)`` permutation applied before chunking (e.g. :func:`difficulty_order`);
            default the given order.

    Returns:
        ``()`` efficiency in ``(0, 1]`` (1 when no member took a step).

    Example: two chunks of two, one slow member in each or both in one::

        >>> import jax.numpy as jnp
        >>> steps = jnp.array([10, 100, 10, 100])
        >>> round(float(lockstep_efficiency(steps, 2)), 6)
        0.55
        >>> round(float(lockstep_efficiency(steps, 2, difficulty_order(steps))), 6)
        1.0
    """
    s = jnp.asarray(steps, dtype=jnp.result_type(float))
    if s.ndim != 1:
        raise ValueError(f"steps must be (N,), got shape {s.shape}")
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer)) \
            or chunk_size < 1:
        raise ValueError(f"chunk_size must be a positive int, got {chunk_size!r}")
    chunk_size = int(chunk_size)
    if order is not None:
        order = jnp.asarray(order)
        if not is_traced(order) and (order.shape != s.shape or not np.array_equal(
                np.sort(np.asarray(order)), np.arange(s.shape[0]))):
            raise ValueError(f"order must be a permutation of range({s.shape[0]}), got "
                             f"{np.asarray(order)!r}")
        s = s[order]
    n = s.shape[0]
    n_chunks = -(-n // chunk_size)
    pad = n_chunks * chunk_size - n
    padded = jnp.concatenate([s, jnp.full((pad,), -jnp.inf, s.dtype)]).reshape(n_chunks, -1)
    counts = jnp.sum(jnp.isfinite(padded), axis=1)
    executed = jnp.sum(counts * jnp.max(padded, axis=1))
    # no member took a step (every solve empty): nothing was wasted
    return jnp.where(executed > 0, jnp.sum(s) / jnp.where(executed > 0, executed, 1.0), 1.0)


def difficulty_order(difficulty: ArrayLike) -> jax.Array:
    """Permutation grouping members of similar predicted difficulty (stable ``argsort``).

    Chunk the members in this order, then scatter the outputs back with
    ``out[order] = chunked_out`` (or run with ``inputs[order]`` and invert with
    ``jnp.argsort(order)``), or pass it as :func:`jrigid.ensemble.run`'s ``order``.

    Args:
        difficulty: ``(N,)`` predicted cost per member (a pilot solve's step count, or a
            closed-form proxy). Only the ranking matters. For torque-free maps
            ``|L|² = |Iω|²`` is free and ranks Tsit5's step counts well (how well, and
            against other proxies: ``benchmarks/lockstep.py``).

    Returns:
        ``(N,)`` int permutation, easiest first.
    """
    difficulty = jnp.asarray(difficulty)
    if difficulty.ndim != 1:
        raise ValueError(f"difficulty must be (N,), one number per member, got shape "
                         f"{difficulty.shape}")
    return jnp.argsort(difficulty, stable=True)
