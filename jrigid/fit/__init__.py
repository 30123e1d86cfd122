"""Parameter inference through differentiable trajectories.

Fit inertia (ratios or full tensor), initial spin and orientation, or the parameters of
a top, to observed motion, with error bars:

1. build the scene from raw parameters with the maps of :mod:`jrigid.fit.params`
   (physical for every input; torque-free motion fixes only the moment *ratios*, so
   :func:`moment_ratios` fixes the trace explicitly);
2. wrap the builder in a forward model, :class:`Simulated` (``jrigid.simulate``) or
   :class:`Exact` (closed-form torque-free);
3. pair it with observations (:class:`Gyroscope`, :class:`Orientations`,
   :class:`AxisDirections`) in a :class:`Problem`;
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
from jrigid.fit.problem import Exact, Problem, Simulated
from jrigid.fit.uncertainty import Laplace, laplace, propagate

__all__ = [
    "AxisDirections",
    "Exact",
    "FitResult",
    "Gyroscope",
    "Laplace",
    "Orientations",
    "Prediction",
    "Problem",
    "Simulated",
    "axis_loss",
    "fit",
    "gyroscope_loss",
    "inertia_tensor",
    "laplace",
    "moment_ratios",
    "moment_ratios_raw",
    "moments",
    "moments_raw",
    "orientation_loss",
    "positive",
    "positive_raw",
    "propagate",
    "unit_quaternion",
]
