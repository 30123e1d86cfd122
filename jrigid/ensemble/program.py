"""One chunk of an ensemble on a set of devices: the compiled program and its evaluation.

:func:`compiled` lowers and compiles ``jax.jit(jax.vmap(fn))`` (or, for a batched ``fn``,
``fn`` on each device's group through ``jax.shard_map``) once per function, input
shapes, chunk batch and devices, and keeps it for later calls in the same process.
:func:`evaluate` pads one chunk's inputs to the batch (repeating its last member), places
them on the devices, runs the program and returns the outputs of the real members as
numpy arrays. The in-process dispatcher and the workers of an executor both use these
two (:mod:`jrigid.ensemble.dispatch`).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from typing import Any

import jax
import numpy as np

from jrigid.ensemble import sharding

__all__ = ["compiled", "evaluate"]

# Compiled chunk programs, reused by later calls with the same fn and shapes.
_COMPILED: dict[Any, Any] = {}
_COMPILED_MAX = 16
_LOCK = threading.Lock()


def compiled(fn, leaves: Sequence[np.ndarray], treedef, shared, batch: int,
             devices: Sequence[jax.Device], batched: bool) -> tuple[Any, float]:
    """``(program, compile seconds)``: ``jax.jit(jax.vmap(fn))`` for a chunk of ``batch``.

    Args:
        fn: the member function, ``fn(member)`` or ``fn(member, shared)``.
        leaves: the inputs' leaves (any leading size; only their trailing shapes and
            dtypes matter) and ``treedef`` their structure.
        shared: ``None`` or ``(leaves, treedef)`` of the values common to all members,
            passed replicated as traced arguments.
        batch: members per call, a multiple of ``len(devices)``.
        devices: the 1-D mesh the chunk is split over.
        batched: ``fn`` takes a whole group: each device calls it on its own slice
            (``jax.shard_map``, no communication between devices).

    The program is called ``program(shared_leaves, *chunk_leaves)`` with arrays placed
    as :func:`evaluate` does. Compile seconds are 0 for a program reused from an earlier
    call (kept per function object, so a new closure compiles again).
    """
    avals = tuple((a.shape[1:], a.dtype.str) for a in leaves)
    s_leaves, s_treedef = shared if shared is not None else ([], None)
    s_avals = tuple((a.shape, a.dtype.str) for a in s_leaves)
    key = (fn, batched, treedef, avals, s_treedef, s_avals, batch, tuple(d.id for d in devices))
    try:
        hit = _COMPILED.get(key)
    except TypeError:  # unhashable fn
        key, hit = None, None
    if hit is not None:
        return hit, 0.0

    def chunk_fn(s_values, *xs):
        if shared is None:
            one = lambda *m: fn(jax.tree_util.tree_unflatten(treedef, m))  # noqa: E731
        else:
            common = jax.tree_util.tree_unflatten(s_treedef, s_values)
            one = lambda *m: fn(jax.tree_util.tree_unflatten(treedef, m), common)  # noqa: E731
        return one(*xs) if batched else jax.vmap(one)(*xs)

    shard = sharding.member_sharding(devices)
    replicated = sharding.replicated(shard)
    program = chunk_fn
    if batched:
        program = jax.shard_map(
            chunk_fn,
            mesh=shard.mesh,
            in_specs=(replicated.spec, *[shard.spec] * len(leaves)),
            out_specs=shard.spec,
            check_vma=False,  # diffrax's loops mix replicated and per-device carries
        )
    structs = [
        jax.ShapeDtypeStruct((batch, *a.shape[1:]), a.dtype, sharding=shard) for a in leaves
    ]
    s_structs = [jax.ShapeDtypeStruct(a.shape, a.dtype, sharding=replicated) for a in s_leaves]
    start = time.perf_counter()
    result = jax.jit(program).lower(s_structs, *structs).compile()
    seconds = time.perf_counter() - start
    if key is not None:
        with _LOCK:
            if len(_COMPILED) >= _COMPILED_MAX:
                _COMPILED.pop(next(iter(_COMPILED)))
            _COMPILED[key] = result
    return result, seconds


def evaluate(program, chunk_leaves: Sequence[np.ndarray], shared_leaves: Sequence[np.ndarray],
             batch: int, devices: Sequence[jax.Device], names) -> dict[str, np.ndarray]:
    """Run ``program`` (from :func:`compiled`) on one chunk; outputs of its real members.

    ``chunk_leaves`` have the chunk's member count ``m ≤ batch`` as leading axis; the
    chunk is padded to ``batch`` by repeating its last member, and the padding is dropped
    from the returned ``{name: (m, ...)}`` arrays.
    """
    shard = sharding.member_sharding(devices)
    real = chunk_leaves[0].shape[0]
    index = np.minimum(np.arange(batch), real - 1)
    placed = sharding.place([np.take(a, index, axis=0) for a in chunk_leaves], shard)
    s_placed = sharding.place(list(shared_leaves), sharding.replicated(shard))
    out = sharding.fetch(program(s_placed, *placed))
    return {k: np.ascontiguousarray(out[k][:real]) for k in names}
