"""Explicit Runge–Kutta pairs with fused stages, as diffrax solvers.

diffrax's Runge–Kutta solvers are generic over the tableau and the state's pytree; on a
CPU, for a state of eight numbers, that generality is most of a step's cost. The
solvers here evaluate the same tableaus with every stage written out (constants folded,
zero coefficients skipped) on the state raveled into one flat array, so that XLA fuses
each stage into a few kernels. They are ordinary ``diffrax.AbstractAdaptiveSolver``
subclasses: ``diffrax.diffeqsolve`` with its step-size controllers, ``SaveAt``, events
and adjoints works with them as with diffrax's own.

- :class:`FusedTsit5` — Tsitouras' 5(4) pair, 7 stages (FSAL), 4th-order dense output;
- :class:`FusedDopri8` — Dormand–Prince 8(7), 14 stages (FSAL), 7th-order dense output
  (inaccurate inside steps: see its docstring);
- :class:`FusedDop853` — Hairer's DOP853 (scipy's ``DOP853``), 13 stages (FSAL) and 3
  more for its 7th-order dense output, error estimate from a 5th- and a 3rd-order one;
- :class:`TightDop853` — the same pair with all of a step's stages (its dense output's
  too) in one loop, as diffrax's generic Runge–Kutta step evaluates them, its error
  estimate scaled by a factor (10): the default solver of :func:`jrigid.simulate`.
  Its stages in a loop compile in about half the time of written-out ones
  (``fuse_below`` writes them out for small vector fields: 6–13 % faster per solve on a
  free rotor, 0.9–1.2 s more compilation).

The first two tableaus are diffrax's own (``diffrax.Tsit5.tableau``,
``diffrax.Dopri8.tableau``), so each takes the same steps as its diffrax counterpart up
to rounding; :class:`FusedDop853`'s step, error estimate and dense output are scipy's
(tested against it), with diffrax's step-size controller.
"""

from jrigid.solvers import fused, pairs, tight  # noqa: I001
from jrigid.solvers.fused import *  # noqa: F403
from jrigid.solvers.pairs import *  # noqa: F403
from jrigid.solvers.tight import *  # noqa: F403

# The package's names: each listed once, in the ``__all__`` of the module defining it.
__all__: list[str] = []
__all__ += fused.__all__
__all__ += pairs.__all__
__all__ += tight.__all__
