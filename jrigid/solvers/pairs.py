"""The fused pairs: Tsitouras 5(4), Dormand–Prince 8(7), Hairer's DOP853; their dense outputs."""

from __future__ import annotations

from typing import ClassVar

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
from numpy.polynomial import Polynomial

from jrigid.solvers._dop853_coefficients import coefficients as _dop853
from jrigid.solvers.fused import (
    FusedRungeKutta,
    PolynomialInterpolation,
    StageInterpolation,
    _combination,
    rounded_consistent,
    single,
)

__all__ = ["FusedDop853", "FusedDopri8", "FusedTsit5"]


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
    0.1–0.2·rtol at every output time, and :class:`FusedDop853` is the eighth-order
    pair whose dense output holds up.
    """

    tableau: ClassVar[diffrax.ButcherTableau] = diffrax.Dopri8.tableau
    interpolation_cls: ClassVar = _Dopri8Dense

    def order(self, terms):
        return 8


def _dop853_tableau() -> diffrax.ButcherTableau:
    """Hairer's DOP853 (Hairer, Nørsett, Wanner, *Solving ODEs I*, II.10; the coefficients
    of scipy's ``DOP853``): 12 stages and the first-same-as-last one at ``(t1, y1)``.

    ``b_error`` is the 5th-order estimate; :meth:`FusedDop853.error_estimate` combines
    it with the 3rd-order one as DOP853 does.
    """
    A, n = _dop853.A, _dop853.N_STAGES
    b = np.append(_dop853.B, 0.0)
    return diffrax.ButcherTableau(
        c=_dop853.C[1 : n + 1].copy(),
        b_sol=b,
        b_error=_dop853.E5.copy(),
        a_lower=tuple(A[i, :i].copy() for i in range(1, n + 1)),
    )


class _Dop853Dense(StageInterpolation):
    """DOP853's 7th-order continuous extension (Hairer's, as scipy's).

    ``y(t0 + θh) = y0 + θ(F0 + (1−θ)(F1 + θ(F2 + (1−θ)(F3 + θ(F4 + (1−θ)(F5 + θF6))))))``
    with ``F0 = y1 − y0``, ``F1 = h f0 − F0``, ``F2 = 2F0 − h (f1 + f0)`` and
    ``F3..6 = h D K`` over the 16 stages ``K`` (``f1 = f(t1, y1)``). Evaluated as
    ``y0 + a(θ) F0 + h Σᵢ vᵢ(θ) Kᵢ`` with the scalar weights of each ``Fⱼ`` computed
    first: one vector–matrix product, which XLA keeps inside a one-kernel loop (a
    matrix–matrix ``D K`` would not be), and no expansion of the stages' polynomials
    (which would lose about 100 ulps to cancellation).
    """

    t0: jax.Array
    t1: jax.Array
    y0: object
    y1: object
    f: object
    h: jax.Array | None = None

    def point(self, h, x):
        u = 1 - x
        # The weight of each F_j in the nested form: x, x u, x² u, x² u², x³ u², x³ u³, x⁴ u³.
        w = [x, x * u]
        for j in range(2, 7):
            w.append(w[-1] * (u if j % 2 else x))
        dtype = jnp.result_type(x)
        v = jnp.asarray(_dop853.D.T, dtype) @ jnp.stack(w[3:])  # (16,)
        v = v.at[0].add(w[1] - w[2]).at[_dop853.N_STAGES].add(-w[2])
        a = w[0] - w[1] + 2 * w[2]

        def leaf(y0, y1, k):
            return y0 + a * (y1 - y0) + (h * jnp.tensordot(v, k, axes=1)).astype(y0.dtype)

        return jax.tree_util.tree_map(leaf, self.y0, self.y1, self.f)


class FusedDop853(FusedRungeKutta):
    """Hairer's DOP853 with fused stages: the pair of scipy's ``solve_ivp(method="DOP853")``.

    An 8th-order step of 12 stages plus the first-same-as-last one; the error estimate
    combines a 5th- and a 3rd-order one as Hairer's does
    (``ρ e5``, ``ρ = |e5| / √(|e5|² + 0.01 |e3|²)``);
    three more stages per step give its 7th-order dense output, so that output times
    inside a step are about as accurate as the step ends: 15 new evaluations of the
    vector field a step, where :class:`FusedDopri8` takes 13 and interpolates far worse.

    Measured on free rotors (``simulate``, rtol 1e-6 to 1e-12, 2001 output times): error
    inside steps 0.6–3·rtol against 6–23·rtol for :class:`FusedDopri8`. Its global
    error per tolerance grows on long runs (up to 30·rtol over 100 time units near the
    intermediate axis, 130·rtol on a heavy top), where :class:`FusedTsit5`'s shrinks.
    At equal error, on the quaternion-acceleration form, it beats :class:`FusedTsit5`
    only at tight tolerances: 1.06–1.14× at 1e-10 on free rotors, 1.5–2.1× on a heavy
    top from 1e-6 to 1e-8 (``benchmarks/speed_vs_error.py``).
    """

    tableau: ClassVar[diffrax.ButcherTableau] = _dop853_tableau()
    interpolation_cls: ClassVar = _Dop853Dense
    extra_stages: ClassVar[tuple] = tuple(
        (_dop853.A[i, :i].copy(), float(_dop853.C[i]))
        for i in range(_dop853.N_STAGES + 1, _dop853.N_STAGES_EXTENDED)
    )

    def order(self, terms):
        return 8

    def error_estimate(self, h, stages):
        e5 = super().error_estimate(h, stages)
        e3 = _E3_SINGLE if single(stages[0].dtype) else _dop853.E3
        return _dop853_error(e5, _combination(None, h, e3, stages))


#: DOP853's 3rd-order error weights for float32 stages (:func:`rounded_consistent`)
_E3_SINGLE = rounded_consistent(_dop853.E3, 0.0)


def _dop853_error(e5, e3):
    """DOP853's error estimate from its 5th- and 3rd-order ones: ``ρ e5`` with
    ``ρ = |e5| / √(|e5|² + 0.01 |e3|²)`` (1 where both vanish), ``|·|`` the Euclidean norm
    of the whole state (of each member, for a state whose leaves carry a batch axis first).

    This is the estimate scipy's (and Hairer's) DOP853 controls steps with,
    ``|e5|² / √(|e5|² + 0.01 |e3|²)``, taken on the unscaled state so that the controller
    can scale it: a rotation of the frame (an orthogonal map of the state) rotates the
    estimate with it. (A component-by-component ``ρ`` would not.)
    """

    def squares(leaves):
        return sum(a * a if jnp.ndim(a) == 0 else jnp.sum(a * a, axis=-1, keepdims=True)
                   for a in leaves)

    n5 = squares(jax.tree_util.tree_leaves(e5))
    d2 = n5 + 0.01 * squares(jax.tree_util.tree_leaves(e3))
    positive = d2 > 0
    rho = jnp.where(positive, jnp.sqrt(n5 / jnp.where(positive, d2, 1.0)), 1.0)
    return jax.tree_util.tree_map(lambda a: a * rho, e5)
