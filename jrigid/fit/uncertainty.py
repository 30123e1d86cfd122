"""Gauss–Newton (Laplace) uncertainty at an optimum.

For whitened residuals ``r(θ)`` (unit-variance Gaussian noise) the loss ``½ Σ r²`` has
the Gauss–Newton Hessian ``H = Jᵀ J`` with ``J = ∂r/∂θ``; the Laplace approximation of
the posterior (flat prior) is ``N(θ̂, H⁻¹)``. ``J`` is computed by forward mode
(``jax.jacfwd``; the :class:`~jrigid.fit.problem.Simulated` model switches to
``diffrax.ForwardMode``), which costs one tangent solve per parameter — cheap for the
few parameters of a rigid-body fit.

``H⁻¹`` comes from the singular value decomposition of the column-scaled Jacobian
``J D⁻¹`` (``D`` the column norms; not of ``H``, whose condition number is the square,
and independent of the parameters' units). A direction whose scaled singular value is
below ``rcond`` times the largest (default ``√eps``, 1.5e-8 in float64: determined
more than ~10⁸ times worse than the best direction, beyond the accuracy of an ODE
solver's Jacobian) is one the data cannot determine, and so is every parameter whose
column is below ``rcond`` times the largest column (one the model ignores, or sees only
through rounding and the solver's error; so parameters should be scaled within a factor
10⁸ of each other, as those of :mod:`jrigid.fit.params` are). Along such a direction the variance is
infinite: every parameter it involves gets ``σ = inf`` (``cov`` has ``inf`` on its
diagonal and ``NaN`` in its row and column), and :func:`laplace` warns with the
combination in the parameters' names. Quantities the data do determine keep finite
error bars through :func:`propagate`, which uses the pseudo-inverse ``cov_pinv`` and
checks that the quantity does not move along any undetermined direction.

A raw quaternion (:func:`jrigid.fit.unit_quaternion`) has one such direction by
construction, its norm: a *gauge* direction (a rescaling of one parameter array that
changes no residual). It gives its raw components ``σ = inf`` too but no warning;
report the rotation through :func:`propagate`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from jrigid.fit.problem import Problem
from jrigid.fit.verdict import FitWarning

__all__ = ["Laplace", "laplace", "parameter_names", "propagate", "residuals_and_jacobian"]


def parameter_names(params) -> list[str]:
    """Names of the flattened parameters (``ravel_pytree`` order), e.g. ``shape[0]``.

    Args:
        params: the parameter pytree.

    Returns:
        one name per scalar: the leaf's path (dictionary keys and attribute names
        joined by dots) and, for a non-scalar leaf, its flat index.
    """
    names = []
    for path, leaf in jax.tree_util.tree_leaves_with_path(params):
        parts = []
        for k in path:
            if isinstance(k, jax.tree_util.DictKey):
                parts.append(str(k.key))
            elif isinstance(k, jax.tree_util.GetAttrKey):
                parts.append(k.name)
            elif isinstance(k, jax.tree_util.SequenceKey):
                parts.append(str(k.idx))
            else:
                parts.append(str(k))
        base = ".".join(parts) or "params"
        size = int(np.size(leaf))
        if np.ndim(leaf) == 0:
            names.append(base)
        else:
            names.extend(f"{base}[{i}]" for i in range(size))
    return names


def _combination(direction: np.ndarray, names: list[str]) -> str:
    """``0.707·a − 0.707·b`` for a unit direction: largest components first (ties in
    parameter order), the first one positive, components under 1% of the largest dropped."""
    d = np.asarray(direction, dtype=float)
    size = np.round(np.abs(d), 9)
    order = sorted(range(d.shape[0]), key=lambda i: (-size[i], i))
    d = d * np.sign(d[order[0]])
    out = ""
    for i in order:
        if size[i] < 0.01 * size[order[0]]:
            break
        term = f"{abs(d[i]):.3g}·{names[i]}"
        out = term if not out else out + (" + " if d[i] > 0 else " − ") + term
    return out


@dataclass
class Laplace:
    """Gauss–Newton covariance of the raw parameters at ``params``.

    Attributes:
        params: the parameter pytree (the optimum).
        flat: ``(P,)`` the parameters flattened (``jax.flatten_util.ravel_pytree`` order).
        cov: ``(P, P)`` covariance; for a parameter involved in a direction the data do
            not determine, ``inf`` on the diagonal and ``NaN`` elsewhere in its row and column.
        sigma: pytree like ``params``, the standard deviations (``inf`` where undetermined).
        rank: numerical rank of the scaled Jacobian (``< P`` when some direction is
            undetermined, gauge directions included).
        chi2: ``Σ r²`` at ``params``.
        dof: residuals minus rank.
        cov_pinv: ``(P, P)`` the pseudo-inverse: the covariance of the determined
            combinations, zero along every null direction (what :func:`propagate` uses).
        undetermined: ``(K, P)`` unit directions in raw-parameter space along which no
            residual changes (gauge directions excluded).
        gauge: ``(G, P)`` the gauge directions (the norm of a raw quaternion, or of any
            parameter array the model only uses up to scale).
        names: the ``P`` parameter names of :func:`parameter_names`.
        scaled: whether ``cov`` was multiplied by ``χ²/dof``.
    """

    params: Any
    flat: jax.Array
    cov: jax.Array
    sigma: Any
    rank: int
    chi2: float
    dof: int
    cov_pinv: jax.Array | None = None
    undetermined: np.ndarray | None = None
    gauge: np.ndarray | None = None
    names: tuple[str, ...] = ()
    scaled: bool = False

    def describe(self) -> list[str]:
        """One combination per undetermined direction, in the parameters' names:
        ``"0.707·a − 0.707·b"`` means that moving ``a`` up and ``b`` down together
        changes no residual."""
        return [_combination(v, list(self.names)) for v in self.undetermined]

    def summary(self, digits: int = 4) -> str:
        """One line per raw parameter component: ``path[i] = value ± σ``."""
        lines = []
        values = jax.tree_util.tree_leaves_with_path(self.params)
        sigmas = jax.tree_util.tree_leaves(self.sigma)
        for (path, v), s in zip(values, sigmas, strict=True):
            name = jax.tree_util.keystr(path)
            for i, (vi, si) in enumerate(zip(np.ravel(v), np.ravel(s), strict=True)):
                idx = f"[{i}]" if np.ndim(v) else ""
                lines.append(f"{name}{idx} = {vi:.{digits}g} ± {si:.2g}")
        return "\n".join(lines)

    @classmethod
    def from_jacobian(
        cls,
        params,
        residuals: jax.Array,
        jac: jax.Array,
        *,
        scale_by_chi2: bool = False,
        rcond: float | None = None,
        size: int | None = None,
    ) -> Laplace:
        """The Laplace covariance from whitened residuals ``(N,)`` and their Jacobian ``(N, P)``.

        See :func:`laplace` for the arguments; ``size`` is the number of residuals that
        count (default ``N``; fewer for a :meth:`Problem.until <jrigid.fit.Problem.until>`
        whose later residuals are zero). Raises ``ValueError`` when ``residuals`` or
        ``jac`` is not finite, or ``scale_by_chi2`` without degrees of freedom.
        """
        flat, unravel = ravel_pytree(params)
        r = np.asarray(residuals, dtype=float)
        j = np.asarray(jac, dtype=float)
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(j))):
            raise ValueError(
                "laplace: the residuals or their Jacobian are not finite at params "
                "(a failed simulation, or a point outside the model's domain)"
            )
        n, p = j.shape
        dtype = jnp.asarray(flat).dtype
        cut = float(np.sqrt(np.finfo(dtype).eps)) if rcond is None else float(rcond)
        # column scaling: units do not matter; a column below the cut-off times the
        # largest (a parameter the model ignores, or one whose effect is rounding and the
        # solver's error: the overall scale of a torque-free body's moments, 1e-15 of the
        # largest column, which scaled to length 1 looked determined) is scaled as the
        # largest, so it stays as small
        norms = np.linalg.norm(j, axis=0)
        top = norms.max() if p else 0.0
        zero = norms <= cut * top
        d = np.where(zero | (norms == 0), top if top > 0 else 1.0, norms)
        _, s, vt = np.linalg.svd(j / d[None, :], full_matrices=True)
        s = np.concatenate([s, np.zeros(p - s.shape[0])]) if s.shape[0] < p else s
        keep = s > cut * (s[0] if s.shape[0] else 0.0)
        rank = int(np.sum(keep))
        inv = np.where(keep, 1.0 / np.where(keep, s, 1.0) ** 2, 0.0)
        cov_pinv = ((vt.T * inv[None, :]) @ vt) / np.outer(d, d)
        # null space in raw coordinates, orthonormal
        null = vt[~keep].T / d[:, None]  # (P, m)
        if null.shape[1]:
            null, _ = np.linalg.qr(null)
        gauge = _gauge_directions(params, j / d[None, :], d, cut * (s[0] if s.size else 0.0))
        undetermined = null
        if null.shape[1] and gauge.shape[1]:
            qg, _ = np.linalg.qr(gauge)
            rest = null - qg @ (qg.T @ null)
            u, sv, _ = np.linalg.svd(rest, full_matrices=False)
            undetermined = u[:, : max(null.shape[1] - gauge.shape[1], 0)]
            undetermined = undetermined[:, sv[: undetermined.shape[1]] > 0.5]
        undetermined = _sparse_basis(undetermined)
        chi2 = float(np.sum(r * r))
        dof = (n if size is None else int(size)) - rank
        scale = 1.0
        if scale_by_chi2:
            if dof <= 0:
                raise ValueError("scale_by_chi2 needs more residuals than parameters")
            scale = chi2 / dof
        cov_pinv = cov_pinv * scale
        involved = np.zeros(p, dtype=bool)
        if null.shape[1]:
            involved = np.max(np.abs(null), axis=1) > 1e-6
        cov = np.where(involved[:, None] | involved[None, :], np.nan, cov_pinv)
        cov[np.diag_indices(p)] = np.where(involved, np.inf, np.diagonal(cov_pinv))
        sigma = unravel(jnp.asarray(np.sqrt(np.clip(np.diagonal(cov), 0.0, None)), dtype))
        return cls(
            params=params,
            flat=flat,
            cov=jnp.asarray(cov, dtype),
            sigma=sigma,
            rank=rank,
            chi2=chi2,
            dof=dof,
            cov_pinv=jnp.asarray(cov_pinv, dtype),
            undetermined=undetermined,
            gauge=gauge.T.copy(),
            names=tuple(parameter_names(params)),
            scaled=bool(scale_by_chi2),
        )


def _sparse_basis(basis: np.ndarray) -> np.ndarray:
    """``(K, P)`` unit rows spanning the columns of ``basis (P, K)``, each with as few
    parameters as the reduced row echelon form allows (so that a parameter the model
    ignores and a pair seen only as a sum come out as separate directions)."""
    a = np.array(basis.T, dtype=float)  # (K, P)
    k, p = a.shape
    row = 0
    for col in range(p):
        if row == k:
            break
        pivot = row + int(np.argmax(np.abs(a[row:, col])))
        if abs(a[pivot, col]) < 1e-8:
            continue
        a[[row, pivot]] = a[[pivot, row]]
        a[row] /= a[row, col]
        others = np.arange(k) != row
        a[others] -= np.outer(a[others, col], a[row])
        row += 1
    a[np.abs(a) < 1e-12] = 0.0
    return a / np.linalg.norm(a, axis=1, keepdims=True) if k else a


def _gauge_directions(params, scaled_jac, d, cut) -> np.ndarray:
    """``(P, G)`` unit radial directions of the parameter arrays the model uses only up to
    scale. An array the model does not use at all (every direction of it below ``cut``)
    has no gauge: all of its directions are undetermined."""
    leaves = jax.tree_util.tree_leaves(params)
    out = []
    offset = 0
    p = scaled_jac.shape[1]
    for leaf in leaves:
        size = int(np.size(leaf))
        x = np.ravel(np.asarray(leaf, dtype=float))
        used = size and np.linalg.norm(scaled_jac[:, offset:offset + size], 2) > cut
        if size >= 2 and np.linalg.norm(x) > 0 and used:
            u = np.zeros(p)
            u[offset : offset + size] = x / np.linalg.norm(x)
            us = d * u
            if np.linalg.norm(scaled_jac @ (us / np.linalg.norm(us))) <= cut:
                out.append(u)
        offset += size
    return np.stack(out, axis=1) if out else np.zeros((p, 0))


@eqx.filter_jit
def residuals_and_jacobian(problem: Problem, params) -> tuple[jax.Array, jax.Array]:
    """Whitened residuals ``(N,)`` of ``problem`` at ``params`` and their Jacobian ``(N, P)``.

    Forward mode (``jax.jacfwd``; :class:`~jrigid.fit.Simulated` switches to
    ``diffrax.ForwardMode``); ``P`` counts the flattened parameters
    (``jax.flatten_util.ravel_pytree`` order). Compiled once per problem structure, and
    shared by :func:`laplace` and ``fit(..., method="lm")``.
    """
    flat, unravel = ravel_pytree(params)
    res = lambda x: problem.residuals(unravel(x), forward_mode=True)  # noqa: E731
    return res(flat), jax.jacfwd(res)(flat)


def laplace(
    problem: Problem,
    params,
    *,
    scale_by_chi2: bool | None = None,
    rcond: float | None = None,
) -> Laplace:
    """Gauss–Newton (Laplace) covariance ``(JᵀJ)⁻¹`` at ``params``.

    Args:
        problem: the :class:`~jrigid.fit.problem.Problem` (its whitened residuals).
        params: the optimum (raw parameter pytree).
        scale_by_chi2: multiply by ``χ²/dof`` (when the observations' ``sigma`` is only
            a relative weight, not the true noise level); default: when some
            observation was given no ``sigma`` and ``dof > 0`` (with ``dof ≤ 0`` a
            warning says that the covariance assumes ``σ = 1``).
        rcond: relative cut-off of the column-scaled singular values (see the module
            docstring); default ``√eps``.

    Returns:
        :class:`Laplace`.

    Warns:
        FitWarning: when the data do not determine some direction of the parameters
            (gauge directions excepted); the message names the combination, and every
            parameter it involves gets ``σ = inf``.
    """
    if not isinstance(problem, Problem):
        raise ValueError(f"laplace needs a Problem, got {type(problem).__name__}")
    r, jac = residuals_and_jacobian(problem, params)
    size = problem.active_size
    auto = scale_by_chi2 is None
    scale = (not problem.sigma_given) if auto else bool(scale_by_chi2)
    lap = Laplace.from_jacobian(params, r, jac, rcond=rcond, size=size)
    if scale and not (auto and lap.dof <= 0):
        lap = Laplace.from_jacobian(params, r, jac, scale_by_chi2=True, rcond=rcond, size=size)
    elif scale:
        warnings.warn(
            "laplace: σ was not given and no degrees of freedom are left to estimate it "
            f"(dof = {lap.dof}): the covariance assumes σ = 1",
            FitWarning,
            stacklevel=2,
        )
    if lap.undetermined.shape[0]:
        warnings.warn(
            "laplace: the data do not determine the direction(s) "
            + "; ".join(lap.describe())
            + " of the parameters (no residual changes along them). The parameters "
            "involved get σ = inf: fix or drop one of them, or report combinations the "
            "data do determine with fit.propagate",
            FitWarning,
            stacklevel=2,
        )
    return lap


def propagate(fn, lap: Laplace) -> tuple[jax.Array, jax.Array]:
    """Value and standard deviation of a derived quantity ``fn(params)`` (delta method).

    Args:
        fn: differentiable ``params -> array`` (e.g. moments from raw parameters, a tilt
            angle from a raw quaternion).
        lap: from :func:`laplace`.

    Returns:
        ``(value, sigma)`` of the shape of ``fn(params)``; ``sigma = sqrt(diag(G C Gᵀ))``
        with ``G = ∂fn/∂θ`` (forward mode) and ``C`` the pseudo-inverse ``cov_pinv``;
        ``inf`` for every output that moves along a direction the data do not determine
        (``|G v| > 1e-6 ‖G‖`` for a null direction ``v``, gauge directions included).
    """
    _, unravel = ravel_pytree(lap.params)
    g = lambda x: jnp.ravel(fn(unravel(x)))  # noqa: E731
    value = fn(lap.params)
    jac = jax.jacfwd(g)(lap.flat)
    c = lap.cov if lap.cov_pinv is None else lap.cov_pinv
    cov = jac @ c @ jac.T
    sigma = jnp.sqrt(jnp.clip(jnp.diagonal(cov), 0.0))
    null = [x for x in (lap.undetermined, lap.gauge) if x is not None and x.shape[0]]
    if null:
        v = jnp.asarray(np.concatenate(null, axis=0), jac.dtype)  # (K, P)
        along = jnp.max(jnp.abs(jac @ v.T), axis=1)
        size = jnp.linalg.norm(jac, axis=1)
        sigma = jnp.where(along > 1e-6 * size, jnp.inf, sigma)
    return value, sigma.reshape(jnp.shape(value))
