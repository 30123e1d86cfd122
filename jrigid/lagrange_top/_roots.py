"""Roots of the heavy top's cubic ``f(u) = (1−u²)(α−βu) − (b−au)²`` without cancellation.

The method is in :mod:`jrigid.lagrange_top`: the largest root ``c'`` of the deflated cubic
first (trigonometric start polished by Newton, the last step on the traced coefficients
carrying the derivative of the implicit function), or the smallest one near the separatrix
of the sleeping top.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from jrigid.special.kernels import safe_sqrt

_NEWTON_STEPS = 4


def _safe_inv(x):
    """``1/x``, and 0 where ``x = 0`` (finite derivative there)."""
    ok = x != 0
    return jnp.where(ok, 1.0 / jnp.where(ok, x, 1.0), 0.0)


def _outer_roots(a2, a1, a0):
    """Smallest and largest root of ``c³ + a2 c² + a1 c + a0`` (three real roots).

    Returns ``(c_lo, c_hi, c_mid)``: the outer roots, differentiable, and an estimate of
    the middle one (no derivative). The trigonometric formula gives starts, Newton's method
    polishes the outer roots (monotone from outside the critical points, where the cubic
    is convex or concave), and one last Newton step on the traced coefficients carries
    the derivative ``dc = −(dg)/g'(c)`` of the implicit function.
    """

    def g(c, a2, a1, a0):
        return ((c + a2) * c + a1) * c + a0

    def gp(c, a2, a1):
        return (3.0 * c + 2.0 * a2) * c + a1

    b2, b1, b0 = (jax.lax.stop_gradient(x) for x in (a2, a1, a0))
    shift = b2 / 3.0
    p = b1 - b2 * shift
    q = (2.0 * shift * shift - b1) * shift + b0  # 2 b2³/27 - b2 b1/3 + b0
    r2 = jnp.maximum(-p / 3.0, 0.0)
    r = jnp.sqrt(r2)
    ok = r > 0
    angle = jnp.arccos(jnp.clip(-q / (2.0 * jnp.where(ok, r * r2, 1.0)), -1.0, 1.0)) / 3.0
    third = 2.0 * math.pi / 3.0
    c_lo, c_hi, c_mid = (
        jnp.where(ok, 2.0 * r * jnp.cos(angle - k * third), jnp.cbrt(-q)) - shift
        for k in (2.0, 0.0, 1.0)
    )
    # the roots lie outside the critical points (local maximum and minimum)
    disc = jnp.sqrt(jnp.maximum(b2 * b2 - 3.0 * b1, 0.0))
    c = jnp.stack([jnp.minimum(c_lo, -(disc + b2) / 3.0), jnp.maximum(c_hi, (disc - b2) / 3.0)])
    b2, b1, b0, a2, a1, a0 = (x[None] for x in (b2, b1, b0, a2, a1, a0))  # both roots at once

    def newton(_, c):
        d = gp(c, b2, b1)
        return c - jnp.where(d > 0, g(c, b2, b1, b0) / jnp.where(d > 0, d, 1.0), 0.0)

    c = jax.lax.stop_gradient(jax.lax.fori_loop(0, _NEWTON_STEPS, newton, c))
    d = gp(c, a2, a1)
    c = c - jnp.where(d > 0, g(c, a2, a1, a0) / jnp.where(d > 0, d, 1.0), 0.0)
    return c[0], c[1], c_mid


def _roots(f0, f1, f2, beta):
    """Roots of ``f(u0 + x) = β x³ + f2 x² + f1 x + f0`` as ``(c', x1, x2, x2 − x1, γ)``.

    ``c' = β x3`` and ``γ = c' − β x2 = β (u3 − u2)``, with ``x1 ≤ 0 ≤ x2``. The roots of
    ``c³ + f2 c² + β f1 c + β² f0`` are ``β x1 ≤ β x2 ≤ c'``. Usually ``c'`` is well separated
    and is found first, ``x1, x2`` following from ``x1 x2 = −f0/c'`` and ``x1 + x2 =
    (f1 − β x1 x2)/c'``. Near the separatrix of the sleeping top ``β x2`` and ``c'`` nearly
    coincide; then the smallest root is found first and the close pair comes from
    ``(β x2) c' = −β² f0/(β x1)``, ``β x2 + c' = (β f1 − (β x2) c')/(β x1)``, without
    cancellation.
    """
    r_lo, r_hi, r_mid = _outer_roots(f2, beta * f1, beta * beta * f0)
    # Newton from the trigonometric start (off by up to ~√eps of the scale when two roots
    # nearly coincide) converges to c' unless the upper pair is that close
    close_top = (beta > 0) & (r_lo < 0) & (r_hi - r_mid < 1e-4 * (r_mid - r_lo))
    # largest root first
    inv_c = _safe_inv(jnp.where(r_hi > 0, r_hi, 0.0))
    prod_roots = -f0 * inv_c  # x1 x2 <= 0
    sum_roots = (f1 - beta * prod_roots) * inv_c
    sq = safe_sqrt(sum_roots * sum_roots - 4.0 * prod_roots)  # x2 - x1
    right = sum_roots >= 0
    big = 0.5 * (sum_roots + jnp.where(right, sq, -sq))  # the root of larger size
    other = prod_roots * _safe_inv(big)
    x2 = jnp.where(right, big, other)
    x1 = jnp.where(right, other, big)
    # smallest root first
    inv_lo = _safe_inv(jnp.where(close_top, r_lo, -1.0))
    pair_prod = -beta * beta * f0 * inv_lo  # (beta x2) c' >= 0
    pair_sum = (beta * f1 - pair_prod) * inv_lo  # beta x2 + c' >= 0
    pair_gap = safe_sqrt(pair_sum * pair_sum - 4.0 * pair_prod)  # c' - beta x2
    top = 0.5 * (pair_sum + pair_gap)
    mid = pair_prod * _safe_inv(top)
    inv_beta = _safe_inv(beta)
    # c' = 0: u0 = u2 = u3 = 1, the top is at rest on the unstable equilibrium upright
    upright = top <= 0
    return (
        jnp.where(close_top, top, r_hi),
        jnp.where(close_top, jnp.where(upright, 0.0, r_lo * inv_beta), x1),
        jnp.where(close_top, mid * inv_beta, x2),
        jnp.where(close_top, jnp.where(upright, 0.0, (mid - r_lo) * inv_beta), sq),
        jnp.where(close_top, pair_gap, r_hi - beta * x2),
    )
