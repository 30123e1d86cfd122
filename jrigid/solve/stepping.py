"""How a solve steps: the default solver and its options, the controller, the projection.

Every diffrax-based jrigid solve steps under :func:`controller` (a PI controller on the
error scaled vector by vector, :class:`VectorPIDController`), with
its solver wrapped in :class:`ProjectedSolver` for formulations that carry a quaternion
(back onto ``|q| = 1`` and onto the scene's invariants after each step, :func:`projected`),
and calls diffrax through :func:`run`.
"""

from __future__ import annotations

import functools

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jrigid._checks import all_finite, check_number, is_traced
from jrigid._folds import rms_norm
from jrigid.formulations import AbstractFormulation
from jrigid.invariants import Invariants
from jrigid.solve.flat import Flat, vector_lengths
from jrigid.solvers import TightDop853

__all__ = [
    "DEFAULT_SOLVER",
    "PI_COEFFICIENTS",
    "ProjectedSolver",
    "UnitTimeTerm",
    "VectorPIDController",
    "WrappedSolver",
    "check_dt0",
    "controller",
    "interpolating_at",
    "projected",
    "run",
    "saved_times",
    "solver_options",
    "traced_once",
    "unit_times",
]


#: The solver of :func:`jrigid.simulate` and the other integrators when none is given
#: (a class, instantiated per call): DOP853, its stages in one loop, its error
#: estimate scaled by 10 (:class:`jrigid.solvers.TightDop853`). Measured against the
#: Tsitouras 5(4) pair on the same form (``benchmarks/speed_vs_error.py``, free rotors
#: and a heavy top): 0.98–3.1× as fast at equal error from 1e-6 to 1e-10 (0.69–1.6× at
#: 1e-4), and more accurate per tolerance (final error 0.04–12·rtol against 0.2–70·rtol).
DEFAULT_SOLVER = TightDop853


def traced_once(method):
    """``method`` (of a solver or a controller) as an ``equinox.filter_jit`` function:
    traced once per input structure and then reused, and inlined into the program that
    calls it. diffrax traces the body of its loop three times (once for its shapes,
    twice in the loop itself); with the step and the step-size control traced once, the
    default solve of a heavy top traced in 0.66–0.69 s instead of 0.72–0.77 s (three
    fresh processes each). The compiled program, and so its speed, are unchanged."""
    return eqx.filter_jit(method)


class WrappedSolver(diffrax.AbstractWrappedSolver):
    """A diffrax solver wrapping another, forwarding everything to it: the base of
    jrigid's wrappers (:class:`ProjectedSolver`, :class:`~jrigid.solve.saving.SavingSolver`),
    which override what they change.

    Attributes:
        solver: the wrapped diffrax solver (``isinstance`` checks see through it).
    """

    solver: diffrax.AbstractSolver

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
        return self.solver.step(terms, t0, t1, y0, args, solver_state, made_jump)

    def func(self, terms, t0, y0, args):
        return self.solver.func(terms, t0, y0, args)


class ProjectedSolver(WrappedSolver):
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
        formulation: the formulation (or its flat form, :class:`~jrigid.solve.Flat`)
            whose :meth:`~jrigid.formulations.AbstractFormulation.project` is applied.
        invariants: the values to restore (:class:`~jrigid.invariants.Invariants`), or
            ``None`` for the constraint manifold only.
    """

    formulation: AbstractFormulation | Flat = eqx.field(static=True)
    invariants: Invariants | None = None

    @traced_once
    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        y1, y_error, dense_info, solver_state, result = self.solver.step(
            terms, t0, t1, y0, args, solver_state, made_jump
        )
        y1 = self.formulation.project(y1, args, self.invariants)
        if isinstance(dense_info, dict) and "y1" in dense_info:
            dense_info = dict(dense_info, y1=y1)
        return y1, y_error, dense_info, solver_state, result

    def outputs(self, ys, args, y0, keep_ends: bool = False):
        """The saved states ``ys`` (leading axis: the saved times) projected the same way.

        With ``keep_ends``, the first and last rows are returned as they are: in the
        layout of :func:`jrigid.solve.saving.saved` they are the initial state and the
        final step's result, both projected already (projecting them again moved the
        initial state by rounding, so that ``q[0]`` depended on the number of outputs).

        Outputs between steps are interpolated, so they are projected after the solve,
        one at a time in a loop. (As one batched (``vmap``) projection it ran faster,
        17 µs against 58 µs for 1001 outputs of a free rotor, but compiled 0.45 s longer
        — 2.2 s against 1.7 s — because XLA:CPU generates a vectorised loop for each of
        its operations. Projecting in diffrax's ``SaveAt`` function instead compiles the
        projection into the loop a second time.) Slots that are not finite (unfilled
        after a failure, or a diverged state) are returned unchanged; ``y0`` stands in
        for them inside the projection, so that its derivative stays finite. A batched
        formulation's slot counts as one: any non-finite member leaves it unprojected.
        """
        tree_map = jax.tree_util.tree_map

        def one(y):
            finite = all_finite(y)
            safe = tree_map(lambda a, b: jnp.where(finite, a, b), y, y0)
            done = self.formulation.project(safe, args, self.invariants)
            return tree_map(lambda a, b: jnp.where(finite, a, b), done, y)

        def body(i, ys):
            y = one(tree_map(lambda a: a[i], ys))
            return tree_map(lambda a, b: a.at[i].set(b), ys, y)

        n = jax.tree_util.tree_leaves(ys)[0].shape[0]
        start, stop = (1, n - 1) if keep_ends else (0, n)
        return jax.lax.fori_loop(start, stop, body, ys)


def interpolating_at(solver, ts):
    """``solver`` for a solve whose interpolation only saves at ``ts (T,)``: a
    :class:`~jrigid.solvers.TightDop853` then computes its dense output's stages only in
    steps that hold an output time (:meth:`~jrigid.solvers.TightDop853.at_outputs`);
    any other solver is returned as it is."""
    return solver.at_outputs(ts) if isinstance(solver, TightDop853) else solver


def projected(solver, formulation, invariants) -> ProjectedSolver:
    """``solver`` wrapped in :class:`ProjectedSolver`; project the saved states with
    :meth:`ProjectedSolver.outputs` after the solve.

    Args:
        solver: the diffrax solver to wrap.
        formulation: whose :meth:`~jrigid.formulations.AbstractFormulation.project` is
            applied after every step (and by ``outputs`` to the saved states).
        invariants: the values to restore, or ``None`` for the constraints only.
    """
    return ProjectedSolver(solver, formulation, invariants)


@functools.cache
def _instance(cls):
    """One shared default instance of an option class (modules are immutable)."""
    return cls()


# The adjoints a solve supports. BacksolveAdjoint differentiates the solver's step
# through its arguments, which the projected solver and the flat state do not allow
# (JAX failed with "Unexpected tangent" or a tracer conversion); ImplicitAdjoint is
# exact only at a steady state, which a rigid body's motion over ts is not.
_ADJOINTS = (diffrax.RecursiveCheckpointAdjoint, diffrax.DirectAdjoint, diffrax.ForwardMode)
_UNSUPPORTED = {
    "BacksolveAdjoint": "it solves the adjoint equation backwards through the solver's "
                        "step, which jrigid's projected solver and flat state do not allow; ",
    "ImplicitAdjoint": "its derivatives are those of a steady state, not of the motion "
                       "over ts; ",
}


def solver_options(solver, adjoint, max_steps, dt0, default=None):
    """Defaults and checks of a numerical solve's options: ``(solver, adjoint, dt0, max_steps)``.

    ``solver`` defaults to ``default()`` (:data:`DEFAULT_SOLVER`), ``adjoint`` to
    ``diffrax.RecursiveCheckpointAdjoint()``; ``ValueError`` for a non-diffrax solver, an
    adjoint other than the recursive-checkpoint, direct or forward-mode one, a
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
    if not isinstance(adjoint, _ADJOINTS):
        raise ValueError(
            f"adjoint={type(adjoint).__name__}() is not supported: "
            + _UNSUPPORTED.get(type(adjoint).__name__, "")
            + "use diffrax.RecursiveCheckpointAdjoint() (the default, reverse mode), "
            "diffrax.DirectAdjoint() or diffrax.ForwardMode() (forward mode)"
        )
    if (
        isinstance(max_steps, bool)
        or not isinstance(max_steps, (int, np.integer))
        or max_steps < 1
    ):
        raise ValueError(f"max_steps must be a positive int, got {max_steps!r}")
    return solver, adjoint, check_dt0(dt0), int(max_steps)


def check_dt0(dt0):
    """``dt0`` as a ``()`` float array (``None`` stays ``None``); ``ValueError`` if it is
    not a scalar, or concrete and not finite and positive."""
    if dt0 is None:
        return None
    dt0 = jnp.asarray(dt0, dtype=jnp.result_type(float))
    if dt0.shape != ():
        raise ValueError(f"dt0 must be a scalar, got shape {dt0.shape}")
    if not is_traced(dt0) and not bool(jnp.isfinite(dt0) & (dt0 > 0)):
        raise ValueError(f"dt0 must be finite and > 0, got {dt0}")
    return dt0


class VectorPIDController(diffrax.PIDController):
    """diffrax's PID controller, with each vector of the state measured against its own
    length rather than each entry against itself.

    diffrax scales the error of entry ``i`` by ``atol + rtol max(|y0ᵢ|, |y1ᵢ|)``. For a
    quaternion, ``q̇`` or ω that weighs an entry passing through zero (which any rotation
    does) with ``atol`` alone, so the accepted error jumps with the frame the body is
    seen in, and the step-size sequence with it. Here entry ``i`` is scaled by
    ``atol + rtol max(|v0|, |v1|)``, ``v`` the vector (leaf of the formulation's
    variables, :func:`~jrigid.solve.flat.vector_lengths`) it belongs to: a rotation of
    the frame leaves the scaled error unchanged, and so the steps. The starting step
    (when ``dt0`` is ``None``) is chosen as diffrax chooses it, on the same scale. Only
    the scale differs from diffrax's controller (its norm, coefficients and acceptance
    are used as they are).

    Attributes:
        layout: the :class:`~jrigid.solve.flat.Flat` layout of a flat state, or ``None``
            when the state is the formulation's own pytree (each leaf its vectors along
            the last axis).
        acceptance: ``c ≥ 1``, the scaled error below which a step is accepted
            (diffrax's: 1). The safety factor is lowered with it, to
            ``safety c^(−icoeff/k)`` (``k`` the solver's error order), so that the
            error at which the PI controller neither grows nor shrinks the step,
            ``safety^(k/icoeff)`` (0.06 at diffrax's safety 0.9, ``k = 8``), stays where
            it is: every step is chosen as with ``c = 1``, and a step that overshoots
            that error up to ``c / 0.06`` times is kept instead of redone.
        time_scale: ``T`` for a solve in unit time ``τ = (t − t0) / T`` (:func:`run` with
            ``unit_time=True``), ``None`` for a solve in ``t``. The starting step is
            then chosen in ``t`` (Hairer's rule depends on the unit of time), so that
            the steps are those of the solve in ``t`` (to the rounding of their error
            estimates: about 1e-7 of a step).
    """

    layout: Flat | None = eqx.field(static=True, default=None)
    acceptance: float = eqx.field(static=True, default=1.0)
    time_scale: jax.Array | None = None

    def __check_init__(self):
        check_number("acceptance", self.acceptance, 1)

    def _lengths(self, y):
        lengths = vector_lengths if self.layout is None else self.layout.lengths
        return jax.lax.stop_gradient(lengths(y))

    def init(self, terms, t0, t1, y0, dt0, args, func, error_order):
        if dt0 is None:
            dt0 = self._initial_step(terms, t0, y0, args, func, error_order)
        t_next, state = super().init(terms, t0, t1, y0, dt0, args, func, error_order)
        return t_next, (state, jnp.array(False))

    def nonfinite_trials(self, controller_state) -> jax.Array:
        """``()`` bool from this controller's final state (``diffrax.SaveAt(...,
        controller_state=True)``): whether a trial step since the last accepted one had a
        non-finite state or error estimate. A solve that ended with ``dt_min_reached``
        and this flag collapsed on non-finite values
        (:attr:`~jrigid.trajectory.Result.nonfinite`), otherwise on a step too small for
        its error (:attr:`~jrigid.trajectory.Result.step_size_collapse`).

        Raises:
            ValueError: ``controller_state`` is not this controller's (``None``: the solve
                did not save it).
        """
        return self._parts(controller_state)[1]

    @staticmethod
    def _parts(controller_state, size: int = 2):
        """``controller_state`` checked to be a tuple of ``size``, as this controller's
        states are (a pair; a :class:`~jrigid.solve.saving.SavingController`'s three)."""
        if not (isinstance(controller_state, tuple) and len(controller_state) == size):
            raise ValueError(
                "nonfinite_trials needs this controller's final state: solve with "
                f"diffrax.SaveAt(..., controller_state=True), got {type(controller_state)}")
        return controller_state

    def _initial_step(self, terms, t0, y0, args, func, error_order):
        """Hairer's starting step (*Solving ODEs I*, II.4; diffrax's when ``dt0`` is
        ``None``) on the per-vector scale. The field is evaluated in a two-pass loop, so
        that it is compiled once here."""
        y0, args = jax.lax.stop_gradient((y0, args))
        tree_map = jax.tree_util.tree_map
        # chosen in t (func is dy/dt); a solve in unit time steps h / T
        time_scale = None if self.time_scale is None else jax.lax.stop_gradient(self.time_scale)
        scale = tree_map(lambda n: self.atol + self.rtol * n, self._lengths(y0))

        def scaled_norm(v):
            return self.norm(tree_map(jnp.divide, v, scale))

        d0 = scaled_norm(y0)

        def first_step(f0):
            d1 = scaled_norm(f0)
            small = (d0 < 1e-5) | (d1 < 1e-5)
            return jnp.where(small, 1e-6, 0.01 * d0 / jnp.where(small, 1.0, d1)), d1

        def body(i, carry):
            t, y, f0, _ = carry
            f = func(terms, t, y, args)
            f0 = tree_map(lambda a, b: jnp.where(i == 0, b, a), f0, f)
            h0, _ = first_step(f0)
            return t0 + in_unit(h0), tree_map(lambda a, b: a + h0 * b, y0, f0), f0, f

        def in_unit(h):
            return h if time_scale is None else h / time_scale

        zeros = tree_map(lambda s: jnp.zeros(s.shape, s.dtype),
                         jax.eval_shape(lambda: func(terms, t0, y0, args)))
        t_start = jnp.asarray(t0, jnp.result_type(d0))
        _, _, f0, f1 = jax.lax.fori_loop(0, 2, body, (t_start, y0, zeros, zeros))
        h0, d1 = first_step(f0)
        d2 = scaled_norm(tree_map(jnp.subtract, f1, f0)) / h0
        max_d = jnp.maximum(d1, d2)
        order = self._get_error_order(error_order)
        h1 = jnp.where(max_d <= 1e-15, jnp.maximum(1e-6, h0 * 1e-3),
                       (0.01 / jnp.where(max_d <= 1e-15, 1.0, max_d)) ** (1 / order))
        h = jnp.minimum(100 * h0, h1)
        # A field that is not finite at the start (a NaN torque) makes the rule NaN, and a
        # NaN step is rejected forever without reaching dtmin (the solve then ran out of
        # max_steps): start from Hairer's fallback instead, so that the rejected steps
        # shrink to dtmin and the solve ends as non-finite.
        h = jnp.where(jnp.isfinite(h) & (h > 0), h, 1e-6)
        return jax.lax.stop_gradient(in_unit(h))

    @traced_once
    def adapt_step_size(self, t0, t1, y0, y1_candidate, args, y_error, error_order,
                        controller_state):
        controller_state, nonfinite = controller_state
        bad = ~(all_finite(y1_candidate) & all_finite(y_error))
        y0, y1 = self._lengths(y0), self._lengths(y1_candidate)
        controller = self
        if self.acceptance != 1:
            c, k = self.acceptance, self._get_error_order(error_order)
            y_error = jax.tree_util.tree_map(lambda e: e / c, y_error)
            controller = eqx.tree_at(lambda s: s.safety, self,
                                     self.safety * c ** (-self.icoeff / k))
        keep, t_next0, t_next1, jump, state, result = super(
            VectorPIDController, controller
        ).adapt_step_size(t0, t1, y0, y1, args, y_error, error_order, controller_state)
        if self.dtmin is not None and not self.force_dtmin:
            # diffrax reports a proposal below dtmin; one that lands on it exactly (the
            # times are rounded: dtmin is a few ulps of t) would instead be accepted
            # whatever its error, step after step, until the state is NaN
            at_dtmin = state[2]
            result = diffrax.RESULTS.where(at_dtmin, diffrax.RESULTS.dt_min_reached, result)
        # what a collapse is blamed on: the trials since the last accepted step
        nonfinite = (nonfinite & ~keep) | bad
        return keep, t_next0, t_next1, jump, (state, nonfinite), result


#: The PI coefficients of :func:`controller`. On the free rotor, the rotor near its
#: intermediate axis and the heavy top of ``benchmarks/speed_vs_error.py`` (rtol 1e-4 to
#: 1e-10, the default solver), diffrax's default I controller on its per-entry scale, with
#: DOP853's estimate combined entry by entry, rejected a quarter of all steps. This
#: controller, with the estimate combined from whole-state norms as Hairer's DOP853 does,
#: takes 0.65–0.91× (mean 0.73×) that work at equal final error (work ∝ steps ×
#: error^(1/8)); with the I controller instead 0.65–1.0× (mean 0.83×); per-entry scale and
#: PI control 0.66–0.95× (mean 0.75×). PI control does most of it; the per-vector scale
#: makes the steps independent of the frame.
PI_COEFFICIENTS = dict(pcoeff=0.3, icoeff=0.3)


def controller(ts, rtol, atol, norm=None, layout=None, cls=None, formulation=None,
               unit_time=False, **fields) -> VectorPIDController:
    """The step-size controller of every jrigid solve: a PI controller (coefficients
    :data:`PI_COEFFICIENTS`) on the error scaled per vector (:class:`VectorPIDController`;
    ``layout``: the :class:`~jrigid.solve.flat.Flat` of a flat state), ``norm`` diffrax's
    default RMS unless given; ``cls`` a subclass to build instead, with its own ``fields``
    (:class:`~jrigid.solve.saving.SavingController`). With a ``formulation``, it works to
    that formulation's :meth:`~jrigid.formulations.AbstractFormulation.step_tolerances`.
    With ``unit_time``, it steps a solve in unit time (:func:`run`) as it would in ``t``.

    ``dtmin`` is ``4 eps max(|t0|, |t1|)`` without forcing: a step proposed at or below
    it ends the solve with ``dt_min_reached``
    (:attr:`~jrigid.trajectory.Result.step_size_collapse` or ``nonfinite``).
    """
    eps = jnp.finfo(ts.dtype).eps
    if formulation is not None:
        rtol, atol = formulation.step_tolerances(rtol, atol, eps)
        fields = dict(fields, acceptance=formulation.step_acceptance())
    extra = {"norm": rms_norm if norm is None else norm}
    dtmin = 4 * eps * jnp.maximum(jnp.abs(ts[0]), jnp.abs(ts[-1]))
    if unit_time:
        fields = dict(fields, time_scale=ts[-1] - ts[0])
        dtmin = dtmin / fields["time_scale"]
    return (VectorPIDController if cls is None else cls)(
        rtol=rtol,
        atol=atol,
        dtmin=dtmin,
        force_dtmin=False,
        layout=layout,
        **PI_COEFFICIENTS,
        **extra,
        **fields,
    )


def _check_times(ts) -> None:
    if jnp.ndim(ts) != 1 or jnp.shape(ts)[0] < 2:
        raise ValueError(f"output times must have shape (T,) with T >= 2, got {jnp.shape(ts)}")


def unit_times(ts) -> jax.Array:
    """``ts (T,)`` in the unit time of a solve over them, ``τ = (t − ts[0]) / (ts[-1] −
    ts[0])``, from exactly 0 to exactly 1 (:func:`run` with ``unit_time=True``; XLA may
    divide by multiplying with the reciprocal, which in float32 put ``ts[-1]`` at
    ``1 − 6e-8``).

    Raises:
        ValueError: ``ts`` is not one-dimensional with at least two times.
    """
    _check_times(ts)
    tau = jnp.clip((ts[1:-1] - ts[0]) / (ts[-1] - ts[0]), 0, 1)
    return jnp.concatenate([jnp.zeros_like(ts[:1]), tau, jnp.ones_like(ts[:1])])


def saved_times(saved, ts) -> jax.Array:
    """The saved times ``(T + 1,)`` of a solve in unit time over ``ts (T,)``, laid out as
    ``SaveAt(ts=ts, t1=True)`` lays them out (each output time reached, ``inf`` beyond,
    then the end), back in ``t``: the output times themselves, and the end exactly
    ``ts[-1]`` when the solve finished.

    Raises:
        ValueError: ``ts`` is not ``(T,)`` with ``T >= 2``, or ``saved`` not ``(T + 1,)``.
    """
    _check_times(ts)
    if jnp.shape(saved) != (jnp.shape(ts)[0] + 1,):
        raise ValueError(f"saved times must have shape (T + 1,) = ({jnp.shape(ts)[0] + 1},) "
                         f"for ts of shape {jnp.shape(ts)}, got {jnp.shape(saved)}")
    reached = jnp.where(jnp.isfinite(saved[:-2]), ts[:-1], jnp.inf)
    tau = saved[-2:]
    t = jnp.where(tau == 1, ts[-1], ts[0] + (ts[-1] - ts[0]) * tau)
    return jnp.concatenate([reached, t])


class UnitTimeTerm(diffrax.ODETerm):
    """``dy/dt = f(t, y, args)`` as a term of the unit time ``τ = (t − t0) / span``.

    ``vf(τ, y, args)`` is ``f(t0 + span τ, y, args)`` and the control of ``τ0 → τ1`` is
    ``span (τ1 − τ0)``, so that a Runge–Kutta step in ``τ`` forms the increments of the
    step in ``t`` (one product per step; a field ``span f`` would cost one per stage,
    10–17 % of a free rotor's solve).

    Attributes:
        vector_field: ``f``.
        t0, span: the start and length of the solve in ``t``.
    """

    t0: jax.Array
    span: jax.Array

    def vf(self, t, y, args):
        return super().vf(self.t0 + self.span * t, y, args)

    def contr(self, t0, t1, **kwargs):
        return self.span * (t1 - t0)


def run(formulation, solver, ts, dt0, y0, scene, *, saveat, stepsize_controller, adjoint,
        max_steps, event=None, unit_time=False) -> diffrax.Solution:
    """``diffrax.diffeqsolve`` of ``formulation``'s vector field over ``ts[0] → ts[-1]``.

    The scene is the vector field's ``args``, and the solve never throws
    (``throw=False``): its outcome becomes a :class:`~jrigid.trajectory.Result` code in
    :func:`jrigid.solve.finish` or :func:`jrigid.solve.classify`.

    With ``unit_time=True`` the solve runs in ``τ = (t − ts[0]) / (ts[-1] − ts[0])``, from
    the constant 0 to the constant 1 (:class:`UnitTimeTerm`: each step's stage increments
    are those of the step in ``t``; the solver must take its increments from the term's
    ``contr``, as diffrax's and jrigid's solvers do). diffrax computes the point
    from which it rounds a step's end to the end of the solve as 100 chained
    ``nextafter`` calls on it, which for traced ends compile into about 1700 scalar
    operations (0.25–0.3 s of the default solve's 0.9 s of XLA compilation) and for
    constant ends are computed while tracing. The caller gives every time of the solve
    in ``τ`` (``saveat``, the controller's output times: :func:`unit_times`; ``dt0`` is
    given in ``t``), steps it with ``controller(..., unit_time=True)``, and reads
    ``sol.ts`` in ``τ`` (:func:`saved_times`); the vector field is called with ``t``.
    """
    term, t0, t1 = diffrax.ODETerm(formulation.vector_field), ts[0], ts[-1]
    if unit_time:
        term = UnitTimeTerm(formulation.vector_field, ts[0], ts[-1] - ts[0])
        t0, t1, dt0 = 0.0, 1.0, None if dt0 is None else dt0 / term.span
    return diffrax.diffeqsolve(
        term,
        solver,
        t0,
        t1,
        dt0,
        y0,
        args=scene,
        saveat=saveat,
        stepsize_controller=stepsize_controller,
        adjoint=adjoint,
        event=event,
        max_steps=max_steps,
        throw=False,
    )
