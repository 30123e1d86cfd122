"""The shared solve kit: what every jrigid integrator does before and after its loop.

:func:`jrigid.simulate`, :func:`jrigid.ensemble.simulate_lockstep`, the leapfrog,
the splitting integrators, the closed forms and the contact solver all

1. convert and check their inputs (:mod:`jrigid.solve.inputs`: :func:`prepare`,
   :func:`input_checks`, then :func:`validate`, :func:`guard` or :func:`screen`; in
   float32 a :class:`PrecisionWarning` when the horizon is too long for the tolerance);
2. step with diffrax (:mod:`jrigid.solve.stepping`: :func:`solver_options`, the PID
   :func:`controller`, the solver wrapped in :class:`ProjectedSolver` for formulations
   that carry a quaternion, :func:`run`), on the state flattened to one array
   (:mod:`jrigid.solve.flat`: :class:`Flat`), saving the outputs through the controller
   when nothing else is asked of diffrax (:mod:`jrigid.solve.saving`);
3. turn the outcome into a :class:`~jrigid.trajectory.Result` code and a
   :class:`~jrigid.trajectory.Trajectory` (:mod:`jrigid.solve.outcome`: :func:`classify`,
   :func:`finish`, :func:`finish_sampled`), and raise or not (:func:`raise_on_failure`).

The result types themselves (``Trajectory``, ``Result``, ``SimulationError``) live in
:mod:`jrigid.trajectory`.
"""

from jrigid.solve import flat, inputs, outcome, saving, stepping  # noqa: I001
from jrigid.solve.flat import *  # noqa: F403
from jrigid.solve.inputs import *  # noqa: F403
from jrigid.solve.outcome import *  # noqa: F403
from jrigid.solve.saving import *  # noqa: F403
from jrigid.solve.stepping import *  # noqa: F403

# The package's names: each listed once, in the ``__all__`` of the module defining it.
__all__: list[str] = []
__all__ += flat.__all__
__all__ += inputs.__all__
__all__ += outcome.__all__
__all__ += saving.__all__
__all__ += stepping.__all__
