"""One step of each optimiser :func:`jrigid.fit.fit` drives: L-BFGS, optax's others, and
Levenberg–Marquardt.

Every step function has the signature ``step(f, optimizer, params, state) -> (params,
state, value, grad)``: the next iterate and the value and gradient at ``params``, so that
the driver checks its stopping rules before it accepts the iterate.

- :func:`lbfgs_step` — L-BFGS: optax's direction (``scale_by_lbfgs``, memory 10, the
  initial scaling ``sᵀy/yᵀy``) and a strong-Wolfe line search run from Python;
- :func:`plain_step` — any other optax transformation (Adam, ...), reverse-mode gradients;
- :func:`lm_step` — Levenberg–Marquardt on a :class:`~jrigid.fit.Problem`'s residuals.

L-BFGS compiles two programs: the loss's ``value_and_grad`` (reverse mode) and the
two-loop recursion of ``optax.lbfgs`` without its line search. The line search is
scipy's ``line_search`` — Nocedal & Wright's bracketing and zoom (Algorithms 3.5 and
3.6), which optax's ``scale_by_zoom_linesearch`` ports to a ``lax.while_loop`` — with
optax's constants (``c1 = 1e-4``, ``c2 = 0.9``, first trial step 1; at most 10
bracketing and 11 zoom trials), on the raveled parameters. Each trial point costs one
call of the compiled ``value_and_grad``, and the value and gradient at the accepted
point serve the next step. (Run inside one compiled step, as optax runs it, the search
holds the loss's gradient three times — both branches of a ``lax.cond`` in its loop, and
the first step's evaluation; through a differentiable ODE solve that step took about
twice as long to compile as one gradient, ``benchmarks/fit_lbfgs.py``.) Unlike optax's,
the search has no Hager–Zhang approximate-Wolfe test for a loss flat to rounding near a
minimum: a search that fails there ends the fit by the ``ftol`` rule (below).

A trial point whose loss or gradient is not finite (a failed integration) counts as
``f = inf``, so the search backs off. When the search fails, the trial with the lowest
loss among those with sufficient decrease is taken (optax's "safe" step). When there is
none because even the shortest trial overshot a narrow valley (an ill-conditioned loss:
measured on a tumbling body near its intermediate axis, the minimum along steepest
descent lay 20 halvings below the first trial step), the search is repeated from the
minimum of a quadratic fitted to that trial, up to three times. When that fails too,
the step stops with ``stalled`` set — and the driver with ``"ftol"`` — if the decrease
the quasi-Newton model promised, ``−½ ∇f·d``, is negligible: below
``max(ftol, eps) · max(1, |f|)``, or below the loss's noise seen by the search (the loss
rose at the shortest trial step by more than the promise, and by about as much at the
longest: a loss computed by an adaptive ODE solver changes by about its tolerance
wherever the solver's steps change, so near a minimum it is smooth only to that level).
Otherwise the memory is cleared and the search repeated along steepest descent, and if
that fails too the driver stops with ``"stalled"`` (see :mod:`jrigid.fit.driver`).

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
import warnings
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jax.flatten_util import ravel_pytree
from scipy.optimize import line_search

from jrigid.fit.uncertainty import residuals_and_jacobian

__all__ = [
    "LBFGSState",
    "LMState",
    "lbfgs_init",
    "lbfgs_step",
    "lm_step",
    "make_optimizer",
    "negligible_decrease",
    "plain_step",
]

_MU_MAX = 1e16


@functools.lru_cache(maxsize=32)
def make_optimizer(method: str, learning_rate: float | None) -> optax.GradientTransformation:
    """One optimiser object per setting, so that its compiled update is reused.

    For ``"lbfgs"``: ``optax.lbfgs`` without its line search (the direction
    ``−P_k ∇f``, times ``learning_rate`` when one is given); :func:`lbfgs_step` searches
    along it.
    """
    if method == "lbfgs":
        return optax.lbfgs(learning_rate=learning_rate, linesearch=None)
    return optax.adam(1e-2 if learning_rate is None else learning_rate)


class LBFGSState(NamedTuple):
    """L-BFGS's state between steps: optax's ``scale_by_lbfgs`` state, the value and
    gradient at the current point (from the line search that reached it; ``None`` at a
    start), whether the memory is empty, the relative decrease ``ftol`` below which a
    failed search is the optimum to rounding, and whether the last line search failed
    (with the decrease ``−½ ∇f·d`` the quasi-Newton model promised along its direction,
    and the loss's noise that search saw, :func:`_noise`)."""

    opt_state: Any
    value: jax.Array | None = None
    grad: Any = None
    fresh: bool = True
    ftol: float = 0.0
    stalled: bool = False
    model_decrease: float = 0.0
    noise: float = 0.0


def lbfgs_init(optimizer, params, ftol: float = 0.0) -> LBFGSState:
    """The state of :func:`lbfgs_step` at ``params`` (empty memory)."""
    # strip weak types, else the second direction recompiles
    state = jax.tree_util.tree_map(
        lambda x: jnp.asarray(x, dtype=jnp.asarray(x).dtype), optimizer.init(params)
    )
    return LBFGSState(state, ftol=ftol)


def negligible_decrease(decrease: float, value, ftol: float, noise: float = 0.0) -> bool:
    """Whether a decrease of the loss promised by a model, where no step achieves it, is
    the optimum to rounding: ``decrease ≤ max(ftol, eps) · max(1, |f|)``, ``eps`` the
    machine epsilon of the loss's dtype (float32 cannot show a smaller change), or
    ``decrease ≤ noise``, the loss's noise measured along the failed search."""
    eps = float(jnp.finfo(jnp.result_type(value)).eps)
    return bool(decrease <= max(max(ftol, eps) * max(1.0, abs(float(value))), noise))


@eqx.filter_jit
def _value_and_grad(f, p):
    """``(f(p), ∇f(p))``: the one compiled program of the loss per loss structure (``f`` is
    traced, so problems that differ only in their data share it)."""
    return jax.value_and_grad(f)(p)


@eqx.filter_jit
def _direction(optimizer, grad, opt_state, p):
    """The L-BFGS direction at ``p`` (optax's two-loop recursion) and the new state."""
    return optimizer.update(grad, opt_state, p)


# Strong Wolfe conditions as optax's zoom line search (Nocedal & Wright's constants).
_C1, _C2 = 1e-4, 0.9


class _Trials:
    """Value and gradient of ``f`` at points ``x0 + α d`` of a line, each computed once
    (one call of :func:`_value_and_grad`); a non-finite value or gradient reads as
    ``f = inf``, so that the search backs off."""

    def __init__(self, f, unravel, dtype, x0, d):
        self.f, self.unravel, self.dtype, self.x0, self.d = f, unravel, dtype, x0, d
        self.dd = float(d @ d)
        self.points: dict[bytes, tuple] = {}

    def __call__(self, x):
        key = np.asarray(x, dtype=float).tobytes()
        if key not in self.points:
            p = self.unravel(jnp.asarray(x, dtype=self.dtype))
            value, grad = _value_and_grad(self.f, p)
            v = float(value)
            g = np.asarray(ravel_pytree(grad)[0], dtype=float)
            if not (np.isfinite(v) and np.all(np.isfinite(g))):
                v = np.inf
            alpha = float((np.asarray(x) - self.x0) @ self.d) / self.dd
            self.points[key] = (v, g, alpha, p, value, grad)
        return self.points[key]


def _line_search(f, unravel, flat, d, f0, g0):
    """Strong-Wolfe step along ``d``: ``((p, value, grad) at the new point or None, trials)``.

    scipy's ``line_search`` (Nocedal & Wright's Algorithms 3.5 and 3.6, which optax's
    zoom line search ports) from step 1 (optax's ``initial_guess_strategy="one"``), at
    most 10 bracketing and 11 zoom trials. When it fails, the trial with the lowest value
    among those with sufficient decrease is taken (optax's "safe" step). When there is
    none because even the shortest trial step overshot a narrow valley (the loss rose
    there, smoothly: :func:`_shorter_step`), the search is repeated from the minimum of
    the quadratic through ``f0``, the slope at 0 and that trial, at most
    :data:`_RESCALES` times; ``None`` when no trial decreased the loss sufficiently.
    """
    x0 = np.asarray(flat, dtype=float)
    trials = _Trials(f, unravel, flat.dtype, x0, d)
    slope0 = float(g0 @ d)
    scale = 1.0
    for _ in range(_RESCALES + 1):
        with warnings.catch_warnings():
            # a failed search warns (scipy's LineSearchWarning, a RuntimeWarning): handled
            warnings.simplefilter("ignore", RuntimeWarning)
            alpha, *_, new_slope = line_search(
                lambda x: trials(x)[0], lambda x: trials(x)[1], x0, scale * d, gfk=g0,
                old_fval=f0, c1=_C1, c2=_C2,
            )  # fmt: skip
        if alpha is not None and new_slope is not None:
            _, _, _, p, value, grad = trials(x0 + alpha * scale * d)
            return (p, value, grad), trials
        safe = [t for t in trials.points.values()
                if t[0] <= f0 + _C1 * t[2] * slope0 and t[2] > 0]  # fmt: skip
        if safe:
            _, _, _, p, value, grad = min(safe, key=lambda t: t[0])
            return (p, value, grad), trials
        scale = _shorter_step(trials, f0, slope0)
        if scale is None:
            break
    return None, trials


#: How many times a failed line search is repeated from a shorter first step.
_RESCALES = 3


def _shorter_step(trials, f0, slope0) -> float | None:
    """The first step of a repeated search after one whose every trial overshot: the
    minimum ``α_q = −φ'(0) α² / (2 (φ(α) − φ(0) − φ'(0) α))`` of the quadratic through the
    shortest trial ``α`` (at most ``α / 10``); ``None`` when that trial did not rise by
    more than the linear decrease it was promised (a loss flat to its noise, or not
    finite, which a shorter step does not cure) or the search already saw noise."""
    finite = [(t[2], t[0]) for t in trials.points.values() if t[2] > 0 and np.isfinite(t[0])]
    if not finite or _noise(trials, f0) > 0:
        return None
    alpha, value = min(finite)
    rise = value - f0
    if not rise > -slope0 * alpha:
        return None
    return min(-slope0 * alpha**2 / (2 * (rise - slope0 * alpha)), 0.1 * alpha)


def _noise(trials, f0) -> float:
    """The loss's noise seen by a failed search: how much it rose at the shortest trial
    step, when it rose about as much at the longest (less than the square root of the
    ratio of the steps, which a rise from a wrong slope — linear in the step — or from
    curvature — quadratic — exceeds); ``0`` when the trials look smooth or are too few.

    A loss computed by an adaptive ODE solver changes by about its tolerance wherever the
    solver's steps change, so near a minimum it is flat only to that level.
    """
    rises = sorted((t[2], t[0] - f0) for t in trials.points.values()
                   if t[2] > 0 and np.isfinite(t[0]))  # fmt: skip
    if len(rises) < 3:
        return 0.0
    (a_min, e_min), (a_max, e_max) = rises[0], rises[-1]
    span = a_max / a_min
    if not (span >= 16.0 and e_min > 0.0 and e_max <= e_min * np.sqrt(span)):
        return 0.0
    return float(e_min)


def lbfgs_step(f, optimizer, p, s: LBFGSState, settled=None):
    """One L-BFGS step on the loss ``f`` from ``p``: optax's direction, then a strong-Wolfe
    line search driven from Python over one compiled ``value_and_grad`` of ``f``.

    Args:
        f: the loss, ``params -> ()``.
        optimizer: :func:`make_optimizer` ``("lbfgs", ...)``, the direction.
        p: the current parameters.
        s: :class:`LBFGSState` (:func:`lbfgs_init` at a start).
        settled: optional ``(value, grad) -> bool``, the driver's stopping rules: when
            they hold at ``p`` no line search is run and ``p`` is returned.

    Returns:
        ``(next params, state, value at p, gradient at p)``. When the line search finds
        no step with sufficient decrease along the L-BFGS direction, it searches again
        along steepest descent with the memory cleared, unless the decrease the model
        promised is negligible (:func:`negligible_decrease`: below ``ftol``, rounding or
        the loss's noise); when that fails too, or without the second search, ``p``
        itself, with ``state.stalled`` set (and ``model_decrease``, ``noise``).
    """
    if s.value is None:
        value, grad = _value_and_grad(f, p)
    else:
        value, grad = s.value, s.grad
    s = s._replace(value=value, grad=grad, stalled=False, noise=0.0)
    flat, unravel = ravel_pytree(p)
    g0 = np.asarray(ravel_pytree(grad)[0], dtype=float)
    f0 = float(value)
    if not (np.isfinite(f0) and np.all(np.isfinite(g0))):
        return p, s, value, grad
    if settled is not None and settled(value, grad):
        return p, s, value, grad
    promised = None  # −½ ∇f·d of the first descent direction
    noise = 0.0  # the loss's noise seen along it
    while True:
        direction, opt_state = _direction(optimizer, grad, s.opt_state, p)
        d = np.asarray(ravel_pytree(direction)[0], dtype=float)
        slope0 = float(g0 @ d)
        if slope0 < 0:  # a descent direction (else the memory is forgotten below)
            found, trials = _line_search(f, unravel, flat, d, f0, g0)
            if found is not None:
                new_p, new_value, new_grad = found
                new_s = s._replace(opt_state=opt_state, value=new_value, grad=new_grad,
                                   fresh=False)  # fmt: skip
                return new_p, new_s, value, grad
            if promised is None:
                promised, noise = -0.5 * slope0, _noise(trials, f0)
        negligible = promised is not None and negligible_decrease(promised, value, s.ftol, noise)
        if s.fresh or negligible:
            decrease = np.inf if promised is None else promised
            return p, s._replace(stalled=True, model_decrease=decrease, noise=noise), value, grad
        # the quasi-Newton model misled the search: forget it, search along −∇f
        s = s._replace(opt_state=lbfgs_init(optimizer, p).opt_state, fresh=True)


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
