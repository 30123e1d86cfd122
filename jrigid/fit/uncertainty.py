"""Gauss–Newton (Laplace) uncertainty at an optimum.

For whitened residuals ``r(θ)`` (unit-variance Gaussian noise) the loss ``½ Σ r²`` has
the Gauss–Newton Hessian ``H = Jᵀ J`` with ``J = ∂r/∂θ``; the Laplace approximation of
the posterior (flat prior) is ``N(θ̂, H⁻¹)``. ``J`` is computed by forward mode
(``jax.jacfwd``; the :class:`~jrigid.fit.problem.Simulated` model switches to
``diffrax.ForwardMode``), which costs one tangent solve per parameter — cheap for the
few parameters of a rigid-body fit.

``H⁻¹`` comes from the singular value decomposition of ``J`` (not of ``H``, whose
condition number is the square); singular values below ``rcond`` times the largest are
treated as zero (a pseudo-inverse) and counted out of ``rank``: a raw
quaternion has one such direction (its norm), a fit with an unobservable parameter
another. Report derived, observable quantities with :func:`propagate`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from jrigid.fit.problem import Problem

__all__ = ["Laplace", "laplace", "propagate"]


@dataclass
class Laplace:
    """Gauss–Newton covariance of the raw parameters at ``params``.

    Attributes:
        params: the parameter pytree (the optimum).
        flat: ``(P,)`` the parameters flattened (``jax.flatten_util.ravel_pytree`` order).
        cov: ``(P, P)`` covariance.
        sigma: pytree like ``params``, the standard deviations.
        rank: numerical rank of ``JᵀJ`` (``< P`` when some direction is unobservable).
        chi2: ``Σ r²`` at ``params``.
        dof: residuals minus rank.
    """

    params: Any
    flat: jax.Array
    cov: jax.Array
    sigma: Any
    rank: int
    chi2: float
    dof: int

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


@eqx.filter_jit
def _residuals_and_jacobian(problem, params):
    flat, unravel = ravel_pytree(params)
    res = lambda x: problem.residuals(unravel(x), forward_mode=True)  # noqa: E731
    return res(flat), jax.jacfwd(res)(flat)


def laplace(
    problem: Problem,
    params,
    *,
    scale_by_chi2: bool = False,
    rcond: float | None = None,
) -> Laplace:
    """Gauss–Newton (Laplace) covariance ``(JᵀJ)⁻¹`` at ``params``.

    Args:
        problem: the :class:`~jrigid.fit.problem.Problem` (its whitened residuals).
        params: the optimum (raw parameter pytree).
        scale_by_chi2: multiply by ``χ²/dof`` (when the observations' ``sigma`` is only
            a relative weight, not the true noise level).
        rcond: relative singular-value cut-off of the pseudo-inverse (singular values
            of ``J`` below ``rcond`` times the largest count as zero); default
            ``10 · eps · max(N, P)``.

    Returns:
        :class:`Laplace`.
    """
    flat, unravel = ravel_pytree(params)
    r, jac = _residuals_and_jacobian(problem, params)
    if not bool(jnp.all(jnp.isfinite(r)) & jnp.all(jnp.isfinite(jac))):
        raise ValueError(
            "laplace: the residuals or their Jacobian are not finite at params "
            "(a failed simulation, or a point outside the model's domain)"
        )
    # SVD of J rather than an eigen-decomposition of JᵀJ, which would square the
    # condition number (and lose the small singular values in float32).
    _, s, vt = jnp.linalg.svd(jac, full_matrices=False)
    n, p = jac.shape
    cut = (10.0 * jnp.finfo(jac.dtype).eps * max(n, p) if rcond is None else rcond) * s[0]
    keep = s > cut
    inv = jnp.where(keep, 1.0 / jnp.where(keep, s, 1.0) ** 2, 0.0)
    cov = (vt.T * inv[None, :]) @ vt
    rank = int(jnp.sum(keep))
    chi2 = float(jnp.sum(r * r))
    dof = int(r.shape[0]) - rank
    if scale_by_chi2:
        if dof <= 0:
            raise ValueError("scale_by_chi2 needs more residuals than parameters")
        cov = cov * (chi2 / dof)
    sigma = unravel(jnp.sqrt(jnp.clip(jnp.diagonal(cov), 0.0)))
    return Laplace(params, flat, cov, sigma, rank, chi2, dof)


def propagate(fn, lap: Laplace) -> tuple[jax.Array, jax.Array]:
    """Value and standard deviation of a derived quantity ``fn(params)`` (delta method).

    Args:
        fn: differentiable ``params -> array`` (e.g. moments from raw parameters, a tilt
            angle from a raw quaternion).
        lap: from :func:`laplace`.

    Returns:
        ``(value, sigma)`` of the shape of ``fn(params)``; ``sigma = sqrt(diag(G C Gᵀ))``
        with ``G = ∂fn/∂θ`` (forward mode).
    """
    _, unravel = ravel_pytree(lap.params)
    g = lambda x: jnp.ravel(fn(unravel(x)))  # noqa: E731
    value = fn(lap.params)
    jac = jax.jacfwd(g)(lap.flat)
    cov = jac @ lap.cov @ jac.T
    sigma = jnp.sqrt(jnp.clip(jnp.diagonal(cov), 0.0)).reshape(jnp.shape(value))
    return value, sigma
