"""The shared solve kit: what every jrigid integrator does before and after its loop.

:func:`jrigid.simulate`, :func:`jrigid.ensemble.simulate_lockstep`, the leapfrog and
the contact solver all

1. convert and shape-check their inputs (:func:`prepare`, raises ``ValueError`` before
   anything is compiled);
2. check their values (:func:`input_checks`: a list of ``(bad, message)`` pairs that
   are traced, so the same checks run inside ``jit``/``vmap``): either up front
   (:func:`validate`), as a runtime error (:func:`guard`), or as a per-member
   :attr:`~jrigid.trajectory.Result.invalid_input` code with benign stand-in inputs
   (:func:`screen`), so that one bad member of a sweep does not stop the others;
   in float32, warn (:class:`PrecisionWarning`, :func:`warn_precision`) when the horizon
   is too long for the tolerance;
3. step with diffrax under :func:`controller` (a PID controller), the solver wrapped in
   :class:`ProjectedSolver` for formulations that carry a quaternion (back onto
   ``|q| = 1`` and onto the scene's invariants after each step);
4. turn diffrax's outcome into a :class:`~jrigid.trajectory.Result` code
   (:func:`classify`) and a :class:`~jrigid.trajectory.Trajectory` (:func:`finish`),
   and raise or not (:func:`raise_on_failure`).
"""

from __future__ import annotations

import functools
import warnings

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jrigid import quaternion as quat
from jrigid._checks import is_traced
from jrigid.formulations import AbstractFormulation
from jrigid.invariants import Invariants
from jrigid.scene import Scene
from jrigid.solvers import FusedTsit5
from jrigid.state import State
from jrigid.trajectory import CAUSES, Result, SimulationError, Trajectory

__all__ = [
    "DEFAULT_SOLVER",
    "PrecisionWarning",
    "ProjectedSolver",
    "classify",
    "controller",
    "default_tolerances",
    "finish",
    "finish_sampled",
    "guard",
    "input_checks",
    "normalised",
    "precision_problem",
    "prepare",
    "raise_on_failure",
    "screen",
    "solver_options",
    "validate",
    "warn_precision",
]


#: The solver of :func:`jrigid.simulate` and the other integrators when none is given
#: (a class, instantiated per call).
DEFAULT_SOLVER = FusedTsit5

# --------------------------------------------------------------------------- projection


class ProjectedSolver(diffrax.AbstractWrappedSolver):
    """Wrap a diffrax solver; project every step's result back onto the constraints.

    ``step`` calls the inner solver, then replaces ``y1`` by
    ``formulation.project(y1, args, invariants)``: ``q ← q/|q|`` (and for
    ``quaternion_acceleration`` ``q̇ ← ½ q ⊗ (0, ω)``, which keeps ``q·q̇ = 0``), and,
    when ``invariants`` is given, the smallest change of ``(q, ω)`` that restores the
    scene's conserved quantities (:func:`jrigid.invariants.project`). The error estimate
    is the inner solver's, so step control is unchanged. A first-same-as-last solver
    reuses its last stage, evaluated before projection, in the next step: the mismatch
    is of the size of the projection (the local error), so the order is unaffected.

    Attributes:
        solver: the wrapped diffrax solver (any; ``isinstance`` checks see through it).
        formulation: the formulation whose
            :meth:`~jrigid.formulations.AbstractFormulation.project` is applied.
        invariants: the values to restore (:class:`~jrigid.invariants.Invariants`), or
            ``None`` for the constraint manifold only.
    """

    solver: diffrax.AbstractSolver
    formulation: AbstractFormulation = eqx.field(static=True)
    invariants: Invariants | None = None

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
        y1 = self.formulation.project(y1, args, self.invariants)
        if isinstance(dense_info, dict) and "y1" in dense_info:
            dense_info = dict(dense_info, y1=y1)
        return y1, y_error, dense_info, solver_state, result

    def func(self, terms, t0, y0, args):
        return self.solver.func(terms, t0, y0, args)

    def save(self, t, y, args):
        """``SaveAt`` function: project an interpolated output the same way."""
        return self.formulation.project(y, args, self.invariants)


# --------------------------------------------------------------------------- inputs


def default_tolerances(dtype) -> tuple[float, float]:
    """``(rtol, atol)`` defaults: ``(1e-8, 1e-10)`` in float64, ``(1e-5, 1e-7)`` in float32."""
    if jnp.dtype(dtype).itemsize >= 8:
        return 1e-8, 1e-10
    return 1e-5, 1e-7


@functools.cache
def _default_array(dtype, which: int) -> np.ndarray:
    """The default ``rtol`` (0) or ``atol`` (1) of ``dtype`` (a NumPy scalar array: a
    literal when traced, never a captured device array)."""
    return np.asarray(default_tolerances(dtype)[which], dtype=dtype)


def _as(x, dtype, name: str, shape: tuple[int, ...]) -> jax.Array:
    if not (isinstance(x, jax.Array) and x.dtype == dtype):  # fast path: already converted
        x = jnp.asarray(x, dtype=dtype)
    if x.shape != shape:
        raise ValueError(
            f"{name} must have shape {shape}, got {x.shape} (use jax.vmap for batches)"
        )
    return x


def prepare(scene: Scene, state: State, ts, rtol, atol, dtype):
    """Static checks (types, shapes) and dtype conversion of a solve's inputs.

    Args:
        scene: the :class:`~jrigid.scene.Scene`.
        state: one :class:`~jrigid.state.State` (``q (4,)``, ``qdot (4,)``, ``x, v (3,)``
            in free flight).
        ts: ``(T,)`` output times, ``T ≥ 2``.
        rtol, atol: scalars or ``None`` (:func:`default_tolerances`).
        dtype: the floating dtype everything is converted to.

    Returns:
        ``(state, ts, rtol, atol)`` as arrays of ``dtype``.

    Raises:
        ValueError: a wrong type, shape or holder/state mismatch (values are checked by
            :func:`input_checks`).
    """
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
    if not (isinstance(ts, jax.Array) and ts.dtype == dtype):
        ts = jnp.asarray(ts, dtype=dtype)
    if ts.ndim != 1 or ts.shape[0] < 2:
        raise ValueError(f"ts must be a 1-D array of at least 2 times, got shape {ts.shape}")
    rtol = _default_array(dtype, 0) if rtol is None else _as(rtol, dtype, "rtol", ())
    atol = _default_array(dtype, 1) if atol is None else _as(atol, dtype, "atol", ())
    fields = (
        _as(state.q, dtype, "initial_state.q", (4,)),
        _as(state.qdot, dtype, "initial_state.qdot", (4,)),
        None if state.x is None else _as(state.x, dtype, "initial_state.x", (3,)),
        None if state.v is None else _as(state.v, dtype, "initial_state.v", (3,)),
    )
    if any(new is not old for new, old in zip(fields, (state.q, state.qdot, state.x, state.v),
                                              strict=True)):
        state = State(*fields)
    return state, ts, rtol, atol


#: Indices of the tolerance checks in :func:`input_checks` (their messages get the values).
TOLERANCE_CHECKS = (0, 1, 2)


def input_checks(formulation, scene, state: State, ts, rtol, atol) -> list[tuple[jax.Array, str]]:
    """``[(bad, message), ...]``: every value check of a solve's inputs, in report order.

    The ``bad`` flags are ``()`` boolean arrays (traced under ``jit``/``vmap``): the
    tolerances, the output times, the initial state (finite, a nonzero quaternion), the
    body (:meth:`jrigid.body.RigidBody.problems`) and the formulation's domain (e.g.
    gimbal lock of Euler angles).
    """
    eps = jnp.finfo(rtol.dtype).eps
    name = jnp.dtype(rtol.dtype).name
    finite = lambda a: jnp.all(jnp.isfinite(a))  # noqa: E731
    n = quat.norm(state.q)  # scale-safe: |q| = 1e-300 or 1e300 is a valid orientation
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
            ~(n > 0) & finite(state.q),
            "initial_state.q is the zero quaternion: it represents no rotation",
        ),
        (~finite(state.qdot), "initial_state.qdot is not finite (NaN or inf)"),
    ]
    if state.x is not None:
        out.append((~(finite(state.x) & finite(state.v)), "initial_state.x or .v is not finite"))
    out.extend(scene.body.problems())
    domain = formulation.domain_error(scene, normalised(state))
    if domain is not None:
        out.append(domain)
    return out


def normalised(state: State) -> State:
    """``state`` with ``q`` scaled to unit norm (``q̇`` by the same factor).

    Exact for any finite non-zero ``|q|`` (:func:`jrigid.quaternion.norm`), so an
    orientation given as ``1e300 q`` or ``1e-300 q`` integrates as ``q``.
    """
    n = quat.norm(state.q)
    n = jnp.where(n > 0, n, 1.0)
    return State(state.q / n, state.qdot / n, state.x, state.v)


@eqx.filter_jit
def _flags(formulation, scene, state, ts, rtol, atol):
    return jnp.stack([bad for bad, _ in input_checks(formulation, scene, state, ts, rtol, atol)])


def message(checks_or_messages, index: int, rtol=None, atol=None) -> str:
    """The message of check ``index``, with the tolerances' values for a tolerance check."""
    entry = checks_or_messages[index]
    text = entry[1] if isinstance(entry, tuple) else entry
    if index in TOLERANCE_CHECKS and rtol is not None:
        text += f" (got rtol={float(rtol):.3g}, atol={float(atol):.3g})"
    return text


class PrecisionWarning(UserWarning):
    """A solve runs in a floating-point precision that cannot meet its tolerance."""


def precision_problem(state: State, ts, rtol) -> str | None:
    """Why a float32 solve cannot meet ``rtol`` over ``ts``, or ``None``.

    In float32 the time itself is resolved only to ``|t| eps / 2`` (``eps = 1.2e-7``),
    so at the end of the horizon the orientation is uncertain by about
    ``|ω| max(|t0|, |t1|) eps`` radians whatever the step size (``ω`` the initial
    angular velocity, from ``q`` and ``q̇``); rounding in every step adds to that. When
    this floor exceeds ``rtol`` no float32 setting can give outputs as accurate as asked.
    (Below ``10 eps``, ``rtol`` itself is refused by :func:`input_checks`.) The floor is
    a bound, not a forecast: with the default invariant projection float32's error
    stayed within 2× of float64's at the same ``rtol`` over 10⁴ periods of a free rotor;
    without it, it was 6–100× larger (README, "What float32 can and cannot do").

    Only float32 inputs are examined (float64 returns ``None`` without any work), and
    only concrete ones: under ``jit``/``vmap`` there are no values to look at.

    Args:
        state: the initial :class:`~jrigid.state.State` (``q (4,)``, ``qdot (4,)``).
        ts: ``(T,)`` output times.
        rtol: ``()`` relative tolerance; its dtype is the solve's.

    Returns:
        The message, or ``None``.
    """
    dtype = jnp.dtype(rtol.dtype)
    if dtype.itemsize >= 8 or is_traced((state.q, state.qdot, ts, rtol)):
        return None
    q, qdot, ts, rtol = (
        np.asarray(a, np.float64) for a in jax.device_get((state.q, state.qdot, ts, rtol))
    )
    eps = float(jnp.finfo(dtype).eps)
    with np.errstate(all="ignore"):
        rate = 2.0 * np.linalg.norm(qdot) / np.linalg.norm(q)  # |ω| (|q ⊗ q̇| = |q| |q̇|)
    horizon = max(abs(ts[0]), abs(ts[-1]))
    floor = rate * horizon * eps
    if not (np.isfinite(floor) and floor > rtol) or rtol < 10 * eps:  # (else refused)
        return None
    return (
        f"{dtype.name} resolves times near t = {horizon:.4g} only to ±{horizon * eps / 2:.2g}: "
        f"at |ω| = {rate:.3g} the orientation there cannot be resolved to better than "
        f"~{floor:.2g} rad, coarser than rtol = {float(rtol):.3g} asks (rounding also "
        "accumulates over the steps, most where no invariants are projected); for accuracy "
        "beyond this floor enable float64 (jax.config.update('jax_enable_x64', True)) and "
        "tighten rtol, or shorten the horizon"
    )


def warn_precision(state: State, ts, rtol, stacklevel: int = 3) -> None:
    """Issue a :class:`PrecisionWarning` if :func:`precision_problem` finds one.

    ``stacklevel`` as in :func:`warnings.warn`, counted from the caller of this
    function (the default points at the caller's caller: the user's call of a solver).
    """
    text = precision_problem(state, ts, rtol)
    if text is not None:
        warnings.warn(text, PrecisionWarning, stacklevel=stacklevel)


def validate(formulation, scene, state, ts, rtol, atol) -> None:
    """Raise ``ValueError`` for the first failed value check (concrete inputs; else nothing)."""
    if is_traced((scene, state, ts, rtol, atol)):
        return
    flags = jax.device_get(_flags(formulation, scene, state, ts, rtol, atol))
    if flags.any():
        checks = input_checks(formulation, scene, state, ts, rtol, atol)
        raise ValueError(message(checks, int(flags.argmax()), rtol, atol))


def guard(tree, checks: list[tuple[jax.Array, str]]):
    """``tree``, with one ``equinox.branched_error_if`` over a list of ``(bad, message)``."""
    bad = jnp.stack([b for b, _ in checks])
    return eqx.branched_error_if(tree, jnp.any(bad), jnp.argmax(bad), [m for _, m in checks])


def screen(checks, scene: Scene, state: State, ts, rtol, atol):
    """Stand-in inputs for a member whose inputs fail a check (traced, ``vmap``-safe).

    Returns ``(invalid, cause, scene, state, ts, rtol, atol)``: ``invalid ()`` bool,
    ``cause ()`` the index of the first failed check, and the inputs with every array
    of an invalid member replaced by a benign one (a unit sphere at rest, the identity
    orientation, ``ts`` spread evenly over ``[0, 1]``, the default tolerances), so that
    its solve is quick and finite; its outputs are then set to NaN and its result to
    :attr:`~jrigid.trajectory.Result.invalid_input` by :func:`finish`.
    """
    bad = jnp.stack([b for b, _ in checks])
    invalid = jnp.any(bad)
    cause = jnp.argmax(bad).astype(jnp.int32)
    dtype = rtol.dtype
    pick = lambda good, a: jnp.where(invalid, jnp.asarray(good, a.dtype), a)  # noqa: E731
    body = scene.body
    body = eqx.tree_at(
        lambda b: (b.moments, b.mass, b.com, b.frame),
        body,
        (
            pick(jnp.ones(3), body.moments),
            pick(1.0, body.mass),
            pick(jnp.zeros(3), body.com),
            pick(jnp.array([1.0, 0.0, 0.0, 0.0]), body.frame),
        ),
    )
    scene = eqx.tree_at(lambda s: s.body, scene, body)
    identity = jnp.array([1.0, 0.0, 0.0, 0.0], dtype)
    state = State(
        pick(identity, state.q),
        pick(jnp.zeros(4), state.qdot),
        None if state.x is None else pick(jnp.zeros(3), state.x),
        None if state.v is None else pick(jnp.zeros(3), state.v),
    )
    ts = pick(jnp.linspace(0.0, 1.0, ts.shape[0], dtype=dtype), ts)
    default_rtol, default_atol = default_tolerances(dtype)
    return invalid, cause, scene, state, ts, pick(default_rtol, rtol), pick(default_atol, atol)


# --------------------------------------------------------------------------- solve


@functools.cache
def _instance(cls):
    """One shared default instance of an option class (modules are immutable)."""
    return cls()


def solver_options(solver, adjoint, max_steps, dt0, default=None):
    """Defaults and checks of a numerical solve's options: ``(solver, adjoint, dt0, max_steps)``.

    ``solver`` defaults to ``default()`` (:data:`DEFAULT_SOLVER`), ``adjoint`` to
    ``diffrax.RecursiveCheckpointAdjoint()``; ``ValueError`` for a non-diffrax solver, a
    ``max_steps`` that is not a positive int (``bool`` is refused, NumPy integers are
    accepted, and returned as a Python ``int``: diffrax needs it static) or a concrete
    ``dt0`` that is not finite and positive.
    """
    if solver is None:
        solver = _instance(DEFAULT_SOLVER if default is None else default)
    if not isinstance(solver, diffrax.AbstractSolver):
        raise ValueError(f"solver must be a diffrax solver, got {solver!r}")
    adjoint = _instance(diffrax.RecursiveCheckpointAdjoint) if adjoint is None else adjoint
    if not isinstance(adjoint, diffrax.AbstractAdjoint):
        raise ValueError(f"adjoint must be a diffrax adjoint, got {adjoint!r}")
    if (
        isinstance(max_steps, bool)
        or not isinstance(max_steps, (int, np.integer))
        or max_steps < 1
    ):
        raise ValueError(f"max_steps must be a positive int, got {max_steps!r}")
    if dt0 is not None:
        dt0 = jnp.asarray(dt0, dtype=jnp.result_type(float))
        if dt0.shape != ():
            raise ValueError(f"dt0 must be a scalar, got shape {dt0.shape}")
        if not is_traced(dt0) and not bool(jnp.isfinite(dt0) & (dt0 > 0)):
            raise ValueError(f"dt0 must be finite and > 0, got {dt0}")
    return solver, adjoint, dt0, int(max_steps)


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


def _all_finite(tree) -> jax.Array:
    leaves = jax.tree_util.tree_leaves(tree)
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(a)) for a in leaves]))


def classify(sol_result, formulation, scene, y_end, t_end, ys, span, user_event=False):
    """Map diffrax's result to a :class:`~jrigid.trajectory.Result` code (``()`` int32).

    A collapsed step size is blamed on non-finite values if the vector field is
    non-finite at the last accepted state or at probes a little beyond it (rejected
    trial steps are not kept, so their NaNs are not otherwise visible). An event is
    :attr:`~jrigid.trajectory.Result.gimbal_lock` for a formulation's own event and
    :attr:`~jrigid.trajectory.Result.event` when the user passed one (``user_event``).
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
    event_code = Result.event if user_event else Result.gimbal_lock
    code = jnp.where(sol_result == R.event_occurred, event_code, code)
    ok = jnp.where(_all_finite(ys), Result.success, Result.nonfinite)
    return jnp.where(sol_result == R.successful, ok, code).astype(jnp.int32)


def finish(scene, formulation, ts, saved_ts, saved_ys, sol_result, sol_stats,
           interpolation=None, invalid=None, user_event=False):
    """One member's :class:`~jrigid.trajectory.Trajectory` from a diffrax solution.

    Args:
        scene, formulation: as solved.
        ts: ``(T,)`` the requested output times.
        saved_ts: ``(T + 1,)`` ``sol.ts`` of ``SaveAt(ts=ts, t1=True)``.
        saved_ys: ``sol.ys``, leading axis ``T + 1``.
        sol_result, sol_stats: ``sol.result`` and ``sol.stats`` (the step counts are kept).
        interpolation: ``sol.interpolation`` or ``None``.
        invalid: ``()`` bool from :func:`screen`, or ``None``: an invalid member's
            outputs are NaN and its code :attr:`~jrigid.trajectory.Result.invalid_input`.
        user_event: whether an event of the user's may have stopped the solve.
    """
    stats = {k: sol_stats[k] for k in ("num_steps", "num_accepted_steps", "num_rejected_steps")}
    # diffrax writes the final state into the first unfilled slot: on failure that is
    # not the last one. Keep only slots saved at their requested time; NaN elsewhere.
    valid = saved_ts[:-1] == ts
    if invalid is not None:
        valid = valid & ~invalid
    t_end = jnp.max(jnp.where(jnp.isfinite(saved_ts), saved_ts, -jnp.inf))
    i_end = jnp.argmax(saved_ts == t_end)
    y_end = jax.tree_util.tree_map(lambda a: a[i_end], saved_ys)

    def _mask(a):
        keep = valid.reshape(valid.shape + (1,) * (a.ndim - 1))
        return jnp.where(keep, a[:-1], jnp.nan)

    ys = jax.tree_util.tree_map(_mask, saved_ys)
    result = classify(sol_result, formulation, scene, y_end, t_end, ys, ts[-1] - ts[0],
                      user_event)
    if invalid is not None:
        result = jnp.where(invalid, jnp.int32(Result.invalid_input), result)
        t_end = jnp.where(invalid, ts[0], t_end)
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


def finish_sampled(scene, formulation, ts, ys, invalid=None, interpolation=None, steps=None):
    """A :class:`~jrigid.trajectory.Trajectory` of states computed directly at ``ts``.

    For solvers without diffrax's loop (the closed forms, fixed-step integrators):
    the result is ``success`` if every output is finite, else ``nonfinite``; an
    ``invalid`` member (:func:`screen`) gets NaN outputs and ``invalid_input``.

    Args:
        ys: the formulation's states at ``ts`` (leading axis ``T``).
        invalid: ``()`` bool or ``None``.
        interpolation: a dense output (``evaluate(t)``) or ``None``.
        steps: ``()`` int32 step count (zero for a closed form).
    """
    if invalid is not None:
        ys = jax.tree_util.tree_map(lambda a: jnp.where(invalid, jnp.nan, a), ys)
    result = jnp.where(_all_finite(ys), Result.success, Result.nonfinite).astype(jnp.int32)
    t_stop = ts[-1]
    if invalid is not None:
        result = jnp.where(invalid, jnp.int32(Result.invalid_input), result)
        t_stop = jnp.where(invalid, ts[0], t_stop)
    steps = jnp.zeros((), jnp.int32) if steps is None else steps
    stats = dict(num_steps=steps, num_accepted_steps=steps,
                 num_rejected_steps=jnp.zeros((), jnp.int32))
    return Trajectory.build(scene, formulation, ts, ys, stats=stats, result=result,
                            t_stop=t_stop, interpolation=interpolation)


def raise_on_failure(traj: Trajectory, throw: bool, ts, rtol, atol, max_steps: int,
                     messages=None, cause=None):
    """Apply ``throw`` (see :func:`jrigid.simulate`) to a solved trajectory.

    Concrete results: ``ValueError`` for an invalid input (``messages[cause]``),
    :class:`~jrigid.trajectory.SimulationError` for a failed integration (for a batch:
    its first failed member, with the count). Traced results: one
    ``equinox.branched_error_if`` whose message is the cause first, then the remedy.
    ``throw=False`` returns ``traj`` as it is.
    """
    if not throw:
        return traj
    if is_traced(traj.result):
        texts = [""] * len(Result)
        for k, cause_text, remedy in ((k, *CAUSES[k]) for k in Result if k.failed):
            texts[k] = (
                f"jrigid.simulate failed: {cause_text.format(max_steps=max_steps)}; "
                f"{remedy}. (Under vmap, pass throw=False for per-member result codes.)"
            )
        if messages is not None and cause is not None:
            # An invalid input names its check (the first invalid member's under vmap).
            codes = traj.result.reshape(-1)
            bad_input = jnp.any(codes == Result.invalid_input)
            first_cause = jnp.reshape(cause, (-1,))[jnp.argmax(codes == Result.invalid_input)]
            traj = eqx.branched_error_if(
                traj, bad_input, first_cause, [f"jrigid.simulate: {m}" for m in messages]
            )
        codes = traj.result.reshape(-1)
        is_failure = (codes != Result.success) & (codes != Result.event)
        first = codes[jnp.argmax(is_failure)]
        return eqx.branched_error_if(traj, jnp.any(is_failure), first, texts)
    codes = np.asarray(traj.result)
    failed = (codes != Result.success) & (codes != Result.event)
    if not failed.any():
        return traj
    flat = failed.reshape(-1)
    k = int(flat.argmax())
    which = f"member {k} of {flat.size} ({int(flat.sum())} failed) " if codes.ndim else ""
    code = Result(int(codes.reshape(-1)[k]))
    if code == Result.invalid_input and messages is not None:
        index = int(np.asarray(cause).reshape(-1)[k])
        where = f" (member {k} of {flat.size})" if codes.ndim else ""
        raise ValueError(message(messages, index, rtol, atol) + where)
    member = traj
    if codes.ndim:
        member = jax.tree_util.tree_map(lambda a: a.reshape(-1, *a.shape[codes.ndim:])[k], traj)
    cause_text, remedy = CAUSES[code]
    raise SimulationError(
        f"jrigid.simulate failed {which}at t={float(member.t_stop):.6g} "
        f"(integrating {float(ts[0]):.6g} → {float(ts[-1]):.6g}, "
        f"{int(member.stats['num_accepted_steps'])} accepted and "
        f"{int(member.stats['num_rejected_steps'])} rejected steps, "
        f"rtol={float(rtol):.3g}, atol={float(atol):.3g}): "
        f"{cause_text.format(max_steps=max_steps)}; remedy: {remedy}."
    )
