"""Chunked, sharded, resumable ``vmap`` over ensemble members: :func:`run`.

``run(fn, inputs)`` evaluates ``fn`` on every member of ``inputs`` (a pytree of arrays
with a common leading axis ``N``) with ``jax.jit(jax.vmap(fn))``, compiled once for a
fixed chunk shape:

- members are processed ``chunk_size`` at a time (bounding memory); the last chunk is
  padded by repeating its last member and the padding is dropped from the results, so
  no chunk triggers a new compilation;
- each chunk is split over a 1-D mesh of ``devices`` (:mod:`jrigid.ensemble.sharding`);
- with ``out_dir``, each finished chunk is written atomically to
  ``out_dir/chunk_00000.npz``, ... next to ``meta.json``
  (:mod:`jrigid.ensemble.storage`); running again with the same ``out_dir`` loads the
  finished chunks and computes only the rest.

Members are computed independently: a member's outputs do not depend on the chunk,
the padding or the number of devices it was computed with (bit for bit; tested). The
exception is ``batched=True``, for functions that couple the members of a group on
purpose (:func:`~jrigid.ensemble.simulate_lockstep`): there each device's share of a
chunk is one group.

Errors: bad inputs, a ``fn`` that does not return a dict of arrays and an ``out_dir``
holding a different run raise ``ValueError`` before anything is computed. An error
raised by ``fn`` itself at run time (e.g. an ``equinox`` runtime check) propagates;
chunks finished before it stay on disk.
"""

from __future__ import annotations

import json
import math
import os
import pathlib
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

import jax
import numpy as np

from jrigid.ensemble import sharding, storage

__all__ = ["run"]

# Compiled chunk programs, reused by later calls with the same fn and shapes.
_COMPILED: dict[Any, Any] = {}
_COMPILED_MAX = 16


def _named_leaves(inputs, what: str = "inputs") -> tuple[list[tuple[str, np.ndarray]], Any]:
    """``[(key path, host array), ...]`` and the treedef; numpy, canonical dtypes."""
    path_leaves, treedef = jax.tree_util.tree_flatten_with_path(inputs)
    if not path_leaves and what == "inputs":
        raise ValueError("inputs has no arrays: pass a pytree (e.g. a dict) of arrays")
    out = []
    for path, leaf in path_leaves:
        name = jax.tree_util.keystr(path)
        try:
            a = np.asarray(leaf)
        except Exception as err:  # noqa: BLE001
            raise ValueError(f"{what}{name} is not an array ({type(leaf).__name__})") from err
        if a.dtype == object or a.dtype.kind not in "biufc":
            raise ValueError(f"{what}{name} must be a numeric or bool array, got dtype {a.dtype}")
        a = np.asarray(a, dtype=jax.dtypes.canonicalize_dtype(a.dtype))
        out.append((name, a))
    return out, treedef


def _check_finite(named: list[tuple[str, np.ndarray]], what: str) -> None:
    for name, a in named:
        if a.dtype.kind in "fc":
            bad = ~np.isfinite(a)
            if bad.any():
                first = int(np.argwhere(bad)[0][0]) if a.ndim else 0
                where = f", first at member {first}" if what == "inputs" else ""
                raise ValueError(
                    f"{what}{name} has non-finite values (NaN or inf){where}; fix the "
                    f"{what} or pass check_finite=False"
                )


def _check_inputs(named: list[tuple[str, np.ndarray]], check_finite: bool) -> int:
    """The common member count ``N``; ``ValueError`` naming the first bad leaf."""
    for name, a in named:
        if a.ndim == 0:
            raise ValueError(
                f"inputs{name} is a scalar: every input needs a leading member axis "
                "(pass values common to all members as shared=...)"
            )
    sizes = {name: a.shape[0] for name, a in named}
    if len(set(sizes.values())) != 1:
        listing = ", ".join(f"inputs{k}: {v}" for k, v in sizes.items())
        raise ValueError(f"inputs must share the leading (member) axis; got sizes {listing}")
    n = next(iter(sizes.values()))
    if n == 0:
        raise ValueError("inputs have no members (leading axis of size 0)")
    if check_finite:
        _check_finite(named, "inputs")
    return n


def _output_spec(fn, example, batch: int | None = None) -> dict[str, tuple[tuple[int, ...], str]]:
    """``{name: (per-member shape, dtype)}`` of ``fn``'s outputs, by abstract evaluation.

    ``batch``: ``fn`` is batched and ``example`` has that many members; each output must
    have the leading axis ``batch``, which is stripped from the returned shapes.
    """
    out = jax.eval_shape(lambda *args: fn(*args), *example)
    if not isinstance(out, dict) or not out:
        raise ValueError(
            f"fn must return a non-empty dict of arrays (name -> array), got {type(out).__name__}"
        )
    spec = {}
    for name, value in out.items():
        if not isinstance(name, str) or not name.isidentifier():
            raise ValueError(f"fn's output names must be identifiers (str), got {name!r}")
        if not isinstance(value, jax.ShapeDtypeStruct):
            raise ValueError(
                f"fn's output {name!r} must be one array, got {type(value).__name__} "
                "(flatten nested outputs into separate names)"
            )
        shape = tuple(value.shape)
        if batch is not None:
            if shape[:1] != (batch,):
                raise ValueError(
                    f"batched fn's output {name!r} has shape {shape}: it must have the "
                    f"group's leading member axis ({batch})"
                )
            shape = shape[1:]
        spec[name] = (shape, np.dtype(value.dtype).str)
    return spec


def _compiled(fn, leaves, treedef, shared, batch: int, shard, devices, batched: bool):
    """``jax.jit(jax.vmap(fn))`` lowered and compiled once for a chunk of ``batch`` members.

    ``batched``: ``fn`` takes a whole group of members itself: each device calls it on
    its own slice of the chunk (``jax.shard_map``, no communication between devices).

    ``shared`` is ``None`` or ``(leaves, treedef)`` of the values common to all members,
    passed (replicated) as traced arguments: ``fn(member, shared)``.
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
    compiled = jax.jit(program).lower(s_structs, *structs).compile()
    seconds = time.perf_counter() - start
    if key is not None:
        if len(_COMPILED) >= _COMPILED_MAX:
            _COMPILED.pop(next(iter(_COMPILED)))
        _COMPILED[key] = compiled
    return compiled, seconds


def _prepare_dir(
    out_dir: pathlib.Path, meta: dict[str, Any], resume: bool, writer: bool
) -> dict[str, Any] | None:
    """Check a stored run against ``meta`` (resume) or clear it; write ``meta.json``.

    Returns the stored ``meta.json`` of a resumed run (``None`` for a new one).
    """
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
    if not writer:
        return stored
    out_dir.mkdir(parents=True, exist_ok=True)
    storage.remove_stale_temporaries(out_dir)
    if not resume:
        storage.remove_run(out_dir)
    if stored is None:
        storage.write_meta(out_dir, meta)
    return stored


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
        shared: optional pytree of arrays common to all members (output times, a
            scene, tolerances), passed to ``fn`` as its second argument, replicated on
            every device and traced: other values of the same shapes reuse the
            compiled program. Fingerprinted in ``meta.json`` like ``inputs``.
        check_finite: reject NaN/inf in float inputs (``ValueError``).
        info: optional dict, filled with run statistics: ``compile_seconds``,
            ``run_seconds``, ``chunks_computed``, ``chunks_loaded``, ``n_devices``,
            ``batch`` (members per compiled call), ``chunk_size``, ``n_chunks``,
            ``group`` (members per call of a batched ``fn``; 1 otherwise).
        order: optional ``(N,)`` permutation: members are computed (and chunked, and
            stored) in the order ``inputs[order]``, and the results are put back in input
            order. Under ``vmap`` an adaptive solve runs until the slowest member of its
            chunk is done, so grouping members of similar cost raises the useful work
            (e.g. ``order=jrigid.stability.difficulty_order(proxy)``). It is part of the
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

    Returns:
        ``dict[str, np.ndarray]``: each output of ``fn`` stacked over members, leading
        axis ``N``, in input order.

    Raises:
        ValueError: inputs without a common leading axis, non-finite float inputs, a
            bad ``chunk_size``/``metadata``/``devices``, ``fn`` not returning a dict of
            arrays, or an ``out_dir`` holding a different (or unreadable) run.
    """
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size < 1:
        raise ValueError(f"chunk_size must be a positive int, got {chunk_size!r}")
    if not callable(fn):
        raise ValueError(f"fn must be callable, got {type(fn).__name__}")
    named, treedef = _named_leaves(inputs)
    n = _check_inputs(named, check_finite)
    inverse = None
    if order is not None:
        order = _permutation(order, n)
        named = [(k, a[order]) for k, a in named]
        inverse = np.argsort(order)
    s_named, s_treedef = _named_leaves(shared, "shared")
    if check_finite:
        _check_finite(s_named, "shared")
    s_leaves = [a for _, a in s_named]
    s_pair = None if shared is None else (s_leaves, s_treedef)
    try:
        meta_user = json.loads(json.dumps({} if metadata is None else metadata))
    except (TypeError, ValueError) as err:
        raise ValueError(f"metadata must be JSON-serialisable: {err}") from None
    if not isinstance(meta_user, dict):
        raise ValueError(f"metadata must be a dict, got {type(metadata).__name__}")
    devs = sharding.resolve_devices(devices)
    leaves = [a for _, a in named]
    size = min(chunk_size, n)
    n_chunks = math.ceil(n / size)
    batch = sharding.padded_size(size, len(devs))
    group = batch // len(devs)
    lead = (group,) if batched else ()
    example = jax.tree_util.tree_unflatten(
        treedef, [jax.ShapeDtypeStruct(lead + a.shape[1:], a.dtype) for a in leaves]
    )
    args = (example,)
    if shared is not None:
        args += (jax.tree_util.tree_unflatten(
            s_treedef, [jax.ShapeDtypeStruct(a.shape, a.dtype) for a in s_leaves]
        ),)
    spec = _output_spec(fn, args, group if batched else None)
    meta = {
        "format": "jrigid.ensemble/1",
        "n_members": n,
        "chunk_size": size,
        "n_chunks": n_chunks,
        "inputs": {
            "sha256": storage.fingerprint(named),
            "leaves": {k: {"shape": list(a.shape), "dtype": a.dtype.str} for k, a in named},
        },
        "shared": None if shared is None else {
            "sha256": storage.fingerprint([("treedef", storage.structure(s_treedef)), *s_named]),
            "leaves": {k: {"shape": list(a.shape), "dtype": a.dtype.str} for k, a in s_named},
        },
        "outputs": {k: {"shape": list(s), "dtype": d} for k, (s, d) in spec.items()},
        "metadata": meta_user,
        "fn": getattr(fn, "__qualname__", type(fn).__name__),
        "batched": {"group": group} if batched else False,
        "versions": storage.versions(),
        "created": storage.now(),
    }
    # A mesh over several processes computes each chunk together: process 0 writes.
    spans = sharding.spans_processes(devs)
    writer = not spans or jax.process_index() == 0
    path = None if out_dir is None else pathlib.Path(out_dir)
    if path is not None:
        stored = _prepare_dir(path, meta, resume, writer)
        if stored is not None:
            meta["created"] = stored.get("created", meta["created"])

    start = time.perf_counter()
    results: list[dict[str, np.ndarray] | None] = [None] * n_chunks
    if path is not None and resume:
        for i in range(n_chunks):
            results[i] = storage.load_chunk(path, i, spec, min(size, n - i * size))
    done = np.array([r is not None for r in results])
    if spans:
        from jax.experimental import multihost_utils

        done = np.asarray(multihost_utils.broadcast_one_to_all(done))
        results = [r if d else None for r, d in zip(results, done, strict=True)]
        if any(d and r is None for r, d in zip(results, done, strict=True)):
            raise ValueError(
                f"process {jax.process_index()} cannot read the chunks process 0 found in "
                f"{path}: with several processes out_dir must be on a shared file system"
            )
    loaded = int(done.sum())
    todo = [i for i in range(n_chunks) if not done[i]]

    shard = sharding.member_sharding(devs)
    compile_seconds = 0.0
    show = (sys.stderr.isatty() or n_chunks > 1) if progress is None else bool(progress)
    bar = None
    if show and writer:
        from tqdm.auto import tqdm

        bar = tqdm(total=n, desc="ensemble", unit="member", leave=False)
        bar.update(sum(min(size, n - i * size) for i in range(n_chunks) if done[i]))
    try:
        if todo:
            program, compile_seconds = _compiled(
                fn, leaves, treedef, s_pair, batch, shard, devs, bool(batched)
            )
            s_placed = sharding.place(s_leaves, sharding.replicated(shard))

        def finish(i, real, device_out):
            out = sharding.fetch(device_out)
            chunk = {k: np.ascontiguousarray(out[k][:real]) for k in spec}
            if path is not None and writer:
                storage.write_chunk(path, i, chunk)
            results[i] = chunk
            if bar is not None:
                bar.update(real)

        # Dispatch chunk i (asynchronously) before fetching and writing chunk i - 1.
        pending = None
        for i in todo:
            lo = i * size
            real = min(size, n - lo)
            index = lo + np.minimum(np.arange(batch), real - 1)
            placed = sharding.place([np.take(a, index, axis=0) for a in leaves], shard)
            current = (i, real, program(s_placed, *placed))
            if pending is not None:
                finish(*pending)
            pending = current
        if pending is not None:
            finish(*pending)
    finally:
        if bar is not None:
            bar.close()
    if path is not None and writer and todo:
        storage.write_meta(path, dict(meta, completed=storage.now()))
    if info is not None:
        info.update(
            compile_seconds=compile_seconds,
            run_seconds=time.perf_counter() - start - compile_seconds,
            chunks_computed=len(todo),
            chunks_loaded=loaded,
            n_devices=len(devs),
            batch=batch,
            chunk_size=size,
            n_chunks=n_chunks,
            group=group if batched else 1,
        )
    out = {k: np.concatenate([r[k] for r in results], axis=0) for k in spec}
    return out if inverse is None else {k: v[inverse] for k, v in out.items()}


def _permutation(order, n: int) -> np.ndarray:
    """``order`` as an ``(n,)`` int array holding each of ``0 … n−1`` once (else ``ValueError``)."""
    a = np.asarray(order)
    if a.shape != (n,) or a.dtype.kind not in "iu" or not np.array_equal(np.sort(a), np.arange(n)):
        raise ValueError(
            f"order must be a permutation of the {n} members (an int array of shape ({n},) "
            f"holding 0 … {n - 1} once each), got shape {a.shape} and dtype {a.dtype}"
        )
    return a

