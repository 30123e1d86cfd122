"""Legendre's third integral in Carlson's form, for the phases ``χ± = φ ± ψ`` of the heavy top.

``e G = e sn³ R_J(cn², dn², 1, e² + n cn²)/3`` at a reduced elliptic argument, its
complete value over a quarter period with its limit at ``e = 0``, the quarter-period shift
``τ → τ − K`` and the reduction of a phase modulo ``4π`` (the method is in
:mod:`jrigid.lagrange_top`).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from jrigid import special
from jrigid.batching import sign

# Duplication steps of R_J: every argument lies in [0, 1] here (z = 1), for which 12 steps
# reach full float64 accuracy (see jrigid.special.elliprj_sqrt).
_RJ_STEPS = 12
_FOUR_PI = 4.0 * math.pi


def _safe_rsqrt(x):
    """``1/√x`` for ``x > 0``, and 0 elsewhere (finite derivative there)."""
    ok = x > 0
    return jnp.where(ok, jax.lax.rsqrt(jnp.where(ok, x, 1.0)), 0.0)


def _reduce_4pi(x):
    """``x`` modulo ``4π`` into ``[-2π, 2π]`` (two-piece Cody-Waite constant)."""
    hi = np.float32(_FOUR_PI)
    lo = _FOUR_PI - float(hi)
    k = jnp.round(x / _FOUR_PI)
    return (x - k * float(hi)) - k * lo


def _unit_complex(z, fallback):
    """``z/|z|`` (as a complex number), or ``fallback`` where ``z = 0``."""
    a2 = jnp.real(z) ** 2 + jnp.imag(z) ** 2
    ok = a2 > 0
    r = jnp.sqrt(jnp.where(ok, a2, 1.0))
    return jnp.where(ok, z / r, fallback)


def _quarter_shift(sr, cr, dr, j, kp):
    """Reduced ``(sn, cn, dn, j)`` at ``τ − K`` from those at ``τ`` (DLMF 22.4.3).

    ``(sr, cr ≥ 0, dr)`` are the values at the reduced argument ``r ∈ [−K, K]`` of
    ``τ = 2jK + r``; the result is the same for ``τ' = τ − K = 2j'K + r'``.
    """
    up = sr >= 0
    return (
        jnp.where(up, -cr, cr) / dr,
        kp * jnp.abs(sr) / dr,
        kp / dr,
        jnp.where(up, j, j - 1.0),
    )


def _rj(sx, sy, sp):
    """``R_J(sx², sy², 1, sp²)`` for stacked arguments (one call site: one compiled loop)."""
    return special.elliprj_sqrt(sx, sy, jnp.ones_like(sx), sp, steps=_RJ_STEPS)


def _partial_args(e, n, sr, cr, dr):
    """``R_J`` square-root arguments of ``e G`` at a reduced point, and where ``p > 0``."""
    p = e * e + n * cr * cr
    ok = p > 0
    return (cr, dr, jnp.sqrt(jnp.where(ok, p, 1.0))), ok


def _partial(rj, ok, e, sr):
    """``e G = e sn³ R_J(cn², dn², 1, e² + n cn²)/3`` from its ``R_J`` (0 where ``p = 0``)."""
    return jnp.where(ok, e * sr**3 * rj / 3.0, 0.0)


def _complete_args(e, kp):
    """``R_J`` square-root arguments of the quarter-period ``e G``: ``(0, √m1, |e|)``."""
    ok = e * e > 0
    return (jnp.zeros_like(e), kp, jnp.where(ok, jnp.abs(e), 1.0)), ok


def _complete(rj, ok, e, kp, m1, e_complete):
    """``e R_J(0, m1, 1, e²)/3`` from its ``R_J``, with its limit at ``e = 0``."""
    limit = sign(e) * math.pi / (2.0 * kp) - e * e_complete / m1
    return jnp.where(ok, e * rj / 3.0, limit)
