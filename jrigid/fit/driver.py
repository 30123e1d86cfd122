"""The :func:`fit` driver: optax's L-BFGS (with its zoom line search), Adam, or
Levenberg–Marquardt on a :class:`~jrigid.fit.problem.Problem`'s residuals.

Levenberg–Marquardt (``method="lm"``) takes the residuals' Jacobian by forward mode
(``jax.jacfwd`` with diffrax's ``ForwardMode``): one tangent per parameter, the right
choice when the parameters are few (see the README's adjoint measurement), and the
Gauss–Newton model it steps on is the one :func:`jrigid.fit.laplace` uses for the error
bars. The first-order methods take reverse-mode gradients.

One compiled step function per call; the loop runs in Python so that it can stop,
record a history and drive a ``tqdm`` progress bar. Stopping rules, checked before
every step, in this order:

- ``gtol``: the largest gradient component ``‖∇f‖_∞ ≤ gtol`` → converged;
- ``ftol``: the decrease of the last step ``|f_{k−1} − f_k| ≤ ftol · max(1, |f_k|)`` →
  converged (for Adam, whose steps do not decrease ``f`` monotonically, it must hold
  for 5 consecutive steps);
- non-finite loss or gradient → stopped, not converged;
- ``max_iter`` steps taken → stopped, not converged.
"""

from __future__ import annotations

import functools
import sys
from dataclasses import dataclass, field
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jax.flatten_util import ravel_pytree

from jrigid.fit.problem import Problem
from jrigid.fit.uncertainty import _residuals_and_jacobian

__all__ = ["FitResult", "fit"]


@dataclass
class FitResult:
    """Outcome of :func:`fit`.

    Attributes:
        params: the final parameter pytree.
        loss: final loss value.
        grad_norm: final ``‖∇f‖_∞``.
        n_iter: optimiser steps taken.
        converged: whether ``gtol`` or ``ftol`` was met.
        reason: why the loop stopped (``"gtol"``, ``"ftol"``, ``"max_iter"``, ``"nonfinite"``).
        history: ``{"loss": [...], "grad_norm": [...], "params": [...]}``, one entry per
            evaluated iterate (the start included); ``params`` only with ``record_params``.
    """

    params: Any
    loss: float
    grad_norm: float
    n_iter: int
    converged: bool
    reason: str
    history: dict = field(default_factory=dict)


def _as_loss(objective):
    if isinstance(objective, Problem):
        return objective.loss
    if not callable(objective):
        raise ValueError("objective must be a Problem or a callable theta -> scalar loss")
    return objective


def _inf_norm(tree) -> jax.Array:
    leaves = jax.tree_util.tree_leaves(tree)
    return jnp.max(jnp.stack([jnp.max(jnp.abs(x)) for x in leaves]))


@functools.lru_cache(maxsize=32)
def _optimizer(method: str, learning_rate: float | None) -> optax.GradientTransformation:
    """One optimiser object per setting, so that the compiled step is reused."""
    if method == "lbfgs":
        return optax.lbfgs(learning_rate=learning_rate)
    return optax.adam(1e-2 if learning_rate is None else learning_rate)


@eqx.filter_jit
def _lbfgs_step(f, optimizer, p, s):
    value, grad = optax.value_and_grad_from_state(f)(p, state=s)
    updates, s = optimizer.update(grad, s, p, value=value, grad=grad, value_fn=f)
    return optax.apply_updates(p, updates), s, value, grad


def _gauss_newton(problem, p):
    """``(½ Σ r², gradient Jᵀr, Gauss–Newton matrix JᵀJ)`` at ``p`` (flat), forward mode.

    The compiled residual Jacobian is the one :func:`jrigid.fit.laplace` uses, so the
    error bars after an ``"lm"`` fit cost no second compilation.
    """
    r, jac = _residuals_and_jacobian(problem, p)
    return 0.5 * jnp.sum(r * r), jac.T @ r, jac.T @ jac


@eqx.filter_jit
def _lm_trial(p, grad, gn, lam):
    """``p + δ`` with ``(JᵀJ + λ diag(JᵀJ)) δ = −Jᵀr`` (Marquardt's scaling)."""
    flat, unravel = ravel_pytree(p)
    d = jnp.diag(gn)
    damped = gn + jnp.diag(lam * jnp.where(d > 0, d, 1.0))
    return unravel(flat + jnp.linalg.solve(damped, -grad))


def _lm_step(problem, _optimizer, p, s):
    """One accepted Levenberg–Marquardt step (λ raised until the loss decreases).

    ``s = (λ, (value, grad, JᵀJ) at p or None)``. Returns ``p`` unchanged when no damping
    up to ``1e16`` decreases the loss (a minimum to rounding: the ``ftol`` rule stops).
    """
    lam, cache = s
    value, grad, gn = _gauss_newton(problem, p) if cache is None else cache
    _, unravel = ravel_pytree(p)
    while lam < 1e16:
        trial = _lm_trial(p, grad, gn, lam)
        new = _gauss_newton(problem, trial)
        if bool(new[0] < value):
            return trial, (max(lam / 3.0, 1e-12), new), value, unravel(grad)
        lam *= 4.0
    return p, (lam, (value, grad, gn)), value, unravel(grad)


@eqx.filter_jit
def _plain_step(f, optimizer, p, s):
    value, grad = jax.value_and_grad(f)(p)
    updates, s = optimizer.update(grad, s, p)
    return optax.apply_updates(p, updates), s, value, grad


def fit(
    objective,
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
) -> FitResult:
    """Minimise ``objective(params)`` from ``params0``.

    Args:
        objective: a :class:`~jrigid.fit.problem.Problem` (its :meth:`~Problem.loss`) or
            any differentiable ``params -> ()`` function.
        params0: starting pytree of float arrays (raw, unconstrained parameters; see
            :mod:`jrigid.fit.params`).
        method: ``"lbfgs"`` (``optax.lbfgs`` with zoom line search; default), ``"adam"``,
            or ``"lm"`` (Levenberg–Marquardt with forward-mode Jacobians; ``objective``
            must be a :class:`~jrigid.fit.problem.Problem`).
        learning_rate: Adam's step (default ``1e-2``); for L-BFGS ``None`` lets the line
            search choose; for ``"lm"`` the initial damping λ (default ``1e-3``).
        max_iter: largest number of optimiser steps.
        gtol: stop when ``‖∇f‖_∞ ≤ gtol``.
        ftol: stop when the relative decrease falls below ``ftol`` (see module docstring).
        optimizer: any optax transformation instead of ``method`` (used like Adam,
            without line search).
        progress: show a ``tqdm`` bar; default: when ``max_iter ≥ 100`` and stderr is a
            terminal.
        record_params: keep every iterate in ``history["params"]``.

    Returns:
        :class:`FitResult`.

    Raises:
        ValueError: unknown method, non-positive ``max_iter``, a non-finite loss at
            ``params0``, or ``"lm"`` with an objective that is not a ``Problem``.
    """
    f = _as_loss(objective)
    if not isinstance(max_iter, int) or max_iter < 1:
        raise ValueError(f"max_iter must be a positive int, got {max_iter!r}")
    params = jax.tree_util.tree_map(lambda x: jnp.asarray(x, dtype=jnp.result_type(float)), params0)
    if optimizer is None and method not in ("lbfgs", "adam", "lm"):
        raise ValueError(f"method must be 'lbfgs', 'adam' or 'lm', got {method!r}")
    marquardt = optimizer is None and method == "lm"
    linesearch = optimizer is None and method == "lbfgs"
    if marquardt:
        if not isinstance(objective, Problem):
            raise ValueError("method='lm' needs a Problem (it fits the residuals)")
        f, state = objective, (1e-3 if learning_rate is None else float(learning_rate), None)
    else:
        optimizer = _optimizer(method, learning_rate) if optimizer is None else optimizer
        # strip weak types, else the second step recompiles
        state = jax.tree_util.tree_map(
            lambda x: jnp.asarray(x, dtype=jnp.asarray(x).dtype), optimizer.init(params)
        )

    # One compiled function per fit: it returns the value and gradient at ``p`` and the
    # next iterate; the loop checks the stopping rules on the former before accepting
    # the latter.
    # ``f`` is an argument (a pytree when it is a Problem's bound method), so problems
    # that differ only in their data reuse the compiled step.
    step = _lm_step if marquardt else _lbfgs_step if linesearch else _plain_step

    show = (max_iter >= 100 and sys.stderr.isatty()) if progress is None else bool(progress)
    bar = None
    if show:
        from tqdm.auto import tqdm

        bar = tqdm(total=max_iter, desc=f"fit ({method})", leave=False)

    history: dict[str, list] = {"loss": [], "grad_norm": []}
    if record_params:
        history["params"] = []
    patience = 1 if linesearch or marquardt else 5
    small = 0
    reason = "max_iter"
    n_iter = 0
    try:
        while True:
            new_params, new_state, value, grad = step(f, optimizer, params, state)
            value_f = float(value)
            gnorm = float(_inf_norm(grad))
            if n_iter == 0 and not np.isfinite(value_f):
                raise ValueError(f"the loss at params0 is not finite ({value_f})")
            history["loss"].append(value_f)
            history["grad_norm"].append(gnorm)
            if record_params:
                history["params"].append(jax.device_get(params))
            if bar is not None:
                bar.set_postfix(loss=f"{value_f:.4g}", grad=f"{gnorm:.2g}")
            if not (np.isfinite(value_f) and np.isfinite(gnorm)):
                reason = "nonfinite"
                break
            if gnorm <= gtol:
                reason = "gtol"
                break
            if n_iter > 0:
                prev = history["loss"][-2]
                small = small + 1 if abs(prev - value_f) <= ftol * max(1.0, abs(value_f)) else 0
                if small >= patience:
                    reason = "ftol"
                    break
            if n_iter >= max_iter:
                break
            params, state = new_params, new_state
            n_iter += 1
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    return FitResult(
        params=params,
        loss=history["loss"][-1],
        grad_norm=history["grad_norm"][-1],
        n_iter=n_iter,
        converged=reason in ("gtol", "ftol"),
        reason=reason,
        history=history,
    )
