"""Adaptive integration of a scene with diffrax: :func:`simulate`.

One entry point, :func:`simulate`, over :func:`diffrax.diffeqsolve` with a
:class:`diffrax.PIDController`. The whole solve is compiled once per scene structure,
formulation, solver, ``max_steps`` and number of output times; tolerances, ``dt0``,
the output times and every array inside the scene and the initial state are traced
inputs, so changing them does not recompile.

Constraint handling for quaternion formulations: :class:`ProjectedSolver` wraps any
diffrax solver and maps each step's result back onto ``|q| = 1`` (and ``q·q̇ = 0``).
It is on by default (``project=True``): ``benchmarks/constraint_drift.py`` compares it
with the stabilising term of :class:`~jrigid.formulations.QuaternionAcceleration`
over 10⁴ rotation periods of an asymmetric body (Tsit5). Without either remedy
``|q| − 1`` grows to about the tolerance (1.1e-6 at rtol 1e-6, 2.6e-10 at rtol 1e-9);
projection keeps it 3–5× lower at the output times (which are interpolated, hence not
exactly on the constraint) and leaves the energy and ``|L|`` errors unchanged. The
stabilising term bounds the constraints as well, but multiplies the energy error by
1.5–60 depending on gain and tolerance, so projection is the default.

Input errors raise ``ValueError`` before anything is compiled (concrete inputs) or,
inside ``jit``/``vmap``/``grad``, come from ``equinox.error_if`` at run time with the
same message. Integration failures are reported by :class:`Result` code:

- with concrete values and ``throw=True``, :class:`SimulationError` names the cause,
  the time reached, the step counts and a remedy;
- inside a transformation with ``throw=True``, an ``equinox`` runtime error carries
  the cause and remedy (under ``vmap``: if any member fails);
- with ``throw=False``, nothing is raised: ``Trajectory.result`` holds the code (one
  per member under ``vmap``), ``Trajectory.t_stop`` the time reached, and every output
  after ``t_stop`` is ``NaN``.

Timing: the Python-side checks cost about a millisecond per call; for benchmarks wrap
the call, ``fast = equinox.filter_jit(simulate)``, which leaves ~0.2 ms of dispatch.
Step counts are in ``Trajectory.stats``.

Adjoints: ``RecursiveCheckpointAdjoint`` (default, reverse mode) and
``diffrax.ForwardMode()`` (for ``jax.jacfwd``) work; ``BacksolveAdjoint`` does not.

``solver="exact"`` skips the integration for a torque-free scene and evaluates the
closed-form motion of :mod:`jrigid.exact` at ``ts`` (plus the ballistic parabola of the
centre of mass under uniform gravity in free flight). The closed-form ``q`` and ``ω`` are
converted to the formulation's variables with ``formulation.from_state`` and the
:class:`~jrigid.trajectory.Trajectory` is built as for the numerical path; ``rtol``,
``atol``, ``max_steps``, ``dt0``, ``adjoint`` and ``project`` are ignored, the step
counts are zero. It works under ``jit``, ``vmap`` and ``grad``.
"""

from __future__ import annotations

import enum

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from jrigid import exact
from jrigid import quaternion as quat
from jrigid._checks import is_traced
from jrigid.formulations import AbstractFormulation, get_formulation
from jrigid.scene import FreeFlight, FreeRotation, Gravity, Scene
from jrigid.state import State
from jrigid.trajectory import Trajectory

__all__ = [
    "ExactMotion",
    "ProjectedSolver",
    "Result",
    "SimulationError",
    "check_exact_scene",
    "simulate",
]


class Result(enum.IntEnum):
    """Outcome codes in ``Trajectory.result`` (an int32 array, one per ``vmap`` member).

    - ``success`` (0): reached ``ts[-1]``;
    - ``max_steps`` (1): the step budget ran out;
    - ``step_size_collapse`` (2): the step size fell below ``4 eps |t|`` with a finite
      vector field (a singular or very stiff solution);
    - ``nonfinite`` (3): NaN/inf in the vector field or state (e.g. a NaN torque);
    - ``gimbal_lock`` (4): the Euler-angle formulation reached ``sin θ ≈ 0``;
    - ``solver_failure`` (5): any other diffrax failure (e.g. an implicit solver's
      root find).
    """

    success = 0
    max_steps = 1
    step_size_collapse = 2
    nonfinite = 3
    gimbal_lock = 4
    solver_failure = 5


_CAUSE = {
    Result.max_steps: (
        "max_steps={max_steps} exhausted before reaching the final time",
        "raise max_steps, loosen rtol/atol, or shorten the time span",
    ),
    Result.step_size_collapse: (
        "the step size collapsed (below 4 machine epsilons of t): the solution is "
        "singular or too stiff there",
        "check the torque and parameters for a singularity, or try an implicit solver "
        "such as diffrax.Kvaerno5()",
    ),
    Result.nonfinite: (
        "the vector field or state became non-finite (NaN or inf)",
        "check the scene parameters and torque function for NaN/inf (e.g. division by "
        "zero, a NaN parameter)",
    ),
    Result.gimbal_lock: (
        "Euler-angle gimbal lock: |sin θ| fell below min_sin_theta, where the "
        "Euler-angle rates (eq. 17.36) are singular",
        "use formulation='quaternion_acceleration' (or 'quaternion_omega')",
    ),
    Result.solver_failure: (
        "the solver reported a failure (e.g. an implicit solver's root find did not "
        "converge)",
        "loosen rtol/atol or change the solver",
    ),
}


class SimulationError(RuntimeError):
    """Raised by :func:`simulate` when an integration fails (cause and remedy in the text)."""


def _traced_message(code: Result, max_steps: int) -> str:
    cause, remedy = _CAUSE[code]
    return (
        f"jrigid.simulate failed: {cause.format(max_steps=max_steps)}; {remedy}. "
        "(Under vmap, pass throw=False for per-member Trajectory.result codes.)"
    )


# --------------------------------------------------------------------------- projection


class ProjectedSolver(diffrax.AbstractWrappedSolver):
    """Wrap a diffrax solver; project every step's result onto the constraint manifold.

    ``step`` calls the inner solver, then replaces ``y1`` by
    ``formulation.project(y1, args)`` (for ``quaternion_acceleration``:
    ``q ← q/|q|``, ``q̇ ← ½ q ⊗ (0, ω)`` with the step's ω, which keeps ω and hence
    the kinetic energy; for ``quaternion_omega``: ``q ← q/|q|``). The error estimate is
    the inner solver's, so step control is unchanged. A first-same-as-last solver reuses
    its last stage, evaluated before projection, in the next step: the mismatch is of
    the size of the projection (the local error), so the order is unaffected.

    Attributes:
        solver: the wrapped diffrax solver (any; ``isinstance`` checks see through it).
        formulation: the formulation whose :meth:`project` is applied.
    """

    solver: diffrax.AbstractSolver
    formulation: AbstractFormulation = eqx.field(static=True)

    @property
    def term_structure(self):
        return self.solver.term_structure

    @property
    def interpolation_cls(self):  # pyright: ignore
        return self.solver.interpolation_cls

    @property
    def term_compatible_contr_kwargs(self):
        return self.solver.term_compatible_contr_kwargs

    @property
    def root_finder(self):
        """The wrapped implicit solver's root finder (diffrax sets its tolerances)."""
        return self.solver.root_finder

    @property
    def root_find_max_steps(self):
        return self.solver.root_find_max_steps

    @property
    def scan_kind(self):
        """The wrapped Runge–Kutta solver's ``scan_kind`` (diffrax sets it for forward mode)."""
        return self.solver.scan_kind

    def order(self, terms):
        return self.solver.order(terms)

    def strong_order(self, terms):
        return self.solver.strong_order(terms)

    def error_order(self, terms):
        return self.solver.error_order(terms)

    def init(self, terms, t0, t1, y0, args):
        return self.solver.init(terms, t0, t1, y0, args)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        y1, y_error, dense_info, solver_state, result = self.solver.step(
            terms, t0, t1, y0, args, solver_state, made_jump
        )
        y1 = self.formulation.project(y1, args)
        if isinstance(dense_info, dict) and "y1" in dense_info:
            dense_info = dict(dense_info, y1=y1)
        return y1, y_error, dense_info, solver_state, result

    def func(self, terms, t0, y0, args):
        return self.solver.func(terms, t0, y0, args)


# --------------------------------------------------------------------------- checks




def _as(x, dtype, name: str, shape: tuple[int, ...]) -> jax.Array:
    x = jnp.asarray(x, dtype=dtype)
    if x.shape != shape:
        raise ValueError(
            f"{name} must have shape {shape}, got {x.shape} (use jax.vmap for batches)"
        )
    return x


def prepare(scene: Scene, state: State, ts, rtol, atol, dtype):
    """Static checks (types, shapes) and dtype conversion of the inputs; no value checks."""
    if not isinstance(scene, Scene):
        raise ValueError(f"scene must be a jrigid Scene, got {type(scene).__name__}")
    if not isinstance(state, State):
        raise ValueError(
            f"initial_state must be a jrigid State (see jrigid.initial), got {type(state).__name__}"
        )
    if scene.translates and (state.x is None or state.v is None):
        raise ValueError("a FreeFlight scene needs x and v in the initial state")
    if not scene.translates and (state.x is not None or state.v is not None):
        raise ValueError("x and v are only for FreeFlight scenes; this scene does not translate")
    ts = jnp.asarray(ts, dtype=dtype)
    if ts.ndim != 1 or ts.shape[0] < 2:
        raise ValueError(f"ts must be a 1-D array of at least 2 times, got shape {ts.shape}")
    wide = jnp.dtype(dtype).itemsize >= 8
    rtol = _as(rtol if rtol is not None else (1e-8 if wide else 1e-5), dtype, "rtol", ())
    atol = _as(atol if atol is not None else (1e-10 if wide else 1e-7), dtype, "atol", ())
    state = State(
        _as(state.q, dtype, "initial_state.q", (4,)),
        _as(state.qdot, dtype, "initial_state.qdot", (4,)),
        None if state.x is None else _as(state.x, dtype, "initial_state.x", (3,)),
        None if state.v is None else _as(state.v, dtype, "initial_state.v", (3,)),
    )
    return state, ts, rtol, atol


def problems(formulation, scene, state: State, ts, rtol, atol) -> list[tuple[jax.Array, str]]:
    """``[(bad, message), ...]``: value checks of the inputs, in the order reported."""
    eps = jnp.finfo(rtol.dtype).eps
    name = jnp.dtype(rtol.dtype).name
    finite = lambda a: jnp.all(jnp.isfinite(a))  # noqa: E731
    n2 = jnp.sum(state.q * state.q)
    out = [
        (~jnp.isfinite(rtol) | (rtol <= 0), "rtol must be finite and > 0"),
        (
            rtol < 10 * eps,
            f"rtol is below 10 machine epsilons ({10 * float(eps):.3g}) of {name}: the error "
            "control cannot meet it; raise rtol (or enable float64)",
        ),
        (~jnp.isfinite(atol) | (atol < 0), "atol must be finite and >= 0"),
        (~finite(ts), "ts has non-finite entries"),
        (jnp.any(jnp.diff(ts) <= 0), "ts must be strictly increasing"),
        (~finite(state.q), "initial_state.q has non-finite entries (NaN or inf)"),
        (
            n2 <= jnp.finfo(rtol.dtype).tiny,
            "initial_state.q is the zero quaternion: it represents no rotation",
        ),
        (~finite(state.qdot), "initial_state.qdot is not finite (NaN or inf)"),
    ]
    if state.x is not None:
        out.append((~(finite(state.x) & finite(state.v)), "initial_state.x or .v is not finite"))
    domain = formulation.domain_error(scene, _normalised(state))
    if domain is not None:
        out.append(domain)
    return out


def _normalised(state: State) -> State:
    n = jnp.sqrt(jnp.sum(state.q * state.q))
    n = jnp.where(n > 0, n, 1.0)
    return State(state.q / n, state.qdot / n, state.x, state.v)


@eqx.filter_jit
def _flags(formulation, scene, state, ts, rtol, atol):
    return jnp.stack([bad for bad, _ in problems(formulation, scene, state, ts, rtol, atol)])


def validate(formulation, scene, state, ts, rtol, atol) -> None:
    """Raise ``ValueError`` for the first failed value check (concrete inputs only)."""
    if is_traced((scene, state, ts, rtol, atol)):
        return
    flags = jax.device_get(_flags(formulation, scene, state, ts, rtol, atol))
    if flags.any():
        first = int(flags.argmax())
        message = problems(formulation, scene, state, ts, rtol, atol)[first][1]
        if first < 3:  # the tolerance checks
            message += f" (got rtol={float(rtol):.3g}, atol={float(atol):.3g})"
        raise ValueError(message)


def _guard(tree, checks: list[tuple[jax.Array, str]]):
    """One ``equinox.branched_error_if`` for a list of ``(bad, message)`` checks."""
    bad = jnp.stack([b for b, _ in checks])
    return eqx.branched_error_if(tree, jnp.any(bad), jnp.argmax(bad), [m for _, m in checks])


# --------------------------------------------------------------------------- solve


def _all_finite(tree) -> jax.Array:
    leaves = jax.tree_util.tree_leaves(tree)
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(a)) for a in leaves]))


def _classify(sol_result, formulation, scene, y_end, t_end, ys, span):
    """Map diffrax's result to a :class:`Result` code.

    A collapsed step size is blamed on non-finite values if the vector field is
    non-finite at the last accepted state or at probes a little beyond it (rejected
    trial steps are not kept, so their NaNs are not otherwise visible).
    """
    R = diffrax.RESULTS
    f_end = formulation.vector_field(t_end, y_end, scene)
    finite = _all_finite(y_end) & _all_finite(f_end)
    for frac in (1e-12, 1e-8, 1e-4):
        d = frac * span
        y_probe = jax.tree_util.tree_map(lambda y, f, d=d: y + d * f, y_end, f_end)
        finite = finite & _all_finite(formulation.vector_field(t_end + d, y_probe, scene))
    code = jnp.where(sol_result == R.max_steps_reached, Result.max_steps, Result.solver_failure)
    code = jnp.where(
        sol_result == R.dt_min_reached,
        jnp.where(finite, Result.step_size_collapse, Result.nonfinite),
        code,
    )
    code = jnp.where(sol_result == R.event_occurred, Result.gimbal_lock, code)
    ok = jnp.where(_all_finite(ys), Result.success, Result.nonfinite)
    return jnp.where(sol_result == R.successful, ok, code).astype(jnp.int32)


@eqx.filter_jit
def _solve(scene, state, ts, rtol, atol, dt0, formulation, solver, adjoint, max_steps, project,
           dense):
    state, ts = _guard((state, ts), problems(formulation, scene, state, ts, rtol, atol))
    scene = eqx.tree_at(lambda s: s.body, scene, scene.body.check())
    y0 = formulation.from_state(scene, _normalised(state))
    if project:
        solver = ProjectedSolver(solver, formulation)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(formulation.vector_field),
        solver,
        ts[0],
        ts[-1],
        dt0,
        y0,
        args=scene,
        saveat=diffrax.SaveAt(ts=ts, t1=True, dense=dense),
        stepsize_controller=controller(ts, rtol, atol),
        adjoint=adjoint,
        event=formulation.event(),
        max_steps=max_steps,
        throw=False,
    )
    return finish(scene, formulation, ts, sol.ts, sol.ys, sol.result, sol.stats,
                  sol.interpolation)


def controller(ts, rtol, atol, norm=None) -> diffrax.PIDController:
    """The PID step-size controller of every jrigid solve (``norm``: diffrax's default RMS).

    ``dtmin`` is ``4 eps max(|t0|, |t1|)`` without forcing: a smaller step ends the solve
    with ``dt_min_reached`` (:attr:`Result.step_size_collapse` or ``nonfinite``).
    """
    eps = jnp.finfo(ts.dtype).eps
    extra = {} if norm is None else {"norm": norm}
    return diffrax.PIDController(
        rtol=rtol,
        atol=atol,
        dtmin=4 * eps * jnp.maximum(jnp.abs(ts[0]), jnp.abs(ts[-1])),
        force_dtmin=False,
        **extra,
    )


def finish(scene, formulation, ts, saved_ts, saved_ys, sol_result, sol_stats,
           interpolation=None):
    """One member's :class:`~jrigid.trajectory.Trajectory` from a diffrax solution.

    Args:
        saved_ts: ``(T + 1,)`` ``sol.ts`` of ``SaveAt(ts=ts, t1=True)``.
        saved_ys: ``sol.ys``, leading axis ``T + 1``.
        sol_result, sol_stats: ``sol.result`` and ``sol.stats`` (the step counts are kept).
    """
    stats = {k: sol_stats[k] for k in ("num_steps", "num_accepted_steps", "num_rejected_steps")}
    # diffrax writes the final state into the first unfilled slot: on failure that is
    # not the last one. Keep only slots saved at their requested time; NaN elsewhere.
    valid = saved_ts[:-1] == ts
    t_end = jnp.max(jnp.where(jnp.isfinite(saved_ts), saved_ts, -jnp.inf))
    i_end = jnp.argmax(saved_ts == t_end)
    y_end = jax.tree_util.tree_map(lambda a: a[i_end], saved_ys)

    def _mask(a):
        keep = valid.reshape(valid.shape + (1,) * (a.ndim - 1))
        return jnp.where(keep, a[:-1], jnp.nan)

    ys = jax.tree_util.tree_map(_mask, saved_ys)
    result = _classify(sol_result, formulation, scene, y_end, t_end, ys, ts[-1] - ts[0])
    return Trajectory.build(
        scene,
        formulation,
        ts,
        ys,
        stats=stats,
        result=result,
        t_stop=t_end,
        interpolation=interpolation,
    )

# --------------------------------------------------------------------------- exact


def check_exact_scene(scene: Scene) -> None:
    """Raise ``ValueError`` unless ``scene`` is torque free, as ``solver="exact"`` needs.

    Allowed: a :class:`~jrigid.scene.FreeRotation` or :class:`~jrigid.scene.FreeFlight`
    holder whose loads are only :class:`~jrigid.scene.Gravity` (no torque about the
    centre of mass; in free flight the centre of mass follows a parabola).
    """
    names = ", ".join(type(load).__name__ for load in scene.loads)
    holder = type(scene.holder).__name__
    if not isinstance(scene.holder, (FreeRotation, FreeFlight)):
        if names:
            what = f"needs a torque-free scene; this scene has a {holder} with {names}"
        else:
            what = (
                "solves rotation about the centre of mass (FreeRotation or FreeFlight); "
                f"this scene has a {holder} holder"
            )
        raise ValueError(f"solver='exact' {what}: use a diffrax solver")
    others = [type(load).__name__ for load in scene.loads if not isinstance(load, Gravity)]
    if others:
        raise ValueError(
            "solver='exact' needs a torque-free scene; this scene has a "
            f"{holder} with {', '.join(others)} load(s): use a diffrax solver"
        )


class ExactMotion(eqx.Module):
    """Closed-form motion of a torque-free scene as a dense output (``evaluate(t)``).

    ``evaluate(t)`` returns the formulation's state at time ``t``: ``q, ω`` from
    :func:`jrigid.exact.evaluate` and, in free flight, ``x = x0 + v0 Δt + ½ g Δt²``,
    ``v = v0 + g Δt`` with ``Δt = t − t0`` and ``g`` the sum of the scene's gravity fields.
    """

    consts: exact.ExactConstants
    t0: jax.Array
    x0: jax.Array | None
    v0: jax.Array | None
    scene: Scene
    formulation: AbstractFormulation = eqx.field(static=True)

    def evaluate(self, t):
        dt = t - self.t0
        q, omega = exact.evaluate(self.consts, dt)
        x = v = None
        if self.scene.translates:
            g = jnp.zeros(3, dtype=dt.dtype)
            for load in self.scene.loads:
                g = g + load.g
            x = self.x0 + dt * self.v0 + (0.5 * dt * dt) * g
            v = self.v0 + dt * g
        state = State(q, quat.derivative(q, omega), x, v)
        return self.formulation.from_state(self.scene, state)


@eqx.filter_jit
def _solve_exact(scene, state, ts, rtol, atol, formulation, dense):
    state, ts = _guard((state, ts), problems(formulation, scene, state, ts, rtol, atol))
    scene = eqx.tree_at(lambda s: s.body, scene, scene.body.check())
    state = _normalised(state)
    consts = exact.prepare(scene.body.moments, state.q, state.omega)
    motion = ExactMotion(consts, ts[0], state.x, state.v, scene, formulation)
    ys = jax.vmap(motion.evaluate)(ts)
    result = jnp.where(_all_finite(ys), Result.success, Result.nonfinite).astype(jnp.int32)
    zero = jnp.zeros((), jnp.int32)
    stats = dict(num_steps=zero, num_accepted_steps=zero, num_rejected_steps=zero)
    return Trajectory.build(
        scene,
        formulation,
        ts,
        ys,
        stats=stats,
        result=result,
        t_stop=ts[-1],
        interpolation=motion if dense else None,
    )


def simulate(
    scene: Scene,
    initial_state: State,
    ts: ArrayLike,
    *,
    formulation: str | AbstractFormulation = "quaternion_acceleration",
    solver: diffrax.AbstractSolver | str | None = None,
    rtol: ArrayLike | None = None,
    atol: ArrayLike | None = None,
    max_steps: int = 100_000,
    dt0: ArrayLike | None = None,
    adjoint: diffrax.AbstractAdjoint | None = None,
    project: bool = True,
    dense: bool = False,
    throw: bool = True,
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
        solver: any diffrax solver; default ``diffrax.Tsit5()``. Or ``"exact"``: the
            closed-form solution (:mod:`jrigid.exact`) for torque-free scenes only
            (:func:`check_exact_scene`); then ``rtol``, ``atol``, ``max_steps``, ``dt0``,
            ``adjoint`` and ``project`` are ignored, ``stats`` are zero, and
            ``dense=True`` keeps the closed form for :meth:`Trajectory.at`.
        rtol, atol: PID tolerances, traced (changing them does not recompile). Defaults
            ``1e-8`` and ``1e-10`` (float64), ``1e-5`` and ``1e-7`` (float32).
            ``rtol`` must be finite, ``> 0`` and at least ``10 eps``.
        max_steps: static step budget (accepted plus rejected steps).
        dt0: initial step; ``None`` lets diffrax choose.
        adjoint: diffrax adjoint; default ``diffrax.RecursiveCheckpointAdjoint()``.
        project: wrap the solver in :class:`ProjectedSolver` (quaternion formulations).
        dense: keep the dense interpolation for :meth:`Trajectory.at`.
        throw: raise on failure (see the module docstring); ``False`` returns the
            :class:`Result` code in ``Trajectory.result``.

    Returns:
        :class:`~jrigid.trajectory.Trajectory`; ``stats`` holds step counts.

    Raises:
        ValueError: bad input (non-physical inertia, zero quaternion, NaN state,
            impossible tolerances, a scene the formulation cannot represent,
            ``solver="exact"`` for a scene with a torque, ...).
        SimulationError: a failed integration, when ``throw`` and values are concrete.
    """
    formulation = get_formulation(formulation)
    if isinstance(scene, Scene) and any(load.impulsive for load in scene.loads):
        raise ValueError("a scene with a Floor bounces: use jrigid.contact.simulate_bounces")
    if isinstance(solver, str):
        if solver != "exact":
            raise ValueError(f"solver must be a diffrax solver or 'exact', got {solver!r}")
        state, ts, rtol, atol = prepare(
            scene, initial_state, ts, None, None, jnp.result_type(float)
        )
        check_exact_scene(scene)
        formulation.check_scene(scene)
        validate(formulation, scene, state, ts, rtol, atol)
        traj = _solve_exact(scene, state, ts, rtol, atol, formulation, bool(dense))
        return _raise_on_failure(traj, throw, ts, rtol, atol, max_steps)
    solver, adjoint, dt0 = solver_options(solver, adjoint, max_steps, dt0)
    state, ts, rtol, atol = prepare(scene, initial_state, ts, rtol, atol, jnp.result_type(float))
    formulation.check_scene(scene)
    validate(formulation, scene, state, ts, rtol, atol)
    project = bool(project) and formulation.carries_quaternion
    traj = _solve(
        scene, state, ts, rtol, atol, dt0,
        formulation, solver, adjoint, max_steps, project, bool(dense),
    )
    return _raise_on_failure(traj, throw, ts, rtol, atol, max_steps)


def solver_options(solver, adjoint, max_steps, dt0):
    """Defaults and checks of the numerical solve's options: ``(solver, adjoint, dt0)``.

    ``solver`` defaults to ``diffrax.Tsit5()``, ``adjoint`` to
    ``diffrax.RecursiveCheckpointAdjoint()``; ``ValueError`` for a non-diffrax solver, a
    ``max_steps`` that is not a positive int, or a concrete ``dt0`` that is not finite and
    positive.
    """
    solver = diffrax.Tsit5() if solver is None else solver
    if not isinstance(solver, diffrax.AbstractSolver):
        raise ValueError(f"solver must be a diffrax solver, got {solver!r}")
    adjoint = diffrax.RecursiveCheckpointAdjoint() if adjoint is None else adjoint
    if not isinstance(max_steps, int) or max_steps < 1:
        raise ValueError(f"max_steps must be a positive int, got {max_steps!r}")
    if dt0 is not None:
        dt0 = jnp.asarray(dt0, dtype=jnp.result_type(float))
        if not is_traced(dt0) and not bool(jnp.isfinite(dt0) & (dt0 > 0)):
            raise ValueError(f"dt0 must be finite and > 0, got {dt0}")
    return solver, adjoint, dt0


def _raise_on_failure(traj, throw, ts, rtol, atol, max_steps):
    """Apply ``throw`` (see :func:`simulate`) to a solved trajectory."""
    if not throw:
        return traj
    if is_traced(traj.result):
        messages = [""] + [_traced_message(Result(k), max_steps) for k in range(1, len(Result))]
        codes = traj.result.reshape(-1)  # one code, or a batch's (first failure reported)
        first = codes[jnp.argmax(codes != 0)]
        return eqx.branched_error_if(traj, jnp.any(codes != 0), first, messages)
    codes = jax.device_get(traj.result)
    which = ""
    if codes.ndim:  # a batch (jrigid.ensemble.simulate_lockstep): report its first failure
        failed = codes.reshape(-1) != 0
        if not failed.any():
            return traj
        k = int(failed.argmax())
        which = f"member {k} of {failed.size} ({int(failed.sum())} failed) "
        traj = jax.tree_util.tree_map(lambda a: a.reshape(-1, *a.shape[codes.ndim:])[k], traj)
    code = Result(int(traj.result))
    if code != Result.success:
        cause, remedy = _CAUSE[code]
        raise SimulationError(
            f"jrigid.simulate failed {which}at t={float(traj.t_stop):.6g} "
            f"(integrating {float(ts[0]):.6g} → {float(ts[-1]):.6g}, "
            f"{int(traj.stats['num_accepted_steps'])} accepted and "
            f"{int(traj.stats['num_rejected_steps'])} rejected steps, "
            f"rtol={float(rtol):.3g}, atol={float(atol):.3g}): "
            f"{cause.format(max_steps=max_steps)}; remedy: {remedy}."
        )
    return traj
