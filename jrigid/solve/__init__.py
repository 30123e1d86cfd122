"""The shared solve kit: what every jrigid integrator does before and after its loop.

:func:`jrigid.simulate`, :func:`jrigid.ensemble.simulate_lockstep`, the leapfrog,
the splitting integrators, the closed forms and the contact solver all

1. convert and check their inputs (:mod:`jrigid.solve.inputs`: :func:`prepare`,
   :func:`input_checks`, then :func:`validate`, :func:`guard` or :func:`screen`; in
   float32 a :class:`PrecisionWarning` when the horizon is too long for the tolerance);
2. step with diffrax (:mod:`jrigid.solve.stepping`: :func:`solver_options`, the PID
   :func:`controller`, the solver wrapped in :class:`ProjectedSolver` for formulations
   that carry a quaternion, :func:`run`);
3. turn the outcome into a :class:`~jrigid.trajectory.Result` code and a
   :class:`~jrigid.trajectory.Trajectory` (:mod:`jrigid.solve.outcome`: :func:`classify`,
   :func:`finish`, :func:`finish_sampled`), and raise or not (:func:`raise_on_failure`).

The result types themselves (``Trajectory``, ``Result``, ``SimulationError``) live in
:mod:`jrigid.trajectory`.
"""

from jrigid.solve.inputs import (
    TOLERANCE_CHECKS,
    PrecisionWarning,
    default_tolerances,
    guard,
    input_checks,
    message,
    normalised,
    precision_problem,
    prepare,
    screen,
    validate,
    warn_precision,
)
from jrigid.solve.outcome import classify, finish, finish_sampled, raise_on_failure
from jrigid.solve.stepping import (
    DEFAULT_SOLVER,
    ProjectedSolver,
    controller,
    projected,
    run,
    solver_options,
)

__all__ = [
    # inputs
    "TOLERANCE_CHECKS", "PrecisionWarning", "default_tolerances", "guard", "input_checks",
    "message", "normalised", "precision_problem", "prepare", "screen", "validate",
    "warn_precision",
    # stepping
    "DEFAULT_SOLVER", "ProjectedSolver", "controller", "projected", "run", "solver_options",
    # outcome
    "classify", "finish", "finish_sampled", "raise_on_failure",
]  # fmt: skip
