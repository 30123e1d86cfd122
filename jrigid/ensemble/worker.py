"""The task an executor's worker runs: compute one chunk, write it, return it.

:func:`jrigid.ensemble.run` with ``executor=`` submits one :func:`run_task` per chunk
that is not on disk yet. The task carries a :class:`Job` (the member function and what
every chunk shares, serialised once by the driver with ``cloudpickle``, so closures and
lambdas travel too), the chunk's index and its input arrays. The worker

1. sets JAX's configuration as the driver's (``jax_enable_x64``) and JAX's persistent
   compilation cache (``jax_compilation_cache_dir``), before it unpickles anything: a
   worker that finds the chunk program in the cache loads it instead of compiling;
2. compiles the chunk program once (kept for its later tasks; :mod:`jrigid.ensemble.program`)
   and evaluates the chunk on its first local device;
3. writes the chunk atomically to ``out_dir`` (:func:`jrigid.ensemble.storage.write_chunk`),
   tagged with its index and the run's identity, and returns the outputs with its
   compile time and its name.

A task writes nothing else and holds no lock: a task run twice (a worker lost after
writing, a resubmitted chunk) writes the same bytes.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import pathlib
import platform
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import jax
import numpy as np

from jrigid.ensemble import program, storage

__all__ = ["ChunkDone", "Job", "configure", "pack", "run_task"]


@dataclasses.dataclass(frozen=True)
class Job:
    """What every chunk of one run shares (shipped to workers as bytes, :func:`pack`).

    Pytree structures travel as pytrees (``example``, ``shared``), not as treedefs: a
    treedef of equinox modules does not survive pickling, the modules do.

    Attributes:
        fn, batch, batched: as in :func:`jrigid.ensemble.program.compiled`.
        example: one member's inputs (a pytree; its structure is the members').
        shared: the pytree of values common to all members, or ``None``.
        names: the output names.
        run: the run identity (written into each chunk file).
        out_dir: the run's folder (a path every worker can write) or ``None``.
    """

    fn: Callable[..., dict[str, Any]]
    example: Any
    shared: Any
    batch: int
    batched: bool
    names: tuple[str, ...]
    run: str
    out_dir: str | None


@dataclasses.dataclass(frozen=True)
class ChunkDone:
    """A finished chunk: its ``index``, ``outputs`` (``{name: (m, ...)}``), whether the
    worker wrote it to ``out_dir`` (``written``), the seconds it took to get the program
    (``compile_seconds``, 0 when reused), to evaluate (``seconds``), and the ``worker``
    (``host:pid``)."""

    index: int
    outputs: dict[str, np.ndarray]
    written: bool
    compile_seconds: float
    seconds: float
    worker: str


def pack(job: Job) -> tuple[bytes, str]:
    """``(payload, key)``: ``job`` serialised with ``cloudpickle`` and its SHA-256."""
    import cloudpickle

    payload = cloudpickle.dumps(job)
    return payload, hashlib.sha256(payload).hexdigest()


_JOBS: dict[str, tuple[Job, Any, Any]] = {}
_JOBS_MAX = 4
_LOCK = threading.Lock()


def _job(payload: bytes, key: str) -> tuple[Job, Any, Any]:
    """``(job, member treedef, shared (leaves, treedef) or None)``, unpickled once per run
    and process (so its compiled program is reused)."""
    import cloudpickle

    with _LOCK:
        hit = _JOBS.get(key)
        if hit is None:
            job = cloudpickle.loads(payload)
            treedef = jax.tree_util.tree_structure(job.example)
            shared = None
            if job.shared is not None:
                leaves, s_treedef = jax.tree_util.tree_flatten(job.shared)
                shared = ([np.asarray(a) for a in leaves], s_treedef)
            hit = (job, treedef, shared)
            if len(_JOBS) >= _JOBS_MAX:
                _JOBS.pop(next(iter(_JOBS)))
            _JOBS[key] = hit
    return hit


def configure(x64: bool, compile_cache: str | None) -> None:
    """Set this process's ``jax_enable_x64`` and JAX's persistent compilation cache folder.

    JAX decides whether to use the cache at its first compilation: a folder set later is
    taken up by resetting the cache (``compilation_cache.reset_cache``).
    """
    if bool(jax.config.jax_enable_x64) != bool(x64):
        jax.config.update("jax_enable_x64", bool(x64))
    if compile_cache and jax.config.jax_compilation_cache_dir != str(compile_cache):
        from jax.experimental.compilation_cache import compilation_cache

        jax.config.update("jax_compilation_cache_dir", str(compile_cache))
        compilation_cache.reset_cache()


def run_task(payload: bytes, key: str, index: int, leaves: Sequence[np.ndarray], x64: bool,
             compile_cache: str | None) -> ChunkDone:
    """Compute chunk ``index`` of the job in ``payload`` on this process's first device.

    Args:
        payload, key: from :func:`pack`.
        index: the chunk's index.
        leaves: the chunk's input arrays (leading axis: its member count).
        x64: the driver's ``jax_enable_x64`` (set before anything is unpickled, so that
            arrays come back in their dtypes).
        compile_cache: folder of JAX's persistent compilation cache, or ``None``.

    Returns:
        :class:`ChunkDone`.
    """
    configure(x64, compile_cache)
    job, treedef, shared = _job(payload, key)
    devices = jax.local_devices()[:1]
    prog, compile_seconds = program.compiled(
        job.fn, leaves, treedef, shared, job.batch, devices, job.batched
    )
    start = time.perf_counter()
    shared_leaves = [] if shared is None else shared[0]
    out = program.evaluate(prog, leaves, shared_leaves, job.batch, devices, job.names)
    seconds = time.perf_counter() - start
    written = False
    if job.out_dir is not None:
        storage.write_chunk(pathlib.Path(job.out_dir), index, out, job.run)
        written = True
    return ChunkDone(index, out, written, compile_seconds, seconds,
                     f"{platform.node()}:{os.getpid()}")
