"""Small safe arithmetic of the closed-form torque-free motion, and the distance to the
separatrix in double-double arithmetic.

``L² − 2E I_mid = Σ I_k (I_k − I_mid) ω_k²`` is a difference of two terms, and its relative
rounding error becomes the relative error of ``1 − m`` and thus of the period. It is
evaluated exactly (error-free transformations: Dekker's product, Knuth's sum) so that the
phase after many periods is limited by the rounding of ``t`` alone.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def _safe_div(a, b):
    ok = b != 0
    return jnp.where(ok, a / jnp.where(ok, b, 1.0), 0.0)


def _clip(x, lo, hi):
    """Clip against rounding, keeping the derivative of ``x`` (straight through).

    The quantities clipped here lie in ``[lo, hi]`` mathematically; a value pushed past a
    bound by rounding must not lose its derivative (at a symmetric body ``dn τ0 = 1``
    exactly, and whether it rounds to ``1 + ulp`` must not matter)."""
    return x + jax.lax.stop_gradient(jnp.clip(x, lo, hi) - x)


def _hypot(x, y, r):
    """``sqrt(x² + r y²)`` for ``r ≥ 0`` without under/overflow, differentiable in ``r``."""
    big = jnp.maximum(jnp.abs(x), jnp.abs(y))
    ok = big > 0
    b = jnp.where(ok, big, 1.0)
    return jnp.where(ok, b * jnp.sqrt((x / b) ** 2 + r * (y / b) ** 2), 0.0)


def _unstack(x):
    return x[..., 0], x[..., 1], x[..., 2]


def _two_sum(a, b):
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


def _fast_two_sum(a, b):
    s = a + b
    return s, b - (s - a)


def _split(a):
    factor = 134217729.0 if jnp.finfo(a.dtype).bits > 32 else 4097.0  # 2^27 + 1, 2^12 + 1
    c = factor * a
    hi = c - (c - a)
    return hi, a - hi


def _two_prod(a, b):
    p = a * b
    ah, al = _split(a)
    bh, bl = _split(b)
    return p, ((ah * bh - p) + ah * bl + al * bh) + al * bl


def _dd_mul(x, y):
    p, e = _two_prod(x[0], y[0])
    return _fast_two_sum(p, e + (x[0] * y[1] + x[1] * y[0]))


def _distance_to_separatrix(i_lo, i_mid, i_hi, w_lo, w_hi):
    """``L² - 2E I_mid = I_hi (I_hi - I_mid) w_hi² - I_lo (I_mid - I_lo) w_lo²``, exactly
    rounded; the derivative is that of the plain formula."""
    plain = i_hi * (i_hi - i_mid) * w_hi**2 - i_lo * (i_mid - i_lo) * w_lo**2
    args = [jax.lax.stop_gradient(x) for x in (i_lo, i_mid, i_hi, w_lo, w_hi)]
    i_lo, i_mid, i_hi, w_lo, w_hi = args
    zero = jnp.zeros_like(i_hi)
    t_hi = _dd_mul(_dd_mul((i_hi, zero), _two_sum(i_hi, -i_mid)), _two_prod(w_hi, w_hi))
    t_lo = _dd_mul(_dd_mul((i_lo, zero), _two_sum(i_mid, -i_lo)), _two_prod(w_lo, w_lo))
    s, e = _two_sum(t_hi[0], -t_lo[0])
    exact_value = s + (e + (t_hi[1] - t_lo[1]))
    return plain + jax.lax.stop_gradient(exact_value - plain)
