"""The common case of an ensemble: :func:`simulate_many`, :func:`jrigid.simulate` for every member.

By default (``shared_step=None``) each chunk of members is integrated as one system with
a shared step (:func:`~jrigid.ensemble.simulate_lockstep`) in the
``quaternion_omega`` formulation, the fastest way through a sweep on a CPU
(``benchmarks/ensemble_throughput.py``); a group in which a member fails (non-finite
values, the step budget) is solved again member by member, so that member does not take
its group mates with it. ``shared_step=False`` gives every member its own step control
(``jax.vmap(simulate)``). Invalid members (a zero quaternion, a non-physical body, NaN
values) get :attr:`~jrigid.trajectory.Result.invalid_input` and NaN outputs and leave
the others as they would be without them; the run names how many there are, and the
first (a :class:`SweepWarning` and ``info``).
"""

from __future__ import annotations

import concurrent.futures as cf
import hashlib
import inspect
import os
import pathlib
import re
import warnings
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import jax
import numpy as np
from jax.typing import ArrayLike

from jrigid.ensemble import storage
from jrigid.ensemble.lockstep import simulate_lockstep
from jrigid.ensemble.runner import run
from jrigid.formulations import get_formulation
from jrigid.integrate import simulate
from jrigid.scene import Scene
from jrigid.solve import check_dt0, default_tolerances, validate_shared, warn_precision
from jrigid.state import State
from jrigid.trajectory import Result, Trajectory

__all__ = ["SWEEP_DEFAULTS", "SweepWarning", "default_summary", "failed_groups", "simulate_many"]

#: Where :func:`simulate_many`'s defaults differ from :func:`jrigid.simulate`'s: the
#: ``(q, ω)`` formulation, several times faster in a shared step on the benchmark map
#: at equal or better error (the projection onto the invariants is the same).
SWEEP_DEFAULTS: dict[str, Any] = {"formulation": "quaternion_omega"}

# simulate's options a shared-step solve (simulate_lockstep) takes as well.
_LOCKSTEP_OPTIONS = {"formulation", "solver", "rtol", "atol", "max_steps", "dt0", "adjoint",
                     "project", "throw"}


class SweepWarning(UserWarning):
    """Some members of a :func:`simulate_many` sweep were invalid or failed (the text says
    how many, and names the first)."""


def default_summary(traj: Trajectory) -> dict[str, jax.Array]:
    """Outputs kept per member by default: the motion at ``ts`` and the solver outcome.

    Returns ``q (T, 4)`` (or absent for ``body_omega``), ``omega (T, 3)``, ``result ()``
    (a :class:`jrigid.integrate.Result` code) and ``num_steps ()``.
    """
    out = {"omega": traj.omega, "result": traj.result, "num_steps": traj.stats["num_steps"]}
    if traj.q is not None:
        out["q"] = traj.q
    return out


def simulate_many(
    scene: Scene | Callable[[Any], Scene],
    states: State,
    ts: ArrayLike,
    *,
    params: Any = None,
    summary: Callable[[Trajectory], dict[str, jax.Array]] | None = None,
    chunk_size: int = 1024,
    out_dir: str | os.PathLike | None = None,
    metadata: dict[str, Any] | None = None,
    resume: bool = True,
    progress: bool | None = None,
    devices: Sequence[jax.Device] | None = None,
    info: dict[str, Any] | None = None,
    order: Any = None,
    shared_step: bool | None = None,
    executor: cf.Executor | None = None,
    compile_cache: str | os.PathLike | bool | None = None,
    **simulate_kwargs,
) -> dict[str, np.ndarray]:
    """Simulate ``N`` initial states (and/or parameters) with :func:`ensemble.run <run>`.

    Args:
        scene: a :class:`~jrigid.scene.Scene` shared by all members, or a function
            ``scene(params_member) -> Scene`` building each member's scene from its
            row of ``params``.
        states: :class:`~jrigid.state.State` whose arrays have a leading axis ``N``
            (``q (N, 4)``, ``qdot (N, 4)``; e.g. ``jax.vmap(jrigid.initial.from_omega)``).
        ts: ``(T,)`` output times, the same for every member.
        params: pytree of arrays with leading axis ``N`` passed to ``scene`` (only when
            ``scene`` is a function).
        summary: ``summary(trajectory) -> dict[str, array]``, what to keep per member;
            default :func:`default_summary` (``q``, ``omega`` at ``ts``, ``result``,
            ``num_steps``). Reduce here (e.g. final state only) to save memory and disk.
            ``result`` is always kept (added when the summary lacks it).
        chunk_size, out_dir, metadata, resume, progress, devices: as in :func:`run`.
        info, order, executor, compile_cache: as in :func:`run` (``executor``: a Dask
            ``Client.get_executor()``, a ``ProcessPoolExecutor``, ...: the same call on
            one machine, a workstation pool or a cluster). ``ts``, the scene (when
            fixed), ``rtol``, ``atol`` and ``dt0`` are passed as ``run``'s traced
            ``shared`` values (other values do not recompile; they are fingerprinted in
            ``meta.json``); the other ``simulate_kwargs``, ``shared_step`` and the
            summary's and scene function's names and code (bytecode and closure values;
            not the globals or other functions they read) are stored in the metadata,
            so resuming with other settings is refused. Pass the same ``summary``
            function object (not a new lambda) to reuse the compiled program between
            calls. ``info`` also receives
            ``invalid_input``/``first_invalid`` and ``failed``/``first_failed`` (member
            counts and the first member's index, or ``None``), ``shared_step`` and
            ``solved_again`` (members of failed groups solved again per member).
        shared_step: ``None`` (default): ``True`` unless an option only per-member solves
            have is given (``saveat``, ``event``, ``dense``, a ``stepsize_controller``,
            ``project="manifold"``), for ``solver="exact"``, or when the formulation stops
            at an event (``euler_angles``). ``True``: each device's share of a chunk (with an
            executor, each chunk) is integrated as one system with a shared step
            (:func:`~jrigid.ensemble.simulate_lockstep`): several times the throughput
            on a CPU, every member within its tolerance. A member's results then depend
            on its group — the members of its chunk, so on ``chunk_size``, ``order`` and
            the device count, which a resumed run keeps (it is then identical) — and,
            if a member of the group fails (non-finite values, ``max_steps``), the whole
            group is solved again member by member (each member's own ``simulate``; a
            second program, compiled only then; with ``out_dir`` stored in
            ``out_dir/per_member``), so the others are unaffected by it. ``False``: every
            member has its own adaptive step (``jax.vmap(simulate)``), and its results
            depend on its own inputs only: bit for bit, whatever its chunk, padding,
            thread or worker, for one batch size (``chunk_size`` ÷ devices); to rounding
            (about 1e-14 in float64) between batch sizes, which XLA vectorises
            differently.
        **simulate_kwargs: passed to :func:`jrigid.simulate` (``solver``, ``rtol``,
            ``formulation``, ...), with :data:`SWEEP_DEFAULTS` (``formulation=
            "quaternion_omega"``) where not given. ``throw`` defaults to ``False`` here:
            a failed or invalid member gets a nonzero ``result`` code and NaN outputs
            instead of stopping the run, and a :class:`SweepWarning` names how many and
            the first.

    Returns:
        ``dict[str, np.ndarray]`` of the summary outputs, leading axis ``N``.

    Raises:
        ValueError: as :func:`run`; ``params`` given with a fixed scene or missing for a
            scene function; ``states`` not a :class:`~jrigid.state.State`.

    Example: three spins of one body, kept at five times each::

        >>> import jax, jax.numpy as jnp
        >>> jax.config.update("jax_enable_x64", True)
        >>> from jrigid import RigidBody, Scene, ensemble, initial
        >>> scene = Scene(RigidBody(jnp.array([1.0, 2.0, 3.0])))
        >>> omegas = jnp.array([[1.0, 0.0, 0.1], [0.0, 0.1, 2.0], [0.1, 1.0, 0.0]])
        >>> states = jax.vmap(lambda w: initial.from_omega(None, w))(omegas)
        >>> out = ensemble.simulate_many(scene, states, jnp.linspace(0.0, 1.0, 5),
        ...                              progress=False)
        >>> out["q"].shape, out["omega"].shape, out["result"].tolist()
        ((3, 5, 4), (3, 5, 3), [0, 0, 0])
        >>> bool(jnp.allclose(out["omega"][:, 0], omegas))
        True
    """
    if not isinstance(states, State):
        raise ValueError(f"states must be a jrigid State with a leading axis, got {type(states)}")
    if np.ndim(states.q) != 2:
        raise ValueError(
            "states must have one leading member axis (q of shape (N, 4)), got q of shape "
            f"{np.shape(states.q)}; for a grid of members, flatten it first, e.g. "
            "jax.tree_util.tree_map(lambda a: a.reshape((-1,) + a.shape[2:]), states)")
    if isinstance(scene, Scene):
        if params is not None:
            raise ValueError("params is only used when scene is a function params -> Scene")
    elif callable(scene):
        if params is None:
            raise ValueError("scene is a function: pass params (its per-member arguments)")
    else:
        raise ValueError(f"scene must be a Scene or a function returning one, got {scene!r}")
    ts = np.asarray(ts, dtype=jax.dtypes.canonicalize_dtype(np.float64))
    if ts.ndim != 1 or ts.shape[0] < 2:
        raise ValueError(f"ts must be a 1-D array of at least 2 times, got {ts!r}")
    kwargs = {"throw": False, **SWEEP_DEFAULTS, **simulate_kwargs}
    # Settings every member shares are traced in the sweep: checked here, once, so that a
    # bad one is an error and not N invalid members.
    validate_shared(ts, kwargs.get("rtol"), kwargs.get("atol"), ts.dtype)
    check_dt0(kwargs.get("dt0"))
    rtol = kwargs.get("rtol")
    rtol = default_tolerances(ts.dtype)[0] if rtol is None else rtol
    warn_precision(states, ts, np.asarray(rtol, ts.dtype))  # float32 only, the fastest member
    if isinstance(scene, Scene) and np.shape(scene.body.moments) != (3,):
        raise ValueError(
            f"scene has a member axis (body.moments has shape {np.shape(scene.body.moments)}):"
            " pass a function params -> Scene and its per-member params instead"
        )
    lockstep = _use_lockstep(shared_step, kwargs)
    # Arrays common to all members are traced (changing them does not recompile).
    shared = {"ts": ts}
    for name in _TRACED:
        if kwargs.get(name) is not None:
            shared[name] = np.asarray(kwargs.pop(name), dtype=ts.dtype)
    fixed = isinstance(scene, Scene)
    if fixed:
        shared["scene"] = scene
    member = _Member(
        None if fixed else scene,
        default_summary if summary is None else summary,
        tuple(sorted(kwargs.items())),
        lockstep,
    )
    inputs = {"state": states} if params is None else {"state": states, "params": params}
    meta = dict(metadata or {})
    meta["simulate"] = {
        "kwargs": {k: {"repr": _describe(v), "sha256": _value_identity(v)}
                   for k, v in member.kwargs},
        "summary": _code_identity(member.summary),
        "scene": None if fixed else _code_identity(scene),
        "shared_step": member.lockstep,
    }
    # What both runs (the sweep and the failed groups solved again) share.
    options = dict(
        shared=shared,
        chunk_size=chunk_size,
        resume=resume,
        progress=progress,
        devices=devices,
        check_finite=False,  # a NaN member is an invalid member, not a failed sweep
        executor=executor,
        compile_cache=compile_cache,
    )
    stats: dict[str, Any] = {}
    out = run(member, inputs, out_dir=out_dir, metadata=meta, info=stats, order=order,
              batched=member.lockstep, **options)
    regrouped = np.zeros(0, dtype=int)
    if member.lockstep:
        regrouped = failed_groups(out["result"], None if order is None else np.asarray(order),
                                  stats["chunk_size"], stats["group"])
    if regrouped.size:
        # Solve the failed groups again, member by member (stored in out_dir/per_member).
        again = run(
            member._replace(lockstep=False),
            jax.tree_util.tree_map(lambda a: np.asarray(a)[regrouped], inputs),
            out_dir=None if out_dir is None else os.path.join(out_dir, "per_member"),
            metadata=dict(meta, solved_again="per member: the members of failed groups"),
            **options,
        )
        for k in out:
            out[k][regrouped] = again[k]
        if out_dir is not None:
            _rewrite_chunks(out_dir, out, regrouped, order, stats["chunk_size"])
    stats.update(_tally(out["result"]), shared_step=member.lockstep,
                 solved_again=int(regrouped.size))
    if info is not None:
        info.update(stats)
    if stats["invalid_input"] or stats["failed"]:
        warnings.warn(SweepWarning(_sweep_message(stats, out["result"])), stacklevel=2)
    return out


_TRACED = ("rtol", "atol", "dt0")


def _use_lockstep(shared_step: bool | None, kwargs: dict[str, Any]) -> bool:
    """Whether the members are solved in shared-step groups (see ``shared_step``)."""
    if shared_step is not None:
        return bool(shared_step)
    if set(kwargs) - _LOCKSTEP_OPTIONS or kwargs.get("project", True) not in (True, False):
        return False
    if isinstance(kwargs.get("solver"), str):  # "exact": closed form, no steps to share
        return False
    return get_formulation(kwargs["formulation"]).event() is None


def _tally(codes: np.ndarray) -> dict[str, Any]:
    """Counts and first indices of invalid and failed members from their result codes."""
    invalid = np.flatnonzero(codes == Result.invalid_input)
    failed = np.flatnonzero(_failed(codes))
    return {
        "invalid_input": int(invalid.size),
        "first_invalid": int(invalid[0]) if invalid.size else None,
        "failed": int(failed.size),
        "first_failed": int(failed[0]) if failed.size else None,
    }


def _sweep_message(stats: dict[str, Any], codes: np.ndarray) -> str:
    n = codes.shape[0]
    parts = []
    if stats["invalid_input"]:
        parts.append(
            f"{stats['invalid_input']} of {n} members have invalid input (first: member "
            f"{stats['first_invalid']}); their outputs are NaN and their result is "
            "invalid_input (jrigid.simulate on that member's inputs names the problem)"
        )
    if stats["failed"]:
        first = stats["first_failed"]
        parts.append(
            f"{stats['failed']} of {n} members failed (first: member {first}, result "
            f"{Result(int(codes[first])).name}); their outputs after the failure are NaN"
        )
    return "simulate_many: " + "; ".join(parts) + "."


def _describe(value) -> str:
    """``repr`` without memory addresses (stable across sessions, for ``meta.json``)."""
    return re.sub(r" at 0x[0-9a-fA-F]+", "", repr(value))


def _value_identity(value, seen: frozenset = frozenset()) -> str:
    """A SHA-256 of everything in ``value``: its pytree structure (static fields of
    equinox modules included), each array leaf's dtype, shape and bytes, the code
    identity of each function in it, and the ``repr`` of any other leaf. (``repr`` alone
    shows an array of more than 1000 entries with an ellipsis, 8 digits of each entry,
    and an equinox module's arrays as their shapes only: two different ``SaveAt(ts=...)``
    would look the same.)"""
    leaves, treedef = jax.tree_util.tree_flatten(value)
    h = hashlib.sha256(_describe(treedef).encode())
    for leaf in leaves:
        if isinstance(leaf, (np.ndarray, np.generic, jax.Array)):
            a = np.asarray(leaf)
            h.update(f"|{a.dtype.str}{a.shape}|".encode())
            h.update(np.ascontiguousarray(a).tobytes())
        elif getattr(leaf, "__code__", None) is not None and id(leaf) not in seen:
            h.update(_code_identity(leaf, seen)["sha256"].encode())
        else:
            h.update(f"|{_describe(leaf)}|".encode())
    return h.hexdigest()


def _code_identity(fn: Callable, seen: frozenset = frozenset()) -> dict[str, str]:
    """What tells a function apart in ``meta.json``, across sessions: its qualified name,
    and a SHA-256 of its bytecode (constants and names included; not where it stands in
    its file) and of the values its closure holds (:func:`_value_identity`: every entry
    of an array). Two lambdas, or one function edited or closing over other values,
    differ; the globals and functions it reads are not included. (A new Python version
    compiles other bytecode: a run stored with another one is not resumed.)"""
    name = f"{getattr(fn, '__module__', '?')}.{getattr(fn, '__qualname__', type(fn).__name__)}"
    code = getattr(fn, "__code__", None)
    seen = seen | {id(fn)}
    text = _value_identity(fn, seen) if code is None else _bytecode(code)
    cells = [_value_identity(c.cell_contents, seen)
             for c in getattr(fn, "__closure__", None) or ()]
    digest = hashlib.sha256("\n".join([text, *cells]).encode()).hexdigest()
    return {"name": name, "sha256": digest}


def _bytecode(code) -> str:
    """A code object's instructions, names and constants (nested code objects alike)."""
    consts = [_bytecode(c) if inspect.iscode(c) else repr(c) for c in code.co_consts]
    return "|".join([code.co_code.hex(), repr(code.co_names), *consts])


def _rewrite_chunks(out_dir, out: dict[str, np.ndarray], regrouped: np.ndarray, order,
                    chunk_size: int) -> None:
    """Store the outputs of the members solved again in the chunk files that hold them,
    so that ``out_dir`` holds what :func:`simulate_many` returns (and a resumed run finds
    those groups solved)."""
    if jax.process_index() != 0:
        return
    path = pathlib.Path(out_dir)
    n = out["result"].shape[0]
    perm = np.arange(n) if order is None else np.asarray(order)
    position = np.empty(n, dtype=int)
    position[perm] = np.arange(n)
    with storage.lock(path):
        run_id = storage.run_id(storage.read_meta(path))
        for index in np.unique(position[regrouped] // chunk_size):
            members = perm[index * chunk_size:(index + 1) * chunk_size]
            storage.write_chunk(path, int(index), {k: v[members] for k, v in out.items()},
                                run_id)


def _failed(codes: np.ndarray) -> np.ndarray:
    """Which result codes are failures of the solve (not invalid inputs, not events)."""
    return (codes != Result.success) & (codes != Result.event) & (codes != Result.invalid_input)


def failed_groups(codes: np.ndarray, order: np.ndarray | None, chunk_size: int,
                  group: int) -> np.ndarray:
    """Members (input indices, in computing order) of the shared-step groups that failed.

    Args:
        codes: ``(N,)`` result codes in input order.
        order: the computing order (``None``: input order).
        chunk_size: members per chunk; ``group``: members per group (a chunk is split
            into groups of ``group`` consecutive members).

    Returns:
        the input indices of every member of every group in which a member's solve
        failed, in computing order.
    """
    n = codes.shape[0]
    perm = np.arange(n) if order is None else np.asarray(order)
    position = np.arange(n)
    group_id = (position // chunk_size) * (chunk_size + 1) + (position % chunk_size) // group
    bad = np.unique(group_id[_failed(codes[perm])])
    return perm[np.isin(group_id, bad)]


class _Member(NamedTuple):
    """One member's simulation (``lockstep``: one group's); hashable, so equal settings
    reuse the compiled program."""

    scene_fn: Callable[[Any], Scene] | None
    summary: Callable[[Trajectory], dict[str, jax.Array]]
    kwargs: tuple
    lockstep: bool = False

    def keep(self, traj: Trajectory) -> dict[str, jax.Array]:
        """The summary of one member's trajectory, with its ``result`` code."""
        out = dict(self.summary(traj))
        out.setdefault("result", traj.result)
        return out

    def __call__(self, member, shared):
        shared = dict(shared)
        ts = shared.pop("ts")
        kwargs = dict(self.kwargs)
        if self.scene_fn is None:
            scene = shared.pop("scene")
        elif self.lockstep:
            scene = jax.vmap(self.scene_fn)(member["params"])
        else:
            scene = self.scene_fn(member["params"])
        if not self.lockstep:
            return self.keep(simulate(scene, member["state"], ts, **shared, **kwargs))
        traj = simulate_lockstep(
            scene, member["state"], ts, batched_scene=self.scene_fn is not None, **shared,
            **kwargs,
        )
        return jax.vmap(self.keep)(traj)
