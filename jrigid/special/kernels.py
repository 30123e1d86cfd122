"""Unchecked kernels of the special functions, for closed-form solvers built on them.

The public functions of :mod:`jrigid.special` check their domain, broadcast and convert
their arguments. A solver that has already arranged its arguments (``jrigid.exact``)
calls these kernels instead; they are the same code, differentiable in forward and reverse
mode, but arguments outside the stated domain give unspecified results (not NaN).

* :func:`rf_sqrt`, :func:`rj_sqrt` — Carlson's ``R_F`` and ``R_J`` given the *square roots*
  of their arguments, so that derivatives stay finite where an argument is zero
  (``R_F(cos²φ, ..)`` at ``φ = π/2`` differentiates through ``cos φ``, not ``sqrt(0)``);
* :func:`safe_sqrt` — ``sqrt(max(x, 0))`` with a finite derivative at zero;
* :func:`parity_sign` — ``(-1)^j`` for an integer-valued float;
* :func:`jacobi_with_index` — ``sn, cn, dn, am`` and the half-period index (re-exported).
"""

from __future__ import annotations

import jax

from ._carlson import _rf_sqrt, _rj_sqrt, _safe_sqrt
from ._jacobi import _parity_sign, jacobi_with_index

__all__ = ["jacobi_with_index", "parity_sign", "rf_sqrt", "rj_sqrt", "safe_sqrt"]


def rf_sqrt(sx, sy, sz) -> jax.Array:
    """``R_F(sx², sy², sz²)`` (DLMF 19.16.1) for ``sx, sy, sz ≥ 0``, at most one zero.

    Args:
        sx, sy, sz: ``(...)`` arrays of one shape (no broadcasting or conversion).

    Returns:
        ``(...)`` array, full float64 accuracy for argument ratios down to about 1e-100.
    """
    return _rf_sqrt(sx, sy, sz)


def rj_sqrt(sx, sy, sz, sp, steps: int = 18) -> jax.Array:
    """``R_J(sx², sy², sz², sp²)`` (DLMF 19.16.2) for ``sx, sy, sz ≥ 0`` (at most one
    zero) and ``sp > 0``.

    Args:
        sx, sy, sz, sp: ``(...)`` arrays of one shape.
        steps: number of duplication steps (static). 12 give full float64 accuracy for
            ``x, y, z ≤ 1 = z`` and ``1 ≤ p ≤ 10⁴`` with ``y`` down to 1e-60; larger ``p``
            needs more (18 reach ``p = 10⁸``).

    Returns:
        ``(...)`` array.
    """
    return _rj_sqrt(sx, sy, sz, sp, steps=steps)


def safe_sqrt(x) -> jax.Array:
    """``sqrt(max(x, 0))`` whose derivative at ``x ≤ 0`` is zero instead of infinite.

    Args:
        x: ``(...)`` array.

    Returns:
        ``(...)`` array.
    """
    return _safe_sqrt(x)


def parity_sign(j) -> jax.Array:
    """``(-1)^j`` for an integer-valued float ``j`` (``(...)``); returns ``(...)``."""
    return _parity_sign(j)
