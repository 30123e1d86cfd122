"""The chapter's closed-form results, and the rate measurements that test them.

Each result is implemented once, in JAX, differentiable in its inputs; the demo, the
experiments, the fit features and the tests call these functions.

Closed form:

- :func:`body_precession_rate` — a torque-free symmetric body (``I1 = I2``): ``ω`` turns
  about body axis 3 at ``Ω = (I3/I1 − 1) ω3`` (eq. 17.47, Problem 17.5);
- :func:`plate_theory` — the same body seen from space, in Euler angles about ``L``:
  precession ``φ̇ = |L|/I1``, spin ``ψ̇ = ω3 (I1 − I3)/I1``, ``|L| cos θ = I3 ω3``, so the
  wobble-to-spin ratio is ``|φ̇/ψ̇| = I3/((I3 − I1) cos θ) = 2/((1 − h²/3r²) cos θ)`` for a
  plate of radius ``r`` and thickness ``h``, ``2/cos θ`` for a thin one (Feynman's plate,
  Problem 17.4);
- :func:`free_rates` — the mean precession, spin and nutation rates and the tilt range of
  any torque-free body, from the constants of :mod:`jrigid.exact` (Landau & Lifshitz §37);
- :func:`flip_theory` / :func:`flip_interval` — the flip interval ``2K(m)/λ`` near the
  intermediate axis (Problem 17.6, the Dzhanibekov effect), and
  :func:`flip_interval_asymptotic`, its ``(2/λ) ln(C/ε)`` form near the separatrix;
- :func:`gyroscope_rates` — the slow and fast steady precession of the heavy top, the roots
  of ``I1 Ω² cos θ − I3 ω3 Ω + M g l = 0`` and their fast-top limits (eq. 17.51), and
  :func:`fast_top_nutation`, the nutation of a fast top released with ``φ̇ = θ̇ = 0``. The
  nutation period and range of any heavy symmetric top are
  :func:`jrigid.lagrange_top.nutation_period` and :func:`jrigid.lagrange_top.nutation_range`
  (they read that module's constants).

Measurements on a sampled motion (:func:`axis_angles`, :func:`angle_rate`,
:func:`trajectory_rates`, :func:`wobble_to_spin`, :func:`omega_phase_rate`,
:func:`zero_crossings`): Euler angles of a body axis about a fixed space direction (``L``
for a torque-free body, the vertical for a top), unwrapped (:func:`unwrap`: the ``2π``
corrections are piecewise constant, so the derivative is that of the raw angles), and
their mean rates as least-squares slopes. This is exact for uniform rotation; a periodic
modulation of amplitude ``A`` (rad) biases the slope by ``O(A/D)`` for a record of length
``D``, so use records of many periods. The samples must be dense enough that no angle moves
by more than ``π`` between two of them.

No matplotlib here (``jrigid.viz`` draws these angles; :func:`jrigid.viz.euler_about` is
:func:`axis_angles` returning numpy).
"""

from __future__ import annotations

from jrigid.theory import _free, _measure, _top  # noqa: I001
from jrigid.theory._free import *  # noqa: F403
from jrigid.theory._measure import *  # noqa: F403
from jrigid.theory._top import *  # noqa: F403

# The package's names: each listed once, in the ``__all__`` of the module defining it.
__all__: list[str] = []
__all__ += _free.__all__
__all__ += _measure.__all__
__all__ += _top.__all__
