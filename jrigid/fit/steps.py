"""One step of each optimiser :func:`jrigid.fit.fit` drives: optax's, and Levenberg–Marquardt.

Every step function has the signature ``step(f, optimizer, params, state) -> (params,
state, value, grad)``: the next iterate and the value and gradient at ``params``, so that
the driver checks its stopping rules before it accepts the iterate.

- :func:`lbfgs_step` — ``optax.lbfgs`` with its zoom line search (value and gradient
  reused from the line search's state);
- :func:`plain_step` — any other optax transformation (Adam, ...), reverse-mode gradients;
- :func:`lm_step` — Levenberg–Marquardt on a :class:`~jrigid.fit.Problem`'s residuals.

Levenberg–Marquardt takes the residuals' Jacobian by forward mode (``jax.jacfwd`` with
diffrax's ``ForwardMode``): one tangent per parameter, the right choice when the
parameters are few (see the README's adjoint measurement), and the Gauss–Newton model it
steps on is the one :func:`jrigid.fit.laplace` uses for the error bars. The step solves
``(JᵀJ + μ D) h = −Jᵀr`` with ``D`` the largest ``diag(JᵀJ)`` met so far (MINPACK's
scaling) and accepts it when the gain ratio ``ρ = (actual decrease)/(decrease predicted
by the linear model) > 1e-4``; ``μ`` then shrinks by ``max(1/3, 1 − (2ρ − 1)³)``, and on
a rejection grows by ``ν = 2, 4, 8, …`` (Madsen, Nielsen & Tingleff, *Methods for
non-linear least squares problems*, 2004, §3.2). Marquardt's own ``D = diag(JᵀJ)`` of the
current point lets a parameter whose Jacobian column fades (a saturating map such as the
softmax of :func:`jrigid.fit.moment_ratios` near a flat body) take ever longer steps —
"parameter evaporation" (Transtrum & Sethna, arXiv:1201.5885), which can throw a raw
shape parameter onto a rod in one step — the running maximum keeps its damping.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jax.flatten_util import ravel_pytree

from jrigid.fit.uncertainty import residuals_and_jacobian

__all__ = ["LMState", "lbfgs_step", "lm_step", "make_optimizer", "plain_step"]

_MU_MAX = 1e16


@functools.lru_cache(maxsize=32)
def make_optimizer(method: str, learning_rate: float | None) -> optax.GradientTransformation:
    """One optimiser object per setting, so that the compiled step is reused."""
    if method == "lbfgs":
        return optax.lbfgs(learning_rate=learning_rate)
    return optax.adam(1e-2 if learning_rate is None else learning_rate)


@eqx.filter_jit
def lbfgs_step(f, optimizer, p, s):
    """One ``optax.lbfgs`` step on the loss ``f`` from ``p`` (optimiser state ``s``)."""
    value, grad = optax.value_and_grad_from_state(f)(p, state=s)
    updates, s = optimizer.update(grad, s, p, value=value, grad=grad, value_fn=f)
    return optax.apply_updates(p, updates), s, value, grad


class LMState(NamedTuple):
    """Levenberg–Marquardt's state between steps: the damping ``mu`` and its growth
    factor ``nu``, the scale ``D``, the residuals and Jacobian at the current point, and
    whether the last step stalled (with the decrease Gauss–Newton still promised)."""

    mu: float
    nu: float
    scale: jax.Array | None  # running maximum of diag(JᵀJ)
    cache: tuple | None  # (r, J) at the current point
    stalled: bool = False
    gn_decrease: float = 0.0


@jax.jit
def _normal_equations(r, jac, scale):
    """``(½ Σ r², Jᵀr, JᵀJ, max(scale, diag JᵀJ))``, the scale floored above zero."""
    gn = jac.T @ jac
    d = jnp.diagonal(gn) if scale is None else jnp.maximum(scale, jnp.diagonal(gn))
    top = jnp.max(d)
    d = jnp.where(d > 1e-12 * top, d, jnp.where(top > 0, 1e-12 * top, 1.0))
    return 0.5 * jnp.sum(r * r), jac.T @ r, gn, d


@jax.jit
def _lm_trial(flat, grad, gn, scale, mu):
    """``flat + h`` with ``(JᵀJ + μ D) h = −Jᵀr``, and the decrease the linear model predicts."""
    h = jnp.linalg.solve(gn + jnp.diag(mu * scale), -grad)
    predicted = -(grad @ h) - 0.5 * (h @ gn @ h)
    return flat + h, predicted


@jax.jit
def _gauss_newton_decrease(r, jac):
    """Decrease of ``½ Σ r²`` the undamped Gauss–Newton step promises, ``½ ‖P_J r‖²``."""
    h = jnp.linalg.lstsq(jac, -r)[0]
    return 0.5 * (jnp.sum(r * r) - jnp.sum((r + jac @ h) ** 2))


def lm_step(problem, _optimizer, p, s: LMState):
    """One accepted Levenberg–Marquardt step (gain-ratio test, MINPACK scaling).

    Returns ``p`` unchanged with ``stalled=True`` when no damping up to ``μ = 1e16`` is
    accepted.
    """
    flat, unravel = ravel_pytree(p)
    r, jac = residuals_and_jacobian(problem, p) if s.cache is None else s.cache
    value, grad, gn, scale = _normal_equations(r, jac, s.scale)
    mu, nu = s.mu, s.nu
    value_f = float(value)
    while mu <= _MU_MAX:
        trial, predicted = _lm_trial(flat, grad, gn, scale, jnp.asarray(mu, flat.dtype))
        predicted = float(predicted)
        if np.isfinite(predicted) and predicted > 0:
            r_new, jac_new = residuals_and_jacobian(problem, unravel(trial))
            new_value = 0.5 * float(jnp.sum(r_new * r_new))
            rho = (value_f - new_value) / predicted
            if np.isfinite(new_value) and rho > 1e-4:
                mu = max(mu * max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), 1e-15)
                state = LMState(mu, 2.0, scale, (r_new, jac_new))
                return unravel(trial), state, value, unravel(grad)
        mu *= nu
        nu *= 2.0
    decrease = float(_gauss_newton_decrease(r, jac))
    return p, LMState(mu, nu, scale, (r, jac), True, decrease), value, unravel(grad)


@eqx.filter_jit
def plain_step(f, optimizer, p, s):
    """One step of an optax transformation without line search (Adam, ...) on ``f``."""
    value, grad = jax.value_and_grad(f)(p)
    updates, s = optimizer.update(grad, s, p)
    return optax.apply_updates(p, updates), s, value, grad
