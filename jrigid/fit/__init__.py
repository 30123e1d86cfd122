"""Parameter inference through differentiable trajectories.

Fit inertia (ratios or full tensor), initial spin and orientation, or the parameters of
a top, to observed motion, with error bars:

1. build the scene from raw parameters with the maps of :mod:`jrigid.fit.params`
   (physical for every input; torque-free motion fixes only the moment *ratios*, so
   :func:`moment_ratios` fixes the trace explicitly);
2. wrap the builder in a forward model, :class:`Simulated` (``jrigid.simulate``) or
   :class:`Exact` (closed-form torque-free);
3. pair it with observations (:class:`Gyroscope`, :class:`Orientations`,
   :class:`AxisDirections`, or derived features of :mod:`jrigid.fit.features`:
   :class:`WobbleRatio`, :class:`PrecessionRate`, :class:`SpinRate`, :class:`Tilt`,
   :class:`NutationRate`, :class:`FlipPeriod`) in a :class:`Problem`;
4. :func:`fit` (optax L-BFGS or Adam) and :func:`laplace` (Gauss–Newton covariance),
   :func:`propagate` for derived quantities.

Example::

    def build(theta):
        body = RigidBody(fit.moment_ratios(theta["shape"]))
        return Scene(body), initial.from_omega(None, theta["omega0"])

    problem = fit.Problem(fit.Exact(build), fit.Gyroscope(ts, omega_measured, sigma=0.01))
    result = fit.fit(problem, {"shape": jnp.zeros(2), "omega0": omega_guess})
    lap = fit.laplace(problem, result.params)
    moments, moments_sigma = fit.propagate(lambda p: fit.moment_ratios(p["shape"]), lap)
"""

from jrigid.fit.driver import FitResult, fit
from jrigid.fit.features import (
    FlipPeriod,
    FreeRates,
    NutationRate,
    PrecessionRate,
    SpinRate,
    Tilt,
    WobbleRatio,
    angle_rate,
    axis_angles,
    free_rates,
    omega_phase_rate,
    rates_from_constants,
    trajectory_rates,
    unwrap,
)
from jrigid.fit.observations import (
    AxisDirections,
    Gyroscope,
    Orientations,
    Prediction,
    axis_loss,
    gyroscope_loss,
    orientation_loss,
)
from jrigid.fit.params import (
    inertia_tensor,
    moment_ratios,
    moment_ratios_raw,
    moments,
    moments_raw,
    positive,
    positive_raw,
    unit_quaternion,
)
from jrigid.fit.problem import Exact, Invariants, Problem, Simulated
from jrigid.fit.uncertainty import Laplace, laplace, propagate

__all__ = [
    "AxisDirections",
    "Exact",
    "FitResult",
    "FlipPeriod",
    "FreeRates",
    "Gyroscope",
    "Invariants",
    "Laplace",
    "NutationRate",
    "Orientations",
    "PrecessionRate",
    "Prediction",
    "Problem",
    "Simulated",
    "SpinRate",
    "Tilt",
    "WobbleRatio",
    "angle_rate",
    "axis_angles",
    "axis_loss",
    "fit",
    "free_rates",
    "gyroscope_loss",
    "inertia_tensor",
    "laplace",
    "moment_ratios",
    "moment_ratios_raw",
    "moments",
    "moments_raw",
    "omega_phase_rate",
    "orientation_loss",
    "positive",
    "positive_raw",
    "propagate",
    "rates_from_constants",
    "trajectory_rates",
    "unit_quaternion",
    "unwrap",
]
