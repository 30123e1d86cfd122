"""The generic fused explicit Runge–Kutta step (see :mod:`jrigid.solvers`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

import diffrax
import equinox.internal as eqxi
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

__all__ = ["FusedRungeKutta", "PolynomialInterpolation", "StageInterpolation"]


def _combination(base, h, coefficients, stages):
    """``base + h Σ cᵢ kᵢ`` over the nonzero coefficients (Python floats: folded by XLA)."""
    total = None
    for c, k in zip(coefficients, stages, strict=False):
        c = float(c)
        if c == 0.0:
            continue
        term = c * k
        total = term if total is None else total + term
    if total is None:
        return base
    return total * h if base is None else base + h * total


def rounded_consistent(row, total: float) -> np.ndarray:
    """``row`` rounded to float32, its smallest nonzero entry then adjusted so that the
    entries (summed exactly, in float64) add up to ``total`` to within that entry's ulp."""
    r = np.asarray(row, np.float32).astype(np.float64)
    nonzero = np.flatnonzero(r)
    if nonzero.size:
        j = nonzero[np.argmin(np.abs(r[nonzero]))]
        r[j] = np.float64(np.float32(r[j] + (total - r.sum())))
    return r


def single_precision(tableau: diffrax.ButcherTableau) -> diffrax.ButcherTableau:
    """``tableau`` with float32 coefficients that keep its consistency conditions.

    Rounded to float32 one by one, DOP853's weights (up to 5.8 in size) no longer sum to
    one: by about 5e-7, an error of that relative size in every step's increment, which
    over many steps becomes a phase error independent of the tolerance. Adjusting the
    smallest weight of each row restores ``Σ bᵢ = 1``, ``Σⱼ aᵢⱼ = cᵢ`` and ``Σ eᵢ = 0`` to
    within that weight's ulp (DOP853's: about 1e-10; a row of large entries, one of
    Tsitouras', to 1.2e-7), keeping the first-same-as-last row equal to ``b``.
    """
    c = np.asarray(tableau.c, np.float32).astype(np.float64)
    b = rounded_consistent(tableau.b_sol, 1.0)
    rows = [rounded_consistent(a, c_i) for a, c_i in zip(tableau.a_lower, c, strict=True)]
    if np.array_equal(tableau.b_sol[:-1], tableau.a_lower[-1]):
        rows[-1] = b[:-1].copy()
    return diffrax.ButcherTableau(c=c, b_sol=b, b_error=rounded_consistent(tableau.b_error, 0.0),
                                  a_lower=tuple(rows))


_SINGLE: dict[int, tuple[diffrax.ButcherTableau, diffrax.ButcherTableau]] = {}


def single(dtype) -> bool:
    """Whether ``dtype`` is a floating type of 32 bits or fewer (coefficients rounded to
    it need :func:`single_precision`)."""
    return bool(jnp.issubdtype(dtype, jnp.floating)) and jnp.finfo(dtype).bits <= 32


def in_precision(tableau: diffrax.ButcherTableau, dtype) -> diffrax.ButcherTableau:
    """``tableau`` for stages of floating type ``dtype``: :func:`single_precision`'s in
    float32 or narrower (computed once per tableau: the solvers' are class constants),
    else itself."""
    if not single(dtype):
        return tableau
    key = id(tableau)
    if key not in _SINGLE:
        _SINGLE[key] = (tableau, single_precision(tableau))  # holds it: the id stays its own
    return _SINGLE[key][1]


class StageInterpolation(diffrax.AbstractLocalInterpolation):
    """Dense output of one step from its stages (abstract).

    Subclasses hold the step's ``t0``, ``t1`` and what they need of diffrax's
    ``dense_info`` (``y0``, ``y1``, the stages ``f``, the step's control ``h``), and give
    the state at ``t0 + θ (t1 − t0)`` in :meth:`point`; ``evaluate`` is diffrax's
    interface over it.
    """

    def point(self, h, theta):
        """The state at ``t0 + θ (t1 − t0)`` (``h``: the step's control, its increment is
        ``h Σ bᵢ fᵢ``; ``θ`` a scalar in ``[0, 1]``)."""
        raise NotImplementedError

    def evaluate(self, t0, t1=None, left=True):
        """The state at ``t0``, or its increment from ``t0`` to ``t1`` (diffrax's interface)."""
        del left
        if t1 is not None:
            return jax.tree_util.tree_map(
                lambda a, b: a - b, self.evaluate(t1), self.evaluate(t0)
            )
        span = self.t1 - self.t0  # pyright: ignore
        h = span if self.h is None else self.h  # pyright: ignore
        return self.point(h, (t0 - self.t0) / jnp.where(span == 0, 1, span))  # pyright: ignore


class PolynomialInterpolation(StageInterpolation):
    """Dense output ``y(t0 + θh) = y0 + h Σᵢ bᵢ(θ) fᵢ`` of one step.

    ``bᵢ(θ) = Σⱼ B[i, j] θ^(j+1)`` with the class's coefficient matrix ``B`` (subclasses
    set :attr:`coefficients`). Built by diffrax from a step's ``dense_info``.

    Attributes:
        t0, t1: the step's end points.
        y0: the state at ``t0`` (the solver's pytree).
        f: the stage derivatives, the state's pytree with a leading stage axis ``s``.
        h: the step's control (``t1 − t0`` when ``None``; a term of another time
            than the solve's, :class:`~jrigid.solve.UnitTimeTerm`, scales it).
    """

    t0: jax.Array
    t1: jax.Array
    y0: object
    f: object
    h: jax.Array | None
    coefficients: ClassVar[np.ndarray]

    def __init__(self, *, t0, t1, y0, y1, f, h=None):
        del y1  # part of diffrax's interface; the polynomial ends at it by construction
        self.t0 = t0
        self.t1 = t1
        self.y0 = y0
        self.f = f
        self.h = h

    def point(self, h, theta):
        dtype = jnp.result_type(theta)
        coeffs = jnp.asarray(self.coefficients, dtype)
        powers = theta ** jnp.arange(1, coeffs.shape[1] + 1, dtype=dtype)
        weights = h * (coeffs @ powers)  # (s,)
        return jax.tree_util.tree_map(
            lambda y, f: y + jnp.tensordot(weights, f, axes=1).astype(y.dtype), self.y0, self.f
        )


class FusedRungeKutta(diffrax.AbstractAdaptiveSolver):
    """An explicit embedded Runge–Kutta pair with its stages written out (abstract).

    Subclasses set :attr:`tableau` (a ``diffrax.ButcherTableau`` of an explicit pair
    whose last stage is evaluated at the step's end, first-same-as-last),
    :attr:`interpolation_cls` (a :class:`StageInterpolation` subclass over all the
    stages) and ``order``; a pair whose dense output needs more stages than the step
    lists them in :attr:`extra_stages`, and one with another error estimate overrides
    :meth:`error_estimate`. ``terms`` must be a single ``diffrax.ODETerm``.
    """

    tableau: ClassVar[diffrax.ButcherTableau]
    term_structure: ClassVar = diffrax.AbstractTerm
    interpolation_cls: ClassVar[Callable[..., StageInterpolation]]
    #: ``((a_row, c), ...)``: stages evaluated after the step for its dense output only
    #: (``a_row`` over all the stages before it, the first-same-as-last one included).
    extra_stages: ClassVar[tuple] = ()

    def init(self, terms, t0, t1, y0, args):
        return ravel_pytree(terms.vf(t0, y0, args))[0]

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)

    def error_estimate(self, h, stages):
        """The local error estimate ``(n,)`` from the step's stages (``h Σ βᵢ kᵢ``)."""
        return _combination(None, h, in_precision(self.tableau, stages[0].dtype).b_error,
                            stages)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        flat0, unravel = ravel_pytree(y0)
        tab = in_precision(self.tableau, flat0.dtype)

        def field(t, flat):
            return ravel_pytree(terms.vf(t, unravel(flat), args))[0].astype(flat.dtype)

        h = terms.contr(t0, t1)  # the increments' step (t1 − t0 for diffrax's ODETerm)
        f0 = jax.lax.cond(
            eqxi.unvmap_any(made_jump),
            lambda: field(t0, flat0),
            lambda: solver_state,
        )
        stages = [f0]
        # First-same-as-last: the last row's stage is evaluated at (t1, y1).
        flat1 = _append_stages(field, t0, t1, h, flat0, stages, tab.a_lower, tab.c)
        error = self.error_estimate(h, stages)
        f1 = stages[-1]
        if self.extra_stages:
            rows, cs = zip(*self.extra_stages, strict=True)
            _append_stages(field, t0, t1, h, flat0, stages, rows, cs)
        dense_info = dict(
            y0=y0, y1=unravel(flat1), f=jax.vmap(unravel)(jnp.stack(stages)), h=h
        )
        return (
            unravel(flat1),
            unravel(error),
            dense_info,
            f1,
            diffrax.RESULTS.successful,
        )


def _append_stages(field, t0, t1, h, flat0, stages, rows, cs):
    """Evaluate the stages of ``rows`` (coefficients over ``stages``, step ``h``) at nodes
    ``cs`` of ``t0 → t1``, appending each to ``stages``; return the state of the last one."""
    y_stage = flat0
    for row, c in zip(rows, cs, strict=True):
        y_stage = _combination(flat0, h, row, stages)
        t_stage = t1 if float(c) == 1.0 else t0 + float(c) * (t1 - t0)
        # A barrier per stage: XLA would otherwise fuse a stage's vector field into
        # every later stage that uses it, recomputing it (measured: up to 4x slower).
        stages.append(jax.lax.optimization_barrier(field(t_stage, y_stage)))
    return y_stage
