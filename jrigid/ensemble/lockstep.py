"""One adaptive solve for a whole batch of members: :func:`simulate_lockstep`.

``jax.vmap(jrigid.simulate)`` gives every member its own step-size control. The
vmapped ``while`` loop still runs until the slowest member is done, and the per-member
control (accept or reject, next step size, saving to ``ts``) is done for every member
at every step: on a CPU that bookkeeping costs more than the vector field of a rigid
body (``benchmarks/ensemble_throughput.py``).

:func:`simulate_lockstep` integrates the batch as ONE system instead: the solver's
state is the whole batch, the formulation's vector field and projection are vmapped over
the members inside a single ``diffrax.diffeqsolve``, and the PID controller measures the
error of a step as the largest member's RMS error (the RMS norm ``simulate`` applies to
one member). A step is accepted when every member meets ``rtol``/``atol``, so each
member is integrated with steps no larger than the hardest member needs; the step
count is about the hardest member's. The outputs have the structure of
``jax.vmap(simulate)``: every leaf of the :class:`~jrigid.trajectory.Trajectory` has a
leading member axis ``N``.

What changes against ``jax.vmap(simulate)``:

- a member's result depends (within the tolerance) on the other members of its batch;
  the same batch gives the same result bit for bit;
- the solve is shared, and so is its outcome: if it stops early (``max_steps``, a step
  size collapse, a member's vector field turning non-finite) every member stops at
  that time; each member's ``result`` code then says what it saw (``nonfinite`` for the
  member that turned non-finite, the solver's reason for the others) and its outputs
  after ``t_stop`` are NaN;
- the step counts in ``stats`` are the batch's, the same for every member;
- formulations with a terminating event (``euler_angles``: gimbal lock) are refused,
  since one member's event would stop the batch; ``dense`` output is not offered.
"""

from __future__ import annotations

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jax.typing import ArrayLike

from jrigid.formulations import AbstractFormulation, check_scene, get_formulation
from jrigid.invariants import Invariants
from jrigid.scene import Scene
from jrigid.solve.inputs import (
    input_checks,
    normalised,
    prepare,
    screen,
    validate_shared,
    warn_precision,
)
from jrigid.solve.outcome import finish, raise_on_failure
from jrigid.solve.stepping import (
    controller,
    interpolating_at,
    projected,
    run,
    saved_times,
    solver_options,
    unit_times,
)
from jrigid.state import State
from jrigid.trajectory import Trajectory

__all__ = ["simulate_lockstep"]


class _Batched(AbstractFormulation):
    """A formulation acting on a batch (leading axis ``N``) through ``vmap``.

    ``scene_axis`` is ``0`` when the scene's arrays carry the member axis, else ``None``.
    Only what the solver calls is provided: the vector field and the projection.
    """

    inner: AbstractFormulation
    scene_axis: int | None = eqx.field(static=True)
    name = "lockstep"

    def vector_field(self, t, y, scene):
        return jax.vmap(self.inner.vector_field, in_axes=(None, 0, self.scene_axis))(t, y, scene)

    def project(self, y, scene, invariants=None):
        if invariants is None:
            return jax.vmap(self.inner.project, in_axes=(0, self.scene_axis))(y, scene)
        return jax.vmap(self.inner.project, in_axes=(0, self.scene_axis, 0))(y, scene, invariants)


def _max_member_rms(scaled_error) -> jax.Array:
    """The largest member's RMS of a batched scaled error (diffrax's default norm per member)."""
    return jnp.max(jax.vmap(optx.rms_norm)(scaled_error))


def _over_members(fn, scene_axis):
    """``vmap`` of ``fn(scene, *member_args)`` over members (the scene batched or not)."""

    def over(scene, *args):
        if scene_axis is None and not args:
            return fn(scene)
        return jax.vmap(fn, in_axes=(scene_axis,) + (0,) * len(args))(scene, *args)

    return over


def _screen_members(formulation, scene, states, ts, rtol, atol, scene_axis):
    """Screen every member (:func:`jrigid.solve.screen`): stand-in inputs where invalid.

    Returns ``(invalid (N,), cause (N,), scene, states, messages)``. A shared scene
    (``scene_axis=None``) stays shared: a member's stand-in replaces only its state, and
    a bad body (invalid for every member) is replaced by the stand-in body.
    """
    messages: list[str] = []

    def one(scene_m, state):
        checks = input_checks(formulation, scene_m, state, ts, rtol, atol)
        messages[:] = [m for _, m in checks]
        invalid, cause, scene_m, state, _, _, _ = screen(checks, scene_m, state, ts, rtol, atol)
        return invalid, cause, scene_m, state

    invalid, cause, scenes, states = jax.vmap(one, in_axes=(scene_axis, 0))(scene, states)
    if scene_axis is None:
        # A valid member's scene is the scene itself (an invalid member's may be the
        # stand-in body); if the body itself is bad, every member is invalid and any
        # stand-in will do.
        first_valid = jnp.argmin(invalid)
        scenes = jax.tree_util.tree_map(lambda a: a[first_valid], scenes)
    return invalid, cause, scenes, states, tuple(messages)


@eqx.filter_jit
def _solve(scene, states, ts, rtol, atol, dt0, formulation, solver, adjoint, max_steps,
           project, scene_axis):
    invalid, cause, scene, states, messages = _screen_members(
        formulation, scene, states, ts, rtol, atol, scene_axis
    )
    states = jax.vmap(normalised)(states)
    y0 = _over_members(lambda sc, s: formulation.from_state(sc, s), scene_axis)(scene, states)
    batched = _Batched(formulation, scene_axis)
    solve_ts = unit_times(ts)  # the solve runs in unit time (jrigid.solve.run)
    saveat = diffrax.SaveAt(ts=solve_ts, t1=True)
    solver = interpolating_at(solver, solve_ts)
    if project:
        invariants = None
        if scene.torque_free or scene.conservative_top:
            invariants = _over_members(
                lambda sc, s: Invariants.of(sc, s.q, s.omega), scene_axis
            )(scene, states)
        solver = projected(solver, batched, invariants)
    sol = run(batched, solver, ts, dt0, y0, scene, saveat=saveat,
              stepsize_controller=controller(ts, rtol, atol, norm=_max_member_rms,
                                             formulation=formulation, unit_time=True),
              adjoint=adjoint, max_steps=max_steps, unit_time=True)
    saved_ts = saved_times(sol.ts, ts)
    # rows 0 and T: the initial state and the final step's result, projected already
    ys = solver.outputs(sol.ys, scene, y0, keep_ends=True) if project else sol.ys
    ys = jax.tree_util.tree_map(lambda a: jnp.moveaxis(a, 1, 0), ys)  # (N, T + 1, ...)

    def one(sc, y, bad):
        return finish(sc, formulation, ts, saved_ts, y, sol.result, sol.stats, invalid=bad)

    traj = jax.vmap(one, in_axes=(scene_axis, 0, 0))(scene, ys, invalid)
    return traj, cause, messages


def simulate_lockstep(
    scene: Scene,
    initial_states: State,
    ts: ArrayLike,
    *,
    formulation: str | AbstractFormulation = "quaternion_acceleration",
    solver: diffrax.AbstractSolver | None = None,
    rtol: ArrayLike | None = None,
    atol: ArrayLike | None = None,
    max_steps: int = 100_000,
    dt0: ArrayLike | None = None,
    adjoint: diffrax.AbstractAdjoint | None = None,
    project: bool = True,
    batched_scene: bool = False,
    throw: bool = True,
) -> Trajectory:
    """Integrate ``N`` members as one system with a shared adaptive step (see module doc).

    Args:
        scene: one :class:`~jrigid.scene.Scene` for all members, or (``batched_scene``)
            a scene whose arrays have a leading member axis ``N`` (e.g.
            ``jax.vmap(make_scene)(params)``).
        initial_states: :class:`~jrigid.state.State` with leading axis ``N``
            (``q (N, 4)``, ``qdot (N, 4)``, ``x, v (N, 3)`` in free flight).
        ts: ``(T,)`` output times shared by all members, strictly increasing, ``T ≥ 2``.
        formulation, solver, rtol, atol, max_steps, dt0, adjoint, project: as in
            :func:`jrigid.simulate`; ``rtol``/``atol`` hold for every member. The
            formulation must have no event (not ``"euler_angles"``).
        batched_scene: whether ``scene`` carries the member axis.
        throw: raise on failure (``SimulationError`` naming the first failed member, or
            an ``equinox`` runtime error inside transformations); ``False``: per-member
            ``Trajectory.result`` codes.

    Returns:
        :class:`~jrigid.trajectory.Trajectory` whose leaves all have leading axis ``N``
        (as ``jax.vmap(simulate)`` returns); ``stats`` are the batch's step counts.

    Raises:
        ValueError: the checks of :func:`jrigid.simulate`, per member (the message names
            the first bad member), states without a common leading axis, or a
            formulation with an event.
        SimulationError: a failed integration, when ``throw`` and values are concrete.
    """
    formulation = get_formulation(formulation)
    if formulation.event() is not None:
        raise ValueError(
            f"the {formulation.name} formulation stops at an event (e.g. gimbal lock), which "
            "in lockstep would stop every member: use jax.vmap(jrigid.simulate) or a "
            "quaternion formulation"
        )
    if not isinstance(scene, Scene):
        raise ValueError(f"scene must be a jrigid Scene, got {type(scene).__name__}")
    if any(load.impulsive for load in scene.loads):
        raise ValueError("a scene with a Floor bounces: use jrigid.contact.simulate_bounces")
    if not isinstance(initial_states, State):
        raise ValueError(
            f"initial_states must be a jrigid State with a leading member axis, got "
            f"{type(initial_states).__name__}"
        )
    leading = {jnp.shape(a)[0] if jnp.ndim(a) else None
               for a in jax.tree_util.tree_leaves(initial_states)}
    if len(leading) != 1 or None in leading or jnp.ndim(initial_states.q) != 2:
        raise ValueError(
            "initial_states must have one leading member axis on every array (q (N, 4), "
            f"qdot (N, 4), ...), got shapes {jax.tree_util.tree_map(jnp.shape, initial_states)}"
        )
    if leading == {0}:
        raise ValueError("initial_states has no members (a leading axis of length 0)")
    scene_axis = 0 if batched_scene else None
    scene_lead = jnp.shape(scene.body.moments)[:-1]
    if scene_lead != ((len(initial_states.q),) if batched_scene else ()):
        raise ValueError(
            f"batched_scene={batched_scene} but the scene's body.moments has shape "
            f"{jnp.shape(scene.body.moments)} for {len(initial_states.q)} members: "
            + ("a batched scene has a leading member axis on every array (e.g. "
               "jax.vmap(make_scene)(params))" if batched_scene
               else "pass batched_scene=True for a scene with a leading member axis")
        )
    solver, adjoint, dt0, max_steps = solver_options(solver, adjoint, max_steps, dt0)
    dtype = jnp.result_type(float)
    states, ts, rtol, atol = jax.vmap(
        lambda sc, s: prepare(sc, s, ts, rtol, atol, dtype), in_axes=(scene_axis, 0),
        out_axes=(0, None, None, None)
    )(scene, initial_states)
    validate_shared(ts, rtol, atol, dtype)  # every member's: not blamed on one
    warn_precision(states, ts, rtol)  # float32 only, judged by the fastest member
    check_scene(formulation, scene)
    project = bool(project) and formulation.carries_quaternion
    traj, cause, messages = _solve(scene, states, ts, rtol, atol, dt0, formulation, solver,
                                   adjoint, max_steps, project, scene_axis)
    return raise_on_failure(traj, throw, ts, rtol, atol, max_steps, messages, cause)
