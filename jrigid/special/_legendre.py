"""Legendre's elliptic integrals in the parameter convention of scipy and mpmath (``m = k²``).

All are Carlson forms (DLMF 19.25.5, 19.25.9, 19.25.14, 19.25.1-3):

* ``F(φ|m) = s R_F(c², Δ², 1)``
* ``E(φ|m) = s R_F(c², Δ², 1) - (m/3) s³ R_D(c², Δ², 1)``
* ``Π(n; φ|m) = s R_F(c², Δ², 1) + (n/3) s³ R_J(c², Δ², 1, 1 - n s²)``

with ``s = sin φ``, ``c = cos φ``, ``Δ² = 1 - m s² = m1 + m c²`` (written the second way so
no digits are lost when ``m → 1``). An amplitude outside ``[-π/2, π/2]`` is reduced with
the quasi-periodicity ``F(φ + jπ) = F(φ) + 2jK`` (likewise ``E`` and ``Π``).

Every function accepts the parameter as ``m`` or its complement ``m1 = 1 - m`` (keyword):
pass ``m1`` when ``m`` is within a few ulps of 1, e.g. ``ellipk(m1=1e-12)``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jrigid._checks import as_floats

from ._carlson import _rd_sqrt, _rf_sqrt, _rj_sqrt, _safe_sqrt

__all__ = ["ellipe", "ellipeinc", "ellipk", "ellipkinc", "ellippi", "ellippiinc"]


def _params(m, m1, *others):
    """Resolve ``(m, m1)`` from whichever was given; broadcast with ``others``."""
    if m is None and m1 is None:
        raise ValueError("give the parameter m or its complement m1 = 1 - m")
    if m1 is None:
        m, *others = as_floats(m, *others, broadcast=True)
        m1 = 1.0 - m
    elif m is None:
        m1, *others = as_floats(m1, *others, broadcast=True)
        m = 1.0 - m1
    else:
        m, m1, *others = as_floats(m, m1, *others, broadcast=True)
        # both given: they must agree to rounding, else neither is trusted (NaN)
        tol = 8 * jnp.finfo(m.dtype).eps * jnp.maximum(1.0, jnp.maximum(jnp.abs(m), jnp.abs(m1)))
        clash = ~(jnp.abs(m + m1 - 1.0) <= tol)
        m, m1 = jnp.where(clash, jnp.nan, m), jnp.where(clash, jnp.nan, m1)
    return m, m1, others


# π/2 in three pieces (Cody-Waite): k times each of the first two is exact for |k| < 2^26
# (float64) or 2^11 (float32), so that φ - kπ/2 keeps full relative accuracy.
_HALF_PI_PIECES = {
    64: (
        float.fromhex("0x1.921fb58p+0"),
        -float.fromhex("0x1.dde974p-27"),
        float.fromhex("0x1.1a62633145c07p-54"),
    ),
    32: (
        float.fromhex("0x1.922p+0"),
        -float.fromhex("0x1.2aep-18"),
        -float.fromhex("0x1.de973ep-31"),
    ),
}


def _reduce_amplitude(phi):
    """``φ = jπ + φr`` with ``φr ∈ [-π/2, π/2]``: returns ``(j, sin φr, cos φr ≥ 0)``.

    ``φ`` is reduced modulo ``π/2`` to ``r ∈ [-π/4, π/4]`` first, so that near the quarter
    points ``φr → ±π/2`` the small ``cos φr = |sin r|`` keeps its relative accuracy (all of
    ``F(φ|m)`` depends on it when ``m → 1``).
    """
    p1, p2, p3 = _HALF_PI_PIECES[64 if jnp.finfo(phi.dtype).bits > 32 else 32]
    k = jnp.round(phi / (0.5 * jnp.pi))
    r = ((phi - k * p1) - k * p2) - k * p3
    odd = jnp.abs(k - 2.0 * jnp.round(0.5 * k)) == 1.0
    # k even: φr = r. k odd: φr = π/2 + r (r <= 0) or -π/2 + r (r > 0).
    up = r > 0
    j = jnp.where(odd, jnp.where(up, k + 1.0, k - 1.0) * 0.5, 0.5 * k)
    s = jnp.where(odd, jnp.where(up, -jnp.cos(r), jnp.cos(r)), jnp.sin(r))
    c = jnp.where(odd, jnp.abs(jnp.sin(r)), jnp.cos(r))
    return j, s, c


def _times_j(j, value):
    """``2 j value`` that is 0 when ``j = 0`` even if ``value`` is infinite."""
    return jnp.where(j == 0, 0.0, 2.0 * j * jnp.where(j == 0, 0.0, value))


def _k(m1):
    zero = jnp.zeros_like(m1)
    return _rf_sqrt(zero, _safe_sqrt(m1), jnp.ones_like(m1))


@jax.custom_jvp
def _e(m1):
    # E = m1 (R_D(0, m1, 1) + R_D(0, 1, m1)) / 3 (DLMF 19.25.1): no cancellation as m -> 1.
    zero, one, sm1 = jnp.zeros_like(m1), jnp.ones_like(m1), _safe_sqrt(m1)
    return m1 * (_rd_sqrt(zero, sm1, one) + _rd_sqrt(zero, one, sm1)) / 3.0


@_e.defjvp
def _e_jvp(primals, tangents):
    # dE/dm1 = (K − E) / (2m) = R_D(0, m1, 1) / 6 (DLMF 19.25.1, 19.4.2), free of the
    # cancellation that differentiating the sum above suffers as m1 → 0 (relative error
    # 5e-5 at m1 = 1e-12, 1e14 at 1e-30)
    (m1,), (dm1,) = primals, tangents
    zero, one = jnp.zeros_like(m1), jnp.ones_like(m1)
    return _e(m1), dm1 * _rd_sqrt(zero, _safe_sqrt(m1), one) / 6.0


#: The largest ``p = 1 − n sin²φ`` the third-kind integrals accept: ``K`` and ``(n/3) R_J``
#: cancel to ``Π ~ 1/√p``, a relative error of about ``eps √p`` (1e-8 at this bound; the
#: duplication steps converge up to it). Beyond, NaN.
MAX_THIRD_KIND_P = 1e16
# duplication steps of R_J for the third-kind integrals: enough up to MAX_THIRD_KIND_P
_STEPS_PI = 40


def _pi(n, m, m1):
    zero, one, sm1 = jnp.zeros_like(m1), jnp.ones_like(m1), _safe_sqrt(m1)
    sp = _safe_sqrt(1.0 - n)
    return _rf_sqrt(zero, sm1, one) + (n / 3.0) * _rj_sqrt(zero, sm1, one, sp, _STEPS_PI)


@jax.jit
def ellipk(m=None, *, m1=None) -> jax.Array:
    """Complete elliptic integral of the first kind ``K(m) = R_F(0, 1 - m, 1)``.

    Args:
        m: ``(...)`` parameter ``m ≤ 1`` (``m = 1`` gives ``inf``), or
        m1: ``(...)`` complementary parameter ``1 - m ≥ 0`` (keyword; accurate near m = 1).

    Returns:
        ``(...)`` array, equal to ``scipy.special.ellipk(m)`` / ``ellipkm1(m1)``.
    """
    m, m1, _ = _params(m, m1)
    return jnp.where(~(m1 >= 0), jnp.nan, jnp.where(m1 == 0, jnp.inf, _k(m1)))


@jax.jit
def ellipe(m=None, *, m1=None) -> jax.Array:
    """Complete elliptic integral of the second kind ``E(m)`` (DLMF 19.25.1).

    Args:
        m: ``(...)`` parameter ``m ≤ 1``, or m1: ``(...)`` complement ``1 - m`` (keyword).

    Returns:
        ``(...)`` array, equal to ``scipy.special.ellipe``.
    """
    m, m1, _ = _params(m, m1)
    inside = m1 > 0  # (m = 1: E = 1, where the derivative is infinite)
    return jnp.where(~(m1 >= 0), jnp.nan,
                     jnp.where(inside, _e(jnp.where(inside, m1, 1.0)), 1.0))


@jax.jit
def ellippi(n, m=None, *, m1=None) -> jax.Array:
    """Complete elliptic integral of the third kind ``Π(n|m) = Π(n; π/2|m)``.

    ``Π(n|m) = ∫_0^{π/2} dθ / ((1 - n sin²θ) √(1 - m sin²θ))`` (mpmath's ``ellippi(n, m)``).

    Args:
        n: ``(...)`` characteristic, ``1 − 1e16 ≤ n < 1`` (``K`` and ``n R_J / 3`` cancel: the
            relative error is about ``eps √(1 − n)``, 1e-11 at ``n = −1e10``); outside,
            NaN (``n > 1`` is a principal value, not implemented).
        m: ``(...)`` parameter ``m < 1``, or m1: ``(...)`` complement ``1 - m`` (keyword).

    Returns:
        ``(...)`` array.
    """
    m, m1, (n,) = _params(m, m1, n)
    bad = ~(m1 > 0) | ~(n < 1) | ~(1.0 - n <= MAX_THIRD_KIND_P)  # (NaN too)
    return jnp.where(bad, jnp.nan, _pi(jnp.where(bad, 0.0, n), m, jnp.where(bad, 1.0, m1)))


@jax.jit
def ellipkinc(phi, m=None, *, m1=None) -> jax.Array:
    """Incomplete elliptic integral of the first kind ``F(φ|m) = ∫_0^φ dθ/√(1 - m sin²θ)``.

    Args:
        phi: ``(...)`` amplitude, any real value (quasi-periodic extension).
        m: ``(...)`` parameter, or m1: ``(...)`` complement ``1 - m`` (keyword).

    Returns:
        ``(...)`` array, equal to ``scipy.special.ellipkinc`` / ``mpmath.ellipf``; NaN where
        ``1 - m sin²φ < 0``.
    """
    m, m1, (phi,) = _params(m, m1, phi)
    j, s, c = _reduce_amplitude(phi)
    d2 = m1 + m * c * c
    one = jnp.ones_like(s)
    out = s * _rf_sqrt(c, _safe_sqrt(d2), one) + _times_j(j, ellipk(m, m1=m1))
    return jnp.where(~(d2 >= 0), jnp.nan, out)  # (NaN too)


@jax.jit
def ellipeinc(phi, m=None, *, m1=None) -> jax.Array:
    """Incomplete elliptic integral of the second kind ``E(φ|m) = ∫_0^φ √(1 - m sin²θ) dθ``.

    Args:
        phi: ``(...)`` amplitude, any real value.
        m: ``(...)`` parameter, or m1: ``(...)`` complement ``1 - m`` (keyword).

    Returns:
        ``(...)`` array, equal to ``scipy.special.ellipeinc`` / ``mpmath.ellipe(φ, m)``.
    """
    m, m1, (phi,) = _params(m, m1, phi)
    j, s, c = _reduce_amplitude(phi)
    d2 = m1 + m * c * c
    one, sd = jnp.ones_like(s), _safe_sqrt(d2)
    f = s * _rf_sqrt(c, sd, one)
    # m <= 1/2: E = F - (m/3) s³ R_D(c², Δ², 1); m > 1/2: DLMF 19.25.9, all terms of one sign,
    # E = m1 F + (m m1/3) s³ R_D(c², 1, Δ²) + m s c / Δ.
    low = m <= 0.5
    e_low = f - (m / 3.0) * s**3 * _rd_sqrt(c, sd, one)
    sd_hi = jnp.where(low | (sd == 0), 1.0, sd)
    e_high = m1 * f + (m * m1 / 3.0) * s**3 * _rd_sqrt(c, one, sd_hi) + m * s * c / sd_hi
    out = jnp.where(low, e_low, e_high) + _times_j(j, ellipe(m, m1=m1))
    return jnp.where(~(d2 >= 0), jnp.nan, out)  # (NaN too)


@jax.jit
def ellippiinc(n, phi, m=None, *, m1=None) -> jax.Array:
    """Incomplete elliptic integral of the third kind (mpmath's ``ellippi(n, φ, m)``).

    ``Π(n; φ|m) = ∫_0^φ dθ / ((1 - n sin²θ) √(1 - m sin²θ))``.

    Args:
        n: ``(...)`` characteristic with ``n sin²φ < 1`` (and ``n < 1`` once ``|φ| > π/2``)
            and ``1 − n sin²φ ≤ 1e16`` (as :func:`ellippi`); otherwise NaN (principal
            values are not implemented).
        phi: ``(...)`` amplitude, any real value.
        m: ``(...)`` parameter, or m1: ``(...)`` complement ``1 - m`` (keyword).

    Returns:
        ``(...)`` array.
    """
    m, m1, (n, phi) = _params(m, m1, n, phi)
    j, s, c = _reduce_amplitude(phi)
    d2 = m1 + m * c * c
    p = 1.0 - n * s * s
    bad = ~(d2 >= 0) | ~(p > 0) | ~(p <= MAX_THIRD_KIND_P) | ((j != 0) & ~(n < 1))
    one, sd = jnp.ones_like(s), _safe_sqrt(d2)
    sp = _safe_sqrt(jnp.where(bad, 1.0, p))
    out = s * _rf_sqrt(c, sd, one) + (n / 3.0) * s**3 * _rj_sqrt(c, sd, one, sp, _STEPS_PI)
    full = jnp.where((j != 0) & ~bad, ellippi(jnp.where(bad, 0.0, n), m, m1=m1), 0.0)
    out = out + _times_j(j, full)
    return jnp.where(bad, jnp.nan, out)
