"""The Taylor branch of the closed-form torque-free motion: short times and slow motions.

Near a spherical body, or a symmetric one spun in its degenerate plane, ``λ → 0`` and the
elliptic constants are not smooth functions of the moments although the motion is. For
``λ |t| ≤ 1/32`` ``ω`` and ``ψ`` are Taylor polynomials in ``t`` of degree 10 and 11 (the
method is in :mod:`jrigid.exact`): ``_taylor`` computes their coefficients for
:func:`~jrigid.exact.prepare` and ``_series`` evaluates them.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ._arith import _unstack

# Taylor branch: degree of ω(t) and the largest λ|t| it is used for.
_SERIES_ORDER = 10
_SLOW = 1.0 / 32.0


def _taylor(ic, wc, lnorm, two_e, sigma, scale, order):
    """Taylor coefficients of ``ω`` (canonical) and ``ψ`` in ``y = t / scale``.

    Returns ``(c, p)``: ``c`` ``(..., order + 1, 3)`` with ``ω = Σ c_n yⁿ`` (Euler's
    equations by Cauchy products), ``p`` ``(..., order + 1)`` with ``ψ = Σ p_n y^(n+1)``
    from ``ψ̇ = (2E/|L| + σ ω3) / (1 + σ I3 ω3/|L|)`` by series division. Working in ``y``
    keeps the coefficients of order ``(λ scale)ⁿ``, without under- or overflow.
    """
    i1, i2, i3 = _unstack(ic)
    # (I ω) × ω = ((I2 - I3) ω2 ω3, (I3 - I1) ω3 ω1, (I1 - I2) ω1 ω2): exactly zero for a
    # steady motion, and differences of moments are exact.
    rate = scale[..., None] * jnp.stack([(i2 - i3) / i1, (i3 - i1) / i2, (i1 - i2) / i3], -1)
    size = order + 1
    index = jnp.arange(size)
    batch = (1,) * (wc.ndim - 1)

    def omega_step(n, c):
        # c_{n+1} = rate Σ_{k ≤ n} (c_k × c_{n-k} without the moments) / (n + 1)
        use = (index <= n).astype(c.dtype).reshape(batch + (size, 1))
        partner = jnp.take(c, jnp.clip(n - index, 0, order), axis=-2)
        cauchy = jnp.sum(use * c[..., (1, 2, 0)] * partner[..., (2, 0, 1)], axis=-2)
        return c.at[..., n + 1, :].set(rate * cauchy / (n + 1))

    c = jnp.zeros(wc.shape[:-1] + (size, 3), wc.dtype).at[..., 0, :].set(wc)
    c = jax.lax.fori_loop(0, order, omega_step, c)
    e = c[..., 2]
    g = (sigma * ic[..., 2] / lnorm)[..., None]
    num = (sigma[..., None] * e).at[..., 0].add(two_e / lnorm)
    den = (g * e).at[..., 0].add(1.0)

    def psi_step(n, ratio):
        # num = den ratio as power series:
        # ratio_n = (num_n - Σ_{1 ≤ k ≤ n} den_k ratio_{n-k}) / den_0
        use = ((index >= 1) & (index <= n)).astype(ratio.dtype).reshape(batch + (size,))
        partner = jnp.take(ratio, jnp.clip(n - index, 0, order), axis=-1)
        acc = num[..., n] - jnp.sum(use * den * partner, axis=-1)
        return ratio.at[..., n].set(acc / den[..., 0])

    ratio = jax.lax.fori_loop(0, size, psi_step, jnp.zeros_like(num))
    p = scale[..., None] * ratio / (index + 1).astype(ratio.dtype).reshape(batch + (size,))
    return c, p


def _series(c, st, slow):
    """``(ω, ψ)`` of the Taylor branch (zeros where ``slow`` is false)."""
    y = jnp.where(slow, st / c.series_scale, 0.0)
    # When lambda = 0 the first-order change of the motion has degree 2 (3 for psi): the
    # higher terms vanish with their derivatives and are left out for unbounded t.
    y_hi = jnp.where(slow & (c.slow_rate > 0), y, 0.0)
    cw, cp = c.series_omega, c.series_psi
    inner = cw[..., _SERIES_ORDER, :]
    for n in range(_SERIES_ORDER - 1, 2, -1):
        inner = cw[..., n, :] + y_hi[..., None] * inner
    yv = y[..., None]
    omega = cw[..., 0, :] + yv * (cw[..., 1, :] + yv * (cw[..., 2, :] + y_hi[..., None] * inner))
    inner = cp[..., _SERIES_ORDER]
    for n in range(_SERIES_ORDER - 1, 2, -1):
        inner = cp[..., n] + y_hi * inner
    psi = y * (cp[..., 0] + y * (cp[..., 1] + y * (cp[..., 2] + y_hi * inner)))
    return omega, psi
