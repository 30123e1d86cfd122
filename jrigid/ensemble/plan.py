"""What an ensemble run will compute: :func:`plan` checks the inputs and fixes the chunks.

A :class:`Plan` holds the members (in computing order), the values common to all of
them, the chunking (``chunk_size`` members a chunk, each padded to ``batch`` members),
the outputs ``fn`` returns (found by abstract evaluation, nothing is computed) and the
``meta.json`` record a resumed run must match. It is all :func:`jrigid.ensemble.run`
needs before it looks at ``out_dir`` (:mod:`jrigid.ensemble.runner`) and hands chunks to
devices or workers (:mod:`jrigid.ensemble.dispatch`).
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable
from typing import Any

import jax
import numpy as np

from jrigid.ensemble import sharding, storage

__all__ = ["Plan", "named_leaves", "plan"]

FORMAT = "jrigid.ensemble/1"


@dataclasses.dataclass(frozen=True)
class Plan:
    """A checked ensemble run (see :func:`plan`).

    Attributes:
        fn: the member function (``fn(member[, shared]) -> dict``).
        treedef: structure of one member's inputs.
        leaves: input arrays in computing order (``inputs[order]``), leading axis ``n``.
        shared: ``None`` or ``(leaves, treedef)`` of the values common to all members.
        n: member count.
        size: members per chunk (the last chunk may have fewer).
        n_chunks: chunk count.
        n_devices: devices each chunk is split over.
        batch: members per compiled call (``size`` rounded up to ``n_devices``).
        batched: ``fn`` takes a group of ``group`` members at once.
        group: members per call of a batched ``fn`` (``batch / n_devices``); 1 otherwise.
        spec: ``{output name: (per-member shape, dtype string)}``.
        meta: the ``meta.json`` record.
        run: the run identity, :func:`jrigid.ensemble.storage.run_id` of ``meta``.
        inverse: ``None`` or the permutation back to input order.
    """

    fn: Callable[..., dict[str, Any]]
    treedef: Any
    leaves: list[np.ndarray]
    shared: tuple[list[np.ndarray], Any] | None
    n: int
    size: int
    n_chunks: int
    n_devices: int
    batch: int
    batched: bool
    group: int
    spec: dict[str, tuple[tuple[int, ...], str]]
    meta: dict[str, Any]
    run: str
    inverse: np.ndarray | None

    def members(self, index: int) -> tuple[int, int]:
        """``(first member, member count)`` of chunk ``index`` (in computing order)."""
        lo = index * self.size
        return lo, min(self.size, self.n - lo)

    def chunk_leaves(self, index: int) -> list[np.ndarray]:
        """The input arrays of chunk ``index``, unpadded (leading axis: its member count)."""
        lo, real = self.members(index)
        return [a[lo:lo + real] for a in self.leaves]

    def assemble(self, chunks: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
        """Every output stacked over members, in input order."""
        out = {k: np.concatenate([c[k] for c in chunks], axis=0) for k in self.spec}
        return out if self.inverse is None else {k: v[self.inverse] for k, v in out.items()}


def named_leaves(tree, what: str = "inputs") -> tuple[list[tuple[str, np.ndarray]], Any]:
    """``[(key path, host array), ...]`` and the treedef of ``tree``; numpy, canonical dtypes.

    ``ValueError`` for a leaf that is not a numeric or boolean array, and for ``inputs``
    without any array.
    """
    path_leaves, treedef = jax.tree_util.tree_flatten_with_path(tree)
    if not path_leaves and what == "inputs":
        raise ValueError("inputs has no arrays: pass a pytree (e.g. a dict) of arrays")
    out = []
    for path, leaf in path_leaves:
        name = jax.tree_util.keystr(path)
        if isinstance(leaf, jax.core.Tracer):
            raise ValueError(
                f"{what}{name} is traced (inside jax.grad, jit or vmap): an ensemble run "
                "computes chunk by chunk on concrete arrays and cannot be transformed; "
                "for derivatives use jrigid.ensemble.simulate_lockstep or "
                "jax.vmap(jrigid.simulate)")
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


def _member_count(named: list[tuple[str, np.ndarray]]) -> int:
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
    return n


def _permutation(order, n: int) -> np.ndarray:
    """``order`` as an ``(n,)`` int array holding each of ``0 … n−1`` once (else ``ValueError``)."""
    a = np.asarray(order)
    if a.shape != (n,) or a.dtype.kind not in "iu" or not np.array_equal(np.sort(a), np.arange(n)):
        raise ValueError(
            f"order must be a permutation of the {n} members (an int array of shape ({n},) "
            f"holding 0 … {n - 1} once each), got shape {a.shape} and dtype {a.dtype}"
        )
    return a


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
        if not isinstance(name, str) or not name.isidentifier() or name.startswith("__"):
            raise ValueError(
                f"fn's output names must be identifiers (str) not starting with '__', got "
                f"{name!r}"
            )
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


def plan(
    fn: Callable[..., dict[str, Any]],
    inputs: Any,
    *,
    chunk_size: int,
    n_devices: int,
    shared: Any = None,
    check_finite: bool = True,
    metadata: dict[str, Any] | None = None,
    order: Any = None,
    batched: bool = False,
) -> Plan:
    """Check a run's arguments and fix its chunks, outputs and ``meta.json`` record.

    Args: as :func:`jrigid.ensemble.run`; ``n_devices`` is the number of devices each
    chunk is split over (1 when chunks go to workers).

    Returns:
        the :class:`Plan`.

    Raises:
        ValueError: inputs without a common leading axis, non-finite float inputs (with
            ``check_finite``), a bad ``chunk_size``/``metadata``/``order``, or ``fn`` not
            returning a dict of arrays.
    """
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer)) \
            or chunk_size < 1:
        raise ValueError(f"chunk_size must be a positive int, got {chunk_size!r}")
    chunk_size = int(chunk_size)
    if not callable(fn):
        raise ValueError(f"fn must be callable, got {type(fn).__name__}")
    named, treedef = named_leaves(inputs)
    n = _member_count(named)
    if check_finite:
        _check_finite(named, "inputs")
    inverse = None
    if order is not None:
        order = _permutation(order, n)
        named = [(k, a[order]) for k, a in named]
        inverse = np.argsort(order)
    s_named, s_treedef = named_leaves(shared, "shared")
    if check_finite:
        _check_finite(s_named, "shared")
    s_leaves = [a for _, a in s_named]
    try:
        meta_user = json.loads(json.dumps({} if metadata is None else metadata))
    except (TypeError, ValueError) as err:
        raise ValueError(f"metadata must be JSON-serialisable: {err}") from None
    if not isinstance(meta_user, dict):
        raise ValueError(f"metadata must be a dict, got {type(metadata).__name__}")
    leaves = [a for _, a in named]
    size = min(chunk_size, n)
    n_chunks = math.ceil(n / size)
    batch = sharding.padded_size(size, n_devices)
    group = batch // n_devices
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
        "format": FORMAT,
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
    return Plan(
        fn=fn,
        treedef=treedef,
        leaves=leaves,
        shared=None if shared is None else (s_leaves, s_treedef),
        n=n,
        size=size,
        n_chunks=n_chunks,
        n_devices=n_devices,
        batch=batch,
        batched=bool(batched),
        group=group if batched else 1,
        spec=spec,
        meta=meta,
        run=storage.run_id(meta),
        inverse=inverse,
    )
