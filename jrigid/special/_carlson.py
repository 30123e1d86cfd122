"""Carlson's symmetric elliptic integrals and the Legendre integrals built on them.

Carlson's duplication algorithms (B. C. Carlson, "Numerical computation of real or
complex elliptic integrals", Numer. Algorithms 10 (1995) 13-26; DLMF 19.36.i-ii) run a
fixed number of duplication steps, so they are plain ``jnp`` code that ``jit``, ``vmap``
and both forward- and reverse-mode ``grad`` go through. Every duplication step divides
the spread of the arguments by 4 and the fifth-order Taylor remainder is the sixth power
of that spread, so ``_STEPS_*`` steps reach full float64 accuracy for arguments whose
ratio is down to about 1e-100 (float32 needs fewer; the same count is used).

Internally each function takes the *square roots* of its arguments (``_rf_sqrt`` ...).
The first duplication step only needs those square roots, and taking them as inputs
keeps derivatives finite when an argument is zero: ``R_F(cos²φ, ..)`` at ``φ = π/2``
differentiates through ``cos φ`` instead of through ``sqrt(0)``.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax import lax

from jrigid._checks import as_floats

__all__ = ["elliprc", "elliprd", "elliprf", "elliprf_sqrt", "elliprj", "elliprj_sqrt"]

_STEPS_RF = 14
_STEPS_RD = 14
_STEPS_RJ = 18
# Public R_J: extra steps so that p up to 1e12 times x, y, z still converges.
_STEPS_RJ_WIDE = 30


def _safe_sqrt(x):
    """``sqrt(max(x, 0))`` with a finite (zero) derivative at zero."""
    pos = x > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def _two_zeros(x, y, z):
    """Where two of ``x, y, z`` are zero: ``R_F`` and ``R_J`` diverge there (a fixed
    number of duplication steps would return a large finite number)."""
    zx, zy, zz = x == 0, y == 0, z == 0
    return (zx & zy) | (zx & zz) | (zy & zz)


def _rc1(t):
    """``R_C(1, 1 + t)`` for ``t > -1``: ``atan(√t)/√t`` or ``atanh(√-t)/√-t``."""
    small = jnp.abs(t) < 1e-3
    ts = jnp.where(small, 1.0, t)
    pos = ts > 0
    r = jnp.sqrt(jnp.abs(ts))
    ra = jnp.where(pos, 0.5, r)
    # atanh(r) = log1p(2r/(1 - r))/2: XLA's arctanh loses ~50 ulp on CPU.
    big = jnp.where(pos, jnp.arctan(r), 0.5 * jnp.log1p(2.0 * ra / (1.0 - ra))) / r
    # Series sum_k (-t)^k / (2k + 1), exact to 1e-19 for |t| < 1e-3.
    series = 1.0 + t * (
        -1.0 / 3.0 + t * (1.0 / 5.0 + t * (-1.0 / 7.0 + t * (1.0 / 9.0 + t * (-1.0 / 11.0))))
    )
    return jnp.where(small, series, big)


def _rf_sqrt(sx, sy, sz):
    """``R_F(sx², sy², sz²)``; at most one of the arguments may be zero."""
    x, y, z = sx * sx, sy * sy, sz * sz
    a0 = (x + y + z) / 3.0
    lam = sx * sy + sx * sz + sy * sz
    state = ((x + lam) / 4.0, (y + lam) / 4.0, (z + lam) / 4.0, (a0 + lam) / 4.0)

    def step(_, s):
        x, y, z, a = s
        rx, ry, rz = jnp.sqrt(x), jnp.sqrt(y), jnp.sqrt(z)
        lam = rx * ry + rx * rz + ry * rz
        return ((x + lam) / 4.0, (y + lam) / 4.0, (z + lam) / 4.0, (a + lam) / 4.0)

    _, _, _, a = lax.fori_loop(1, _STEPS_RF, step, state)
    scale = 4.0 ** (-_STEPS_RF)
    xx = (a0 - x) * scale / a
    yy = (a0 - y) * scale / a
    zz = -(xx + yy)
    e2 = xx * yy - zz * zz
    e3 = xx * yy * zz
    poly = 1.0 - e2 / 10.0 + e3 / 14.0 + e2 * e2 / 24.0 - 3.0 * e2 * e3 / 44.0
    return poly / jnp.sqrt(a)


def _rd_rj_series(e2, e3, e4, e5):
    """The truncated series shared by R_D and R_J (Carlson 1995, eqs. 2.7 and 2.19)."""
    return (
        1.0
        - 3.0 * e2 / 14.0
        + e3 / 6.0
        + 9.0 * e2 * e2 / 88.0
        - 3.0 * e4 / 22.0
        - 9.0 * e2 * e3 / 52.0
        + 3.0 * e5 / 26.0
    )


def _rd_sqrt(sx, sy, sz):
    """``R_D(sx², sy², sz²)``; ``sz > 0`` and at most one of ``sx, sy`` zero."""
    x, y, z = sx * sx, sy * sy, sz * sz
    a0 = (x + y + 3.0 * z) / 5.0
    lam = sx * sy + sx * sz + sy * sz
    acc = 1.0 / (sz * (z + lam))
    state = (
        (x + lam) / 4.0,
        (y + lam) / 4.0,
        (z + lam) / 4.0,
        (a0 + lam) / 4.0,
        acc,
        jnp.full_like(x, 0.25),
    )

    def step(_, s):
        x, y, z, a, acc, f = s
        rx, ry, rz = jnp.sqrt(x), jnp.sqrt(y), jnp.sqrt(z)
        lam = rx * ry + rx * rz + ry * rz
        acc = acc + f / (rz * (z + lam))
        return ((x + lam) / 4.0, (y + lam) / 4.0, (z + lam) / 4.0, (a + lam) / 4.0, acc, f / 4.0)

    _, _, _, a, acc, _ = lax.fori_loop(1, _STEPS_RD, step, state)
    scale = 4.0 ** (-_STEPS_RD)
    xx = (a0 - x) * scale / a
    yy = (a0 - y) * scale / a
    zz = -(xx + yy) / 3.0
    xy = xx * yy
    z2 = zz * zz
    e2 = xy - 6.0 * z2
    e3 = (3.0 * xy - 8.0 * z2) * zz
    e4 = 3.0 * (xy - z2) * z2
    e5 = xy * z2 * zz
    poly = _rd_rj_series(e2, e3, e4, e5)
    return scale * poly / (a * jnp.sqrt(a)) + 3.0 * acc


def _rj_sqrt(sx, sy, sz, sp, steps=_STEPS_RJ):
    """``R_J(sx², sy², sz², sp²)`` for ``p > 0``; at most one of ``x, y, z`` zero."""
    x, y, z, p = sx * sx, sy * sy, sz * sz, sp * sp
    a0 = (x + y + z + 2.0 * p) / 5.0
    delta = (p - x) * (p - y) * (p - z)

    def terms(f, rx, ry, rz, rp, x, y, z, p, a):
        # f = 4^-i at duplication step i.
        lam = rx * ry + rx * rz + ry * rz
        d = (rp + rx) * (rp + ry) * (rp + rz)
        e = (f * f * f) * delta / (d * d)
        inc = f * _rc1(e) / d
        new = ((x + lam) / 4.0, (y + lam) / 4.0, (z + lam) / 4.0, (p + lam) / 4.0, (a + lam) / 4.0)
        return new, inc

    new, acc = terms(1.0, sx, sy, sz, sp, x, y, z, p, a0)

    def step(_, s):
        x, y, z, p, a, acc, f = s
        (x, y, z, p, a), inc = terms(
            f, jnp.sqrt(x), jnp.sqrt(y), jnp.sqrt(z), jnp.sqrt(p), x, y, z, p, a
        )
        return (x, y, z, p, a, acc + inc, f / 4.0)

    *_, a, acc, _ = lax.fori_loop(1, steps, step, (*new, acc, jnp.full_like(x, 0.25)))
    scale = 4.0 ** (-steps)
    xx = (a0 - x) * scale / a
    yy = (a0 - y) * scale / a
    zz = (a0 - z) * scale / a
    pp = -(xx + yy + zz) / 2.0
    p2 = pp * pp
    xyz = xx * yy * zz
    e2 = xx * yy + xx * zz + yy * zz - 3.0 * p2
    e3 = xyz + 2.0 * e2 * pp + 4.0 * p2 * pp
    e4 = (2.0 * xyz + e2 * pp + 3.0 * p2 * pp) * pp
    e5 = xyz * p2
    poly = _rd_rj_series(e2, e3, e4, e5)
    return scale * poly / (a * jnp.sqrt(a)) + 6.0 * acc


# --------------------------------------------------------------------------- public


@jax.jit
def elliprf(x, y, z) -> jax.Array:
    """Carlson's symmetric integral of the first kind ``R_F(x, y, z)`` (DLMF 19.16.1).

    Args:
        x, y, z: ``(...)`` arrays (broadcast), nonnegative, at most one zero.

    Returns:
        ``(...)`` array; matches ``scipy.special.elliprf`` for real arguments.
        Negative arguments give NaN.
    """
    x, y, z = as_floats(x, y, z, broadcast=True)
    bad = ~(x >= 0) | ~(y >= 0) | ~(z >= 0)  # (NaN too)
    out = _rf_sqrt(_safe_sqrt(x), _safe_sqrt(y), _safe_sqrt(z))
    return jnp.where(bad, jnp.nan, jnp.where(_two_zeros(x, y, z), jnp.inf, out))


@jax.jit
def elliprd(x, y, z) -> jax.Array:
    """Carlson's degenerate integral of the second kind ``R_D(x, y, z)`` (DLMF 19.16.5).

    Args:
        x, y: ``(...)`` nonnegative, at most one zero; z: ``(...)`` positive.

    Returns:
        ``(...)`` array; matches ``scipy.special.elliprd``. Invalid arguments give NaN.
    """
    x, y, z = as_floats(x, y, z, broadcast=True)
    bad = ~(x >= 0) | ~(y >= 0) | ~(z > 0)  # (NaN too)
    out = _rd_sqrt(_safe_sqrt(x), _safe_sqrt(y), _safe_sqrt(jnp.where(bad, 1.0, z)))
    return jnp.where(bad, jnp.nan, jnp.where((x == 0) & (y == 0), jnp.inf, out))


@jax.jit
def elliprj(x, y, z, p) -> jax.Array:
    """Carlson's symmetric integral of the third kind ``R_J(x, y, z, p)`` (DLMF 19.16.2).

    Args:
        x, y, z: ``(...)`` nonnegative, at most one zero; p: ``(...)`` positive (the Cauchy
            principal value for ``p < 0`` is not implemented: NaN).

    Returns:
        ``(...)`` array; matches ``scipy.special.elliprj`` for ``p > 0``. The arguments are
        first scaled by a power of two near the largest (``R_J`` is homogeneous of degree
        −3/2), so that no product inside overflows: without it, arguments of order 1e110
        or 1e-110 gave NaN.
    """
    x, y, z, p = as_floats(x, y, z, p, broadcast=True)
    bad = ~(x >= 0) | ~(y >= 0) | ~(z >= 0) | ~(p > 0)  # (NaN too)
    largest = jnp.maximum(jnp.maximum(x, y), jnp.maximum(z, p))
    usable = ~bad & jnp.isfinite(largest)
    _, e = jnp.frexp(jnp.where(usable, largest, 1.0))
    e = lax.stop_gradient(2 * (e // 2))  # even: the scale's square root is exact
    x, y, z, p = (jnp.ldexp(a, -e) for a in (x, y, z, p))
    sp = _safe_sqrt(jnp.where(bad, 1.0, p))
    out = _rj_sqrt(_safe_sqrt(x), _safe_sqrt(y), _safe_sqrt(z), sp, _STEPS_RJ_WIDE)
    out = jnp.ldexp(out, -3 * e // 2)
    return jnp.where(bad, jnp.nan, jnp.where(_two_zeros(x, y, z), jnp.inf, out))


@jax.jit
def elliprc(x, y) -> jax.Array:
    """Carlson's degenerate integral ``R_C(x, y) = R_F(x, y, y)`` (DLMF 19.2.17), closed form.

    Args:
        x: ``(...)`` nonnegative; y: ``(...)`` positive (no principal value for ``y < 0``).

    Returns:
        ``(...)`` array; matches ``scipy.special.elliprc`` for ``y > 0``.
    """
    x, y = as_floats(x, y, broadcast=True)
    bad = ~(x >= 0) | ~(y > 0)  # (NaN too)
    ys = jnp.where(bad, 1.0, y)
    r = jnp.where(bad, 1.0, x) / ys
    # R_C(r, 1) = arccos(√r)/√(1-r) for r < 1, arccosh(√r)/√(r-1) for r > 1; near r = 1
    # the series form r^-1/2 R_C(1, 1/r) avoids the removable singularity.
    low, high = r < 0.5, r > 2.0
    r_lo = jnp.where(low, r, 0.25)
    r_hi = jnp.where(high, r, 4.0)
    r_mid = jnp.where(low | high, 1.0, r)
    h = jnp.where(
        low,
        jnp.arccos(jnp.sqrt(r_lo)) / jnp.sqrt(1.0 - r_lo),
        jnp.where(
            high,
            jnp.arccosh(jnp.sqrt(r_hi)) / jnp.sqrt(r_hi - 1.0),
            _rc1(1.0 / r_mid - 1.0) / jnp.sqrt(r_mid),
        ),
    )
    return jnp.where(bad, jnp.nan, h / jnp.sqrt(ys))


@jax.jit
def elliprf_sqrt(sx, sy, sz) -> jax.Array:
    """``R_F(sx², sy², sz²)`` from the square roots of its arguments.

    The duplication algorithm starts from the square roots, so passing them avoids a
    ``sqrt`` whose derivative is infinite at zero: ``R_F(c², Δ², 1)`` differentiated
    through ``c = cos φ`` stays finite at ``φ = π/2`` (``R_F(x, ..) ≈ R_F(0, ..) −
    √x/√(yz)`` is not differentiable in ``x`` there, but is in ``c``).

    Args:
        sx, sy, sz: ``(...)`` arrays (broadcast), nonnegative, at most one zero.

    Returns:
        ``(...)`` array, ``R_F(sx², sy², sz²)`` (:func:`elliprf`). Differentiable in all
        arguments.
    """
    sx, sy, sz = as_floats(sx, sy, sz, broadcast=True)
    return _rf_sqrt(sx, sy, sz)


@functools.partial(jax.jit, static_argnames="steps")
def elliprj_sqrt(sx, sy, sz, sp, steps: int = _STEPS_RJ) -> jax.Array:
    """``R_J(sx², sy², sz², sp²)`` from the square roots of its arguments.

    Like :func:`elliprf_sqrt`, the square roots keep derivatives finite where ``x = 0``.
    The number of duplication steps is a static argument: the default (18) reaches full
    float64 accuracy when the arguments are within a factor of about ``1e12`` of each
    other or the large ones are at most ``1`` and ``p`` is not the largest by far
    (each step pulls small arguments up to the geometric means of the others); for
    ``x, y, p`` in ``[0, 1]`` and ``z = 1`` (Legendre's third-kind integral in
    Carlson's form, ``p = 1 − n sin²φ``) 12 steps suffice down to ``y = 1e-60``. Use
    :func:`elliprj` (30 steps) when ``p`` may exceed the others by more. When ``p`` is much
    smaller than ``x`` (or ``y``, ``z``) the relative error grows like ``eps √(x/p)/20``
    (the first duplication step's ``R_C`` term, shared with :func:`elliprj`); products
    such as ``sp · R_J`` stay accurate to rounding.

    Args:
        sx, sy, sz: ``(...)`` arrays (broadcast), nonnegative, at most one zero.
        sp: ``(...)`` positive.
        steps: duplication steps (static).

    Returns:
        ``(...)`` array, ``R_J(sx², sy², sz², sp²)`` (:func:`elliprj`). Differentiable in
        all arguments.
    """
    sx, sy, sz, sp = as_floats(sx, sy, sz, sp, broadcast=True)
    return _rj_sqrt(sx, sy, sz, sp, steps)
