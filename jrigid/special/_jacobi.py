"""Jacobi elliptic functions ``sn, cn, dn`` and the amplitude ``am`` (parameter ``m = k²``).

Algorithm (no AGM, so no ``cos(am)`` cancellation near ``m → 1``):

1. Reduce ``u = 2jK + r`` with ``|r| ≤ K``; ``sn, cn`` change sign with ``j`` and ``dn``
   does not (DLMF 22.4.3).
2. Fold ``|r|`` into ``[0, K/2]``: for ``|r| > K/2`` use ``w = K - |r|`` and
   ``sn(K - w) = cd w``, ``cn(K - w) = k' sd w``, ``dn(K - w) = k' nd w`` (DLMF 22.4.3),
   all products and quotients, exact near the separatrix where ``cn`` and ``dn`` are tiny.
3. Halve ``w`` ``N`` times to below ``0.025``, sum the Maclaurin series of ``sn`` and of
   ``1 - cn`` there (DLMF 22.10.1-2, to ``u¹⁰``), then double ``N`` times with the
   duplication formulas (DLMF 22.8.1-3) written without cancellation:
   ``1 - cn(2u) = 2 sn² dn² / D`` and ``cn(2u) = (m cn⁴ + m1(2cn² - 1)) / D`` with
   ``D = dn² + m sn² cn²`` and ``dn² = m1 + m cn²``, and ``sn(2u) = 2 sn cn dn / D``.
   ``1 - cn`` is carried while it is below 1/2 and ``cn`` afterwards (as in Fukushima's
   conditional duplication), so both stay accurate to a few ulps.

Derivatives are analytic (``jax.custom_jvp``): ``∂u sn = cn dn``, ``∂u cn = -sn dn``,
``∂u dn = -m sn cn``, and ``∂m am = -dn ∂m F(φ|m)`` at fixed ``u`` with the Carlson form
``∂m F(φ|m) = sin³φ R_D(cos²φ, 1, Δ²)/6`` plus ``2j dK/dm`` per half period.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax

from ._carlson import _rd_sqrt, _rf_sqrt, _safe_sqrt
from ._legendre import _params, _times_j

__all__ = ["am", "cn", "complete_k", "dn", "ellipj", "jacobi_with_index", "sn"]

_U_SMALL = 0.025
_MAX_HALVINGS = 16  # K/2 < 0.025 * 2**16 for every representable m1 > 0.


def _base(w, m, m1):
    """``(sn, cn, dn)(w|m)`` for ``0 ≤ w ≤ max(K/2, 0.025·2¹⁶)`` by halving and doubling."""
    ratio = jnp.maximum(w / _U_SMALL, 1.0)
    n = jnp.clip(jnp.ceil(jnp.log2(ratio)), 0, _MAX_HALVINGS).astype(jnp.int32)
    u = jnp.ldexp(w, -n)
    v = u * u
    m2, m3, m4 = m * m, m * m * m, m * m * m * m
    b = v * (
        0.5
        - v
        * (
            (1.0 + 4.0 * m) / 24.0
            - v
            * (
                (1.0 + 44.0 * m + 16.0 * m2) / 720.0
                - v
                * (
                    (1.0 + 408.0 * m + 912.0 * m2 + 64.0 * m3) / 40320.0
                    - v * (1.0 + 3688.0 * m + 30768.0 * m2 + 15808.0 * m3 + 256.0 * m4) / 3628800.0
                )
            )
        )
    )
    s = u * (
        1.0
        - v
        * (
            (1.0 + m) / 6.0
            - v
            * (
                (1.0 + 14.0 * m + m2) / 120.0
                - v
                * (
                    (1.0 + 135.0 * m + 135.0 * m2 + m3) / 5040.0
                    - v * (1.0 + 1228.0 * m + 5478.0 * m2 + 1228.0 * m3 + m4) / 362880.0
                )
            )
        )
    )
    c = 1.0 - b

    def double(i, state):
        s, b, c = state
        s2, c2 = s * s, c * c
        d2 = m1 + m * c2
        den = d2 + m * s2 * c2
        s_new = 2.0 * s * c * jnp.sqrt(d2) / den
        b_new = 2.0 * s2 * d2 / den
        c_new = (m * c2 * c2 + m1 * (2.0 * c2 - 1.0)) / den
        b_mode = b_new < 0.5
        b_new, c_new = jnp.where(b_mode, b_new, 1.0 - c_new), jnp.where(b_mode, 1.0 - b_new, c_new)
        active = i < n
        return (
            jnp.where(active, s_new, s),
            jnp.where(active, b_new, b),
            jnp.where(active, c_new, c),
        )

    s, b, c = lax.fori_loop(0, _MAX_HALVINGS, double, (s, b, c))
    return s, c, jnp.sqrt(m1 + m * c * c)


def _parity_sign(j):
    """``(-1)^j`` for an integer-valued float ``j``."""
    return 1.0 - 2.0 * (j - 2.0 * jnp.floor(j / 2.0))


def _jacobi(u, m, m1, kk):
    """``(sn, cn, dn, am, j)`` where ``u = 2jK + r``, ``|r| ≤ K``; ``kk = K(m)`` (no jvp)."""
    finite = m1 > 0
    k_safe = jnp.where(finite, kk, 1.0)
    j = jnp.where(finite, jnp.round(u / (2.0 * k_safe)), 0.0)
    r = u - 2.0 * j * k_safe
    ar = jnp.abs(r)
    upper = finite & (ar > 0.5 * k_safe)
    w = jnp.where(upper, jnp.maximum(k_safe - ar, 0.0), ar)
    w_base = jnp.where(finite, w, 0.0)
    s, c, d = _base(w_base, m, m1)
    kp = jnp.sqrt(jnp.maximum(m1, 0.0))
    sr = jnp.where(upper, c / d, s)
    cr = jnp.where(upper, kp * s / d, c)
    dr = jnp.where(upper, kp / d, d)
    # m = 1 (m1 = 0): sn = tanh, cn = dn = sech.
    t = jnp.where(finite, 0.0, w)
    sr = jnp.where(finite, sr, jnp.tanh(t))
    cr = jnp.where(finite, cr, 1.0 / jnp.cosh(t))
    dr = jnp.where(finite, dr, 1.0 / jnp.cosh(t))
    sr = jnp.where(r < 0, -sr, sr)
    phi = j * jnp.pi + jnp.arctan2(sr, cr)
    sign = _parity_sign(j)
    bad = ~((m1 >= 0) & (m1 <= 1)) | ~jnp.isfinite(u)  # (NaN too)
    nan = jnp.nan
    return (
        jnp.where(bad, nan, sign * sr),
        jnp.where(bad, nan, sign * cr),
        jnp.where(bad, nan, dr),
        jnp.where(bad, nan, phi),
        j,
    )


def _am_dm(sn, cn, dn, j, m1):
    """``∂am/∂m`` at fixed ``u`` from the values at ``u`` and the half-period index ``j``."""
    sign = _parity_sign(j)
    sr, cr = sign * sn, sign * cn  # values at the reduced argument, cr ≥ 0
    one = jnp.ones_like(sn)
    # One R_D call for both R_D(cos²φr, 1, Δ²) and R_D(0, 1, m1) (= 6 dK/dm).
    rd = _rd_sqrt(
        jnp.stack([cr, jnp.zeros_like(cr)]),
        jnp.stack([one, one]),
        jnp.stack([dn, jnp.broadcast_to(_safe_sqrt(m1), dn.shape)]),
    )
    f_m = sr**3 * rd[0] / 6.0
    k_m = rd[1] / 6.0
    return -dn * (f_m + _times_j(j, k_m))


@jax.custom_jvp
def _ellipj_all(u, m, m1, kk):
    return _jacobi(u, m, m1, kk)


@_ellipj_all.defjvp
def _ellipj_all_jvp(primals, tangents):
    # kk = K(m) only selects the period reduction; its tangent is covered by dm.
    u, m, m1, kk = primals
    du, dm, dm1, _ = tangents
    sn, cn, dn, am, j = _ellipj_all(u, m, m1, kk)
    dpar = 0.5 * (dm - dm1)  # m and m1 = 1 - m are one parameter
    am_m = _am_dm(sn, cn, dn, j, m1)
    dam = dn * du + am_m * dpar
    dn_m = -(0.5 * sn * sn + m * sn * cn * am_m) / dn
    ddn = -m * sn * cn * du + dn_m * dpar
    return (sn, cn, dn, am, j), (cn * dam, -sn * dam, ddn, dam, jnp.zeros_like(j))


def complete_k(m1):
    """``K(m) = R_F(0, m1, 1)`` from the complement ``m1 = 1 − m``.

    Args:
        m1: ``(...)`` complementary parameter, ``0 < m1 ≤ 1`` (``m1 = 0`` gives ``inf``).

    Returns:
        ``(...)`` array; differentiable (the ``K`` that :func:`jacobi_with_index` takes).
    """
    return _rf_sqrt(jnp.zeros_like(m1), _safe_sqrt(m1), jnp.ones_like(m1))


def jacobi_with_index(u, m, m1, kk):
    """``(sn, cn, dn, am, j)`` with ``j = round(u / 2K)``; ``m, m1`` and ``kk = K(m)`` given.

    ``(-1)^j (sn, cn)`` are the values at ``u - 2jK ∈ [-K, K]`` (so ``(-1)^j cn ≥ 0``);
    used by :mod:`jrigid.exact` and :mod:`jrigid.lagrange_top` to unwrap quasi-periodic
    integrals (``∫_0^u f = 2j ∫_0^K f + ∫_0^r f`` for ``f`` of period ``2K``).

    Args:
        u: ``(...)`` argument, any real value.
        m, m1: ``(...)`` parameter and its complement ``1 − m`` (both given, consistent).
        kk: ``(...)`` ``K(m)``; must equal :func:`complete_k` ``(m1)`` (not differentiated).

    Returns:
        ``(sn, cn, dn, am, j)``, each ``(...)``; ``j`` is an integer-valued float.
        Differentiable in ``u, m, m1``.
    """
    return _ellipj_all(u, m, m1, kk)


@jax.jit
def ellipj(u, m=None, *, m1=None):
    """Jacobi elliptic functions and amplitude, like ``scipy.special.ellipj``.

    Args:
        u: ``(...)`` argument, any real value.
        m: ``(...)`` parameter in ``[0, 1]``, or
        m1: ``(...)`` complement ``1 - m`` (keyword): exact near the separatrix ``m → 1``,
            e.g. ``ellipj(u, m1=1e-13)``. If both are given they must agree to rounding
            (``|m + m1 − 1| ≤ 8 eps``, else the values are NaN); each is then used where
            it is the accurate one.

    Returns:
        ``(sn, cn, dn, am)``, each ``(...)``; ``am`` is continuous (unwrapped). Outside
        ``0 ≤ m ≤ 1`` the values are NaN. Differentiable in ``u`` and ``m`` (``m < 1``).
    """
    m, m1, (u,) = _params(m, m1, u)
    sn_, cn_, dn_, am_, _ = _ellipj_all(u, m, m1, complete_k(m1))
    return sn_, cn_, dn_, am_


@jax.jit
def sn(u, m=None, *, m1=None) -> jax.Array:
    """Jacobi ``sn(u|m)``; arguments as :func:`ellipj`. Returns ``(...)``."""
    return ellipj(u, m, m1=m1)[0]


@jax.jit
def cn(u, m=None, *, m1=None) -> jax.Array:
    """Jacobi ``cn(u|m)``; arguments as :func:`ellipj`. Returns ``(...)``."""
    return ellipj(u, m, m1=m1)[1]


@jax.jit
def dn(u, m=None, *, m1=None) -> jax.Array:
    """Jacobi ``dn(u|m)``; arguments as :func:`ellipj`. Returns ``(...)``."""
    return ellipj(u, m, m1=m1)[2]


@jax.jit
def am(u, m=None, *, m1=None) -> jax.Array:
    """Jacobi amplitude ``am(u|m)``, the inverse of ``F(φ|m)``, continuous in ``u``.

    Arguments as :func:`ellipj`. Returns ``(...)``.
    """
    return ellipj(u, m, m1=m1)[3]
