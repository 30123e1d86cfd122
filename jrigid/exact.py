"""The torque-free rigid body in closed form: ω(t) and q(t) at any time, without stepping.

Solves Euler's equations with no torque (eqs. 17.34-17.35, ``N = 0``) together with the
quaternion kinematics ``q̇ = ½ q ⊗ (0, ω)`` (eq. 17.44). ``prepare`` computes a pytree of
per-body constants once; ``evaluate`` then costs the same at every time (one Jacobi
triple and one Carlson ``R_J``), however far out. ``solve`` does both.

Method
------
*Canonical frame.* The body axes are permuted (with one sign flip when the permutation
is odd, so the frame stays right-handed) so that axis 3 is the axis the polhode
encircles (largest moment if ``L² > 2E I_mid``, smallest otherwise), axis 2 the middle
one. In that frame (Landau & Lifshitz §37), with ``Δj = L² - 2E Ij``,

    ω1 = ρ A1 cn τ,  ω2 = s ρ σ A2 sn τ,  ω3 = σ A3 dn τ,   τ = λ t + τ0,
    λ² = (I3 - I2) Δ1 / (I1 I2 I3),  m = (I2 - I1)(-Δ3) / ((I3 - I2) Δ1),
    1 - m = (I3 - I1) Δ2 / ((I3 - I2) Δ1),

with ``σ = sign ω3``, ``ρ = sign ω1(0)``, ``s = sign(I3 - I1)``. Every ``Δj`` and amplitude
is formed from ω directly, ``Δj = Σ_k I_k (I_k - I_j) ω_k²``, so that only ``Δ2`` (the
distance to the separatrix) subtracts numbers of like size; it is evaluated with
error-free transformations (double-double arithmetic), exactly rounded, because its
relative error becomes that of ``1 - m`` and of the period. ``1 - m`` is computed from
``Δ2`` and never as ``1 - m``.

*Angular velocity from the initial one.* The addition theorem of ``sn, cn, dn``
(DLMF 22.8.1-3) with ``u = λ t`` writes the solution through ``ω(0) = (w1, w2, w3)``
itself, without ``τ0``::

    ω1 = (w1 cn u - e1 w2 w3 S dn u) / D,   e1 = (I3 - I2)/I1,   S = sn(u)/λ,
    ω2 = (w2 cn u dn u + e2 w1 w3 S) / D,   e2 = (I3 - I1)/I2,
    ω3 = (w3 dn u - e3 w1 w2 S cn u) / D,   e3 = (I2 - I1)/I3,
    D = 1 - m sn²τ0 sn²u = cn²u + dn²τ0 sn²u,

(the first form of ``D`` when ``m sn²τ0 ≤ ½``, the second, free of cancellation,
otherwise), with ``m sn²τ0 = (I2 - I1) I2 w2²/Δ1`` and ``dn²τ0 = I3 (I3 - I1) w3²/Δ1``.
Unlike the amplitude-phase form, this is a smooth function of the moments and of ``ω(0)``
at a spin about a principal axis (where the phase ``τ0`` is undefined) and near one.
``sn τ, cn τ, dn τ`` for the orientation below are ``ω_k(t)`` divided by the amplitudes;
only the index ``j = round(τ / 2K)`` of the half period uses ``τ0``.

*Orientation.* ``q(t) = W ⊗ Z(ψ(t)) ⊗ B(t)*`` where ``B(t)`` is the shortest rotation
taking the fixed body axis ``a = σ e3`` to ``l(t) = L_body(t)/|L|`` (never antipodal,
since ``a·l = I3 |ω3| / |L| ≥ 0``), ``Z(ψ)`` the rotation by ``ψ`` about ``a`` and
``W = q0 ⊗ B(0)`` fixed. Differentiating gives ``ψ̇ = (2E/|L| + a·ω) / (1 + a·l)``
``= β + (α - β)/(1 + c dn τ)`` with ``α = 2E/|L|``, ``β = |L|/I3``, ``c = I3 A3/|L|``.
Its integral takes one of two forms, both ``rate·t + (coef/λ)(P(τ) - P(τ0))`` with
``P(τ) = s³ R_J(x², y², 1, p²) + 2j P_complete`` after ``j`` half periods:

- away from the separatrix, the descending Landen (Gauss) transformation (DLMF
  22.7.1-3), ``1 + dn(z|k) = 2/(1 + k₁ sn²(z/(1+k₁)|k₁²))`` with ``k₁ = (1 - k')/(1 + k')``,
  turns ``1/(1 + c dn)`` into a rational function of ``sn²`` without cancellation::

      ψ(t) = ψ̇₀ t + κ (Q(τ) - Q(τ0)) / λ,
      ψ̇₀ = (2E + |L| A3) / (|L| + I3 A3),   κ = -2 Δ3 A3 k₁ / (|L| + I3 A3)²,
      Q(τ) = (1 + k₁) ∫_0^{φ₁} sin²θ dθ / ((1 - n' sin²θ) √(1 - k₁² sin²θ)),
      n' = -k₁ I1² A1² / (|L| + I3 A3)²  (≤ 0),

  where ``φ₁`` is the (unwrapped) amplitude of the transformed argument and the integral
  is ``sin³φ₁ R_J(cos²φ₁, Δ₁², 1, 1 - n' sin²φ₁)/3`` plus ``2j`` complete integrals;
- near the separatrix (``k' < (1 - c²)/8``), where the Landen modulus ``k₁`` is not a
  smooth function of ``m``, the third-kind integral in ``m`` itself:
  ``1/(1 + c dn) = (1 - c dn)/(a + b sn²)`` with ``a = 1 - c² = -I1 Δ3/((I3 - I1) L²)``,
  ``b = c² m``, ``n = -b/a``, so that, by ``Π(n; φ|m) = F + (n/3) sin³φ R_J(..)`` and
  ``F(am τ) = τ``,

      ψ(t) = (β + (α-β)/a) t + (α-β) n/(3 a λ) (P(τ) - P(τ0))
             - (α-β) c/(λ √(a(a+b))) (Θ(τ) - Θ(τ0)),
      P(τ) = sin³φ R_J(cos²φ, dn²τ, 1, 1 - n sin²φ),   Θ = jπ + atan2(k sin φ, cos φ),
      k = √((a + b)/a),   φ = am τ reduced to [-π/2, π/2].

  The two terms cancel to a factor ``1/a`` (``a ≥ I1 (I3 - I2)/(2 I2 (I3 - I1))`` near the
  separatrix), so this form is used only for ``a ≥ 10⁻⁴``.

This avoids the sign pitfalls of published formulae (Celledoni, Fassò, Säfström & Zanna
2008; van Zon & Schofield 2007): it is derived here from ``q̇ = ½ q ⊗ (0, ω)`` and checked
against high-precision integration of that equation in ``tests/test_exact.py``.

*Slow motion and short times.* Near a spherical body, or a symmetric one spun in its
degenerate plane, ``λ → 0`` and ``m`` depends on the direction from which the degenerate
body is approached, so the amplitude-phase constants are not smooth functions of the
moments there although the motion is. For ``λ |t| ≤ 1/32`` (every ``t`` when ``λ = 0``)
``ω`` and ``ψ`` are instead Taylor polynomials in ``t`` of degree 10 and 11, whose
coefficients follow from Euler's equations by the Cauchy-product recursion
``ω⁽ⁿ⁺¹⁾/(n+1)! = I⁻¹ Σ_k (I ω⁽ᵏ⁾/k!) × ω⁽ⁿ⁻ᵏ⁾/(n-k)!``, and from ``ψ̇ = f(ω3)`` by series
division (in the variable ``32 λ t``, so that no coefficient under- or overflows).
``ω(t)`` is analytic for ``|λ t| < K(1-m)``, and ``K(1-m) ≥ π/2``, so the truncation
error is of order ``(2/(32π))¹¹ ≈ 2e-19`` (both branches agree to rounding where they
meet; tested). When ``λ = 0`` exactly the motion is steady and the first-order change of
it under any perturbation is a polynomial of degree 2 in ``t`` (3 for ``ψ``), which those
terms carry exactly; the higher ones, zero with their derivatives, are left out there so
that large ``t`` cannot overflow them.

*Spins about a body axis.* If two components of ``ω0`` are exactly zero the spin is
steady for any moments; the frame is then chosen with axis 3 along the spin, ``m = 0``,
and the addition theorem above becomes ``cn u → cos(√μ t)``, ``S → sin(√μ t)/√μ``
(``cosh``/``sinh`` for ``μ < 0``, the middle axis; ``cos``/``sin`` from the same
Jacobi call with ``m = 0``), ``dn u = D = 1``, with ``μ = (I3 - I2)(I3 - I1) w3²/(I1 I2)``:
exact, and exact to first order in any perturbation. The derivatives of a spin about the
middle axis grow like ``e^{√-μ t}``; ``√-μ t`` is capped at ``0.45 ln(max float)`` (320
in float64, 40 in float32), beyond which they stay at about ``1e139`` (``1e17``) instead
of overflowing (on the separatrix itself they overflow near ``λ t = 700``).
``ψ = ψ̇(ω0) t``, which with ``a``
along the spin is also exact to first order. At rest, ``q = q0 ⊗ (1, ω0 t/2)``,
``ω = ω0``.

The inputs are rescaled by powers of two (exactly: moments by the largest, ω by its
largest component) so that nothing under- or overflows.

Derivatives: everything is ``jnp`` plus the differentiable kernels of
:mod:`jrigid.special`, so ``jax.grad``/``jax.jacfwd``/``jax.jacrev`` work with respect to
the moments, ``q0``, ``ω0`` and ``t``. The branches are joined with the double-``where``
pattern (an untaken branch runs on safe inputs), so no NaN or infinity reaches a
derivative. They are right also at the degenerate motions: spherical bodies, ties of
the moments (symmetric bodies), spins about any principal axis, the separatrix, and
nearby (tested against forward-mode diffrax and finite differences of high-precision
solutions). Known loss of accuracy: near a spin about the *middle* axis, at a relative
distance ``ε`` from it, the derivatives of ``q`` lose about ``log10(1/ε)`` digits (a
relative error of order ``1e-16/ε``; the values are unaffected).

Bad input: a non-finite or non-positive-definite inertia, a non-finite or zero ``q0`` and
a non-finite ``ω0`` raise ``ValueError`` for concrete input (the checks of
:func:`jrigid.inertia.validate` and :func:`jrigid.quaternion.check_quaternion`) and
``equinox.error_if`` runtime errors under ``jit``; wrong shapes raise ``ValueError``.
``q0`` is normalized. The triangle inequality of physical moments is not required (the
closed form holds for any positive moments) unless asked for with
``allow_nonphysical=False``.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from jrigid import inertia as inertia_checks
from jrigid import quaternion as quat
from jrigid._checks import fail_if
from jrigid.special.kernels import (
    jacobi_with_index,
    parity_sign,
    rf_sqrt,
    rj_sqrt,
    safe_sqrt,
)

__all__ = ["ExactConstants", "evaluate", "omega_period", "prepare", "solve"]

# Duplication steps for R_J(x, y, 1, p) with x, y in [0, 1], p in [1, 10⁴]: 12 reach full
# float64 accuracy down to y = 1e-60 (distances to the separatrix far below rounding).
_RJ_STEPS = 12
# The third-kind form of ψ needs a = 1 - c² ≥ this (so p ≤ 1 + 1/a stays within the
# accuracy of _RJ_STEPS) and is used where k' < a/8 (where Landen's k₁ loses smoothness).
_THIRD_KIND_MIN_A = 1e-4
# Taylor branch: degree of ω(t) and the largest λ|t| it is used for.
_SERIES_ORDER = 10
_SLOW = 1.0 / 32.0
# A generic body (canonical, regime a) on which the general formulas run when they are
# not used, so that their discarded values and derivatives stay finite.
_DUMMY_I = (1.0 / 3.0, 2.0 / 3.0, 1.0)
_DUMMY_W = (0.6, 0.48, 0.64)


class ExactConstants(NamedTuple):
    """Per-body constants of the closed-form solution (a pytree; batch shape ``B``).

    Fields are arrays of shape ``B`` unless noted; "canonical" refers to the permuted
    body frame described in the module docstring, "scaled" to units in which the moments
    are divided by a power of two near the largest and time is multiplied by ``nu``. The
    elliptic constants (``amp`` to ``kappa``) describe the body itself when its motion is
    not steady; for a steady motion they belong to a generic stand-in body (unused).
    Build with :func:`prepare`.
    """

    perm: jax.Array  # (B, 3, 3) signed permutation P, omega_canonical = P @ omega_body
    perm_q: jax.Array  # (B, 4) quaternion of P
    amp: jax.Array  # (B, 3) signed amplitudes of (cn, sn, dn), in units of nu
    inertia: jax.Array  # (B, 3) canonical moments / largest moment
    nu: jax.Array  # time unit: the power of two at max |omega0_k| (0 at rest)
    lam: jax.Array  # lambda / nu
    tau0: jax.Array
    m: jax.Array
    m1: jax.Array  # 1 - m, computed without cancellation
    kk: jax.Array  # K(m) (inf on the separatrix)
    k1: jax.Array  # Landen modulus (1 - k')/(1 + k')
    nprime: jax.Array  # characteristic n' <= 0 of the transformed integral
    q_half: jax.Array  # complete transformed integral (per half period of phi_1)
    q_start: jax.Array  # Q(tau0)
    rate0: jax.Array  # psi-dot_0 / nu
    kappa: jax.Array  # kappa / nu
    sigma: jax.Array  # +-1: a = sigma e3
    lnorm: jax.Array  # |L| in scaled units
    w0: jax.Array  # (B, 4) W = q0_canonical (x) B(0)
    q0: jax.Array  # (B, 4) normalized initial orientation
    omega0: jax.Array  # (B, 3) initial body angular velocity
    steady: jax.Array  # bool: constant omega
    omega_c: jax.Array  # (B, 3) canonical initial omega / nu
    coupling: jax.Array  # (B, 3) canonical (I3 - I2)/I1, (I3 - I1)/I2, (I2 - I1)/I3
    msn0: jax.Array  # m sn²(tau0)
    dn0sq: jax.Array  # dn²(tau0) = 1 - m sn²(tau0)
    psi_third: jax.Array  # bool: psi by the third-kind form (else Landen)
    psi_rate: jax.Array  # psi = rate st + (coef (P - P0) - angle (Theta - Theta0)) / lam
    psi_coef: jax.Array
    psi_angle: jax.Array
    psi_k: jax.Array  # k of Theta = atan2(k sin phi, cos phi)
    psi_n: jax.Array  # characteristic n (third kind) or n' (Landen)
    p_start: jax.Array  # P(tau0)
    theta_start: jax.Array  # Theta(tau0)
    p_complete: jax.Array  # complete integral added per half period (0 if K infinite)
    series_omega: jax.Array  # (B, N + 1, 3) Taylor coefficients of omega_c in y = st/scale
    series_psi: jax.Array  # (B, N + 1) Taylor coefficients of psi in y, degrees 1 .. N + 1
    series_scale: jax.Array  # scaled-time unit of y (1/32 lambda, or 1 when lambda = 0)
    slow_rate: jax.Array  # lambda in scaled units (0 when it vanishes or is not used)
    spin: jax.Array  # bool: omega0 along a body axis (moving)
    spin_rate2: jax.Array  # mu: squared rate of the linearized wobble about that axis
    rest: jax.Array  # bool: omega0 = 0


def _as_inputs(moments, q0, omega0, allow_nonphysical):
    """Checked arrays of one floating dtype (``ValueError`` now, or ``error_if`` if traced)."""
    moments, q0, omega0 = (jnp.asarray(x) for x in (moments, q0, omega0))
    dtype = jnp.result_type(moments, q0, omega0)
    if not jnp.issubdtype(dtype, jnp.inexact):
        dtype = jnp.zeros(()).dtype
    if moments.shape[-1:] != (3,):
        raise ValueError(f"moments must have shape (..., 3), got {moments.shape}")
    if q0.shape[-1:] != (4,):
        raise ValueError(f"q0 must have shape (..., 4), got {q0.shape}")
    if omega0.shape[-1:] != (3,):
        raise ValueError(f"omega0 must have shape (..., 3), got {omega0.shape}")
    moments, q0, omega0 = (x.astype(dtype) for x in (moments, q0, omega0))
    moments = _now_if_concrete(
        lambda x: inertia_checks.validate(
            x, kind="moments", allow_nonphysical=allow_nonphysical
        ),
        moments,
    )
    try:
        q0 = _now_if_concrete(lambda x: quat.check_quaternion(x, unit=False), q0)
    except ValueError as err:
        raise ValueError(f"exact: q0: {err}") from None
    omega0 = _now_if_concrete(
        lambda x: fail_if(
            x, ~jnp.isfinite(x), "exact: omega0 has non-finite entries (NaN or inf)"
        ),
        omega0,
    )
    return moments, q0, omega0


def _now_if_concrete(check, x):
    """Run ``check(x)`` eagerly when ``x`` is concrete, even inside ``jit`` (a concrete
    array closed over by a jitted function raises ``ValueError`` while tracing)."""
    if isinstance(x, jax.core.Tracer):
        return check(x)
    with jax.ensure_compile_time_eval():
        return check(x)


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


def _power_of_two_scale(x):
    """``2^-e`` with ``x = f 2^e``, ``f`` in ``[0.5, 1)`` (``x > 0``); no derivative."""
    _, e = jnp.frexp(jax.lax.stop_gradient(x))
    return jnp.ldexp(jnp.ones_like(x), -e)


def _sign(x):
    """``+1`` for ``x ≥ 0``, ``-1`` otherwise (a constant: no derivative)."""
    return jnp.where(x >= 0, 1.0, -1.0)


def _unstack(x):
    return x[..., 0], x[..., 1], x[..., 2]


# ------------------------------------------------- double-double arithmetic
# L² - 2E I_mid = Σ I_k (I_k - I_mid) ω_k² is a difference of two terms, and its relative
# rounding error becomes the relative error of 1 - m and thus of the period. It is
# evaluated exactly (error-free transformations: Dekker's product, Knuth's sum) so that
# the phase after 10⁴ periods is limited by the rounding of t alone.


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


# ------------------------------------------------------------------ frames


def _signed_permutation(idx, dtype):
    """One-hot rows ``idx`` (a permutation of 0, 1, 2), first row negated if it is odd."""
    p = jax.nn.one_hot(idx, 3, dtype=dtype)
    i0, i1, i2 = idx[..., 0], idx[..., 1], idx[..., 2]
    det = jnp.sign((i1 - i0) * (i2 - i0) * (i2 - i1)).astype(dtype)
    flip = jnp.stack([det, jnp.ones_like(det), jnp.ones_like(det)], axis=-1)
    return p * flip[..., :, None]


def _canonical_permutation(inertia, omega):
    """Signed permutation ``P`` (det +1) to the canonical frame; ``(P, regime_a, Δ_mid)``."""
    order = jnp.argsort(inertia, axis=-1)
    i_sorted = jnp.take_along_axis(inertia, order, axis=-1)
    w_sorted = jnp.take_along_axis(omega, order, axis=-1)
    delta_mid = _distance_to_separatrix(
        i_sorted[..., 0], i_sorted[..., 1], i_sorted[..., 2], w_sorted[..., 0], w_sorted[..., 2]
    )
    regime_a = delta_mid >= 0
    idx = jnp.where(regime_a[..., None], order, order[..., ::-1])
    return _signed_permutation(idx, inertia.dtype), regime_a, delta_mid


def _spin_permutation(omega):
    """Even permutation taking the body axis of the largest ``|ω_k|`` to axis 3."""
    k = jnp.argmax(jnp.abs(omega), axis=-1)
    idx = jnp.stack([(k + 1) % 3, (k + 2) % 3, k], axis=-1)
    return _signed_permutation(idx, omega.dtype)


def _shortest_from_axis(lhat, sigma):
    """Quaternion of the shortest rotation taking ``σ e3`` to the unit vector ``lhat``."""
    l1, l2, l3 = _unstack(lhat)
    c = 1.0 + sigma * l3  # >= 1 by construction
    r = jnp.stack([c, -sigma * l2, sigma * l1, jnp.zeros_like(c)], axis=-1)
    return r / jnp.sqrt(2.0 * c)[..., None]


# ------------------------------------------------------------- general motion


def _landen_args(sr, cr, dn, kp, k1, nprime):
    """Square roots of the ``R_J`` arguments of the transformed integral at a reduced point.

    ``sr, cr ≥ 0, dn`` are ``sn, cn, dn`` at ``r ∈ [-K, K]``; returns ``(sn1, sqrt-args)``.
    """
    onedn = 1.0 + dn
    sn1 = (1.0 + kp) * sr / onedn
    # 1 - k1 = 2k'/(1 + k') exactly (k1 -> 1 near the separatrix).
    dn1 = jnp.sqrt((dn * (1.0 + k1) + 2.0 * kp / (1.0 + kp)) / onedn)
    cn1 = 2.0 * cr / (onedn * dn1)
    return sn1, (cn1, dn1, jnp.ones_like(sn1), jnp.sqrt(1.0 - nprime * sn1 * sn1))


def _third_kind_args(sr, cr, dn, third, kp, k1, n):
    """``(s, sqrt-args)`` with ``P = s³ R_J(args²)`` at a reduced point, either form."""
    sn1, (cn1, dn1, one, p1) = _landen_args(sr, cr, dn, kp, k1, n)
    s = jnp.where(third, sr, sn1)
    args = (
        jnp.where(third, cr, cn1),
        jnp.where(third, dn, dn1),
        one,
        jnp.where(third, jnp.sqrt(1.0 - n * sr * sr), p1),
    )
    return s, args


def _general(ic, wc, regime_a, delta2):
    """Elliptic constants of the motion in the canonical frame (a non-steady body).

    Args: canonical scaled moments and ω0 ``(..., 3)``, the regime flag and the exactly
    rounded ``Δ2``. Returns a dict of ``(...)`` arrays (and ``amp`` ``(..., 3)``).
    """
    i1, i2, i3 = _unstack(ic)
    w1, w2, w3 = _unstack(wc)
    d21, d31, d32 = i2 - i1, i3 - i1, i3 - i2
    lsq = jnp.sum((ic * wc) ** 2, axis=-1)
    lnorm = jnp.sqrt(lsq)
    two_e = jnp.sum(ic * wc * wc, axis=-1)
    delta1 = i2 * d21 * w2 * w2 + i3 * d31 * w3 * w3
    delta3 = -(i1 * d31 * w1 * w1 + i2 * d32 * w2 * w2)
    den = d32 * delta1
    m = _clip(_safe_div(d21 * -delta3, den), 0.0, 1.0)
    m1 = _clip(_safe_div(d31 * delta2, den), 0.0, 1.0)
    lam = jnp.sqrt(den / (i1 * i2 * i3))
    # Amplitudes as hypotenuses (no cancellation, no underflow).
    a1 = _hypot(w1, w2, _safe_div(i2 * d32, i1 * d31))
    a2 = _hypot(w2, w1, _safe_div(i1 * d31, i2 * d32))
    a3 = _hypot(w3, w2, _safe_div(i2 * d21, i3 * d31))
    s = jnp.where(regime_a, 1.0, -1.0)
    sigma, rho = _sign(w3), _sign(w1)
    amp = jnp.stack([rho * a1, s * rho * sigma * a2, sigma * a3], axis=-1)
    cn0 = _clip(_safe_div(rho * w1, a1), 0.0, 1.0)
    sn0 = _clip(_safe_div(s * rho * sigma * w2, a2), -1.0, 1.0)
    dn0 = _clip(_safe_div(sigma * w3, a3), 0.0, 1.0)
    # D of the addition theorem: m sn²τ0 + dn²τ0 = 1, both without cancellation.
    msn0 = _safe_div(d21 * i2 * w2 * w2, delta1)
    dn0sq = _safe_div(i3 * d31 * w3 * w3, delta1)
    one, zero = jnp.ones_like(cn0), jnp.zeros_like(cn0)
    # One R_F call: K(m) = R_F(0, m1, 1) and tau0 = sn0 R_F(cn0², dn0², 1). On the
    # separatrix K is infinite; its (unused) derivative is kept finite by a safe input.
    finite = m1 > 0
    kp = safe_sqrt(m1)
    kp_safe = jnp.where(finite, kp, 1.0)
    rf = rf_sqrt(jnp.stack([zero, cn0]), jnp.stack([kp_safe, dn0]), jnp.stack([one, one]))
    kk = jnp.where(finite, rf[0], jnp.inf)
    tau0 = sn0 * rf[1]

    # Landen-transformed third-kind integral.
    k1 = m / (1.0 + kp) ** 2
    k1c = 4.0 * kp_safe / (1.0 + kp_safe) ** 2
    ab = lnorm + i3 * a3
    nprime = -k1 * (i1 * a1) ** 2 / ab**2
    rate0 = (two_e + lnorm * a3) / ab
    kappa = -2.0 * delta3 * a3 * k1 / ab**2
    # Third-kind integral in m itself (near the separatrix).
    c = i3 * a3 / lnorm
    a_exact = -i1 * delta3 / (d31 * lsq)  # 1 - c², no cancellation
    third = (a_exact >= _THIRD_KIND_MIN_A) & (64.0 * m1 < a_exact * a_exact)
    a = jnp.where(third, a_exact, 1.0)
    b = c * c * m
    gap = -delta3 / (lnorm * i3)  # 2E/|L| - |L|/I3
    n_third = -b / a
    k_third = jnp.sqrt((a + b) / a)
    n = jnp.where(third, n_third, nprime)
    s0, args0 = _third_kind_args(sn0, cn0, dn0, third, kp, k1, n)
    sn1, args_landen = _landen_args(sn0, cn0, dn0, kp, k1, nprime)
    # One R_J call: Landen's complete integral and Q(tau0) (the documented fields), and
    # the complete integral and P(tau0) of the form in use.
    complete = (
        zero,
        jnp.where(third, kp_safe, jnp.sqrt(k1c)),
        one,
        jnp.where(third, jnp.sqrt(1.0 - n_third), jnp.sqrt(1.0 - nprime)),
    )
    landen_complete = (zero, jnp.sqrt(k1c), one, jnp.sqrt(1.0 - nprime))
    rj = rj_sqrt(
        *(jnp.stack(v) for v in zip(landen_complete, args_landen, complete, args0, strict=True)),
        steps=_RJ_STEPS,
    )
    return dict(
        amp=amp,
        lam=lam,
        tau0=tau0,
        m=m,
        m1=m1,
        kk=kk,
        k1=k1,
        nprime=nprime,
        q_half=jnp.where(finite, rj[0] / 3.0, jnp.inf),
        q_start=(1.0 + k1) * sn1**3 * rj[1] / 3.0,
        rate0=rate0,
        kappa=kappa,
        msn0=msn0,
        dn0sq=dn0sq,
        psi_third=third,
        psi_rate=jnp.where(third, lnorm / i3 + gap / a, rate0),
        psi_coef=jnp.where(third, gap * n_third / (3.0 * a), kappa * (1.0 + k1) / 3.0),
        psi_angle=jnp.where(third, gap * c / jnp.sqrt(a * (a + b)), 0.0),
        psi_k=jnp.where(third, k_third, 1.0),
        psi_n=n,
        p_start=s0**3 * rj[3],
        theta_start=jnp.where(third, jnp.arctan2(k_third * sn0, cn0), 0.0),
        p_complete=jnp.where(finite, rj[2], 0.0),
    )


# ---------------------------------------------------------------- Taylor branch


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


# ------------------------------------------------------------------ prepare


def prepare(
    moments: ArrayLike, q0: ArrayLike, omega0: ArrayLike, *, allow_nonphysical: bool = True
) -> ExactConstants:
    """Constants of the torque-free motion of a body (batched over leading dimensions).

    Args:
        moments: ``(..., 3)`` principal moments ``(I1, I2, I3)``, finite and positive
            definite (:func:`jrigid.inertia.validate`), any order.
        q0: ``(..., 4)`` initial orientation, body → space, scalar first, finite and
            non-zero (normalized here).
        omega0: ``(..., 3)`` initial body-frame angular velocity, finite.
        allow_nonphysical: ``True`` (default): any positive moments, as the closed form
            needs no more (e.g. the Hairer-Nørsett-Wanner body ``(0.5, 2, 3)``); ``False``:
            also require the triangle inequality ``Ia + Ib ≥ Ic``, as
            :class:`jrigid.body.RigidBody` does by default.

    Returns:
        :class:`ExactConstants` with batch shape the broadcast of the three batch shapes.

    Raises:
        ValueError: wrong shapes, or, for concrete input, invalid values (above). Under
            ``jit`` invalid values raise an ``equinox`` runtime error naming the problem.
    """
    return _prepare(*_as_inputs(moments, q0, omega0, allow_nonphysical))


@jax.jit
def _prepare(moments, q0, omega0):
    dtype = moments.dtype
    batch = jnp.broadcast_shapes(moments.shape[:-1], q0.shape[:-1], omega0.shape[:-1])
    moments = jnp.broadcast_to(moments, batch + (3,))
    q0 = quat.normalize(jnp.broadcast_to(q0, batch + (4,)))
    omega0 = jnp.broadcast_to(omega0, batch + (3,))

    # Scale-free variables, scaled by powers of two (exactly): moments by the largest, omega
    # by its largest component; nu is the time unit.
    inertia = moments * _power_of_two_scale(jnp.max(moments, axis=-1))[..., None]
    w_max = jnp.max(jnp.abs(omega0), axis=-1)
    moving = w_max > 0
    w_scale = _power_of_two_scale(jnp.where(moving, w_max, 1.0))
    nu = jnp.where(moving, 1.0 / w_scale, 0.0)
    w_hat = omega0 * w_scale[..., None]

    # Steady rotation: omega x (I omega) vanishes exactly (a spherical body, a principal
    # axis, the degenerate plane of a symmetric body, or omega = 0).
    ia, ib, ic_ = _unstack(inertia)
    wa, wb, wc_ = _unstack(w_hat)
    euler_rhs = jnp.stack([(ib - ic_) * wb * wc_, (ic_ - ia) * wc_ * wa, (ia - ib) * wa * wb], -1)
    steady = ~moving | jnp.all(euler_rhs == 0, axis=-1)
    spin = moving & (jnp.sum(w_hat == 0, axis=-1) >= 2)

    # Canonical frame of the body itself (by regime; along the spin for a spin).
    p_regime, regime_a, delta_mid = _canonical_permutation(inertia, w_hat)
    perm = jax.lax.stop_gradient(
        jnp.where(spin[..., None, None], _spin_permutation(w_hat), p_regime)
    )
    ic = jnp.einsum("...ij,...j->...i", jnp.abs(perm), inertia)
    wc = jnp.einsum("...ij,...j->...i", perm, w_hat)
    i1, i2, i3 = _unstack(ic)
    w1, w2, w3 = _unstack(wc)
    d21, d31, d32 = i2 - i1, i3 - i1, i3 - i2
    lnorm = safe_sqrt(jnp.sum((ic * wc) ** 2, axis=-1))
    delta1 = i2 * d21 * w2 * w2 + i3 * d31 * w3 * w3
    lam2 = d32 * delta1 / (i1 * i2 * i3)  # mu (any sign) for a spin, else lambda² >= 0
    general = moving & ~spin & (lam2 > 0)
    slow_rate = jnp.where(general, jnp.sqrt(jnp.where(general, lam2, 1.0)), 0.0)

    # Elliptic constants: of the body when they are used, else of a generic stand-in.
    dummy_i = jnp.broadcast_to(jnp.asarray(_DUMMY_I, dtype), ic.shape)
    dummy_w = jnp.broadcast_to(jnp.asarray(_DUMMY_W, dtype), wc.shape)
    g_ic = jnp.where(general[..., None], ic, dummy_i)
    g_wc = jnp.where(general[..., None], wc, dummy_w)
    di1, di2, di3 = _unstack(dummy_i)
    dw1, _, dw3 = _unstack(dummy_w)
    dummy_delta2 = di3 * (di3 - di2) * dw3 * dw3 - di1 * (di2 - di1) * dw1 * dw1
    g = _general(
        g_ic,
        g_wc,
        jnp.where(general, regime_a, True),
        jnp.where(general, delta_mid, dummy_delta2),
    )

    # Orientation: W = q0_canonical (x) B(0), about a = sigma e3.
    sigma = _sign(w3)
    a_axis = jnp.stack([jnp.zeros_like(sigma), jnp.zeros_like(sigma), sigma], axis=-1)
    lnorm_safe = jnp.where(moving, lnorm, 1.0)
    l0 = jnp.where(moving[..., None], ic * wc / lnorm_safe[..., None], a_axis)
    perm_q = jax.lax.stop_gradient(quat.from_matrix(perm))
    w0 = quat.multiply(quat.multiply(q0, quat.conjugate(perm_q)), _shortest_from_axis(l0, sigma))

    # Taylor branch (any moving body; a stand-in at rest), in y = st / scale.
    s_wc = jnp.where(moving[..., None], wc, dummy_w)
    s_lnorm = jnp.sqrt(jnp.sum((ic * s_wc) ** 2, axis=-1))
    s_two_e = jnp.sum(ic * s_wc * s_wc, axis=-1)
    scale = jax.lax.stop_gradient(
        jnp.where(slow_rate > 0, _SLOW / jnp.where(slow_rate > 0, slow_rate, 1.0), 1.0)
    )
    coef_w, coef_psi = _taylor(
        ic, s_wc, s_lnorm, s_two_e, _sign(s_wc[..., 2]), scale, _SERIES_ORDER
    )

    return ExactConstants(
        perm=perm,
        perm_q=perm_q,
        amp=g["amp"],
        inertia=ic,
        nu=nu,
        lam=g["lam"],
        tau0=g["tau0"],
        m=g["m"],
        m1=g["m1"],
        kk=g["kk"],
        k1=g["k1"],
        nprime=g["nprime"],
        q_half=g["q_half"],
        q_start=g["q_start"],
        rate0=g["rate0"],
        kappa=g["kappa"],
        sigma=sigma,
        lnorm=lnorm,
        w0=w0,
        q0=q0,
        omega0=omega0,
        steady=steady,
        omega_c=wc,
        coupling=jnp.stack([d32 / i1, d31 / i2, d21 / i3], axis=-1),
        msn0=g["msn0"],
        dn0sq=g["dn0sq"],
        psi_third=g["psi_third"],
        psi_rate=g["psi_rate"],
        psi_coef=g["psi_coef"],
        psi_angle=g["psi_angle"],
        psi_k=g["psi_k"],
        psi_n=g["psi_n"],
        p_start=g["p_start"],
        theta_start=g["theta_start"],
        p_complete=g["p_complete"],
        series_omega=coef_w,
        series_psi=coef_psi,
        series_scale=scale,
        slow_rate=slow_rate,
        spin=spin,
        spin_rate2=jnp.where(spin, lam2, 0.0),
        rest=~moving,
    )


# ----------------------------------------------------------------- evaluate


def _expand(consts: ExactConstants, extra: int) -> ExactConstants:
    """Insert ``extra`` axes after the batch axes of every field (for time broadcasting)."""
    batch_ndim = consts.nu.ndim

    def f(x):
        return x.reshape(x.shape[:batch_ndim] + (1,) * extra + x.shape[batch_ndim:])

    return jax.tree_util.tree_map(f, consts)


def evaluate(consts: ExactConstants, t: ArrayLike) -> tuple[jax.Array, jax.Array]:
    """Orientation and angular velocity at times ``t`` (any shape ``S``).

    Args:
        consts: from :func:`prepare`, batch shape ``B``.
        t: ``S``-shaped array of times (``t = 0`` is the initial state).

    Returns:
        ``(q, omega)`` of shapes ``B + S + (4,)`` and ``B + S + (3,)``: the body → space
        unit quaternion and the body-frame angular velocity. The cost per time does not
        depend on ``t``.
    """
    return _evaluate(consts, jnp.asarray(t, dtype=consts.nu.dtype))


def _general_psi(c, omega_lin, u, st):
    """``ψ`` of the general motion from ``ω(t)`` (canonical, scaled), ``u = λ t`` and ``t``."""
    snt = _safe_div(omega_lin[..., 1], c.amp[..., 1])
    cnt = _safe_div(omega_lin[..., 0], c.amp[..., 0])
    dnt = _clip(_safe_div(omega_lin[..., 2], c.amp[..., 2]), 0.0, 1.0)
    finite = jnp.isfinite(c.kk)
    k_safe = jnp.where(finite, c.kk, 1.0)
    tau = jax.lax.stop_gradient(u + c.tau0)
    j = jnp.where(finite, jnp.round(tau / (2.0 * k_safe)), 0.0)
    sign = parity_sign(j)
    sr = _clip(sign * snt, -1.0, 1.0)
    cr = _clip(jnp.abs(cnt), 0.0, 1.0)
    kp = safe_sqrt(c.m1)
    s, args = _third_kind_args(sr, cr, dnt, c.psi_third, kp, c.k1, c.psi_n)
    full = jnp.where(j == 0, 0.0, 2.0 * j * jnp.where(j == 0, 0.0, c.p_complete))
    p = s**3 * rj_sqrt(*args, steps=_RJ_STEPS) + full
    theta = j * jnp.pi + jnp.arctan2(c.psi_k * sr, cr)
    corr = c.psi_coef * (p - c.p_start) - c.psi_angle * (theta - c.theta_start)
    return c.psi_rate * st + corr / c.lam


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


@jax.jit
def _evaluate(consts, t):
    c = _expand(consts, t.ndim)
    t = t.reshape((1,) * consts.nu.ndim + t.shape)
    shape = jnp.broadcast_shapes(c.nu.shape, t.shape)
    t = jnp.broadcast_to(t, shape)
    c = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, shape + x.shape[len(shape) :]), c)
    st = c.nu * t  # scaled time

    # Angular velocity by the addition theorem: general motion or linearized spin (whose
    # cos/sin(√μ t) come from the same Jacobi call with m = 0; cosh/sinh for μ < 0).
    spin = c.spin
    mu = c.spin_rate2
    stable = mu >= 0
    r = safe_sqrt(jnp.abs(mu))
    cap = 0.45 * float(np.log(jnp.finfo(st.dtype).max))
    x = jnp.clip(r * st, -cap, cap)
    u = jnp.where(spin, x, c.lam * st)
    m = jnp.where(spin, 0.0, c.m)
    m1 = jnp.where(spin, 1.0, c.m1)
    kk = jnp.where(spin, 0.5 * jnp.pi, c.kk)
    sn_u, cn_u, dn_u, _, _ = jacobi_with_index(u, m, m1, kk)
    d_u = jnp.where(
        c.msn0 <= 0.5, 1.0 - c.msn0 * sn_u * sn_u, cn_u * cn_u + c.dn0sq * sn_u * sn_u
    )
    grow = jnp.exp(jnp.where(stable, 0.0, x))
    cos_r = jnp.where(stable, cn_u, 0.5 * (grow + 1.0 / grow))
    sin_r = jnp.where(stable, sn_u, 0.5 * (grow - 1.0 / grow))
    moving = r > 0
    sin_r = jnp.where(moving, sin_r / jnp.where(moving, r, 1.0), st)
    cn_ = jnp.where(spin, cos_r, cn_u)
    dn_ = jnp.where(spin, 1.0, dn_u)
    s_ = jnp.where(spin, sin_r, sn_u / c.lam)
    d_ = jnp.where(spin, 1.0, d_u)
    w1, w2, w3 = _unstack(c.omega_c)
    e1, e2, e3 = _unstack(c.coupling)
    omega_lin = jnp.stack(
        [
            w1 * cn_ - e1 * w2 * w3 * s_ * dn_,
            w2 * cn_ * dn_ + e2 * w1 * w3 * s_,
            w3 * dn_ - e3 * w1 * w2 * s_ * cn_,
        ],
        axis=-1,
    ) / d_[..., None]
    # Only a body whose elliptic constants are its own (slow_rate > 0) uses psi_general;
    # the others get safe inputs (at a spin or at rest sn = cn = 0, where atan2 has no
    # derivative).
    general = (c.slow_rate > 0)[..., None]
    psi_general = _general_psi(c, jnp.where(general, omega_lin, c.amp), u, st)

    # Short times and slow motions: Taylor polynomials.
    slow = ~spin & (c.slow_rate * jnp.abs(st) <= _SLOW)
    omega_s, psi_s = _series(c, st, slow)
    omega_c = jnp.where(slow[..., None], omega_s, omega_lin)
    psi_spin = c.series_psi[..., 0] * st
    psi = jnp.where(spin, psi_spin, jnp.where(slow, psi_s, psi_general))

    half = 0.5 * psi
    zrot = jnp.stack(
        [jnp.cos(half), jnp.zeros_like(half), jnp.zeros_like(half), c.sigma * jnp.sin(half)],
        axis=-1,
    )
    lnorm_safe = jnp.where(c.rest, 1.0, c.lnorm)
    lhat = jnp.where(
        c.rest[..., None],
        jnp.zeros_like(omega_c).at[..., 2].set(c.sigma),
        c.inertia * omega_c / lnorm_safe[..., None],
    )
    qc = quat.multiply(
        quat.multiply(c.w0, zrot), quat.conjugate(_shortest_from_axis(lhat, c.sigma))
    )
    q_moving = quat.multiply(qc, c.perm_q)
    omega_moving = c.nu[..., None] * jnp.einsum("...ji,...j->...i", c.perm, omega_c)

    # At rest: q0 (1, ω0 t/2) is q0, with the first-order change of a slow start.
    turn = jnp.concatenate([jnp.ones_like(t)[..., None], 0.5 * c.omega0 * t[..., None]], -1)
    rest = c.rest[..., None]
    q = jnp.where(rest, quat.multiply(c.q0, turn), q_moving)
    omega = jnp.where(rest, c.omega0, omega_moving)
    return q, omega


def solve(
    moments: ArrayLike,
    q0: ArrayLike,
    omega0: ArrayLike,
    ts: ArrayLike,
    *,
    allow_nonphysical: bool = True,
) -> tuple[jax.Array, jax.Array]:
    """Exact torque-free motion (eqs. 17.35 with ``N = 0`` and 17.44) at times ``ts``.

    Args:
        moments: ``(..., 3)`` principal moments (finite, positive, any order).
        q0: ``(..., 4)`` initial orientation, body → space, scalar first (non-zero).
        omega0: ``(..., 3)`` initial body-frame angular velocity.
        ts: ``(T,)`` (or any shape ``S``) finite output times.
        allow_nonphysical: as for :func:`prepare`.

    Returns:
        ``(q, omega)``: ``(..., T, 4)`` and ``(..., T, 3)``. Equivalent to
        ``evaluate(prepare(moments, q0, omega0), ts)``; ``jit``/``vmap``/``grad``-able.

    Raises:
        ValueError: as :func:`prepare`, and for non-finite concrete ``ts`` (under ``jit``
            an ``equinox`` runtime error).
    """
    consts = prepare(moments, q0, omega0, allow_nonphysical=allow_nonphysical)
    ts = jnp.asarray(ts, dtype=consts.nu.dtype)
    ts = fail_if(ts, ~jnp.isfinite(ts), "exact: ts has non-finite entries (NaN or inf)")
    return evaluate(consts, ts)


def omega_period(consts: ExactConstants) -> jax.Array:
    """Period of ``ω(t)``: ``4K(m)/λ`` (``inf`` on the separatrix and for steady spin).

    Args:
        consts: from :func:`prepare`, batch shape ``B``.

    Returns:
        ``B``-shaped array. ``ω`` is exactly periodic with this period; ``q`` is not.
    """
    lam = consts.lam * consts.nu
    finite = (consts.m1 > 0) & ~consts.steady & (lam > 0)
    kk = jnp.where(finite, consts.kk, 1.0)
    return jnp.where(finite, 4.0 * kk / jnp.where(finite, lam, 1.0), jnp.inf)
