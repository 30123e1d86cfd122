"""Whether a fit worked: the checks behind :attr:`FitResult.success <jrigid.fit.FitResult>`.

An optimiser that stops because its steps became small has found *a* stationary point,
not necessarily a good one. :func:`assess` judges the end point of :func:`jrigid.fit.fit`
on what can be known there, and names every cause of failure:

``"nonfinite"``
    the loss or its gradient became NaN or inf.
``"max_iter"``
    the optimiser hit its iteration limit before ``gtol`` or ``ftol`` was met.
``"stalled"``
    the optimiser found no step that decreases the loss although its model of the loss
    promises a decrease larger than ``ftol``: Levenberg–Marquardt no damped step (an
    inaccurate Jacobian); L-BFGS no step with sufficient decrease along its direction
    nor, after a restart, along the negative gradient (a gradient that does not match
    the loss, a loss noisier than the promised decrease, or a loss that is not finite
    around the point).
``"not_stationary"``
    the Gauss–Newton step from the final parameters is longer than
    :data:`STEP_TOL` standard errors, ``‖U_kᵀ r‖ > STEP_TOL`` (``U_k`` the determined
    left singular vectors of the whitened Jacobian; this is the step's length in the
    metric of the Laplace covariance), and it changes some flattened parameter ``θᵢ``
    by more than :data:`STEP_FLOOR` ``· max(1, |θᵢ|)``: the optimiser stopped short of
    the minimum. (A smaller step is rounding and the solver's error. Without ``σ`` and
    with noiseless data, χ²/dof, and with it the standard errors, is itself at rounding
    level: an exact recovery, 2e-13 from the truth, had a step "8 standard errors" long.)
``"chi2"``
    the χ² test rejects the model: with ``dof = N − rank`` degrees of freedom, the
    upper tail probability ``P(χ²_dof ≥ χ²) < chi2_alpha``. Under a right model with the
    right noise level this false alarm happens once in ``1/chi2_alpha`` fits; the default
    ``1e-6`` is the tail beyond about 4.9 standard deviations. A wrong local optimum,
    a wrong model and a ``σ`` that is too small all land here. Tested only when every
    observation was given its ``σ`` (otherwise χ² measures the unknown noise level and
    the covariance is scaled by ``χ²/dof`` instead) and ``dof > 0``. A χ² far *below*
    ``dof`` (lower tail probability below ``chi2_alpha``: ``σ`` larger than the scatter
    of the residuals, and the error bars with it) does not fail the fit but is named in
    the message and warned about (:class:`FitWarning`).
``"edge"``
    the body approaches the edge of the physical region: its smallest triangle gap
    ``min(Ia + Ib − Ic) / (I1 + I2 + I3) < edge_tol`` (default ``1e-5``, ten times the
    floor of :func:`jrigid.fit.moment_ratios`). A moment near zero is such a case (its
    two gaps vanish with it). The parametrisations of :mod:`jrigid.fit.params` flatten
    out there, so an optimiser can stop on the boundary without being at a minimum, and
    the Laplace approximation does not hold. A disk of thickness ``h < 0.008 r`` or a
    rod thinner than ``r < 0.002 L`` is that close to the edge; pass ``edge_tol=0`` to
    fit such bodies.
``"rank"``
    the whitened Jacobian is numerically rank-deficient (see
    :func:`jrigid.fit.laplace`): the message names the parameter combinations the data
    do not determine. The norm of a raw quaternion (a direction the model cannot see by
    construction) is not counted.

:class:`FitWarning` is emitted (or :class:`FitError` raised, ``on_bad_fit="raise"``) with
a message that starts with the causes.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax.numpy as jnp
import numpy as np
from jax.scipy.special import gammainc, gammaincc

__all__ = [
    "CAUSES",
    "DEFAULT_CHI2_ALPHA",
    "DEFAULT_EDGE_TOL",
    "STEP_FLOOR",
    "STEP_TOL",
    "FitError",
    "FitWarning",
    "Verdict",
    "assess",
    "chi2_tail",
    "triangle_gap",
]

DEFAULT_CHI2_ALPHA = 1e-6
DEFAULT_EDGE_TOL = 1e-5
STEP_TOL = 0.1
#: Relative change of a parameter below which a Gauss–Newton step is rounding and the
#: solver's error, however many standard errors long (see ``"not_stationary"``).
STEP_FLOOR = 1e-8
CAUSES = ("nonfinite", "max_iter", "stalled", "not_stationary", "chi2", "edge", "rank")


class FitWarning(UserWarning):
    """A fit that did not succeed, or parameters the data do not determine."""


class FitError(RuntimeError):
    """Raised by :func:`jrigid.fit.fit` with ``on_bad_fit="raise"``.

    Attributes:
        result: the :class:`~jrigid.fit.FitResult` that failed.
    """

    def __init__(self, message: str, result: Any = None):
        super().__init__(message)
        self.result = result


class Verdict(NamedTuple):
    """Outcome of :func:`assess`.

    Attributes:
        success: no cause of failure.
        causes: the failed checks, in the order of :data:`CAUSES`.
        message: the causes explained (first), then the fit's statistics.
        p_value: χ² upper tail probability, or ``None`` when not tested.
        advisory: a warning that does not fail the fit, or ``None``: χ² far *below* its
            degrees of freedom (lower tail probability below ``chi2_alpha``), i.e. ``σ``
            larger than the residuals' scatter, and the error bars with it.
    """

    success: bool
    causes: tuple[str, ...]
    message: str
    p_value: float | None
    advisory: str | None = None


def chi2_tail(chi2: float, dof: int) -> float:
    """Upper tail probability ``P(X ≥ chi2)`` of a χ² distribution with ``dof`` degrees.

    Args:
        chi2: ``()`` the statistic (≥ 0).
        dof: degrees of freedom (> 0).

    Returns:
        the probability, ``Q(dof/2, chi2/2)`` (regularised upper incomplete gamma).
    """
    if dof <= 0:
        raise ValueError(f"dof must be positive, got {dof}")
    return float(gammaincc(jnp.asarray(dof / 2.0), jnp.asarray(chi2 / 2.0)))


def triangle_gap(moments) -> float:
    """Smallest ``(Ia + Ib − Ic) / (I1 + I2 + I3)`` of principal moments ``(3,)``.

    Zero on the edge of the physical region (a flat body; a moment of zero makes two of
    the gaps zero), ``1/3`` for a sphere.
    """
    m = np.asarray(moments, dtype=float).reshape(-1)
    if m.shape != (3,):
        raise ValueError(f"moments must have shape (3,), got {np.shape(moments)}")
    total = float(np.sum(m))
    gaps = (m[0] + m[1] - m[2], m[0] + m[2] - m[1], m[1] + m[2] - m[0])
    return min(gaps) / total if total > 0 else 0.0


def _fmt(x: float) -> str:
    return f"{x:.4g}"


def assess(
    *,
    reason: str,
    n_iter: int,
    max_iter: int,
    laplace=None,
    step_length: float | None = None,
    step_change: float | None = None,
    sigma_given: bool = True,
    moments=None,
    chi2_alpha: float = DEFAULT_CHI2_ALPHA,
    edge_tol: float = DEFAULT_EDGE_TOL,
    method: str = "lm",
) -> Verdict:
    """Judge the end point of a fit (the checks of this module's docstring).

    Args:
        reason: why the optimiser stopped (``"gtol"``, ``"ftol"``, ``"max_iter"``,
            ``"nonfinite"``, ``"stalled"``).
        n_iter: steps taken; max_iter: the limit.
        laplace: the :class:`~jrigid.fit.Laplace` at the end point, or ``None`` (a plain
            objective, or non-finite residuals): then only the optimiser's stop is judged.
        step_length: Gauss–Newton step length in standard errors (``‖U_kᵀ r‖``, scaled
            by ``1/√(χ²/dof)`` when ``σ`` is unknown), or ``None``.
        step_change: largest change of a flattened parameter in that step, relative to
            ``max(1, |θᵢ|)``, or ``None`` (not known: only ``step_length`` is judged).
        sigma_given: every observation came with its ``σ``.
        moments: ``(3,)`` principal moments of the fitted body, or ``None``.
        chi2_alpha: tail probability below which the χ² test fails (``0`` disables).
        edge_tol: smallest triangle gap allowed (``0`` disables).
        method: the optimiser, ``"lm"`` or ``"lbfgs"``: words of a ``"stalled"`` cause.

    Returns:
        :class:`Verdict`.
    """
    causes: dict[str, str] = {}
    notes: list[str] = []
    advisory = None
    if reason == "nonfinite":
        causes["nonfinite"] = f"the loss or its gradient became NaN or inf after {n_iter} steps"
    elif reason == "max_iter":
        causes["max_iter"] = (
            f"the optimiser hit its iteration limit (max_iter={max_iter}) before gtol or "
            "ftol was met"
        )
    elif reason == "stalled" and method == "lbfgs":
        causes["stalled"] = (
            "the line search found no step that decreases the loss enough, neither along "
            "the L-BFGS direction nor along the negative gradient, although the "
            "quasi-Newton model promised a decrease: the gradient does not match the loss, "
            "the loss is noisier than that decrease (a loose solver tolerance), or it is "
            "not finite around this point"
        )
    elif reason == "stalled":
        causes["stalled"] = (
            "no damped Gauss–Newton step decreased the loss although the linear model "
            "promised a decrease: the Jacobian is inaccurate here"
        )
    p_value = None
    if laplace is not None:
        significant = step_change is None or step_change > STEP_FLOOR
        if (step_length is not None and step_length > STEP_TOL and significant
                and reason != "max_iter"):
            causes["not_stationary"] = (
                f"the final parameters are not at a minimum: the Gauss–Newton step from "
                f"them is {_fmt(step_length)} standard errors long (> {STEP_TOL}); the "
                f"optimiser stopped by {reason!r}"
            )
        chi2, dof = laplace.chi2, laplace.dof
        stats = (
            f"χ²/dof = {_fmt(chi2 / dof)} (χ² = {_fmt(chi2)}, dof = {dof}"
            if dof > 0
            else (f"χ² = {_fmt(chi2)} with no degrees of freedom left (dof = {dof}): χ² not tested")
        )
        if dof > 0 and sigma_given:
            p_value = chi2_tail(chi2, dof)
            stats += f", tail probability {p_value:.3g})"
            p_low = float(gammainc(jnp.asarray(dof / 2.0), jnp.asarray(chi2 / 2.0)))
            if chi2_alpha > 0 and p_low < chi2_alpha:
                advisory = (
                    f"χ²/dof = {_fmt(chi2 / dof)} is far below 1 (lower tail probability "
                    f"{p_low:.3g} < chi2_alpha = {chi2_alpha:g}): the residuals scatter much "
                    "less than the σ given, so σ is too large (or the data are not "
                    "independent), and so are the parameters' error bars, which scale "
                    "with it"
                )
            if chi2_alpha > 0 and p_value < chi2_alpha:
                causes["chi2"] = (
                    f"χ²/dof = {_fmt(chi2 / dof)} is far above 1 (tail probability "
                    f"{p_value:.3g} < chi2_alpha = {chi2_alpha:g}): the model does not fit "
                    "the data within their σ — a wrong local optimum, a wrong model, or σ "
                    "too small"
                )
        elif dof > 0:
            stats += (
                "): σ was not given for every observation, so χ²/dof estimates the noise "
                "level and is not a test; the covariance is scaled by it"
            )
        notes.append(stats)
        if laplace.undetermined.shape[0]:
            causes["rank"] = (
                "the Jacobian is rank-deficient: the data do not determine the direction(s) "
                + "; ".join(laplace.describe())
                + " of the parameters (no residual changes along them)"
            )
    else:
        notes.append("no χ² and no covariance (the objective is not a Problem, or its "
                     "residuals are not finite at the end point)")  # fmt: skip
    if moments is not None:
        gap = triangle_gap(moments)
        if edge_tol > 0 and not gap >= edge_tol:
            m = ", ".join(_fmt(float(x)) for x in np.asarray(moments).reshape(-1))
            causes["edge"] = (
                f"the body is at the edge of the physical region: moments ({m}), smallest "
                f"triangle gap (Ia + Ib − Ic)/trace = {gap:.3g} < edge_tol = {edge_tol:g} "
                "(a flat or rod-like body; the parametrisation flattens out there)"
            )
    ordered = tuple(c for c in CAUSES if c in causes)
    if ordered:
        head = "fit failed: " + "; ".join(causes[c] for c in ordered)
    else:
        head = "fit succeeded"
    tail = "; ".join([f"stopped by {reason!r} after {n_iter} steps", *notes])
    message = f"{head}. {tail[0].upper()}{tail[1:]}."
    if advisory is not None:
        message += f" Note: {advisory}."
    return Verdict(not ordered, ordered, message, p_value, advisory)
