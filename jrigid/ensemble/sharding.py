"""Placement of one chunk of ensemble members on a 1-D device mesh.

Every chunk is padded to a multiple of the device count and split along its leading
(member) axis over ``Mesh(devices, ("members",))`` with ``PartitionSpec("members")``:
each device runs the same vmapped program on its own slice. Members are independent, so
no communication happens and every member's result is the same as on one device. (A
batched function, ``run(..., batched=True)``, is called by each device on its own
slice through ``jax.shard_map``: again without communication.)

With several processes (``jax.distributed.initialize()``), the mesh may span devices
of other hosts: :func:`place` builds the global array from each process's local copy
of the chunk with :func:`jax.make_array_from_callback`, and :func:`fetch` gathers the
sharded outputs to every process with
:func:`jax.experimental.multihost_utils.process_allgather`.
"""

from __future__ import annotations

from collections.abc import Sequence

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

__all__ = ["fetch", "member_sharding", "padded_size", "place", "replicated", "resolve_devices",
           "spans_processes"]

AXIS = "members"


def resolve_devices(devices: Sequence[jax.Device] | None) -> list[jax.Device]:
    """``devices`` as a non-empty list (``None``: every device JAX sees, ``jax.devices()``)."""
    devs = list(jax.devices() if devices is None else devices)
    if not devs:
        raise ValueError("devices must name at least one device")
    if len({d.id for d in devs}) != len(devs):
        raise ValueError(f"devices has repeated entries: {devs}")
    bad = [d for d in devs if not isinstance(d, jax.Device)]
    if bad:
        raise ValueError(f"devices must be jax.Device objects (from jax.devices()), got {bad}")
    return devs


def spans_processes(devices: Sequence[jax.Device]) -> bool:
    """Whether ``devices`` include devices of other processes (a multi-host mesh)."""
    me = jax.process_index()
    return any(d.process_index != me for d in devices)


def member_sharding(devices: Sequence[jax.Device]) -> NamedSharding:
    """``NamedSharding`` splitting the leading axis over a 1-D mesh named ``"members"``."""
    mesh = Mesh(np.asarray(list(devices), dtype=object), (AXIS,))
    return NamedSharding(mesh, PartitionSpec(AXIS))


def replicated(shard: NamedSharding) -> NamedSharding:
    """The same mesh, every device holding the whole array (for values shared by all)."""
    return NamedSharding(shard.mesh, PartitionSpec())


def padded_size(chunk: int, n_devices: int) -> int:
    """The batch a chunk of ``chunk`` members is computed in: rounded up to ``n_devices``."""
    return -(-chunk // n_devices) * n_devices


def place(leaves: Sequence[np.ndarray], sharding: NamedSharding) -> list[jax.Array]:
    """Put host arrays on the mesh as ``sharding`` says (e.g. ``(B, ...)`` split on axis 0).

    Each process supplies only the slices of its own devices, so this also works when
    the mesh spans several processes (every process must pass the same data).
    """
    return [
        jax.make_array_from_callback(leaf.shape, sharding, lambda index, leaf=leaf: leaf[index])
        for leaf in leaves
    ]


def fetch(tree):
    """Device arrays (possibly sharded over processes) → numpy arrays on this process."""
    leaves = jax.tree_util.tree_leaves(tree)
    if all(x.is_fully_addressable for x in leaves):
        return jax.tree_util.tree_map(np.asarray, tree)
    from jax.experimental import multihost_utils

    return jax.tree_util.tree_map(
        np.asarray, multihost_utils.process_allgather(tree, tiled=True)
    )
