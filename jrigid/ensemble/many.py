"""The common case of an ensemble: :func:`simulate_many`, :func:`jrigid.simulate` for every member.

Per member (``jax.vmap(simulate)``, the default) or, with ``shared_step=True``, one
lockstep solve per device's share of a chunk (:func:`~jrigid.ensemble.simulate_lockstep`).
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import jax
import numpy as np
from jax.typing import ArrayLike

from jrigid.ensemble.lockstep import simulate_lockstep
from jrigid.ensemble.runner import run
from jrigid.integrate import simulate
from jrigid.scene import Scene
from jrigid.state import State
from jrigid.trajectory import Trajectory

__all__ = ["default_summary", "simulate_many"]


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
    shared_step: bool = False,
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
        chunk_size, out_dir, metadata, resume, progress, devices, info, order: as in
            :func:`run`. ``ts``, the scene (when fixed), ``rtol``, ``atol`` and ``dt0``
            are passed as ``run``'s traced ``shared`` values (other values do not
            recompile; they are fingerprinted in ``meta.json``); the other
            ``simulate_kwargs``, ``shared_step`` and the summary's name are stored in the
            metadata, so resuming with other settings is refused. Pass the same
            ``summary`` function object (not a new lambda) to reuse the compiled program
            between calls.
        shared_step: ``False`` (default): every member has its own adaptive step
            (``jax.vmap(simulate)``), and its results do not depend on the chunk.
            ``True``: each device's share of a chunk (``chunk_size / n_devices``
            members) is integrated as one system with a shared step
            (:func:`~jrigid.ensemble.simulate_lockstep`): several times the throughput
            on a CPU (``benchmarks/ensemble_throughput.py``), every member within its
            tolerance, but a member's results depend on the other members of its group
            (a resumed run must keep the chunk size and device count, so it is still
            identical), and a failure stops its whole group (the members' ``result``
            codes say so). Not for ``euler_angles``.
        **simulate_kwargs: passed to :func:`jrigid.simulate` (``solver``, ``rtol``,
            ``formulation``, ...). ``throw`` defaults to ``False`` here: a failed member
            gets a nonzero ``result`` code and NaN outputs instead of stopping the run.

    Returns:
        ``dict[str, np.ndarray]`` of the summary outputs, leading axis ``N``.

    Raises:
        ValueError: as :func:`run`; ``params`` given with a fixed scene or missing for a
            scene function; ``states`` not a :class:`~jrigid.state.State`.
    """
    if not isinstance(states, State):
        raise ValueError(f"states must be a jrigid State with a leading axis, got {type(states)}")
    if isinstance(scene, Scene):
        if params is not None:
            raise ValueError("params is only used when scene is a function params -> Scene")
    elif callable(scene):
        if params is None:
            raise ValueError("scene is a function: pass params (its per-member arguments)")
    else:
        raise ValueError(f"scene must be a Scene or a function returning one, got {scene!r}")
    ts = np.asarray(ts, dtype=jax.dtypes.canonicalize_dtype(np.float64))
    if ts.ndim != 1 or ts.shape[0] < 2 or not np.all(np.isfinite(ts)):
        raise ValueError(f"ts must be a finite 1-D array of at least 2 times, got {ts!r}")
    kwargs = {"throw": False, **simulate_kwargs}
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
        bool(shared_step),
    )
    inputs = {"state": states} if params is None else {"state": states, "params": params}
    meta = dict(metadata or {})
    meta["simulate"] = {
        "kwargs": {k: _describe(v) for k, v in member.kwargs},
        "summary": getattr(member.summary, "__qualname__", _describe(member.summary)),
        "shared_step": member.lockstep,
    }
    return run(
        member,
        inputs,
        shared=shared,
        chunk_size=chunk_size,
        out_dir=out_dir,
        metadata=meta,
        resume=resume,
        progress=progress,
        devices=devices,
        info=info,
        order=order,
        batched=member.lockstep,
    )


_TRACED = ("rtol", "atol", "dt0")


def _describe(value) -> str:
    """``repr`` without memory addresses (stable across sessions, for ``meta.json``)."""
    return re.sub(r" at 0x[0-9a-fA-F]+", "", repr(value))


class _Member(NamedTuple):
    """One member's simulation (``lockstep``: one group's); hashable, so equal settings
    reuse the compiled program."""

    scene_fn: Callable[[Any], Scene] | None
    summary: Callable[[Trajectory], dict[str, jax.Array]]
    kwargs: tuple
    lockstep: bool = False

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
            return self.summary(simulate(scene, member["state"], ts, **shared, **kwargs))
        traj = simulate_lockstep(
            scene, member["state"], ts, batched_scene=self.scene_fn is not None, **shared,
            **kwargs,
        )
        return jax.vmap(self.summary)(traj)
