"""DOP853 with a conservative error estimate on diffrax's generic Runge–Kutta step (its
stages optionally written out): the default solver of :func:`jrigid.simulate`."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jrigid.solvers._dop853_coefficients import coefficients as _dop853
from jrigid.solvers.fused import in_precision, single
from jrigid.solvers.pairs import (
    _E3_SINGLE,
    FusedDop853,
    _dop853_error,
    _dop853_tableau,
    _Dop853Dense,
)

__all__ = ["TightDop853"]


class _Dop853Increments(_Dop853Dense):
    """DOP853's dense output over diffrax's stage increments ``kᵢ = h fᵢ`` (``f`` holds them)."""

    def point(self, h, x):
        return super().point(jnp.ones_like(h), x)


def _tensordot(row, k):
    """``Σᵢ rowᵢ kᵢ`` over the leading axis of ``k`` (the first ``len(row)`` entries)."""
    return jnp.tensordot(jnp.asarray(row, k.dtype), k[: len(row)], axes=1)


class TightDop853(diffrax.AbstractERK):
    """Hairer's DOP853 (the pair of scipy's ``solve_ivp(method="DOP853")``) as a diffrax
    Runge–Kutta solver, with its error estimate times :attr:`factor`.

    An 8th-order step of 12 stages and the first-same-as-last one; the error estimate
    combines a 5th- and a 3rd-order one as DOP853 does; three more stages per step give
    its 7th-order dense output, so that output times inside a step are about as accurate
    as the step ends (Dormand–Prince 8(7)'s interpolant, ``diffrax.Dopri8``'s, measured
    6–16·rtol inside steps against 0.1–0.3·rtol at step ends on free rotors).

    Scaling the estimate by ``factor`` is the same as running the step-size controller
    at ``rtol / factor`` and ``atol / factor``: with it the tolerances bound the error of
    the result over long runs, not of one step. Plain DOP853 (``factor=1``) ended up to
    130·rtol from the exact motion of a heavy top over 100 time units; ``factor = 10``
    costs ``10^(1/8) ≈ 1.33×`` the steps.

    **How the stages are evaluated.** By default in diffrax's stage loop, one compiled
    vector field. With ``fuse_below = n > 0``, for a vector field of fewer than ``n``
    equations in its traced program (a torque-free rotor's quaternion-acceleration field
    has about 200, a heavy top's 550), the stages are written out as in
    :class:`~jrigid.solvers.FusedDop853`, constants folded and zero coefficients skipped.
    The two take the same steps (up to rounding). Written out, a free rotor's solve took
    6–13 % less time after compilation (``benchmarks/speed_vs_error.py``) but compiled
    0.9–1.2 s longer: 1.5 → 2.4 s saving the two ends, 3.2 → 4.4 s saving 11–1001 times
    (``benchmarks/outputs.py``); on the heavy top it saved 4–7 % for 1.6 s more. For
    many calls of one compiled solve (a sweep, a fit) ``fuse_below=300`` pays; for a
    script's first call it does not, so it is not the default.

    Attributes:
        factor: the scale of the error estimate (``> 0``; 1 is scipy's DOP853 estimate).
        output_ts: ``None`` (the dense output's stages in every step), or the output
            times of a solve that only saves at them (see :meth:`at_outputs`).
        fuse_below: write the stages out for a vector field of fewer traced equations
            than this (0, the default: never).
    """

    tableau: ClassVar[diffrax.ButcherTableau] = _dop853_tableau()
    #: the weights of DOP853's 3rd-order error estimate
    error3: ClassVar[np.ndarray] = _dop853.E3
    interpolation_cls: ClassVar = _Dop853Increments
    factor: float = 10.0
    output_ts: jax.Array | None = None
    fuse_below: int = eqx.field(static=True, default=0)

    def __check_init__(self):
        ok = isinstance(self.factor, (int, float)) and not isinstance(self.factor, bool)
        if not (ok and self.factor > 0):
            raise ValueError(f"TightDop853 factor must be a number > 0, got {self.factor!r}")
        n = self.fuse_below
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
            raise ValueError(f"TightDop853 fuse_below must be an int >= 0, got {n!r}")

    def order(self, terms):
        return 8

    def at_outputs(self, ts) -> TightDop853:
        """This solver, computing the dense output's stages only in steps that hold one of
        the times ``ts (T,)`` (increasing) in ``(t0, t1]``.

        For a solve whose interpolation is used only to save at ``ts`` (diffrax's
        ``SaveAt(ts=ts)``, no dense output, no event): a step without an output time
        then evaluates the vector field 12 times instead of 15. Elsewhere its
        interpolation is not valid.

        Raises:
            ValueError: ``ts`` is not one-dimensional.
        """
        if jnp.ndim(ts) != 1:
            raise ValueError(f"output times must have shape (T,), got {jnp.shape(ts)}")
        return dataclasses.replace(self, output_ts=jnp.asarray(ts))

    def fused(self, terms, t0, y0, args) -> bool:
        """Whether the stages are written out for this vector field (decided when traced)."""
        if self.fuse_below <= 0:
            return False
        program, _, _ = eqx.filter_make_jaxpr(lambda t, y, a: terms.vf(t, y, a))(t0, y0, args)
        return _size(program.jaxpr) < self.fuse_below

    def in_precision_of(self, y0) -> TightDop853:
        """This solver with the coefficients for the floating type of ``y0``: in float32
        (or narrower), those of :func:`~jrigid.solvers.fused.single_precision` (measured
        on a free rotor over 10 to 10⁴ periods, rtol 1e-5 and 2e-6: orientation error
        6–11× smaller, same steps); otherwise itself."""
        dtype = jnp.result_type(*jax.tree_util.tree_leaves(y0))
        if isinstance(self, _SinglePrecision) or not single(dtype):
            return self
        return _SinglePrecision(**{f.name: getattr(self, f.name)
                                   for f in dataclasses.fields(self) if f.init})

    def init(self, terms, t0, t1, y0, args):
        solver = self.in_precision_of(y0)
        if solver is not self:
            return solver.init(terms, t0, t1, y0, args)
        if self.fused(terms, t0, y0, args):
            return _FUSED.init(terms, t0, t1, y0, args)
        return super().init(terms, t0, t1, y0, args)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        solver = self.in_precision_of(y0)
        if solver is not self:
            return solver.step(terms, t0, t1, y0, args, solver_state, made_jump)
        if self.fused(terms, t0, y0, args):
            y1, y_error, dense_info, solver_state, result = _FUSED.step(
                terms, t0, t1, y0, args, solver_state, made_jump
            )
            h = dense_info["h"]
            k = jax.tree_util.tree_map(lambda f: (h * f).astype(f.dtype), dense_info["f"])
        else:
            y1, e5, dense_info, solver_state, result = super().step(
                terms, t0, t1, y0, args, solver_state, made_jump
            )
            k = dense_info["k"]  # the 13 stage increments h f(tᵢ, yᵢ), leading axis
            e3 = jax.tree_util.tree_map(lambda a: _tensordot(self.error3, a), k)
            y_error = _dop853_error(e5, e3)
        y_error = jax.tree_util.tree_map(lambda a: self.factor * a, y_error)
        k = jax.tree_util.tree_map(
            lambda a: jnp.concatenate([a, jnp.zeros((_EXTRA,) + a.shape[1:], a.dtype)]), k
        )

        def dense_stages(k):
            return _dense_stages(terms, t0, t1, y0, args, k)

        if self.output_ts is None:
            k = dense_stages(k)
        else:
            ts = self.output_ts
            i = jnp.searchsorted(ts, t0, side="right")  # the first output time after t0
            inside = (i < ts.shape[0]) & (ts[jnp.minimum(i, ts.shape[0] - 1)] <= t1)
            k = jax.lax.cond(inside, dense_stages, lambda k: k, k)
        return y1, y_error, dict(y0=y0, y1=y1, f=k), solver_state, result


class _SinglePrecision(TightDop853):
    """:class:`TightDop853` with coefficients for float32
    (:func:`~jrigid.solvers.fused.in_precision`)."""

    tableau: ClassVar[diffrax.ButcherTableau] = in_precision(TightDop853.tableau, np.float32)
    error3: ClassVar[np.ndarray] = _E3_SINGLE


class _FusedStages(FusedDop853):
    """DOP853's step with its stages written out, without the dense output's stages
    (:class:`TightDop853` adds them where needed)."""

    extra_stages: ClassVar[tuple] = ()


_FUSED = _FusedStages()


def _size(program) -> int:
    """The number of equations of a jaxpr, those of its inner jaxprs included."""
    total = 0
    for eqn in program.eqns:
        total += 1
        for param in eqn.params.values():
            inner = getattr(param, "jaxpr", param)
            if hasattr(inner, "eqns"):
                total += _size(inner)
    return total


_EXTRA = len(FusedDop853.extra_stages)
_STAGES = _dop853.N_STAGES + 1  # the stages of the step: 12 and the first-same-as-last
# the dense output's stages: their rows of the tableau (zero-padded to all 16 stages), times
_EXTRA_A = np.zeros((_EXTRA, _STAGES + _EXTRA))
for _j, (_row, _) in enumerate(FusedDop853.extra_stages):
    _EXTRA_A[_j, : len(_row)] = _row
_EXTRA_C = np.array([c for _, c in FusedDop853.extra_stages])


def _dense_stages(terms, t0, t1, y0, args, k):
    """``k (16, ...)`` with rows 13–15, the dense output's stages, filled in: one loop,
    so that the vector field is compiled once for them."""
    control = terms.contr(t0, t1)

    def stage(j, k):
        y_j = jax.tree_util.tree_map(
            lambda y, a: y + jnp.tensordot(jnp.asarray(_EXTRA_A, a.dtype)[j], a, axes=1), y0, k
        )
        c = jnp.asarray(_EXTRA_C, jnp.result_type(t0, t1))[j]
        k_j = terms.vf_prod(t0 + c * (t1 - t0), y_j, args, control)
        return jax.tree_util.tree_map(lambda a, b: a.at[_STAGES + j].set(b), k, k_j)

    return jax.lax.fori_loop(0, _EXTRA, stage, k)
