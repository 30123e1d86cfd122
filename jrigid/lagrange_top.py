"""The heavy symmetric (Lagrange) top in closed form: q(t) and ω(t) at any time, without stepping.

A body with central moments ``I1 = I2`` and its centre of mass on the symmetry axis
(``body.com = (0, 0, l)``), on a fixed frictionless pivot under uniform gravity ``g`` (the
chapter's Problem 17.2; :class:`~jrigid.scene.Pivot` with :class:`~jrigid.scene.Gravity`).
``prepare`` computes a pytree of per-top constants once; ``evaluate`` then costs the same
at every time (one Jacobi triple and two Carlson ``R_J``), however far out; ``solve`` does
both. ``applies``/``check_scene`` say whether a :class:`~jrigid.scene.Scene` is such a top.

Method
------
*Integrals.* With ``A = I1 + M l²`` (the transverse moment about the pivot), ``C = I3``,
the vertical ``ẑ = −sign(l) g/|g|`` (so that the potential is ``+M|g||l| u``) and
``u = cos θ = ẑ·(R e3)``, energy, ``L·ẑ = A b`` and ``L·e3 = C ω3 = A a`` give the
classical (Goldstein §5.7) ``u̇² = f(u) = (1−u²)(α−βu) − (b−au)²`` with ``β = 2M|g||l|/A``.
Its roots are ``u1 ≤ u(t) ≤ u2 ≤ 1 ≤ u3`` and

    u(t) = u1 + (u2 − u1) sn²(τ | m),  τ = ω_n t + τ0,
    m = (u2 − u1)/(u3 − u1),  ω_n = ½ √(β (u3 − u1)),   nutation period 2K(m)/ω_n.

Everything is formed from the body-frame vertical ``n = (n1, n2, u0)`` and ``ω`` without
cancellation: ``f(u0) = u̇0² = (n1 ω2 − n2 ω1)²``, ``b − a u0 = n1 ω1 + n2 ω2``,
``α − β u0 = ω1² + ω2²``, so that ``f(u0 + x) = β x³ + f2 x² + f1 x + f0``. ``c' = β (u3 − u0)``
is the largest root of ``c³ + f2 c² + β f1 c + β² f0`` (trigonometric formula polished by
Newton; the last step carries the derivative of the implicit function), which stays
well-defined as ``β → 0`` (no gravity, or the pivot at the centre of mass); then
``x1 x2 = −f0/c'`` (≤ 0) and ``x1 + x2 = (f1 + β f0/c')/c'`` give the other two roots
without cancellation. Near the separatrix of the sleeping top ``u2`` and ``u3`` are close
and the smallest root is found first instead. Distances to the poles, ``1 − u2`` and
``1 + u1``, come from ``(b ∓ a)² = β (1 ∓ u1)(1 ∓ u2)(u3 ∓ 1)``, so that they stay
consistent with ``b ∓ a`` however close the top comes to the vertical (or to hanging
straight down).

*Orientation without gimbal lock.* In a space frame whose ``z`` axis is ``ẑ`` (fixed
rotation ``Q_v``), with ZXZ angles ``φ, θ, ψ``, the quaternion is
``(C₊ cos(χ₊/2), S₋ cos(χ₋/2), S₋ sin(χ₋/2), C₊ sin(χ₊/2))`` with ``C₊ = cos(θ/2) =
√((1+u)/2)``, ``S₋ = sin(θ/2) = √((1−u)/2)`` and ``χ± = φ ± ψ``. The two phases have rates

    χ̇₊ = ω3 − a + (b + a)/(1 + u),   χ̇₋ = a − ω3 + (b − a)/(1 − u),

each singular only at the pole where its amplitude ``C₊`` or ``S₋`` vanishes, so ``θ = 0``
and ``θ = π`` are ordinary points. Their integrals are Legendre's third-kind integrals in
Carlson's form, ``∫ dτ/(1 − u) = (τ + n₋ G(τ))/(1 − u1)`` with ``n₋ = (u2 − u1)/(1 − u1)``
and ``G = sn³ R_J(cn², dn², 1, 1 − n sn²)/3`` unwrapped over half periods, and, after the
quarter-period shift ``τ' = τ − K`` (``sn τ = cd τ'``), ``∫ dτ/(1 + u) = (τ' + (N − m) G(τ'))
/(1 + u2)`` with ``N = ((1 + u1) m + u2 − u1)/(1 + u2)``; both characteristics lie in
``[m, 1]``. The weight of ``G`` is proportional to ``e = ±√(1 − n)`` (``e₋ ∝ b − a``,
``e₊ ∝ b + a``), so each phase is carried as ``W̃ · (e G)``: as the top passes ever closer to
the vertical, ``χ₋`` steps by ``±2π`` at each passage (the half-angle components change
sign; likewise ``χ₊`` near the bottom), and at exactly ``b = a`` that step is taken from the
closed-form limit ``e R_J(0, m1, 1, e²)/3 → ±π/(2√m1) − e E(m)/m1``. A start exactly at a
pole takes the phase of the departure direction (``ż₋ = ½ z₊ (ω1 + iω2)`` at ``θ = 0``).

*Angular velocity.* ``ω3`` is constant; ``ω1 + iω2 = e^{−iψ}(θ̇ + i φ̇ sin θ)`` is written as
``½ e^{i(χ₋−χ₊)/2}(C₊ R₋ − S₋ R̄₊)`` with ``R₋ = (−u̇ + i(b − a))/S₋`` and
``R₊ = (u̇ + i(b + a))/C₊``, both bounded and evaluated in the reduced elliptic variables.

*Long times.* ``τ`` is reduced modulo the period ``2K`` (index ``j``) and each phase is
``Ω t_r + W̃ (e G(r) − e G(τ0)) + j Δ`` with ``t_r`` the reduced time and ``Δ`` the phase
advance per nutation period (taken modulo ``4π``): the cost and the size of every argument
are independent of ``t``; the error grows like the rounding of the time itself,
``eps·t·|ω|``. Inputs are rescaled by a power of two (time unit ``1/ν``).

Degenerate motions: an exactly steady ``u`` (steady precession, the sleeping top, a top at
rest upright or hanging) goes through the same formulas (``u2 = u1``). A motion exactly on
the separatrix of the sleeping top (``u2 = u3 = 1`` to the last bit) is evaluated with
``m1`` replaced by the smallest normal number, i.e. as a very long but finite period.

Derivatives: everything is ``jnp`` plus the differentiable functions of
:mod:`jrigid.special`, so ``jax.grad``/``jax.jacfwd`` work with respect to the moments, the
mass, ``com``, ``g``, ``q0``, ``ω0`` and ``t`` (checked against finite differences and
forward-mode integration in ``tests/test_lagrange_top.py``). They are derivatives within
the family of symmetric tops: the transverse moment is ``(I1 + I2)/2``, so ``∂/∂I1`` and
``∂/∂I2`` are each half the derivative with respect to a common change of both (their sum
is exact); ``com_x, com_y`` do not enter (an off-axis centre of mass is not a Lagrange
top). At instants where the axis is exactly vertical or exactly hanging (always, for a
sleeping top) the derivatives are finite but miss the first-order tilt, whose size is not
a differentiable function of the state there.

Bad input: non-positive moments or mass, ``I1 ≠ I2``, an off-axis centre of mass or a zero
quaternion raise ``ValueError`` for concrete input and ``equinox.error_if`` under ``jit``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from jrigid import quaternion as quat
from jrigid import special
from jrigid._checks import fail_if, is_traced
from jrigid.scene import Gravity, Pivot, Scene

__all__ = [
    "TopConstants",
    "applies",
    "check_scene",
    "evaluate",
    "nutation_period",
    "nutation_range",
    "prepare",
    "prepare_scene",
    "scene_gravity",
    "solve",
]

# Duplication steps of R_J: every argument lies in [0, 1] here (z = 1), for which 12 steps
# reach full float64 accuracy (see jrigid.special.elliprj_sqrt).
_RJ_STEPS = 12
_NEWTON_STEPS = 4
_FOUR_PI = 4.0 * math.pi


class TopConstants(NamedTuple):
    """Per-top constants of the closed-form solution (a pytree; batch shape ``B``).

    Fields are arrays of shape ``B`` unless noted. Times and rates are in the scaled unit
    (``t̂ = ν t``); ``*_m`` fields belong to the phase ``χ₋ = φ − ψ`` and ``*_p`` to
    ``χ₊ = φ + ψ`` (see the module docstring). Build with :func:`prepare`.
    """

    nu: jax.Array  # time scale: a power of two near the largest rate
    q_vert: jax.Array  # (B, 4) Q_v: space frame with z along the vertical -> space
    omega3: jax.Array  # body spin (scaled), constant
    wn: jax.Array  # omega_n (scaled); 0 for an equilibrium
    tau0: jax.Array
    m: jax.Array
    m1: jax.Array  # 1 - m, without cancellation
    kk: jax.Array  # K(m)
    kp: jax.Array  # sqrt(m1)
    sq: jax.Array  # u2 - u1
    omu1: jax.Array  # 1 - u1
    omu2: jax.Array  # 1 - u2
    opu1: jax.Array  # 1 + u1
    opu2: jax.Array  # 1 + u2
    u1: jax.Array
    u2: jax.Array
    n_m: jax.Array  # n- = (u2 - u1)/(1 - u1)
    e_m: jax.Array  # signed sqrt(1 - n-), sign of b - a
    v_m: jax.Array  # (b - a)/((1 - u1) e-)
    rate_m: jax.Array  # linear rate of chi-
    wt_m: jax.Array  # weight of e- G-
    egc_m: jax.Array  # e- G- over a quarter period (complete)
    eg0_m: jax.Array  # e- G-(tau0)
    adv_m: jax.Array  # advance of chi- per nutation period, mod 4 pi
    n_p: jax.Array  # N
    e_p: jax.Array  # signed sqrt(1 - N), sign of b + a
    gp_sqrt: jax.Array  # sqrt(beta (u3 + 1))
    rate_p: jax.Array
    wt_p: jax.Array
    egc_p: jax.Array
    eg0_p: jax.Array  # e+ G+(tau0 - K), unwrapped
    adv_p: jax.Array
    anchor_m: jax.Array  # (B, 2) e^{i chi-(0)/2} (re, im)
    anchor_p: jax.Array  # (B, 2) e^{i chi+(0)/2}


# --------------------------------------------------------------------------- helpers


def _safe_sqrt(x):
    """``sqrt(max(x, 0))`` with a finite (zero) derivative at zero."""
    pos = x > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def _safe_inv(x):
    """``1/x``, and 0 where ``x = 0`` (finite derivative there)."""
    ok = x != 0
    return jnp.where(ok, 1.0 / jnp.where(ok, x, 1.0), 0.0)


def _safe_rsqrt(x):
    """``1/√x`` for ``x > 0``, and 0 elsewhere (finite derivative there)."""
    ok = x > 0
    return jnp.where(ok, jax.lax.rsqrt(jnp.where(ok, x, 1.0)), 0.0)


def _sign(x):
    """``+1`` for ``x ≥ 0``, ``-1`` otherwise (a constant: no derivative)."""
    return jnp.where(x >= 0, 1.0, -1.0)


def _parity(j):
    """``(-1)^j`` for an integer-valued float ``j``."""
    return 1.0 - 2.0 * (j - 2.0 * jnp.floor(0.5 * j))


def _power_of_two_scale(x):
    """``2^-e`` with ``x = f 2^e``, ``f`` in ``[0.5, 1)`` (``x > 0``); no derivative."""
    _, e = jnp.frexp(jax.lax.stop_gradient(x))
    return jnp.ldexp(jnp.ones_like(x), -e)


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
    sq = _safe_sqrt(sum_roots * sum_roots - 4.0 * prod_roots)  # x2 - x1
    right = sum_roots >= 0
    big = 0.5 * (sum_roots + jnp.where(right, sq, -sq))  # the root of larger size
    other = prod_roots * _safe_inv(big)
    x2 = jnp.where(right, big, other)
    x1 = jnp.where(right, other, big)
    # smallest root first
    inv_lo = _safe_inv(jnp.where(close_top, r_lo, -1.0))
    pair_prod = -beta * beta * f0 * inv_lo  # (beta x2) c' >= 0
    pair_sum = (beta * f1 - pair_prod) * inv_lo  # beta x2 + c' >= 0
    pair_gap = _safe_sqrt(pair_sum * pair_sum - 4.0 * pair_prod)  # c' - beta x2
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
    limit = _sign(e) * math.pi / (2.0 * kp) - e * e_complete / m1
    return jnp.where(ok, e * rj / 3.0, limit)


# --------------------------------------------------------------------------- input


def _as_inputs(moments, mass, com, g, q0, omega0):
    """Arrays of one floating dtype with checked trailing shapes and values."""
    arrays = [jnp.asarray(x) for x in (moments, mass, com, g, q0, omega0)]
    dtype = jnp.result_type(*arrays)
    if not jnp.issubdtype(dtype, jnp.inexact):
        dtype = jnp.zeros(()).dtype
    moments, mass, com, g, q0, omega0 = (x.astype(dtype) for x in arrays)
    for name, x, k in (("moments", moments, 3), ("com", com, 3), ("g", g, 3)):
        if x.shape[-1:] != (k,):
            raise ValueError(f"lagrange_top: {name} must have shape (..., {k}), got {x.shape}")
    if q0.shape[-1:] != (4,):
        raise ValueError(f"lagrange_top: q0 must have shape (..., 4), got {q0.shape}")
    if omega0.shape[-1:] != (3,):
        raise ValueError(f"lagrange_top: omega0 must have shape (..., 3), got {omega0.shape}")
    moments = fail_if(
        moments,
        ~jnp.all(moments > 0, axis=-1),
        "lagrange_top: principal moments must be positive",
        lambda: f"got {moments}",
    )
    moments = fail_if(
        moments,
        moments[..., 0] != moments[..., 1],
        "lagrange_top: the body must be symmetric about axis 3 (I1 == I2 exactly)",
        lambda: f"got moments {moments}",
    )
    mass = fail_if(mass, ~(mass > 0), "lagrange_top: mass must be positive", lambda: f"got {mass}")
    com = fail_if(
        com,
        (com[..., 0] != 0) | (com[..., 1] != 0),
        "lagrange_top: the centre of mass must lie on the symmetry axis, com = (0, 0, l)",
        lambda: f"got com {com}",
    )
    q0 = fail_if(q0, ~jnp.any(q0 != 0, axis=-1), "lagrange_top: q0 must be a non-zero quaternion")
    return moments, mass, com, g, q0, omega0


# --------------------------------------------------------------------------- prepare


def prepare(
    moments: ArrayLike,
    mass: ArrayLike,
    com: ArrayLike,
    g: ArrayLike,
    q0: ArrayLike,
    omega0: ArrayLike,
) -> TopConstants:
    """Constants of the motion of a heavy symmetric top on a pivot (batched).

    Args:
        moments: ``(..., 3)`` central principal moments ``(I1, I2, I3)`` with ``I1 = I2``.
        mass: ``(...)`` mass ``M > 0``.
        com: ``(..., 3)`` centre of mass from the pivot in body coordinates, ``(0, 0, l)``
            (``l`` of either sign; ``l = 0`` is a torque-free symmetric body).
        g: ``(..., 3)`` uniform gravitational acceleration in the space frame (any
            direction; ``0`` allowed).
        q0: ``(..., 4)`` initial orientation, body → space, scalar first (normalized here).
        omega0: ``(..., 3)`` initial body-frame angular velocity.

    Returns:
        :class:`TopConstants` with batch shape the broadcast of the input batch shapes.

    Raises:
        ValueError: wrong shapes, non-positive moments or mass, ``I1 ≠ I2``, ``com`` off
            the symmetry axis, a zero ``q0`` (``equinox.error_if`` under ``jit``).
    """
    return _prepare(*_as_inputs(moments, mass, com, g, q0, omega0))


@jax.jit
def _prepare(moments, mass, com, g, q0, omega0):
    batch = jnp.broadcast_shapes(
        moments.shape[:-1], mass.shape, com.shape[:-1], g.shape[:-1], q0.shape[:-1],
        omega0.shape[:-1],
    )  # fmt: skip
    moments = jnp.broadcast_to(moments, batch + (3,))
    mass = jnp.broadcast_to(mass, batch)
    com = jnp.broadcast_to(com, batch + (3,))
    g = jnp.broadcast_to(g, batch + (3,))
    q0 = quat.normalize(jnp.broadcast_to(q0, batch + (4,)))
    omega0 = jnp.broadcast_to(omega0, batch + (3,))

    # ---- the top: transverse moment about the pivot, spin moment, vertical
    lever = com[..., 2]
    big_a = 0.5 * (moments[..., 0] + moments[..., 1]) + mass * lever * lever
    big_c = moments[..., 2]
    g2 = jnp.sum(g * g, axis=-1)
    gnorm = _safe_sqrt(g2)
    down = g / jnp.where(g2 > 0, gnorm, 1.0)[..., None]
    ez = jnp.zeros_like(g).at[..., 2].set(1.0)
    zhat = jnp.where((g2 > 0)[..., None], -_sign(lever)[..., None] * down, ez)
    beta = 2.0 * mass * gnorm * jnp.abs(lever) / big_a
    q_vert = _vertical_frame(zhat)

    # ---- scaled variables (time unit 1/nu, a power of two)
    w = omega0
    a_spin = big_c * w[..., 2] / big_a
    rate = jnp.maximum(jnp.maximum(jnp.max(jnp.abs(w), axis=-1), jnp.abs(a_spin)), _safe_sqrt(beta))
    moving = rate > 0
    scale = _power_of_two_scale(jnp.where(moving, rate, 1.0))
    nu = 1.0 / scale
    w = w * scale[..., None]
    a_spin = a_spin * scale
    beta = beta * scale * scale
    w3 = w[..., 2]
    wc = jax.lax.complex(w[..., 0], w[..., 1])  # omega1 + i omega2

    # ---- the initial orientation about the vertical: z+ = w' + i z', z- = x' + i y'
    qp = quat.multiply(quat.conjugate(q_vert), q0)
    zp0 = jax.lax.complex(qp[..., 0], qp[..., 3])
    zm0 = jax.lax.complex(qp[..., 1], qp[..., 2])
    abs2 = lambda z: jnp.real(z) ** 2 + jnp.imag(z) ** 2  # noqa: E731
    omu0 = 2.0 * abs2(zm0)  # 1 - u0
    opu0 = 2.0 * abs2(zp0)  # 1 + u0
    u0 = abs2(zp0) - abs2(zm0)
    ncx = 2j * zm0 * jnp.conj(zp0)  # n1 + i n2: the vertical in the body frame
    prod = jnp.conj(ncx) * wc
    h0 = jnp.real(prod)  # b - a u0
    udot0 = jnp.imag(prod)  # n1 w2 - n2 w1
    p0 = abs2(wc)
    s2 = abs2(ncx)

    # ---- roots: f(u0 + x) = beta x³ + f2 x² + f1 x + f0
    f0 = udot0 * udot0
    f1 = 2.0 * a_spin * h0 - 2.0 * u0 * p0 - beta * s2
    f2 = 2.0 * beta * u0 - p0 - a_spin * a_spin
    cpr, x1, x2, sq, gap = _roots(f0, f1, f2, beta)  # cpr = beta (u3 - u0)
    alive = cpr > 0
    right = x1 + x2 >= 0

    # ---- distances to the poles, consistent with b -+ a
    dm = h0 - a_spin * omu0  # b - a
    dp = h0 + a_spin * opu0  # b + a
    omu1 = omu0 - x1
    opu2 = opu0 + x2
    gm = jnp.maximum(cpr - beta * omu0, 0.0)  # beta (u3 - 1)
    gpl = cpr + beta * opu0  # beta (u3 + 1)
    omu2_a = jnp.maximum(omu0 - x2, 0.0)
    # The identities hold for the labelling u1 <= u2 <= 1 <= u3 of the deflated cubic; a
    # steady u (u2 = u1, e.g. an unstable equilibrium, where c' is a double root) needs none.
    moving_u = sq > 0
    inv_omu1, inv_opu2, inv_gm = _safe_inv(omu1), _safe_inv(opu2), _safe_inv(gm)
    ok_b = alive & moving_u & (gm > 0) & (omu1 > 0)
    omu2_b = dm * dm * inv_omu1 * inv_gm
    err_a = (omu0 + jnp.abs(x2)) * _safe_inv(omu2_a) + jnp.where(omu2_a > 0, 0.0, jnp.inf)
    err_b = (cpr + beta * omu0) * inv_gm + jnp.where(ok_b, 0.0, jnp.inf)
    use_b = ok_b & (err_b <= err_a)
    omu2 = jnp.where(use_b, omu2_b, omu2_a)
    ok_c = alive & moving_u & (opu2 * gpl > 0)
    opu1 = jnp.where(ok_c, dp * dp * inv_opu2 * _safe_inv(gpl), jnp.maximum(opu0 + x1, 0.0))

    # ---- the elliptic parameters
    den = cpr - beta * x1  # beta (u3 - u1)
    inv_den = _safe_inv(jnp.maximum(den, 0.0))
    m = jnp.clip(beta * sq * inv_den, 0.0, 1.0)
    tiny = jnp.finfo(den.dtype).tiny
    m1 = jnp.clip(jnp.where(den > 0, gap * inv_den, 1.0), tiny, 1.0)
    wn = 0.5 * _safe_sqrt(den)
    timed = wn > 0
    wn_safe = jnp.where(timed, wn, 1.0)
    kp = jnp.sqrt(m1)
    zero, one = jnp.zeros_like(m1), jnp.ones_like(m1)
    # sn0, cn0 >= 0 and the sign of udot0 (as sn0 cn0), linear in udot0 where it vanishes
    sigma_u = _sign(udot0)
    inv_sq = _safe_inv(sq)
    sn0_r = udot0 * _safe_rsqrt(cpr * x2 * sq)
    cn0_r = _safe_sqrt(x2 * inv_sq)
    sn0_l = sigma_u * _safe_sqrt(-x1 * inv_sq)
    cn0_l = sigma_u * udot0 * _safe_rsqrt(cpr * (-x1) * sq)
    sn0 = jnp.where(moving_u, jnp.where(right, sn0_r, sn0_l), 0.0)
    cn0 = jnp.where(moving_u, jnp.where(right, cn0_r, cn0_l), 1.0)
    dn0 = jnp.where(den > 0, _safe_sqrt(cpr * inv_den), 1.0)
    rf = special.elliprf_sqrt(jnp.stack([zero, cn0]), jnp.stack([kp, dn0]), jnp.stack([one, one]))
    kk = rf[0]
    tau0 = sn0 * rf[1]
    period = 2.0 * kk / wn_safe

    # ---- chi- = phi - psi, and chi+ = phi + psi at the quarter-shifted tau0 - K
    n_m = sq * inv_omu1
    e_m_b = dm * inv_omu1 * _safe_rsqrt(gm)
    e_m_a = _sign(dm) * _safe_sqrt(omu2_a * inv_omu1)
    e_m = jnp.where(use_b, e_m_b, e_m_a)
    v_m = jnp.where(use_b | (e_m == 0), _safe_sqrt(gm), dm * inv_omu1 * _safe_inv(e_m))
    wt_m = v_m * n_m / wn_safe
    rate_m = (a_spin - w3) + dm * inv_omu1
    n_p = (opu1 * m + sq) * inv_opu2
    gp_sqrt = _safe_sqrt(gpl)
    e_p = dp * kp * inv_opu2 * _safe_rsqrt(gpl)
    wt_p = gp_sqrt * kp * sq * inv_opu2 / wn_safe
    rate_p = (w3 - a_spin) + dp * inv_opu2
    s_, c_, d_, j_ = _quarter_shift(sn0, cn0, dn0, zero, kp)
    # one R_J call for the four integrals (complete and at tau0, both phases)
    (a_cm, ok_cm) = _complete_args(e_m, kp)
    (a_cp, ok_cp) = _complete_args(e_p, kp)
    (a_0m, ok_0m) = _partial_args(e_m, n_m, sn0, cn0, dn0)
    (a_0p, ok_0p) = _partial_args(e_p, n_p, s_, c_, d_)
    a_e = (zero, kp, one)  # R_D(0, m1, 1) = R_J(0, m1, 1, 1), for E(m)
    rj = _rj(*(jnp.stack(x) for x in zip(a_cm, a_cp, a_0m, a_0p, a_e, strict=True)))
    # E(m) = K - (m/3) R_D(0, m1, 1) (DLMF 19.25.1); only the derivative at e = 0 uses it
    e_complete = kk - m / 3.0 * rj[4]
    egc_m = _complete(rj[0], ok_cm, e_m, kp, m1, e_complete)
    egc_p = _complete(rj[1], ok_cp, e_p, kp, m1, e_complete)
    eg0_m = _partial(rj[2], ok_0m, e_m, sn0)
    eg0_p = _partial(rj[3], ok_0p, e_p, s_) + 2.0 * j_ * egc_p
    adv_m = _reduce_4pi(rate_m * period + 2.0 * wt_m * egc_m)
    adv_p = _reduce_4pi(rate_p * period + 2.0 * wt_p * egc_p)

    # ---- phases at t = 0 (at a pole: the direction the top leaves it in; see docstring)
    # z- = 0: z- ≈ ½ z+ wc t near t = 0 and tau0 = +K, so the step of chi- comes right
    # after t = 0: start from the phase before it. z+ = 0: z+ ≈ -½ z- conj(wc) t and
    # tau0 - K = -K, the step comes right before t = 0: start from the phase after it.
    before_m = -zp0 * wc
    after_p = -zm0 * jnp.conj(wc)
    anchor_m = _unit_complex(zm0, _unit_complex(before_m, 1.0 + 0j))
    anchor_p = _unit_complex(zp0, _unit_complex(after_p, 1.0 + 0j))
    # the linear rates and the period do not exist for an equilibrium (omega_n = 0)
    return TopConstants(
        nu=nu,
        q_vert=q_vert,
        omega3=w3,
        wn=wn,
        tau0=tau0,
        m=m,
        m1=m1,
        kk=kk,
        kp=kp,
        sq=sq,
        omu1=omu1,
        omu2=omu2,
        opu1=opu1,
        opu2=opu2,
        u1=u0 + x1,
        u2=u0 + x2,
        n_m=n_m,
        e_m=e_m,
        v_m=v_m,
        rate_m=rate_m,
        wt_m=jnp.where(timed, wt_m, 0.0),
        egc_m=egc_m,
        eg0_m=eg0_m,
        adv_m=jnp.where(timed, adv_m, 0.0),
        n_p=n_p,
        e_p=e_p,
        gp_sqrt=gp_sqrt,
        rate_p=rate_p,
        wt_p=jnp.where(timed, wt_p, 0.0),
        egc_p=egc_p,
        eg0_p=eg0_p,
        adv_p=jnp.where(timed, adv_p, 0.0),
        anchor_m=jnp.stack([jnp.real(anchor_m), jnp.imag(anchor_m)], axis=-1),
        anchor_p=jnp.stack([jnp.real(anchor_p), jnp.imag(anchor_p)], axis=-1),
    )


def _vertical_frame(zhat):
    """A rotation ``Q_v`` with ``Q_v e_z = ẑ`` (shortest arc from ``±e_z``), ``(..., 4)``."""
    x, y, z = zhat[..., 0], zhat[..., 1], zhat[..., 2]
    upper = z >= 0
    # z >= 0: shortest arc e_z -> zhat; z < 0: (shortest arc -e_z -> zhat) ⊗ (π about x)
    w_up = jnp.stack([1.0 + z, -y, x, jnp.zeros_like(z)], axis=-1)
    w_dn = jnp.stack([-y, 1.0 - z, jnp.zeros_like(z), x], axis=-1)  # (1-z, y, -x, 0) ⊗ (0, 1, 0, 0)
    q = jnp.where(upper[..., None], w_up, w_dn)
    return q / jnp.sqrt(jnp.sum(q * q, axis=-1, keepdims=True))


# --------------------------------------------------------------------------- evaluate


def _expand(consts: TopConstants, extra: int) -> TopConstants:
    """Insert ``extra`` axes after the batch axes of every field (for time broadcasting)."""
    batch_ndim = consts.nu.ndim

    def f(x):
        return x.reshape(x.shape[:batch_ndim] + (1,) * extra + x.shape[batch_ndim:])

    return jax.tree_util.tree_map(f, consts)


def evaluate(consts: TopConstants, t: ArrayLike) -> tuple[jax.Array, jax.Array]:
    """Orientation and body angular velocity of the top at times ``t`` (any shape ``S``).

    The exact solution of Euler's equations about the pivot with the gravity torque
    (eq. 17.35) and the quaternion kinematics (eq. 17.44); see the module docstring.

    Args:
        consts: from :func:`prepare`, batch shape ``B``.
        t: ``S``-shaped array of times (``t = 0`` is the initial state).

    Returns:
        ``(q, omega)`` of shapes ``B + S + (4,)`` and ``B + S + (3,)``, in the dtype of
        ``consts``: the body → space unit quaternion and the body-frame angular velocity.
        The cost per time does not depend on ``t``.
    """
    return _evaluate(consts, jnp.asarray(t, dtype=consts.nu.dtype))


@jax.jit
def _evaluate(consts, t):
    c = _expand(consts, t.ndim)
    t = t.reshape((1,) * consts.nu.ndim + t.shape)
    shape = jnp.broadcast_shapes(c.nu.shape, t.shape)
    t = jnp.broadcast_to(t, shape)
    c = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, shape + x.shape[len(shape) :]), c)

    st = c.nu * t
    timed = c.wn > 0
    wn_safe = jnp.where(timed, c.wn, 1.0)
    tau = c.wn * st + c.tau0
    sn, cn, dn, _, j = special.jacobi_with_index(tau, c.m, c.m1, c.kk)
    sign = _parity(j)
    sr, cr = sign * sn, sign * cn  # at the reduced argument r in [-K, K]
    r = tau - 2.0 * j * c.kk
    t_red = jnp.where(timed, (r - c.tau0) / wn_safe, st)
    jj = jnp.where(timed, j, 0.0)

    # chi- = phi - psi at tau; chi+ = phi + psi at tau' = tau - K (one R_J call for both)
    s2, c2, d2, j2 = _quarter_shift(sr, cr, dn, j, c.kp)
    args_m, ok_m = _partial_args(c.e_m, c.n_m, sr, cr, dn)
    args_p, ok_p = _partial_args(c.e_p, c.n_p, s2, c2, d2)
    rj = _rj(*(jnp.stack(x) for x in zip(args_m, args_p, strict=True)))
    g_m = _partial(rj[0], ok_m, c.e_m, sr) - c.eg0_m
    g_p = _partial(rj[1], ok_p, c.e_p, s2) + 2.0 * (j2 - j) * c.egc_p - c.eg0_p
    chi_m = c.rate_m * t_red + c.wt_m * g_m + _reduce_4pi(jj * c.adv_m)
    chi_p = c.rate_p * t_red + c.wt_p * g_p + _reduce_4pi(jj * c.adv_p)

    anchor_m = jax.lax.complex(c.anchor_m[..., 0], c.anchor_m[..., 1])
    anchor_p = jax.lax.complex(c.anchor_p[..., 0], c.anchor_p[..., 1])
    rot_m = anchor_m * jnp.exp(0.5j * chi_m)
    rot_p = anchor_p * jnp.exp(0.5j * chi_p)

    # half-angle amplitudes
    cr2, sr2 = cr * cr, sr * sr
    half_s = _safe_sqrt(0.5 * (c.omu2 + c.sq * cr2))  # sin(theta/2)
    half_c = _safe_sqrt(0.5 * (c.opu1 + c.sq * sr2))  # cos(theta/2)
    zm = half_s * rot_m
    zp = half_c * rot_p
    q_rel = jnp.stack([jnp.real(zp), jnp.real(zm), jnp.imag(zm), jnp.imag(zp)], axis=-1)
    q = quat.multiply(c.q_vert, q_rel)

    # R- = (-udot + i(b - a))/S-,  R+ = (udot + i(b + a))/C+  (bounded; see docstring)
    d_m2 = c.e_m * c.e_m + c.n_m * cr2
    ok_m = d_m2 > 0
    d_m = jnp.sqrt(jnp.where(ok_m, d_m2, 1.0))
    re_m = -2.0 * c.wn * sr * dn * jnp.where(ok_m, c.n_m * cr / d_m, jnp.sqrt(c.n_m))
    im_m = c.v_m * jnp.where(ok_m, c.e_m / d_m, 0.0)
    big_r_m = _safe_sqrt(2.0 * c.omu1) * jax.lax.complex(re_m, im_m)
    d_p2 = c.e_p * c.e_p + c.n_p * (c.kp * sr / dn) ** 2
    ok_p = d_p2 > 0
    d_p = jnp.sqrt(jnp.where(ok_p, d_p2, 1.0))
    # sr/d_p -> sign(sr) dn/(sqrt(N) k') where e+ = sr = 0 (exactly at the bottom)
    re_p = (
        2.0
        * c.wn
        * cr
        * jnp.where(ok_p, c.sq * c.kp * sr / d_p, _sign(sr) * dn * c.sq * _safe_rsqrt(c.n_p))
    )
    im_p = c.opu2 * c.gp_sqrt / dn * jnp.where(ok_p, c.e_p / d_p, 0.0)
    big_r_p = jnp.sqrt(2.0 / jnp.where(c.opu2 > 0, c.opu2, 1.0)) * jax.lax.complex(re_p, im_p)
    wc = 0.5 * rot_m * jnp.conj(rot_p) * (half_c * big_r_m - half_s * jnp.conj(big_r_p))
    omega = c.nu[..., None] * jnp.stack([jnp.real(wc), jnp.imag(wc), c.omega3], axis=-1)
    return q, omega


def solve(
    moments: ArrayLike,
    mass: ArrayLike,
    com: ArrayLike,
    g: ArrayLike,
    q0: ArrayLike,
    omega0: ArrayLike,
    ts: ArrayLike,
) -> tuple[jax.Array, jax.Array]:
    """Exact motion of a heavy symmetric top on a pivot at times ``ts``.

    Solves the heavy-top equations (Euler's equations about the pivot, eq. 17.35, with the
    gravity torque, and the kinematics ``q̇ = ½ q ⊗ (0, ω)``, eq. 17.44) in closed form.

    Args:
        moments, mass, com, g, q0, omega0: as :func:`prepare`.
        ts: ``(T,)`` (or any shape ``S``) output times.

    Returns:
        ``(q, omega)``: ``(..., T, 4)`` and ``(..., T, 3)``. Equivalent to
        ``evaluate(prepare(moments, mass, com, g, q0, omega0), ts)``;
        ``jit``/``vmap``/``grad``-able.
    """
    return evaluate(prepare(moments, mass, com, g, q0, omega0), ts)


# --------------------------------------------------------------------------- theory


def nutation_period(consts: TopConstants) -> jax.Array:
    """Period of ``θ(t)``: ``2K(m)/ω_n`` (``inf`` for a steady ``θ``).

    Args:
        consts: from :func:`prepare`, batch shape ``B``.

    Returns:
        ``B``-shaped array.
    """
    finite = (consts.wn > 0) & (consts.sq > 0)
    wn = jnp.where(finite, consts.wn * consts.nu, 1.0)
    return jnp.where(finite, 2.0 * consts.kk / wn, jnp.inf)


def nutation_range(consts: TopConstants) -> tuple[jax.Array, jax.Array]:
    """The turning values ``(u1, u2)`` of ``u = cos θ`` (``θ`` between ``acos u2`` and ``acos u1``).

    Args:
        consts: from :func:`prepare`, batch shape ``B``.

    Returns:
        ``(u1, u2)``, each ``B``-shaped, ``−1 ≤ u1 ≤ u2 ≤ 1``.
    """
    return consts.u1, consts.u2


# --------------------------------------------------------------------------- scenes


def _problems(scene: Scene) -> list[str]:
    """Why ``scene`` is not a Lagrange top (empty if it is)."""
    problems = []
    if not isinstance(scene, Scene):
        return [f"expected a Scene, got {type(scene).__name__}"]
    if not isinstance(scene.holder, Pivot):
        problems.append(f"it needs a Pivot holder, the scene has {type(scene.holder).__name__}")
    others = [type(load).__name__ for load in scene.loads if not isinstance(load, Gravity)]
    if others:
        problems.append(f"its only loads may be Gravity, the scene has {', '.join(others)}")
    body = scene.body
    if not is_traced(body.moments, body.com, body.mass):
        moments, com = np.asarray(body.moments), np.asarray(body.com)
        if moments.shape != (3,) or com.shape != (3,):
            problems.append("it needs one body (moments (3,), com (3,)); vmap for batches")
        else:
            if moments[0] != moments[1]:
                problems.append(
                    f"the body must be symmetric about axis 3 (I1 == I2 exactly), got {moments}"
                )
            if com[0] != 0 or com[1] != 0:
                problems.append(
                    f"the centre of mass must lie on the symmetry axis (0, 0, l), got {com}"
                )
    return problems


def applies(scene: Scene) -> bool:
    """Whether the closed form describes ``scene`` (a static, trace-time decision).

    True for a :class:`~jrigid.scene.Pivot` scene whose loads are only
    :class:`~jrigid.scene.Gravity` (any number, summed; none is a torque-free symmetric
    body) and whose body is symmetric, ``I1 == I2`` **exactly**, with its centre of mass
    exactly on the symmetry axis, ``com = (0, 0, l)``. A body that is symmetric only to
    rounding (e.g. built from a tensor) is not: the closed form would silently be the
    motion of a slightly different body. When the body's values are traced (the scene is
    a ``jit`` argument) only the structure is decided here; :func:`prepare` checks the
    values at run time.

    Args:
        scene: a :class:`~jrigid.scene.Scene`.

    Returns:
        ``bool``.
    """
    return not _problems(scene)


def check_scene(scene: Scene) -> None:
    """Raise ``ValueError`` saying why ``scene`` is not a Lagrange top (see :func:`applies`).

    Args:
        scene: a :class:`~jrigid.scene.Scene`.
    """
    problems = _problems(scene)
    if problems:
        raise ValueError(
            "the closed-form heavy symmetric top does not apply: " + "; ".join(problems)
        )


def scene_gravity(scene: Scene) -> jax.Array:
    """``(3,)`` total gravitational field of a scene's :class:`~jrigid.scene.Gravity` loads."""
    total = jnp.zeros(3, dtype=scene.body.moments.dtype)
    for load in scene.loads:
        if isinstance(load, Gravity):
            total = total + load.g
    return total


def prepare_scene(scene: Scene, q0: ArrayLike, omega0: ArrayLike) -> TopConstants:
    """:func:`prepare` for a :class:`~jrigid.scene.Scene` (checked with :func:`check_scene`).

    Args:
        scene: a Lagrange-top scene (one body; its Gravity loads are summed).
        q0: ``(4,)`` initial orientation; omega0: ``(3,)`` initial body angular velocity
            (e.g. ``state.q``, ``state.omega`` of a :class:`~jrigid.state.State`).

    Returns:
        :class:`TopConstants` (batch shape ``()``).
    """
    check_scene(scene)
    body = scene.body
    return prepare(body.moments, body.mass, body.com, scene_gravity(scene), q0, omega0)
