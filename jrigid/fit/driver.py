"""The :func:`fit` driver: L-BFGS (optax's direction, a strong-Wolfe line search), Adam,
or Levenberg–Marquardt on a :class:`~jrigid.fit.problem.Problem`'s residuals, over one or
several horizons — and a verdict on the result.

One step of each method is in :mod:`jrigid.fit.steps`. No local method keeps a fit
from far away out of the optima on the edge of the physical region that the loss of a
long record leads to; a growing record (``horizons``) does.

The loop runs in Python so that it can stop, record a history and drive a ``tqdm``
progress bar; what it calls is compiled once per loss structure and reused by every
iteration, every horizon stage and every problem that differs only in its data (the
loss is an argument of the compiled functions: a pytree when it is a Problem's bound
method). For L-BFGS that is the loss's ``value_and_grad``, which every trial point of the
line search calls, and the small direction update. Stopping rules, checked before every
step is accepted (and, for L-BFGS, before its line search is run), in this order:

- ``gtol``: the largest gradient component ``‖∇f‖_∞ ≤ gtol`` → converged;
- ``ftol``: the decrease of the last step ``|f_{k−1} − f_k| ≤ ftol · max(1, |f_k|)`` →
  converged (for Adam, whose steps do not decrease ``f`` monotonically, it must hold
  for 5 consecutive steps);
- non-finite loss or gradient → stopped (``"nonfinite"``), not converged;
- Levenberg–Marquardt: no damping up to ``μ = 1e16`` gives an accepted step; L-BFGS: the
  line search finds no step with sufficient decrease, neither along the L-BFGS
  direction nor, with the memory cleared, along steepest descent → ``"ftol"`` if the
  model's own step (the undamped Gauss–Newton step; the quasi-Newton step, decrease
  ``−½ ∇f·d``) promises less than ``max(ftol, eps) · max(1, |f|)`` (the optimum to
  rounding; ``eps`` the machine epsilon of the loss's dtype) or, for L-BFGS, less than
  the loss's noise that the failed search saw (the optimum to the accuracy of a loss
  computed by an adaptive ODE solver; see :mod:`jrigid.fit.steps`), else ``"stalled"``,
  not converged;
- ``max_iter`` steps taken → stopped, not converged.

Stopping is not success: :func:`fit` then judges the end point (the checks of
:mod:`jrigid.fit.verdict`: χ², the edge of the physical region, the rank of the
Jacobian, stationarity) and reports the verdict in :attr:`FitResult.success` and
:attr:`FitResult.message`.
"""

from __future__ import annotations

import sys
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax

from jrigid._checks import check_number
from jrigid.fit.problem import Problem
from jrigid.fit.steps import (
    LMState,
    lbfgs_init,
    lbfgs_step,
    lm_step,
    make_optimizer,
    negligible_decrease,
    plain_step,
)
from jrigid.fit.uncertainty import Laplace, residuals_and_jacobian
from jrigid.fit.verdict import (
    DEFAULT_CHI2_ALPHA,
    DEFAULT_EDGE_TOL,
    FitError,
    FitWarning,
    assess,
)

__all__ = ["FitResult", "fit"]

_ON_BAD_FIT = ("warn", "raise", "ignore")


@dataclass(repr=False)
class FitResult:
    """Outcome of :func:`fit`, laid out like scipy's ``least_squares`` result.

    Attributes:
        params: the final parameter pytree.
        loss: final loss value (``½ χ²`` for a :class:`~jrigid.fit.Problem`).
        grad_norm: final ``‖∇f‖_∞``.
        n_iter: optimiser steps taken.
        converged: the optimiser's own stop: ``gtol`` or ``ftol`` was met. Not the
            verdict: see ``success``.
        reason: why the loop stopped (``"gtol"``, ``"ftol"``, ``"max_iter"``,
            ``"nonfinite"``, ``"stalled"``).
        success: the verdict: converged, and none of the checks of
            :mod:`jrigid.fit.verdict` failed.
        message: the verdict in words, the causes of a failure first.
        causes: the failed checks (``"chi2"``, ``"edge"``, ``"rank"``,
            ``"not_stationary"``, ``"max_iter"``, ``"stalled"``, ``"nonfinite"``).
        chi2: ``Σ r²`` of the whitened residuals (``None`` for a plain objective).
        dof: residuals minus the Jacobian's rank.
        chi2_dof: reduced χ², ``chi2 / dof`` (``None`` when ``dof ≤ 0``).
        p_value: χ² upper tail probability (``None`` when not tested: ``σ`` not given
            or ``dof ≤ 0``).
        sigma_given: every observation came with its noise level.
        laplace: the :class:`~jrigid.fit.Laplace` covariance at ``params`` (scaled by
            ``χ²/dof`` when ``σ`` was not given), or ``None``.
        residuals: ``(N,)`` whitened residuals at ``params`` (scipy's ``fun``).
        jac: ``(N, P)`` their Jacobian (flattened parameters).
        history: ``{"loss": [...], "grad_norm": [...], "params": [...]}``, one entry per
            evaluated iterate (the start of each stage included, see ``horizons``);
            ``params`` only with ``record_params``.
    """

    params: Any
    loss: float
    grad_norm: float
    n_iter: int
    converged: bool
    reason: str
    success: bool = False
    message: str = ""
    causes: tuple[str, ...] = ()
    chi2: float | None = None
    dof: int | None = None
    chi2_dof: float | None = None
    p_value: float | None = None
    sigma_given: bool | None = None
    laplace: Laplace | None = None
    residuals: jax.Array | None = None
    jac: jax.Array | None = None
    history: dict = field(default_factory=dict)

    @property
    def cov(self) -> jax.Array | None:
        """``(P, P)`` covariance of the flattened parameters (see :class:`~jrigid.fit.Laplace`)."""
        return None if self.laplace is None else self.laplace.cov

    @property
    def sigma(self) -> Any:
        """Standard deviations, a pytree like ``params`` (``inf`` where undetermined)."""
        return None if self.laplace is None else self.laplace.sigma

    def __repr__(self) -> str:
        stat = "" if self.chi2_dof is None else f", chi2_dof={self.chi2_dof:.4g}"
        return (
            f"FitResult(success={self.success}, reason={self.reason!r}, n_iter={self.n_iter}, "
            f"loss={self.loss:.6g}{stat}, message={self.message!r})"
        )


def _as_loss(problem):
    if isinstance(problem, Problem):
        return problem.loss
    if not callable(problem):
        raise ValueError(
            f"problem must be a fit.Problem or a callable params -> scalar loss, got "
            f"{type(problem).__name__}"
        )
    return problem


def _checked_start(params0):
    """``params0`` as float arrays; ``ValueError`` naming a leaf that is not a finite number."""
    leaves = jax.tree_util.tree_leaves_with_path(params0)
    if not leaves:
        raise ValueError("params0 holds no parameters (an empty pytree)")
    for path, leaf in leaves:
        name = "params0" + jax.tree_util.keystr(path)
        try:
            a = np.asarray(leaf)
        except Exception:  # noqa: BLE001 - any object numpy cannot read
            a = np.asarray(None)
        if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
            raise ValueError(f"{name} must be a real number or array, got {leaf!r}")
        bad = ~np.isfinite(a.astype(float))
        if bad.any():
            where = np.argwhere(bad)[0].tolist() if a.ndim else []
            raise ValueError(
                f"{name} has NaN or inf{f' at index {where}' if where else ''}: start from "
                "finite values"
            )
    dtype = jnp.result_type(float)
    return jax.tree_util.tree_map(lambda x: jnp.asarray(x, dtype=dtype), params0)


def _inf_norm(tree) -> jax.Array:
    leaves = jax.tree_util.tree_leaves(tree)
    return jnp.max(jnp.stack([jnp.max(jnp.abs(x)) for x in leaves]))


def fit(
    problem,
    params0,
    *,
    method: str = "lbfgs",
    learning_rate: float | None = None,
    max_iter: int = 200,
    gtol: float = 1e-8,
    ftol: float = 1e-14,
    optimizer: optax.GradientTransformation | None = None,
    progress: bool | None = None,
    record_params: bool = True,
    on_bad_fit: str = "warn",
    chi2_alpha: float = DEFAULT_CHI2_ALPHA,
    edge_tol: float = DEFAULT_EDGE_TOL,
    rcond: float | None = None,
    horizons: Sequence[float] | None = None,
) -> FitResult:
    """Minimise a problem's loss from ``params0``, then judge the result.

    Args:
        problem: a :class:`~jrigid.fit.problem.Problem` (its :meth:`~Problem.loss`
            ``½ Σ r²`` is minimised, and the result is judged on its residuals), or any
            differentiable ``params -> ()`` loss function (judged only on the
            optimiser's stop).
        params0: starting pytree of finite real arrays (raw, unconstrained parameters;
            see :mod:`jrigid.fit.params`). Start where the model is not degenerate: a
            body that is neither spherical nor symmetric (e.g. the moments of a box of
            roughly the right proportions, :func:`jrigid.inertia.box`, through
            :func:`~jrigid.fit.moment_ratios_raw`) and the initial spin from the data
            (the first gyroscope sample).
        method: ``"lbfgs"`` (L-BFGS: optax's ``scale_by_lbfgs`` direction, memory 10,
            and a strong-Wolfe line search; default), ``"adam"``, or ``"lm"``
            (Levenberg–Marquardt with forward-mode Jacobians; ``problem`` must be a
            :class:`~jrigid.fit.problem.Problem`).
        learning_rate: Adam's step (default ``1e-2``); for L-BFGS a factor on the
            direction, the line search's first trial step (``None``: 1, the
            quasi-Newton step); for ``"lm"`` the initial damping μ relative to
            ``diag(JᵀJ)`` (default ``1e-3``).
        max_iter: largest number of optimiser steps.
        gtol: stop when ``‖∇f‖_∞ ≤ gtol``.
        ftol: stop when the relative decrease falls below ``ftol`` (see module docstring).
        optimizer: any optax transformation instead of ``method`` (used like Adam,
            without line search).
        progress: show a ``tqdm`` bar; default: when ``max_iter ≥ 100`` and stderr is a
            terminal.
        record_params: keep every iterate in ``history["params"]``.
        on_bad_fit: what to do when the verdict is a failure: ``"warn"`` (default; a
            :class:`~jrigid.fit.FitWarning` with the message), ``"raise"`` (a
            :class:`~jrigid.fit.FitError` holding the result), or ``"ignore"``.
        chi2_alpha: χ² tail probability below which the fit fails (default ``1e-6``;
            ``0`` disables the test). See :mod:`jrigid.fit.verdict`.
        edge_tol: smallest relative triangle gap of the fitted body (default ``1e-5``;
            ``0`` disables the check).
        rcond: rank cut-off of the column-scaled Jacobian, as in :func:`~jrigid.fit.laplace`.
        horizons: increasing fractions of the record, e.g. ``(0.25, 0.5)``: fit the
            observations up to ``t0 + h (t_end − t0)`` for each ``h`` in turn
            (:meth:`Problem.until <jrigid.fit.Problem.until>`), each from the previous
            optimum, then the whole record. The loss of a long record of rotation has
            many local optima, and from a far start plain descent often ends in one, on
            the edge of the physical region (see the README); a short record's loss is
            close to quadratic over a wider region. ``max_iter`` applies to each stage;
            ``history`` and ``n_iter`` cover all of them.

    Returns:
        :class:`FitResult`: ``success`` and ``message`` give the verdict; ``chi2``,
        ``dof``, ``chi2_dof``, ``cov``/``sigma``/``laplace`` the statistics at the end
        point (for a :class:`~jrigid.fit.Problem`).

    Raises:
        ValueError: unknown method or ``on_bad_fit``, non-positive ``max_iter``, a
            ``params0`` that is empty or holds NaN/inf or non-numbers, a non-finite loss
            at ``params0``, or ``"lm"`` with an objective that is not a ``Problem``.
        FitError: ``on_bad_fit="raise"`` and the fit failed.

    Warns:
        FitWarning: ``on_bad_fit="warn"`` and the fit failed (the message names the
            causes); also, unless ``on_bad_fit="ignore"``, a successful fit whose χ² is
            far below its degrees of freedom (``σ`` too large: the error bars too).
    """
    f = _as_loss(problem)
    if not isinstance(max_iter, int) or isinstance(max_iter, bool) or max_iter < 1:
        raise ValueError(f"max_iter must be a positive int, got {max_iter!r}")
    if optimizer is None and method not in ("lbfgs", "adam", "lm"):
        raise ValueError(f"method must be 'lbfgs', 'adam' or 'lm', got {method!r}")
    if on_bad_fit not in _ON_BAD_FIT:
        raise ValueError(f"on_bad_fit must be one of {_ON_BAD_FIT}, got {on_bad_fit!r}")
    if not 0.0 <= chi2_alpha < 1.0:
        raise ValueError(f"chi2_alpha must be in [0, 1), got {chi2_alpha!r}")
    if not edge_tol >= 0.0:
        raise ValueError(f"edge_tol must be >= 0, got {edge_tol!r}")
    check_number("gtol", gtol, 0.0)  # (NaN too: a rule that can never be met)
    check_number("ftol", ftol, 0.0)
    if rcond is not None and not 0.0 <= rcond < 1.0:
        raise ValueError(f"rcond must be in [0, 1) or None, got {rcond!r}")
    params = _checked_start(params0)
    is_problem = isinstance(problem, Problem)
    marquardt = optimizer is None and method == "lm"
    linesearch = optimizer is None and method == "lbfgs"
    mu0 = 1e-3 if learning_rate is None else float(learning_rate)
    if marquardt:
        if not is_problem:
            raise ValueError("method='lm' needs a Problem (it fits the residuals)")
        if not mu0 > 0:
            raise ValueError(f"learning_rate (the initial damping) must be > 0, got {mu0}")
    else:
        optimizer = make_optimizer(method, learning_rate) if optimizer is None else optimizer
    stages = _stages(problem, horizons) if horizons is not None else [problem]

    # A step returns the value and gradient at ``p`` and the next iterate; the loop checks
    # the stopping rules on the former before accepting the latter. ``f`` is an argument
    # of what the steps compile (a pytree when it is a Problem's bound method), so
    # problems that differ only in their data (or their horizon) reuse the programs.
    step = lm_step if marquardt else lbfgs_step if linesearch else plain_step
    patience = 1 if linesearch or marquardt else 5

    show = (max_iter >= 100 and sys.stderr.isatty()) if progress is None else bool(progress)
    bar = None
    if show:
        from tqdm.auto import tqdm

        bar = tqdm(total=max_iter * len(stages), desc=f"fit ({method})", leave=False)

    history: dict[str, list] = {"loss": [], "grad_norm": []}
    if record_params:
        history["params"] = []
    n_iter = 0
    try:
        for stage in stages:
            if marquardt:
                f, state = stage, LMState(mu0, 2.0, None, None)
            elif linesearch:
                f = _as_loss(stage)
                state = lbfgs_init(optimizer, params, ftol)
            else:
                f = _as_loss(stage)
                # strip weak types, else the second step recompiles
                state = jax.tree_util.tree_map(
                    lambda x: jnp.asarray(x, dtype=jnp.asarray(x).dtype), optimizer.init(params)
                )
            params, state, reason, steps = _minimise(
                step, f, optimizer, params, state, history, bar,
                marquardt=marquardt, linesearch=linesearch, patience=patience,
                max_iter=max_iter, gtol=gtol, ftol=ftol, record_params=record_params,
                first=n_iter == 0 and stage is stages[0],
            )  # fmt: skip
            n_iter += steps
    finally:
        if bar is not None:
            bar.close()

    result = FitResult(
        params=params,
        loss=history["loss"][-1],
        grad_norm=history["grad_norm"][-1],
        n_iter=n_iter,
        converged=reason in ("gtol", "ftol"),
        reason=reason,
        history=history,
    )
    advisory = _judge(
        result, problem if is_problem else None, state if marquardt else None,
        max_iter=max_iter, chi2_alpha=chi2_alpha, edge_tol=edge_tol, rcond=rcond,
        method="lm" if marquardt else "lbfgs" if linesearch else method,
    )
    if not result.success:
        if on_bad_fit == "raise":
            raise FitError(result.message, result)
        if on_bad_fit == "warn":
            warnings.warn(result.message, FitWarning, stacklevel=2)
    elif advisory is not None and on_bad_fit != "ignore":
        warnings.warn(f"fit succeeded, but {advisory}", FitWarning, stacklevel=2)
    return result


def _stages(problem, horizons) -> list:
    """The problems of a horizon schedule: restricted to growing records, then whole."""
    if not isinstance(problem, Problem):
        raise ValueError("horizons needs a Problem (it shortens the observation record)")
    try:
        fractions = [float(h) for h in horizons]
    except (TypeError, ValueError) as error:
        raise ValueError("horizons must be a sequence of increasing fractions of the record "
                         f"in (0, 1], e.g. (0.25, 0.5), got {horizons!r}") from error
    if not all(0.0 < h <= 1.0 for h in fractions) or any(
        b <= a for a, b in zip(fractions, fractions[1:], strict=False)
    ):
        raise ValueError(
            f"horizons must be increasing fractions of the record in (0, 1], got {horizons!r}"
        )
    t0, t1 = float(problem.t0), float(problem.ts[-1])
    stages = [problem.until(t0 + h * (t1 - t0)) for h in fractions if h < 1.0]
    return [*stages, problem]


def _minimise(step, f, optimizer, params, state, history, bar, *, marquardt, linesearch,
              patience, max_iter, gtol, ftol, record_params, first):  # fmt: skip
    """The optimiser loop of one stage: ``(params, state, reason, steps)``."""
    small = 0
    reason = "max_iter"
    n_iter = 0

    def rule(value_f, gnorm, small):
        """The stopping rule met at a point (``None`` if none) and the ftol streak."""
        if not (np.isfinite(value_f) and np.isfinite(gnorm)):
            return "nonfinite", small
        if gnorm <= gtol:
            return "gtol", small
        if n_iter > 0:
            prev = history["loss"][-1]
            small = small + 1 if abs(prev - value_f) <= ftol * max(1.0, abs(value_f)) else 0
            if small >= patience:
                return "ftol", small
        return None, small

    while True:
        if linesearch:
            # the line search is not run from a point where the loop stops anyway
            def settled(value, grad, n_iter=n_iter, small=small):
                met, _ = rule(float(value), float(_inf_norm(grad)), small)
                return met is not None or n_iter >= max_iter

            new_params, new_state, value, grad = step(f, optimizer, params, state, settled)
        else:
            new_params, new_state, value, grad = step(f, optimizer, params, state)
        value_f = float(value)
        gnorm = float(_inf_norm(grad))
        if first and n_iter == 0 and not np.isfinite(value_f):
            raise ValueError(f"the loss at params0 is not finite ({value_f})")
        met, small = rule(value_f, gnorm, small)
        history["loss"].append(value_f)
        history["grad_norm"].append(gnorm)
        if record_params:
            history["params"].append(jax.device_get(params))
        if bar is not None:
            bar.set_postfix(loss=f"{value_f:.4g}", grad=f"{gnorm:.2g}")
        if met is not None:
            reason = met
            break
        if (marquardt or linesearch) and new_state.stalled:
            state = new_state
            if marquardt:
                small_step = negligible_decrease(new_state.gn_decrease, value, ftol)
            else:
                small_step = negligible_decrease(
                    new_state.model_decrease, value, ftol, new_state.noise
                )
            reason = "ftol" if small_step else "stalled"
            break
        if n_iter >= max_iter:
            break
        params, state = new_params, new_state
        n_iter += 1
        if bar is not None:
            bar.update(1)
    return params, state, reason, n_iter


def _judge(result: FitResult, problem, lm_state, *, max_iter, chi2_alpha, edge_tol, rcond,
           method):  # fmt: skip
    """Fill the verdict and the statistics of ``result`` in place; return the verdict's
    advisory (:attr:`~jrigid.fit.verdict.Verdict.advisory`)."""
    params = result.params
    finite = all(bool(jnp.all(jnp.isfinite(x))) for x in jax.tree_util.tree_leaves(params))
    lap = step_length = step_change = moments = None
    sigma_given = True
    if problem is not None and finite:
        sigma_given = problem.sigma_given
        if lm_state is not None and lm_state.cache is not None:
            r, jac = lm_state.cache
        else:
            r, jac = residuals_and_jacobian(problem, params)
        result.residuals, result.jac = r, jac
        size = problem.active_size
        try:
            lap = Laplace.from_jacobian(params, r, jac, rcond=rcond, size=size)
        except ValueError:
            lap = None
        if lap is not None:
            scale, unscaled = 1.0, lap
            if not sigma_given and lap.dof > 0:
                scale = lap.chi2 / lap.dof
                lap = Laplace.from_jacobian(
                    params, r, jac, rcond=rcond, scale_by_chi2=True, size=size
                )
            g = np.asarray(jac).T @ np.asarray(r)
            # (noiseless data fitted exactly: χ² = 0, so the scaled covariance is zero and
            # cannot be unscaled; the unscaled one gives the same, zero, step)
            c0 = np.asarray(lap.cov_pinv) / scale if scale > 0 else np.asarray(
                unscaled.cov_pinv)
            step = c0 @ g  # the Gauss–Newton step (up to its sign)
            step_length = float(np.sqrt(max(g @ step, 0.0) / scale)) if scale > 0 else 0.0
            relative = np.abs(step) / np.maximum(1.0, np.abs(np.asarray(lap.flat)))
            step_change = float(np.max(relative)) if relative.size else 0.0
            result.chi2, result.dof = lap.chi2, lap.dof
            result.chi2_dof = lap.chi2 / lap.dof if lap.dof > 0 else None
        result.laplace = lap
        try:
            moments = problem.moments(params)
        except ValueError:
            moments = None
    result.sigma_given = sigma_given if problem is not None else None
    verdict = assess(
        reason=result.reason,
        n_iter=result.n_iter,
        max_iter=max_iter,
        laplace=lap,
        step_length=step_length,
        step_change=step_change,
        sigma_given=sigma_given,
        moments=None if moments is None else np.asarray(moments),
        chi2_alpha=chi2_alpha,
        edge_tol=edge_tol,
        method=method,
    )
    result.success = bool(verdict.success and result.converged)
    result.causes = verdict.causes
    result.message = verdict.message
    result.p_value = verdict.p_value
    return verdict.advisory
