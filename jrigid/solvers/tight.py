"""DOP853 with a conservative error estimate, all stages of a step in one loop (or written
out): the default solver of :func:`jrigid.simulate`."""

from __future__ import annotations

import dataclasses
import functools
from typing import ClassVar

import diffrax
import equinox as eqx
import equinox.internal as eqxi
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

    **How the stages are evaluated.** By default in one loop, as diffrax's generic
    Runge–Kutta step evaluates its stages: the first stage (on the first step and after
    a jump), the 11 new ones, the first-same-as-last one at ``(t1, y1)`` and — in a step
    that holds an output time — the dense output's three, so that the compiled program
    holds the vector field once for all of them. (diffrax's stage loop and a second loop
    for the dense output's stages held it twice: a heavy top's default solve compiled
    to 18 % more HLO and 15 % more LLVM IR, with the same steps and the same time per
    step.) Each stage forms ``h Σ aᵢⱼ fⱼ`` as a product and a sum over the stages' vector
    fields (a ``tensordot`` of the increments ``h fⱼ`` measured 12 % slower per step).
    With ``fuse_below = n > 0``, for a vector field of fewer than ``n``
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
        interpolation is not valid. ``ts`` may be empty (``(0,)``), for a solve that saves
        only its two ends: then no step computes them.

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
        state = super().init(terms, t0, t1, y0, args)
        if self.output_ts is None or not self.output_ts.shape[0]:
            return state
        # the first output time after t0, carried from step to step (diffrax keeps the
        # solver's state on a rejected step) instead of searched for in every step
        return state + (self._first_after(t0),)

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
            y_error = jax.tree_util.tree_map(lambda a: self.factor * a, y_error)
            k = jax.tree_util.tree_map(
                lambda a: jnp.concatenate([a, jnp.zeros((_EXTRA,) + a.shape[1:], a.dtype)]),
                k,
            )

            def dense_stages(k):
                return _dense_stages(terms, t0, t1, y0, args, k)

            if self.output_ts is None:
                k = dense_stages(k)
            elif self.output_ts.shape[0]:
                k = jax.lax.cond(self._holds_output(t0, t1), dense_stages, lambda k: k, k)
            return y1, y_error, dict(y0=y0, y1=y1, f=k), solver_state, result
        return self._looped_step(terms, t0, t1, y0, args, solver_state, made_jump)

    def _holds_output(self, t0, t1) -> jax.Array:
        """Whether the step ``t0 → t1`` holds one of the :attr:`output_ts` in ``(t0, t1]``
        (``()`` bool; only with :attr:`output_ts`)."""
        if not self.output_ts.shape[0]:
            return jnp.array(False)
        return self._reaches(self._first_after(t0), t1)

    def _first_after(self, t0) -> jax.Array:
        """``()`` int32: the index of the first of :attr:`output_ts` after ``t0``."""
        return jnp.searchsorted(self.output_ts, t0, side="right").astype(jnp.int32)

    def _reaches(self, i, t1) -> jax.Array:
        """Whether :attr:`output_ts` has an ``i``-th time and it is ``≤ t1``."""
        n = self.output_ts.shape[0]
        return (i < n) & (self.output_ts[jnp.minimum(i, n - 1)] <= t1)

    def _outputs_up_to(self, t1, first) -> tuple[jax.Array, jax.Array]:
        """``(holds, after)``: whether a step ending at ``t1`` holds one of the
        :attr:`output_ts`, given the index ``first`` of the first one after its start,
        and the index of the first one after ``t1`` (a loop over the step's outputs)."""
        after = jax.lax.while_loop(lambda i: self._reaches(i, t1), lambda i: i + 1, first)
        return after > first, after

    def _looped_step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        """The step with every stage in one loop: the first (only on the first step or
        after a jump, as diffrax's), the 11 new ones, the first-same-as-last one at
        ``(t1, y1)`` and, when the step holds an output, the dense output's three: the
        vector field is compiled once (twice with diffrax's stage loop and a loop of the
        dense output's stages)."""
        tree_map = jax.tree_util.tree_map
        a_rows, c_all, b, e5_w = _stage_coefficients(type(self))
        first_step, f0, *first_output = solver_state
        evaluate_first = eqxi.unvmap_any(first_step | made_jump)
        control = terms.contr(t0, t1)
        dtype_t = jnp.result_type(t0, t1)
        nodes = jnp.asarray(c_all, dtype_t)
        leaves0, treedef = jax.tree_util.tree_flatten(y0)
        # The stages' vector fields, one (16, ...) array per leaf of the state (each
        # stage then forms h Σ aᵢⱼ fⱼ, as diffrax's stage loop does).
        fs = tuple(jnp.zeros((_ALL,) + jnp.shape(f), f.dtype).at[0].set(
            jnp.where(evaluate_first, 0, f)) for f in treedef.flatten_up_to(f0))

        def increment(weights, fs):
            """``h Σ wᵢ fᵢ`` over the first ``len(weights)`` stages."""
            return terms.prod(treedef.unflatten([_weighted(weights, a) for a in fs]),
                              control)

        def plus(weights, fs):
            return tree_map(lambda y, d: y + d.astype(y.dtype), y0, increment(weights, fs))

        if self.output_ts is None:
            last, state = _ALL, ()
        elif not self.output_ts.shape[0]:  # no output time (a solve saving its ends only)
            last, state = _STAGES, ()
        else:
            holds, after = self._outputs_up_to(t1, first_output[0])
            last, state = jnp.where(holds, _ALL, _STAGES), (after,)

        def body(carry):
            i, fs = carry
            # Reading a whole buffer is valid under autodiff: a stage reads only the rows
            # written before it (the others have zero coefficients), as diffrax's.
            y_i = plus(jnp.asarray(a_rows, leaves0[0].dtype)[i], [a[...] for a in fs])
            c = nodes[i]
            f = treedef.flatten_up_to(terms.vf(jnp.where(c == 1, t1, t0 + c * (t1 - t0)),
                                               y_i, args))
            return i + 1, tuple(a.at[i].set(b.astype(a.dtype)) for a, b in zip(fs, f,
                                                                               strict=True))

        start = jnp.where(evaluate_first, 0, 1)
        _, fs = eqxi.while_loop(
            lambda carry: carry[0] < last, body, (start, fs), max_steps=_ALL,
            buffers=lambda carry: carry[1],
            kind="checkpointed" if self.scan_kind is None else self.scan_kind,
            checkpoints=_ALL, base=_ALL,
        )
        f1 = treedef.unflatten([a[_STAGES - 1] for a in fs])  # at (t1, y1): the next f0
        y1 = plus(b, fs)
        e5, e3 = increment(e5_w, fs), increment(self.error3, fs)
        y_error = tree_map(lambda a: self.factor * a, _dop853_error(e5, e3))
        k = terms.prod(treedef.unflatten(list(fs)), control)  # the increments h fᵢ
        return (y1, y_error, dict(y0=y0, y1=y1, f=k), (False, f1, *state),
                diffrax.RESULTS.successful)


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
_ALL = _STAGES + _EXTRA


@functools.cache
def _stage_coefficients(cls):
    """``(a (16, 16), c (16,), b (13,), e5 (13,))`` of ``cls.tableau`` (in the precision
    it was rounded to) with the dense output's stages as rows 13–15 of ``a``: every
    stage of a step as one table, for ``TightDop853._looped_step``."""
    tab = cls.tableau
    a = np.zeros((_ALL, _ALL))
    for i, row in enumerate(tab.a_lower, start=1):
        a[i, : len(row)] = row
    a[_STAGES:] = _EXTRA_A
    c = np.concatenate([[0.0], np.asarray(tab.c, float), _EXTRA_C])
    return a, c, np.asarray(tab.b_sol, float), np.asarray(tab.b_error, float)


def _weighted(weights, stages) -> jax.Array:
    """``Σᵢ wᵢ stagesᵢ`` over the first ``len(weights)`` rows of ``stages (m, ...)``
    (a product and a sum: measured faster than ``tensordot`` inside the stage loop)."""
    w = jnp.asarray(weights, stages.dtype)
    w = w.reshape(w.shape + (1,) * (stages.ndim - 1))
    return jnp.sum(w * stages[: w.shape[0]], axis=0)


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
