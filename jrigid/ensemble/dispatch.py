"""Computing the chunks a run still needs: in this process, or on an executor's workers.

- :func:`in_process`: the chunk program is compiled once for the devices of this process
  (split over all of them, :mod:`jrigid.ensemble.sharding`) and the chunks are run on a
  few threads, so that on a CPU with one XLA device several chunks run at once, one per
  core. A mesh spanning processes (``jax.distributed``) runs its chunks one after the
  other, in the same order on every process.
- :func:`on_executor`: one task per chunk (:func:`jrigid.ensemble.worker.run_task`) on
  any :class:`concurrent.futures.Executor` (a ``ProcessPoolExecutor``, a Dask
  ``Client.get_executor()``, ...): each worker computes its chunk on its first device,
  writes it to ``out_dir`` and returns it.

Both call ``finish(index, outputs)`` in the driver's thread as each chunk completes (in
completion order), and both leave the chunks finished before an error on disk.
"""

from __future__ import annotations

import concurrent.futures as cf
import os
import pathlib
from collections.abc import Callable, Sequence
from typing import Any

import jax
import numpy as np

from jrigid.ensemble import program, storage, worker
from jrigid.ensemble.plan import Plan

__all__ = ["in_process", "on_executor", "usable_cores"]

Finish = Callable[[int, dict[str, np.ndarray]], None]


def usable_cores() -> int:
    """CPU cores this process may run on (its affinity mask where the OS has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def _drain(futures: dict[cf.Future, int], handle: Callable[[Any], None]) -> None:
    """Hand each result to ``handle`` as it completes; on an error cancel the rest, raise."""
    try:
        for future in cf.as_completed(futures):
            handle(future.result())
    except BaseException:
        for future in futures:
            future.cancel()
        raise


def in_process(plan: Plan, todo: Sequence[int], devices: Sequence[jax.Device],
               finish: Finish, threads: int) -> dict[str, Any]:
    """Compute chunks ``todo`` on ``devices`` with ``threads`` threads; ``finish`` each.

    Returns ``{"compile_seconds": ..., "threads": ...}``.
    """
    if not todo:
        return {"compile_seconds": 0.0, "threads": 0}
    prog, compile_seconds = program.compiled(
        plan.fn, plan.leaves, plan.treedef, plan.shared, plan.batch, devices, plan.batched
    )
    shared_leaves = [] if plan.shared is None else plan.shared[0]
    names = tuple(plan.spec)

    def one(i):
        return i, program.evaluate(prog, plan.chunk_leaves(i), shared_leaves, plan.batch,
                                   devices, names)

    threads = max(1, min(threads, len(todo)))
    with cf.ThreadPoolExecutor(threads, thread_name_prefix="jrigid-ensemble") as pool:
        _drain({pool.submit(one, i): i for i in todo}, lambda done: finish(*done))
    return {"compile_seconds": compile_seconds, "threads": threads}


def on_executor(plan: Plan, todo: Sequence[int], executor: cf.Executor,
                out_dir: pathlib.Path | None, finish: Finish,
                compile_cache: str | None) -> dict[str, Any]:
    """Submit one task per chunk of ``todo`` to ``executor``; ``finish`` each as it returns.

    A chunk a worker could not write where the driver sees ``out_dir`` (no shared file
    system) is written by the driver. Returns ``{"compile_seconds": the longest of the
    workers', "workers": {worker: {"chunks", "compile_seconds", "seconds"}}}``.
    """
    workers: dict[str, dict[str, float]] = {}
    if not todo:
        return {"compile_seconds": 0.0, "workers": workers}
    example = jax.tree_util.tree_unflatten(plan.treedef, [a[:1] for a in plan.leaves])
    shared = None if plan.shared is None else jax.tree_util.tree_unflatten(
        plan.shared[1], plan.shared[0])
    job = worker.Job(
        fn=plan.fn, example=example, shared=shared, batch=plan.batch,
        batched=plan.batched, names=tuple(plan.spec), run=plan.run,
        out_dir=None if out_dir is None else str(out_dir.resolve()),
    )
    x64 = bool(jax.config.jax_enable_x64)
    try:
        payload, key = worker.pack(job)
    except Exception as err:  # noqa: BLE001 - cloudpickle raises many types
        raise ValueError(
            f"fn (or shared) cannot be sent to the executor's workers: {err}"
        ) from err

    def handle(done: worker.ChunkDone) -> None:
        if out_dir is not None and not storage.chunk_path(out_dir, done.index).exists():
            storage.write_chunk(out_dir, done.index, done.outputs, plan.run)
        stats = workers.setdefault(done.worker,
                                   {"chunks": 0, "compile_seconds": 0.0, "seconds": 0.0})
        stats["chunks"] += 1
        stats["compile_seconds"] += done.compile_seconds
        stats["seconds"] += done.seconds
        finish(done.index, done.outputs)

    futures = {
        executor.submit(worker.run_task, payload, key, i, plan.chunk_leaves(i), x64,
                        compile_cache): i
        for i in todo
    }
    _drain(futures, handle)
    # the workers compile at the same time: the wall-clock share is the longest one
    return {"compile_seconds": max(w["compile_seconds"] for w in workers.values()),
            "workers": workers}
