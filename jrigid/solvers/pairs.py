"""The fused pairs: Tsitouras 5(4) and Dormand–Prince 8(7), with their dense outputs."""

from __future__ import annotations

from typing import ClassVar

import diffrax
import numpy as np
from numpy.polynomial import Polynomial

from jrigid.solvers.fused import FusedRungeKutta, PolynomialInterpolation

__all__ = ["FusedDopri8", "FusedTsit5"]


def _tsit5_dense() -> np.ndarray:
    """``(7, 5)``: Tsitouras' continuous extension ``bᵢ(θ)`` (Tsitouras 2011, as in diffrax)."""
    t = Polynomial([0.0, 1.0])
    b = [
        -1.0530884977290216 * t * (t - 1.3299890189751412)
        * (t**2 - 1.4364028541716351 * t + 0.7139816917074209),
        0.1017 * t**2 * (t**2 - 2.1966568338249754 * t + 1.2949852507374631),
        2.490627285651252793 * t**2 * (t**2 - 2.38535645472061657 * t + 1.57803468208092486),
        -16.54810288924490272 * (t - 1.21712927295533244) * (t - 0.61620406037800089) * t**2,
        47.37952196281928122 * (t - 1.203071208372362603) * (t - 0.658047292653547382) * t**2,
        -34.87065786149660974 * (t - 1.2) * (t - 0.666666666666666667) * t**2,
        2.5 * (t - 1) * (t - 0.6) * t**2,
    ]  # fmt: skip
    out = np.zeros((7, 5))
    for i, bi in enumerate(b):
        coef = bi.coef[1:]
        out[i, : len(coef)] = coef
    return out


def _dopri8_dense() -> np.ndarray:
    """``(14, 6)``: Bogacki–Shampine's interpolant of Dormand–Prince 8(7), as in diffrax.

    diffrax stores ``bᵢ(θ) = θ · polyval(rowᵢ, θ)`` (highest power first).
    """
    rows = np.asarray(diffrax.Dopri8.interpolation_cls.eval_coeffs, dtype=float)
    return rows[:, ::-1].copy()


class _Tsit5Dense(PolynomialInterpolation):
    coefficients: ClassVar[np.ndarray] = _tsit5_dense()


class _Dopri8Dense(PolynomialInterpolation):
    coefficients: ClassVar[np.ndarray] = _dopri8_dense()


class FusedTsit5(FusedRungeKutta):
    """Tsitouras' 5(4) pair (diffrax's ``Tsit5`` tableau) with fused stages."""

    tableau: ClassVar[diffrax.ButcherTableau] = diffrax.Tsit5.tableau
    interpolation_cls: ClassVar = _Tsit5Dense

    def order(self, terms):
        return 5


class FusedDopri8(FusedRungeKutta):
    """Dormand–Prince 8(7) (diffrax's ``Dopri8`` tableau) with fused stages.

    Its dense output (Bogacki–Shampine's interpolant, as in diffrax) is much less
    accurate than its steps: on a free rotor at rtol 1e-9 to 1e-12 the error at output
    times inside a step was 6–16·rtol against 0.1–0.3·rtol at step ends, and forward-mode
    derivatives there up to 300·rtol (measured). Prefer it where output times are few
    or at step ends (``SaveAt(t1=True)``); the default :class:`FusedTsit5` keeps
    0.1–0.2·rtol at every output time.
    """

    tableau: ClassVar[diffrax.ButcherTableau] = diffrax.Dopri8.tableau
    interpolation_cls: ClassVar = _Dopri8Dense

    def order(self, terms):
        return 8
