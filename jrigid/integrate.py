"""Adaptive integration of a scene with diffrax: :func:`simulate`.

One entry point, :func:`simulate`, over :func:`diffrax.diffeqsolve`. The default is
Euler's equations in quaternion-acceleration form (17.50) with Hairer's DOP853 pair,
its stages in one loop (:class:`jrigid.solvers.TightDop853`: its error estimate
scaled by 10, so that the tolerances bound the error of the result over long runs, and
an accurate 7th-order dense output), on the state raveled into one array, under a PID
controller, and after every step
the state is projected back onto ``|q| = 1``, ``q·q̇ = 0`` and onto the invariants the
scene conserves (energy and ``|L|`` for a torque-free body; energy, the vertical and —
for a symmetric top — the axial angular momentum on a pivot under gravity): see
:mod:`jrigid.invariants`. The projection, and step control at a sixth of the requested
tolerances (:class:`~jrigid.formulations.QuaternionAcceleration`'s ``tolerance_scale``:
in this form ω carries the orientation's error), are what make the second-order form as
accurate per tolerance as the first-order ``(q, ω)`` form; the measurements are in the
README ("Measurements"). Its controller also keeps steps whose scaled error is below 4.6
rather than 1, choosing every step as before (``acceptance``): fewer steps are redone.

The whole solve — input checks included — is one compiled program per scene structure,
formulation, solver, ``max_steps`` and number of output times; tolerances, ``dt0``, the
output times and every array inside the scene and the initial state are traced inputs,
so changing them does not recompile. When nothing but the outputs at ``ts`` is asked of
diffrax (no ``saveat``, ``dense``, ``stepsize_controller`` or event; an explicit solver;
the default or forward-mode adjoint), the outputs are saved by the step-size controller
(:mod:`jrigid.solve.saving`) and the whole program runs as one XLA:CPU kernel on the
calling thread (``jrigid._dispatch``): a jitted call then costs its steps and about 40 µs
(Intel Xeon; 85–140 µs on the AMD EPYC of the README's latest run, most of it passing
the scene and state in and the trajectory out).
The compiled program returns only the formulation's states, ``q``, ω, the outcome and the
step counts (the scene and ``ts`` are the inputs); the ``Trajectory``'s other quantities
are computed when first read. (Each array a program returns is initialised and copied
outside the kernel: returning all 22 of the quantities took 0.19 ms instead of 0.06 ms.)

Input errors: a wrong type or shape raises ``ValueError`` before anything is compiled.
Bad values (a zero quaternion, a non-physical inertia, NaN state, impossible
tolerances) are checked inside the compiled program: with ``throw=True`` they raise
``ValueError`` naming the problem (inside ``jit``/``vmap``: an ``equinox`` runtime error
with the same text); with ``throw=False`` the member gets
:attr:`~jrigid.trajectory.Result.invalid_input` and NaN outputs, and under ``vmap`` the
other members are computed as if it were not there. Integration failures are reported by
:class:`~jrigid.trajectory.Result` code: :class:`~jrigid.trajectory.SimulationError`
(cause, time reached, step counts, remedy) with concrete values and ``throw=True``, an
``equinox`` runtime error inside transformations, or the code in ``Trajectory.result``
with ``throw=False`` (outputs after ``t_stop`` are NaN). equinox's
``EQX_ON_ERROR`` environment variable chooses what a runtime error does (``raise``,
the default; ``breakpoint``; ``nan``).

Differentiation: reverse mode (``jax.grad``) through diffrax's
``RecursiveCheckpointAdjoint`` (default); forward mode (``jax.jvp``, ``jax.jacfwd``) needs
``adjoint=diffrax.ForwardMode()``, which :func:`simulate` picks itself when its inputs
are being forward-differentiated (``jax.jacfwd(f)``, ``jax.jit(jax.jacfwd(f))``). It
cannot see a forward derivative taken *outside* a ``jit`` it runs in,
``jax.jacfwd(jax.jit(f))``: JAX then fails with "can't apply forward-mode autodiff (jvp)
to a custom_vjp function"; pass ``adjoint=diffrax.ForwardMode()`` there. Second
derivatives: ``jax.jacfwd(jax.jacfwd(f))`` (``jax.hessian`` takes reverse mode inside
forward mode, which neither adjoint supports). Reverse mode under ``vmap`` works too
(``jax.grad`` of a loss summed over ``jax.vmap(simulate)``).
"""

from __future__ import annotations

import collections.abc
import dataclasses
import functools

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from jrigid import closed_form, splitting, trajectory
from jrigid._checks import all_arrays, float_dtype
from jrigid._dispatch import one_kernel
from jrigid.formulations import AbstractFormulation, check_scene, get_formulation
from jrigid.invariants import Invariants
from jrigid.scene import Scene
from jrigid.solve.flat import Flat
from jrigid.solve.inputs import input_checks, normalised, prepare, screen, warn_precision
from jrigid.solve.outcome import classify, finish, raise_on_failure
from jrigid.solve.saving import SavingController, SavingSolver, saved
from jrigid.solve.stepping import (  # DEFAULT_SOLVER: also named here
    DEFAULT_SOLVER,  # noqa: F401
    ProjectedSolver,
    VectorPIDController,
    controller,
    interpolating_at,
    projected,
    run,
    saved_times,
    solver_options,
    unit_times,
)
from jrigid.state import State
from jrigid.trajectory import Result, SimulationError, Trajectory  # noqa: F401  (also named here)

__all__ = ["simulate"]

_FORWARD_MODE_HINT = (
    "forward-mode differentiation (jax.jvp/jacfwd) of jrigid.simulate needs "
    "adjoint=diffrax.ForwardMode(); the default RecursiveCheckpointAdjoint is for "
    "reverse mode (jax.grad). Second derivatives: jax.jacfwd(jax.jacfwd(f)) (forward "
    "over forward; jax.hessian puts reverse mode inside forward mode, which neither "
    "adjoint supports)"
)


def _forward_differentiated(tree) -> bool:
    """Whether a leaf is being forward-differentiated here (a JVP tracer, possibly batched)."""
    from jax.interpreters import ad

    if _no_transformation():
        return False
    for leaf in jax.tree_util.tree_leaves(tree):
        x = leaf
        while isinstance(x, jax.core.Tracer):
            if isinstance(x, ad.JVPTracer):
                return True
            x = getattr(x, "val", None)
    return False


def _no_transformation() -> bool:
    """Whether no JAX transformation (``jit``, ``jvp``, ``vmap``, ...) is being traced now,
    so that no input can be a tracer (0.2 µs; flattening the inputs to look costs 7 µs)."""
    try:
        from jax._src import core
    except ImportError:  # pragma: no cover - JAX's layout changed
        return False
    clean = getattr(core, "trace_state_clean", None)
    return bool(clean()) if clean is not None else False


def _project_mode(project) -> tuple[bool, bool]:
    """``(manifold, invariants)`` from ``project`` (True, ``"manifold"`` or False)."""
    if project is True or project == "invariants":
        return True, True
    if project == "manifold":
        return True, False
    if project is False or project is None:
        return False, False
    raise ValueError(f"project must be True, 'manifold' or False, got {project!r}")


_SAVE_Y = diffrax.SubSaveAt(t1=True).fn  # diffrax's default: save the state itself


def _check_saveat(saveat) -> None:
    if saveat is None:
        return
    if not isinstance(saveat, diffrax.SaveAt):
        raise ValueError(f"saveat must be a diffrax.SaveAt, got {saveat!r}")
    for sub in jax.tree_util.tree_leaves(saveat.subs, is_leaf=lambda s: isinstance(
            s, diffrax.SubSaveAt)):
        if sub.fn is not _SAVE_Y:
            raise ValueError(
                "saveat with a custom fn is not supported: jrigid derives every output from "
                "the saved states (use the Trajectory's fields)"
            )
    if not isinstance(saveat.subs, diffrax.SubSaveAt):
        raise ValueError("saveat with several SubSaveAt (a pytree of subs) is not supported: "
                         "give one diffrax.SaveAt(t0=..., t1=..., ts=..., steps=...)")
    if not (saveat.subs.t0 or saveat.subs.t1 or saveat.subs.ts is not None or saveat.subs.steps):
        raise ValueError("saveat must save something (t0, t1, ts or steps), not only dense")


def _solve(scene, state, ts, rtol, atol, *options):
    """The compiled solve: ``(traj, cause, messages)``.

    ``options`` (everything but the arrays) are hashable in the common case: then the
    solve is a ``jax.jit`` function cached per options, which dispatches in about half the
    time of ``equinox.filter_jit`` (what a plain call in a loop pays). Otherwise (an
    option holding arrays), ``equinox.filter_jit``. The trajectory's scene (and ``ts``,
    unless a ``saveat`` chose the times) are the inputs, put back here.
    """
    traj = None
    try:
        compiled = _compiled(options)
    except TypeError:  # unhashable options
        compiled = None
    if compiled is not None:
        try:
            traj, cause = compiled.fn(scene, state, ts, rtol, atol)
            messages = _Messages(compiled.messages, (scene, state, rtol))
        except TypeError:
            if all_arrays(scene, state, ts, rtol, atol):
                raise
    if traj is None:
        traj, cause, messages = _filter_solve(scene, state, ts, rtol, atol, *options)
    ts = ts if traj.ts is None else traj.ts
    return trajectory.replace(traj, scene=scene, ts=ts), cause, messages


def _message_key(scene, state, rtol):
    """What a solve's check messages depend on: the inputs' tree structure and the float
    type (its machine epsilon and name are in them; a float32 solve's messages had been
    read for a float64 one of the same structure)."""
    return jax.tree_util.tree_structure((scene, state)), jnp.dtype(rtol.dtype).name


class _Messages(collections.abc.Sequence):
    """The check messages of a solve, looked up (by :func:`_message_key`) only when read:
    a plain call reads them only when an input is invalid, and the lookup flattens the
    scene (about 8 µs)."""

    def __init__(self, table, inputs):
        self._table, self._inputs, self._messages = table, inputs, None

    def _get(self):
        if self._messages is None:
            self._messages = self._table[_message_key(*self._inputs)]
        return self._messages

    def __getitem__(self, index):
        return self._get()[index]

    def __len__(self):
        return len(self._get())


class _Compiled:
    """A ``jax.jit`` solve for one set of options; keeps the check messages of each
    input structure it was traced for (texts, which a jitted function cannot return)."""

    def __init__(self, options):
        self.messages = {}

        def fn(scene, state, ts, rtol, atol):
            traj, cause, messages = _solve_body(scene, state, ts, rtol, atol, *options)
            self.messages[_message_key(scene, state, rtol)] = messages
            return traj, cause

        self.fn = jax.jit(fn)


@functools.lru_cache(maxsize=64)
def _compiled_by_value(options) -> _Compiled:
    return _Compiled(options)


_BY_IDENTITY: dict[tuple[int, ...], tuple[tuple, _Compiled]] = {}


def _compiled(options) -> _Compiled:
    """The compiled solve of ``options``: looked up by the options' identities first
    (hashing the equinox modules among them costs about 7 µs a call), then by value."""
    key = tuple(map(id, options))
    hit = _BY_IDENTITY.get(key)
    if hit is not None and all(a is b for a, b in zip(hit[0], options, strict=True)):
        return hit[1]
    compiled = _compiled_by_value(options)
    if len(_BY_IDENTITY) >= 64:
        _BY_IDENTITY.clear()
    _BY_IDENTITY[key] = (options, compiled)  # holds the options: their ids stay theirs
    return compiled


@eqx.filter_jit
def _filter_solve(*args):
    return _solve_body(*args)


def _refuse(what: str, **options) -> None:
    """``ValueError`` naming the first of ``options`` that is given (not ``None``)."""
    for name, value in options.items():
        if value is not None:
            raise ValueError(f"{what}: it takes no {name}")


def _saves_itself(formulation, solver, adjoint, dense, saveat, stepsize_controller,
                  event) -> bool:
    """Whether a solve saves at ``ts`` through its controller (:mod:`jrigid.solve.saving`)
    and runs as one kernel (:func:`jrigid._dispatch.one_kernel`): when nothing else is
    asked of diffrax (no ``saveat``, ``dense``, controller or event), the solver is
    explicit (an implicit one takes its root finder's tolerances from diffrax's own
    controller) and the adjoint is the default or forward mode. (diffrax's
    ``SaveAt(ts=...)`` checks ``ts`` with runtime errors, which a kernel cannot hold.)"""
    return (saveat is None and not dense and event is None and formulation.event() is None
            and stepsize_controller is None
            and not isinstance(solver, diffrax.AbstractImplicitSolver)
            and isinstance(adjoint, (diffrax.RecursiveCheckpointAdjoint, diffrax.ForwardMode)))


def _solve_body(scene, state, ts, rtol, atol, dt0, formulation, solver, adjoint, max_steps,
                project, dense, saveat, stepsize_controller, event):
    saves_itself = _saves_itself(formulation, solver, adjoint, dense, saveat,
                                 stepsize_controller, event)
    messages = []

    def solve(scene, state, ts, rtol, atol, dt0):
        traj, cause, texts = _solve_arrays(
            scene, state, ts, rtol, atol, dt0, formulation, solver, adjoint, max_steps,
            project, dense, saveat, stepsize_controller, event, saves_itself,
        )
        messages[:] = texts
        return traj, cause

    if saves_itself:
        solve = one_kernel(solve, reverse=not isinstance(adjoint, diffrax.ForwardMode))
    traj, cause = solve(scene, state, ts, rtol, atol, dt0)
    # The scene and the output times are the inputs (an invalid member was solved with
    # stand-ins): :func:`_solve` puts them back, so that a compiled program does not copy
    # inputs to its outputs.
    traj = trajectory.replace(traj, scene=None, ts=None if saveat is None else traj.ts)
    return traj, cause, tuple(messages)


def _solve_arrays(scene, state, ts, rtol, atol, dt0, formulation, solver, adjoint, max_steps,
                  project, dense, saveat, stepsize_controller, event, saves_itself):
    checks = input_checks(formulation, scene, state, ts, rtol, atol)
    if dt0 is not None:  # (traced here under jit: a concrete one was checked already)
        checks.append((~(jnp.isfinite(dt0) & (dt0 > 0)), "dt0 must be finite and > 0"))
    messages = tuple(m for _, m in checks)
    invalid, cause, scene, state, ts, rtol, atol = screen(checks, scene, state, ts, rtol, atol)
    if dt0 is not None:  # the stand-in's first step: a hundredth of its span
        dt0 = jnp.where(invalid, 0.01 * (ts[-1] - ts[0]), dt0)
    state = normalised(state)
    y0 = formulation.from_state(scene, state)
    flat = Flat.of(formulation, y0)  # one array in the loop: fewer operations per step
    user_saveat = saveat is not None
    # Two output times: the ends of the solve, no interpolation at all. (Saving them
    # through the controller measured 5-10 % slower per call and +0.3 s of compilation.)
    ends_only = saves_itself and ts.shape[0] == 2
    if ends_only:
        saveat = diffrax.SaveAt(t0=True, t1=True)
    elif saves_itself:
        saveat = diffrax.SaveAt(t1=True, controller_state=True)
    elif saveat is None:
        saveat = diffrax.SaveAt(ts=ts, t1=True, dense=dense)
    if (isinstance(adjoint, diffrax.ForwardMode) and isinstance(solver, diffrax.AbstractRungeKutta)
            and solver.scan_kind is None):
        # What diffrax's ForwardMode does to the solver it is given, which it cannot do
        # through jrigid's wrappers: stages in a plain loop, which forward mode can enter.
        solver = dataclasses.replace(solver, scan_kind="lax")
    # A solve saving by itself runs in unit time (jrigid.solve.run): its times are solve_ts.
    solve_ts = unit_times(ts) if saves_itself else ts
    if not (user_saveat or dense or event is not None or formulation.event() is not None):
        # its dense output only saves at ts (and nowhere for the ends only: no output
        # time, so that a step neither computes the dense output's stages nor looks for
        # an output time)
        solver = interpolating_at(solver, solve_ts[:0] if ends_only else solve_ts)
    manifold, restore = project
    if manifold and formulation.carries_quaternion:
        invariants = Invariants.of(scene, state.q, state.omega) if restore else None
        solver = projected(solver, flat, invariants)
    projection = solver if isinstance(solver, ProjectedSolver) else None
    if saves_itself and not ends_only:
        solver = SavingSolver(solver)
        kind = "lax" if isinstance(adjoint, diffrax.ForwardMode) else "checkpointed"
        stepsize_controller = controller(
            ts, rtol, atol, layout=flat, cls=SavingController, formulation=formulation,
            unit_time=True, output_ts=solve_ts,
            interpolation_cls=solver.interpolation_cls, loop_kind=kind,
        )
    elif stepsize_controller is None:
        stepsize_controller = controller(ts, rtol, atol, layout=flat, formulation=formulation,
                                         unit_time=saves_itself)
    record = isinstance(stepsize_controller, VectorPIDController)
    if user_saveat:
        # the user's outputs, and the end of the solve (the time it reached, for t_stop
        # and the failure report); dense=True keeps the interpolation here too
        saveat = diffrax.SaveAt(subs=(saveat.subs, diffrax.SubSaveAt(t1=True)),
                                dense=saveat.dense or dense, solver_state=saveat.solver_state,
                                controller_state=saveat.controller_state or record,
                                made_jump=saveat.made_jump)
    elif record and not saveat.controller_state:  # its record of non-finite trial steps
        saveat = diffrax.SaveAt(subs=saveat.subs, dense=saveat.dense,
                                solver_state=saveat.solver_state, controller_state=True,
                                made_jump=saveat.made_jump)
    y0_flat = flat.ravel(y0)
    sol = run(flat, solver, ts, dt0, y0_flat, scene, saveat=saveat,
              stepsize_controller=stepsize_controller, adjoint=adjoint, max_steps=max_steps,
              event=flat.event(formulation.event() if event is None else event),
              unit_time=saves_itself)
    saved_ts, ys = sol.ts, sol.ys
    if user_saveat:
        (saved_ts, end_ts), (ys, end_ys) = sol.ts, sol.ys
    if ends_only:  # (t0, t_end) → the layout of SaveAt(ts=ts, t1=True): (t0, t_end, t_end)
        saved_ts, ys = (jnp.concatenate([a, a[-1:]]) for a in (sol.ts, sol.ys))
    elif saves_itself:
        saved_ts, ys = saved(sol, solve_ts)
    if saves_itself:
        saved_ts = saved_times(saved_ts, ts)
    if projection is not None and not ends_only:
        # Interpolated outputs are projected here; the two ends are the initial state and
        # a step's result, both projected already (and projecting them again doubled the
        # projection's share of compilation: 1 s of the heavy top's 2). In the layout of
        # saved() they are the first and last rows, kept as they are.
        ys = projection.outputs(ys, scene, y0_flat, keep_ends=saves_itself)
    ys = flat.states(ys)
    interpolation = flat.interpolation(sol.interpolation) if (dense or saveat.dense) else None
    trials = stepsize_controller.nonfinite_trials(sol.controller_state) if record else None
    if user_saveat:
        end = (end_ts[-1], jax.tree_util.tree_map(lambda a: a[-1], flat.states(end_ys)))
        traj = _finish_saved(scene, formulation, ts, sol, saved_ts, ys, end, interpolation,
                             invalid, event, trials)
    else:
        traj = finish(scene, formulation, ts, saved_ts, ys, sol.result, sol.stats,
                      interpolation, invalid, user_event=event is not None,
                      nonfinite_trials=trials)
    return traj, cause, messages


def _finish_saved(scene, formulation, ts, sol, saved_ts, ys, end, interpolation, invalid,
                  event, trials):
    """The trajectory of a user's ``SaveAt``: its times ``saved_ts`` as diffrax filled
    them (``inf`` padding becomes NaN outputs); ``ys`` are the saved states as the
    formulation's variables; ``end`` is ``(t, y)`` where the solve stopped."""
    saved = jnp.isfinite(saved_ts) & ~invalid
    t_end, y_end = end

    def _mask(a):
        keep = saved.reshape(saved.shape + (1,) * (a.ndim - 1))
        return jnp.where(keep, a, jnp.nan)

    ys = jax.tree_util.tree_map(_mask, ys)
    filled = jax.tree_util.tree_map(lambda a: jnp.where(jnp.isnan(a), 0.0, a), ys)
    result = classify(sol.result, formulation, scene, y_end, t_end, filled, ts[-1] - ts[0],
                      event is not None, trials)
    result = jnp.where(invalid, jnp.int32(Result.invalid_input), result)
    stats = {k: sol.stats[k] for k in ("num_steps", "num_accepted_steps", "num_rejected_steps")}
    return Trajectory.build(scene, formulation, jnp.where(saved, saved_ts, jnp.nan), ys,
                            stats=stats, result=result, t_stop=t_end,
                            interpolation=interpolation)


def simulate(
    scene: Scene,
    initial_state: State,
    ts: ArrayLike,
    *,
    formulation: str | AbstractFormulation = "quaternion_acceleration",
    solver: diffrax.AbstractSolver | splitting.Splitting | str | None = None,
    rtol: ArrayLike | None = None,
    atol: ArrayLike | None = None,
    max_steps: int = 100_000,
    dt0: ArrayLike | None = None,
    adjoint: diffrax.AbstractAdjoint | None = None,
    project: bool | str = True,
    dense: bool = False,
    throw: bool = True,
    saveat: diffrax.SaveAt | None = None,
    stepsize_controller: diffrax.AbstractStepSizeController | None = None,
    event: diffrax.Event | None = None,
) -> Trajectory:
    """Integrate ``scene`` from ``initial_state`` and sample the motion at ``ts``.

    Args:
        scene: the :class:`~jrigid.scene.Scene`.
        initial_state: :class:`~jrigid.state.State` at ``ts[0]`` (one state; ``vmap``
            for batches). ``q`` is normalised; for ``quaternion_acceleration`` ``q̇`` is
            projected onto ``q·q̇ = 0`` keeping ω.
        ts: ``(T,)`` strictly increasing output times, ``T ≥ 2``; the solve runs from
            ``ts[0]`` to ``ts[-1]``.
        formulation: name (``"quaternion_acceleration"`` default, ``"quaternion_omega"``,
            ``"body_omega"``, ``"euler_angles"``) or a formulation object (e.g.
            ``QuaternionAcceleration(stabilization=1.0)``).
        solver: any diffrax solver; default :data:`jrigid.solve.DEFAULT_SOLVER`
            (:class:`jrigid.solvers.TightDop853`). Fixed-step solvers (``diffrax.Euler``,
            ``diffrax.Heun``, ...) need ``stepsize_controller=diffrax.ConstantStepSize()``
            and ``dt0``. Or ``"exact"``: the closed-form motion (:mod:`jrigid.closed_form`)
            for torque-free scenes; then ``rtol``, ``atol``, ``max_steps``, ``dt0``,
            ``adjoint`` and ``project`` are ignored, ``saveat``, ``stepsize_controller``
            and ``event`` are refused, ``stats`` are zero, and ``dense=True`` keeps the
            closed form for :meth:`Trajectory.at`. (For a heavy symmetric top the closed
            form holds only for a body symmetric about its lever: its derivatives are
            those along symmetric bodies, such as ``I₁ + I₂`` together, not ``I₁`` alone
            or the centre of mass off the axis.) Or a
            :class:`jrigid.splitting.Splitting` (``"splitting"``: its default method with
            step ``dt0``): fixed-step exact-flow splitting for a body on a pivot (or in
            free rotation) under a torque of the orientation and time only; ``rtol``,
            ``atol``, ``max_steps``, ``adjoint`` and ``project`` are ignored, ``dense``,
            ``saveat``, ``stepsize_controller`` and ``event`` are refused.
        rtol, atol: PID tolerances, traced (changing them does not recompile). Defaults
            ``1e-8`` and ``1e-10`` (float64), ``1e-5`` and ``1e-7`` (float32). The
            default formulation steps to ``rtol / 6`` and ``atol / 6``
            (``tolerance_scale`` of
            :class:`~jrigid.formulations.QuaternionAcceleration`): its error at a given
            rtol is then about the ``quaternion_omega`` form's (measured on the hard
            cases of ``benchmarks/hard_cases.py`` at rtol 1e-4, 1e-6, …, 1e-12: within
            0.13·rtol to 1e-10, and within 1.9× that form's error; near the separatrix
            at ε = 1e-6 around rtol 1e-10 the error jumps between 0.04 and 0.5·rtol).
            ``rtol`` must be finite, ``> 0`` and at least ``10 eps``. In float32 a
            :class:`~jrigid.solve.PrecisionWarning` says when the horizon is too long
            for ``rtol`` (:func:`jrigid.solve.precision_problem`; concrete inputs only).
        max_steps: static step budget (accepted plus rejected steps).
        dt0: initial step; ``None`` lets diffrax choose.
        adjoint: diffrax adjoint: ``diffrax.RecursiveCheckpointAdjoint()`` (default,
            reverse mode), ``diffrax.DirectAdjoint()`` or ``diffrax.ForwardMode()``
            (``BacksolveAdjoint`` and ``ImplicitAdjoint`` are refused); default
            ``diffrax.ForwardMode()`` when the inputs are being
            forward-differentiated (``jax.jacfwd``). For ``jax.jacfwd(jax.jit(f))``, where
            the forward derivative is taken outside the ``jit``, pass
            ``adjoint=diffrax.ForwardMode()`` yourself (JAX otherwise fails with "can't
            apply forward-mode autodiff (jvp) to a custom_vjp function"). Second
            derivatives: ``jax.jacfwd(jax.jacfwd(f))``, not ``jax.hessian``.
        project: ``True`` (default): after every step (and at every output) put a
            quaternion formulation's state back on ``|q| = 1`` (``q·q̇ = 0``) and restore
            the scene's invariants (:mod:`jrigid.invariants`); ``"manifold"``: the
            constraints only; ``False``: nothing.
        dense: keep the dense interpolation for :meth:`Trajectory.at`.
        throw: raise on failure (see the module docstring); ``False`` returns the
            :class:`~jrigid.trajectory.Result` code in ``Trajectory.result`` (a member
            with bad inputs under ``vmap``: ``invalid_input``, the others solved). The
            helpers of :mod:`jrigid.initial` check their own inputs and raise, under
            ``jit`` too: for a sweep whose members may be bad, build states with
            :class:`~jrigid.state.State` or use :func:`jrigid.ensemble.simulate_many`.
        saveat: a ``diffrax.SaveAt`` instead of ``SaveAt(ts=ts)`` (e.g. ``steps=True``;
            ``ts`` then only gives the time span). The trajectory's ``ts`` are the saved
            times (diffrax's unfilled slots become NaN: ``steps=True`` gives
            ``max_steps`` rows, the end of each accepted step, not ``ts[0]``, then NaN;
            lower ``max_steps`` or drop the NaN rows).
        stepsize_controller: a diffrax controller instead of the PID controller built
            from ``rtol``/``atol`` (e.g. ``diffrax.ConstantStepSize()`` with ``dt0``).
            It steps to its own tolerances, as diffrax's controllers do (error
            estimate unscaled, and not divided by 6 for the default form, so the same
            numbers give a larger error than ``simulate``'s): passing ``rtol`` or
            ``atol`` as well raises ``ValueError``.
        event: a terminating ``diffrax.Event``; when it fires the result is
            :attr:`~jrigid.trajectory.Result.event` (not a failure) and outputs after
            ``t_stop`` are NaN. Its functions receive ``args = scene``. Without a
            ``root_finder`` (e.g. ``optimistix.Newton(rtol, atol)``) the solve stops at
            the end of the step in which the condition changed sign, so ``t_stop`` is
            that step's end, not the event's time.

    Returns:
        :class:`~jrigid.trajectory.Trajectory`; ``stats`` holds step counts.

    Warns:
        PrecisionWarning: float32 cannot meet ``rtol`` over ``ts`` (see ``rtol``).

    Raises:
        ValueError: bad input (non-physical inertia, zero quaternion, NaN state,
            impossible tolerances, a scene the formulation cannot represent,
            ``solver="exact"`` for a scene with a torque, ...).
        SimulationError: a failed integration, when ``throw`` and values are concrete.

    Example:
        >>> import jax.numpy as jnp, jrigid
        >>> scene = jrigid.Scene(jrigid.RigidBody(jnp.array([1.0, 2.0, 3.0])))
        >>> state = jrigid.initial.from_omega(omega=jnp.array([0.01, 1.0, 0.01]))
        >>> traj = jrigid.simulate(scene, state, jnp.linspace(0.0, 10.0, 11))
        >>> traj.q.shape, int(traj.result)
        ((11, 4), 0)
    """
    formulation = get_formulation(formulation)
    if isinstance(scene, Scene) and any(load.impulsive for load in scene.loads):
        raise ValueError("a scene with a Floor bounces: use jrigid.contact.simulate_bounces")
    dtype = float_dtype()
    if isinstance(solver, str) and solver == "splitting":
        if dt0 is None:
            raise ValueError("solver='splitting' needs dt0 (the step), or pass "
                             "solver=jrigid.splitting.Splitting(method, dt=... or steps=...)")
        solver = splitting.Splitting(dt=dt0)
    if isinstance(solver, splitting.Splitting):
        _refuse("the splitting solver has fixed steps", dense=dense or None, saveat=saveat,
                event=event, stepsize_controller=stepsize_controller)
        state, ts, rtol, atol = prepare(scene, initial_state, ts, None, None, dtype)
        splitting.check_scene(scene)
        check_scene(formulation, scene)
        bound = solver.bound(ts)
        traj, cause, messages = splitting.solve(
            scene, state, ts, rtol, atol, formulation, solver, bound
        )
        return raise_on_failure(traj, throw, ts, rtol, atol, bound, messages, cause,
                                splitting.CAUSES, tolerances=False)
    if isinstance(solver, str):
        if solver != "exact":
            raise ValueError(
                f"solver must be a diffrax solver, 'exact' or 'splitting', got {solver!r}"
            )
        _refuse("solver='exact' follows the closed form without steps", saveat=saveat,
                event=event, stepsize_controller=stepsize_controller)
        state, ts, rtol, atol = prepare(scene, initial_state, ts, None, None, dtype)
        closed_form.check_scene(scene)
        check_scene(formulation, scene)
        traj, cause, messages = closed_form.solve(
            scene, state, ts, rtol, atol, formulation, bool(dense)
        )
        return raise_on_failure(traj, throw, ts, rtol, atol, max_steps, messages, cause)
    solver, adjoint, dt0, max_steps = solver_options(solver, adjoint, max_steps, dt0)
    if isinstance(adjoint, diffrax.RecursiveCheckpointAdjoint) and _forward_differentiated(
        (scene, initial_state, ts, rtol, atol)
    ):
        adjoint = diffrax.ForwardMode()
    if stepsize_controller is not None and (rtol is not None or atol is not None):
        raise ValueError(
            "rtol and atol do not reach a stepsize_controller you pass (it steps to its own "
            "tolerances): set them on the controller, e.g. "
            "diffrax.PIDController(rtol=..., atol=...), and leave out simulate's"
        )
    state, ts, rtol, atol = prepare(scene, initial_state, ts, rtol, atol, dtype)
    check_scene(formulation, scene)
    _check_saveat(saveat)
    warn_precision(state, ts, rtol)
    if stepsize_controller is not None:
        if not isinstance(stepsize_controller, diffrax.AbstractStepSizeController):
            raise ValueError(
                f"stepsize_controller must be a diffrax controller, got {stepsize_controller!r}"
            )
        if isinstance(stepsize_controller, diffrax.ConstantStepSize) and dt0 is None:
            raise ValueError("a ConstantStepSize controller needs dt0 (the step)")
    elif not isinstance(solver, diffrax.AbstractAdaptiveSolver):
        raise ValueError(
            f"{type(solver).__name__} gives no error estimate, so jrigid's adaptive "
            "step-size controller cannot step it: pass "
            "stepsize_controller=diffrax.ConstantStepSize() and dt0 (the step)"
        )
    if event is not None:
        if not isinstance(event, diffrax.Event):
            raise ValueError(f"event must be a diffrax.Event, got {event!r}")
        if formulation.event() is not None:
            raise ValueError(
                f"the {formulation.name} formulation has its own event (gimbal lock); pass "
                "a user event with a quaternion formulation"
            )
    try:
        traj, cause, messages = _solve(
            scene, state, ts, rtol, atol, dt0, formulation, solver, adjoint, max_steps,
            _project_mode(project), bool(dense), saveat, stepsize_controller, event,
        )
    except TypeError as error:
        if "custom_vjp" in str(error) or "forward-mode" in str(error):
            raise TypeError(_FORWARD_MODE_HINT) from error
        raise
    return raise_on_failure(traj, throw, ts, rtol, atol, max_steps, messages, cause)
