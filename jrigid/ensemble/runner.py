"""Chunked, sharded, resumable ``vmap`` over ensemble members: :func:`run`.

``run(fn, inputs)`` evaluates ``fn`` on every member of ``inputs`` (a pytree of arrays
with a common leading axis ``N``) with ``jax.jit(jax.vmap(fn))``, compiled once for a
fixed chunk shape, in three steps:

1. **plan** (:mod:`jrigid.ensemble.plan`): check the inputs, fix the chunks (``chunk_size``
   members each; the last one padded by repeating its last member, the padding dropped
   from the results, so no chunk triggers a new compilation), find ``fn``'s outputs by
   abstract evaluation and write down the ``meta.json`` record;
2. **resume** (:func:`resume_from`): with ``out_dir``, take the folder's lock, check a stored
   run against the plan and load its finished chunks (each tagged with its index and
   the run's identity, :mod:`jrigid.ensemble.storage`);
3. **dispatch** (:mod:`jrigid.ensemble.dispatch`): compute the missing chunks — in this
   process (split over a 1-D mesh of ``devices``, :mod:`jrigid.ensemble.sharding`) or
   one task per chunk on an ``executor`` — writing each atomically to
   ``out_dir/chunk_00000.npz``, ... as it finishes, under one progress bar.

Members are computed independently: a member's outputs do not depend on the chunk,
the padding, the thread or the worker it was computed with (bit for bit; tested), for
one number of members per compiled call (``info["batch"]`` ÷ devices); between
different batch sizes, which XLA vectorises differently, to rounding. The exception is
``batched=True``, for functions that couple the members of a group on purpose
(:func:`~jrigid.ensemble.simulate_lockstep`): there each device's share of a chunk is
one group.

Errors: bad inputs, a ``fn`` that does not return a dict of arrays and an ``out_dir``
holding a different run raise ``ValueError`` before anything is computed. An error
raised by ``fn`` itself at run time (e.g. an ``equinox`` runtime check) propagates;
chunks finished before it stay on disk.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import os
import pathlib
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

import jax
import numpy as np

from jrigid.ensemble import dispatch, sharding, storage
from jrigid.ensemble.plan import Plan, plan

__all__ = ["default_compile_cache", "resume_from", "run"]


def default_compile_cache() -> pathlib.Path:
    """``$XDG_CACHE_HOME/jrigid/jax`` (``~/.cache/jrigid/jax``): the workers' default cache."""
    base = os.environ.get("XDG_CACHE_HOME") or pathlib.Path.home() / ".cache"
    return pathlib.Path(base) / "jrigid" / "jax"


def _check_dir(out_dir: pathlib.Path, meta: dict[str, Any], resume: bool) -> dict[str, Any] | None:
    """The stored ``meta.json`` matching ``meta`` (``None``: none, or not resuming)."""
    if out_dir.exists() and not out_dir.is_dir():
        raise ValueError(f"out_dir {out_dir} exists and is not a folder")
    stored = storage.read_meta(out_dir) if resume and out_dir.is_dir() else None
    if resume and stored is None and out_dir.is_dir() and any(out_dir.glob("chunk_*.npz")):
        raise ValueError(
            f"{out_dir} holds chunk files but no meta.json, so they cannot be matched to "
            "this run. Choose another out_dir, or pass resume=False to delete them."
        )
    if stored is not None:
        diff = storage.mismatches(stored, meta)
        if diff:
            raise ValueError(
                f"{out_dir / storage.META_NAME} belongs to a different run (differs in: "
                f"{', '.join(diff)}). Choose another out_dir, or pass resume=False to "
                "discard the stored chunks and start over."
            )
    return stored


def resume_from(p: Plan, out_dir: pathlib.Path | None, resume: bool, writer: bool,
           spans: bool) -> list[dict[str, np.ndarray] | None]:
    """Prepare ``out_dir`` for the run ``p`` and load the chunks it already holds.

    Checks a stored run against ``p.meta`` (``ValueError`` if it differs), or deletes it
    (``resume=False``); the ``writer`` process writes ``meta.json`` for a new run. With
    a mesh ``spans``-ing processes, process 0 decides which chunks are finished and tells
    the others. Returns one entry per chunk: its outputs, or ``None`` to compute.
    """
    results: list[dict[str, np.ndarray] | None] = [None] * p.n_chunks
    if out_dir is None:
        return results
    stored = _check_dir(out_dir, p.meta, resume)
    if stored is not None:
        p.meta["created"] = stored.get("created", p.meta["created"])
    if writer:
        out_dir.mkdir(parents=True, exist_ok=True)
        storage.remove_stale_temporaries(out_dir)
        if not resume:
            storage.remove_run(out_dir)
        if stored is None:
            storage.write_meta(out_dir, p.meta)
    if resume:
        for i in range(p.n_chunks):
            results[i] = storage.load_chunk(out_dir, i, p.spec, p.members(i)[1], p.run)
    if spans:
        from jax.experimental import multihost_utils

        done = np.array([r is not None for r in results])
        done = np.asarray(multihost_utils.broadcast_one_to_all(done))
        if any(d and r is None for r, d in zip(results, done, strict=True)):
            raise ValueError(
                f"process {jax.process_index()} cannot read the chunks process 0 found in "
                f"{out_dir}: with several processes out_dir must be on a shared file system"
            )
        results = [r if d else None for r, d in zip(results, done, strict=True)]
    return results


def run(
    fn: Callable[[Any], dict[str, Any]],
    inputs: Any,
    *,
    chunk_size: int = 1024,
    out_dir: str | os.PathLike | None = None,
    metadata: dict[str, Any] | None = None,
    resume: bool = True,
    progress: bool | None = None,
    devices: Sequence[jax.Device] | None = None,
    shared: Any = None,
    check_finite: bool = True,
    info: dict[str, Any] | None = None,
    order: Any = None,
    batched: bool = False,
    executor: cf.Executor | None = None,
    compile_cache: str | os.PathLike | bool | None = None,
) -> dict[str, np.ndarray]:
    """Evaluate ``fn`` on every member of ``inputs``: chunked, sharded, saved, resumable.

    Args:
        fn: ``fn(member) -> dict[str, array]`` for ONE member: ``member`` has the
            structure of ``inputs`` without the leading axis. It is run as
            ``jax.jit(jax.vmap(fn))``, compiled once; with ``shared`` it is called
            ``fn(member, shared)``. Compiled programs are cached on ``fn`` (and the
            shapes): calling ``run`` again with the same function object does not
            recompile, a new closure or lambda does.
        inputs: pytree (usually a dict) of numeric arrays with a common leading axis
            ``N ≥ 1``. Float inputs must be finite (see ``check_finite``).
        chunk_size: members per chunk (bounds memory; default 1024). The chunks hold
            ``min(chunk_size, N)`` members; the last one is padded by repeating its
            last member, and each chunk's batch is rounded up to a multiple of the
            number of devices, so every chunk runs the same compiled program.
        out_dir: folder for the results: ``chunk_00000.npz``, ... (one per chunk, the
            outputs of its members) written atomically as each chunk finishes, and
            ``meta.json`` (member count, chunking, output names/shapes/dtypes, an
            inputs fingerprint, ``metadata``, versions). ``None``: keep in memory only.
        metadata: JSON-serialisable dict stored in ``meta.json`` (parameters, seed,
            ...). It is part of what a resumed run must match.
        resume: with an existing run in ``out_dir``: load its finished chunks and
            compute only the missing ones. The inputs' (and ``shared``'s) fingerprint,
            the chunking, the outputs and ``metadata`` must match, else ``ValueError``.
            The code of ``fn`` cannot be fingerprinted: after changing it, use a new
            ``out_dir`` or record a version in ``metadata``. ``False``: delete the
            stored run (``meta.json`` and ``chunk_*.npz`` only) and start over.
        progress: show a ``tqdm`` bar (members done); ``None``: when stderr is a
            terminal or there is more than one chunk.
        devices: devices to shard each chunk over (1-D mesh ``("members",)``);
            ``None``: ``jax.devices()`` (with ``jax.distributed`` initialised, every
            process's devices: see the module :mod:`jrigid.ensemble` for that case).
            Not with ``executor`` (each worker uses its first device).
        shared: optional pytree of arrays common to all members (output times, a
            scene, tolerances), passed to ``fn`` as its second argument, replicated on
            every device and traced: other values of the same shapes reuse the
            compiled program. Fingerprinted in ``meta.json`` like ``inputs``.
        check_finite: reject NaN/inf in float inputs (``ValueError``).
        info: optional dict, filled with run statistics: ``compile_seconds`` (with an
            executor: the longest of the workers', who compile at the same time),
            ``run_seconds`` (wall time less ``compile_seconds``), ``chunks_computed``,
            ``chunks_loaded``, ``n_devices``, ``batch`` (members per compiled call),
            ``chunk_size``, ``n_chunks``, ``group`` (members per call of a batched
            ``fn``; 1 otherwise), ``threads`` (in process: chunks run at once) or
            ``workers`` (with an executor: ``{"host:pid": {"chunks", "compile_seconds",
            "seconds"}}``).
        order: optional ``(N,)`` permutation: members are computed (and chunked, and
            stored) in the order ``inputs[order]``, and the results are put back in input
            order. Under ``vmap`` an adaptive solve runs until the slowest member of its
            chunk is done, so grouping members of similar cost raises the useful work
            (e.g. ``order=jrigid.ensemble.difficulty_order(proxy)``). It is part of the
            fingerprint a resumed run must match.
        batched: ``fn`` takes a whole group of members (``member`` with a leading axis
            ``G``) and returns outputs with that leading axis. A group is one device's
            share of a chunk: ``G = batch / n_devices`` (``info["group"]``); each device
            runs ``fn`` on its group independently (``jax.shard_map``). For functions
            whose members are coupled on purpose, e.g.
            :func:`~jrigid.ensemble.simulate_lockstep`: a member's outputs then depend on
            its group, hence on ``chunk_size`` and the number of devices (both part of
            what a resumed run must match), and on the padding of the last chunk (which
            repeats its last member).
        executor: ``None`` (default): compute in this process, each chunk split over
            ``devices``, several chunks at once on a CPU with fewer devices than cores.
            Or any :class:`concurrent.futures.Executor`: one task per chunk
            (:mod:`jrigid.ensemble.worker`), e.g. a ``ProcessPoolExecutor`` (with the
            ``"spawn"`` start method: JAX does not survive ``fork``), a Dask
            ``distributed.Client(...).get_executor()`` or a ``dask_jobqueue`` cluster's
            client. Each worker computes its chunk on its first device, so a member's
            results are bit for bit those of the in-process run (for ``batched`` ``fn``:
            of an in-process run on one device); ``out_dir`` must then be a folder every
            worker can write (a shared file system). ``fn`` and ``shared`` are sent with
            ``cloudpickle`` (closures work). A worker lost mid-chunk costs that chunk
            only: a scheduler that retries tasks (Dask does) computes it again
            elsewhere; a ``ProcessPoolExecutor`` stops (``BrokenProcessPool``) and a rerun
            resumes. Chunks written before any error stay on disk.
        compile_cache: with ``executor``: folder of JAX's persistent compilation cache
            for the workers (set on each worker before its first compilation), so a
            worker that finds the chunk program there loads it instead of compiling.
            ``None``: the driver's ``jax_compilation_cache_dir`` if set, else
            ``~/.cache/jrigid/jax`` (``$XDG_CACHE_HOME`` if set); ``False``: none. The
            cache is trusted code: keep it where only you can write.

    Returns:
        ``dict[str, np.ndarray]``: each output of ``fn`` stacked over members, leading
        axis ``N``, in input order.

    Raises:
        ValueError: inputs without a common leading axis, non-finite float inputs, a
            bad ``chunk_size``/``metadata``/``devices``, ``fn`` not returning a dict of
            arrays, an ``out_dir`` holding a different (or unreadable) run or in use by
            another run (``out_dir/.lock``), ``devices`` with ``executor``, or an ``fn``
            that cannot be sent to the executor's workers.
    """
    devs, spans = _devices(executor, devices)
    p = plan(fn, inputs, chunk_size=chunk_size, n_devices=max(1, len(devs)), shared=shared,
             check_finite=check_finite, metadata=metadata, order=order, batched=batched)
    # A mesh over several processes computes each chunk together: process 0 writes.
    writer = not spans or jax.process_index() == 0
    path = None if out_dir is None else pathlib.Path(out_dir)
    with _locked(path, writer):
        start = time.perf_counter()
        results = resume_from(p, path, resume, writer, spans)
        todo = [i for i, r in enumerate(results) if r is None]
        stats = _dispatch(p, todo, results, path if writer else None, progress, writer,
                          executor, devs, spans, compile_cache)
        if path is not None and writer and todo:
            storage.write_meta(path, dict(p.meta, completed=storage.now()))
    if info is not None:
        info.update(_statistics(p, todo, stats, time.perf_counter() - start))
    return p.assemble(results)


def _devices(executor: cf.Executor | None,
             devices: Sequence[jax.Device] | None) -> tuple[list[jax.Device], bool]:
    """The devices each chunk is split over (none with an executor: its workers choose)
    and whether they span several processes; ``ValueError`` for a bad combination."""
    if executor is None:
        devs = sharding.resolve_devices(devices)
        return devs, sharding.spans_processes(devs)
    if not isinstance(executor, cf.Executor):
        raise ValueError(
            f"executor must be a concurrent.futures.Executor (e.g. a Dask "
            f"Client.get_executor()), got {type(executor).__name__}"
        )
    if devices is not None:
        raise ValueError("devices is for the in-process run: with an executor each "
                         "worker computes its chunks on its own first device")
    return [], False


def _locked(path: pathlib.Path | None, writer: bool) -> contextlib.AbstractContextManager:
    """The lock on ``path`` (created) for the writing process; nothing otherwise."""
    if path is None or not writer:
        return contextlib.nullcontext()
    if path.exists() and not path.is_dir():
        raise ValueError(f"out_dir {path} exists and is not a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ValueError(f"out_dir {path} cannot be created: {err.strerror or err}") from None
    return storage.lock(path)


def _statistics(p: Plan, todo: Sequence[int], stats: dict[str, Any],
                seconds: float) -> dict[str, Any]:
    """What ``run`` reports in ``info``: the chunking, and where the ``seconds`` went."""
    return dict(
        run_seconds=seconds - stats["compile_seconds"],
        chunks_computed=len(todo),
        chunks_loaded=p.n_chunks - len(todo),
        n_devices=p.n_devices,
        batch=p.batch,
        chunk_size=p.size,
        n_chunks=p.n_chunks,
        group=p.group,
        **stats,
    )


def _dispatch(p: Plan, todo, results, path, progress, writer, executor, devs, spans,
              compile_cache) -> dict[str, Any]:
    """Compute chunks ``todo`` into ``results`` (and ``path``) under one progress bar."""
    show = (sys.stderr.isatty() or p.n_chunks > 1) if progress is None else bool(progress)
    bar = None
    if show and writer:
        from tqdm.auto import tqdm

        # left on screen (and in a log) at its end; a resumed run starts at what it loaded
        bar = tqdm(total=p.n, initial=p.n - sum(p.members(i)[1] for i in todo),
                   desc="ensemble", unit="member")

    def finish(i: int, chunk: dict[str, np.ndarray]) -> None:
        if path is not None and executor is None:
            storage.write_chunk(path, i, chunk, p.run)
        results[i] = chunk
        if bar is not None:
            bar.update(p.members(i)[1])

    try:
        if executor is not None:
            cache = compile_cache
            if cache is None:
                cache = jax.config.jax_compilation_cache_dir or default_compile_cache()
            cache = str(cache) if cache else None
            return dispatch.on_executor(p, todo, executor, path, finish, cache)
        threads = 1 if spans else max(2, dispatch.usable_cores() // len(devs))
        return dispatch.in_process(p, todo, devs, finish, threads)
    finally:
        if bar is not None:
            bar.close()
