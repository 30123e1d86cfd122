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
   :class:`NutationRate`, :class:`FlipPeriod`; a new kind of data subclasses
   :class:`AbstractObservation`) in a :class:`Problem`;
4. :func:`fit` (optax L-BFGS or Adam, or Levenberg–Marquardt) and :func:`laplace`
   (Gauss–Newton covariance), :func:`propagate` for derived quantities.

:func:`fit` judges its result (:mod:`jrigid.fit.verdict`): ``result.success`` is
``False``, with a :class:`FitWarning` naming the cause (or a :class:`FitError` with
``on_bad_fit="raise"``), when χ²/dof is far above 1, the body reaches the edge of the
physical region, the Jacobian is rank-deficient, or the optimiser stopped short.

Choosing a start. Fits of rigid-body motion have many local optima; start where the
model is not degenerate and near the data: the initial spin from the first gyroscope
sample (a gyroscope measures ω(t0) directly), and the shape from a rough guess of the
moments, ordered like the body's axes and *not* a sphere or a symmetric body (where the
motion depends on the shape only through degenerate limits) — the proportions of a
box of about the right size (:func:`jrigid.inertia.box`) will do. The loss of a long
record has optima on the edge of the physical region (a rod, a flat body) that plain
descent from a far start often ends in; fitting a growing record,
``fit(..., horizons=(0.25, 0.5))``, avoids most of them. If the verdict says the fit
failed, try other starts.

Example: moment ratios and initial spin of a tumbling body from a noisy gyroscope::

    >>> import jax, jax.numpy as jnp, numpy as np
    >>> jax.config.update("jax_enable_x64", True)
    >>> from jrigid import exact, fit, initial
    >>> from jrigid.body import RigidBody
    >>> from jrigid.scene import Scene
    >>> def build(theta):
    ...     body = RigidBody(fit.moment_ratios(theta["shape"]))
    ...     return Scene(body), initial.from_omega(None, theta["omega0"])
    >>> truth = jnp.array([1.0, 2.0, 2.5]) / 5.5          # moment ratios, trace 1
    >>> ts = jnp.linspace(0.0, 8.0, 41)
    >>> _, omega = exact.solve(truth, jnp.array([1.0, 0, 0, 0]), jnp.array([0.3, 2.0, 0.2]), ts)
    >>> measured = omega + 0.02 * np.random.default_rng(0).standard_normal(omega.shape)
    >>> problem = fit.Problem(fit.Exact(build), fit.Gyroscope(ts, measured, sigma=0.02))
    >>> start = {"shape": fit.moment_ratios_raw(jnp.array([1.0, 1.5, 2.0])),
    ...          "omega0": measured[0]}
    >>> result = fit.fit(problem, start, method="lm")
    >>> result.success, result.dof, bool(0.7 < result.chi2_dof < 1.3)
    (True, 118, True)
    >>> lap = fit.laplace(problem, result.params)
    >>> moments, moments_sigma = fit.propagate(lambda p: fit.moment_ratios(p["shape"]), lap)
    >>> bool(np.all(np.abs(moments - truth) < 3 * moments_sigma))
    True
"""

from jrigid.fit import driver, features, observations, params, problem, uncertainty, verdict  # noqa: I001
from jrigid.fit.driver import *  # noqa: F403
from jrigid.fit.features import *  # noqa: F403
from jrigid.fit.observations import *  # noqa: F403
from jrigid.fit.params import *  # noqa: F403
from jrigid.fit.problem import *  # noqa: F403
from jrigid.fit.uncertainty import *  # noqa: F403
from jrigid.fit.verdict import *  # noqa: F403

# The package's names: each listed once, in the ``__all__`` of the module defining it.
__all__: list[str] = []
__all__ += driver.__all__
__all__ += features.__all__
__all__ += observations.__all__
__all__ += params.__all__
__all__ += problem.__all__
__all__ += uncertainty.__all__
__all__ += verdict.__all__
