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
``Δ2`` and never as ``1 - m``. ``τ0 = sn0 R_F(cn0², dn0², 1)``.

*Orientation.* ``q(t) = W ⊗ Z(ψ(t)) ⊗ B(t)*`` where ``B(t)`` is the shortest rotation
taking the fixed body axis ``a = σ e3`` to ``l(t) = L_body(t)/|L|`` (never antipodal,
since ``a·l = I3 |ω3| / |L| ≥ 0``), ``Z(ψ)`` the rotation by ``ψ`` about ``a`` and
``W = q0 ⊗ B(0)`` fixed. Differentiating gives ``ψ̇ = (2E/|L| + a·ω) / (1 + a·l)``
``= (2E + |L| x)/(|L| + I3 x)`` with ``x = A3 dn τ``. Its integral uses the descending
Landen (Gauss) transformation (DLMF 22.7.1-3), ``1 + dn(z|k) = 2/(1 + k₁ sn²(z/(1+k₁)|k₁²))``
with ``k₁ = (1 - k')/(1 + k')``, which turns ``1/(a + b dn)`` into a rational function of
``sn²`` without the cancellation of the textbook Π-plus-arctan form:

    ψ(t) = ψ̇₀ t + κ (Q(τ) - Q(τ0)) / λ,
    ψ̇₀ = (2E + |L| A3) / (|L| + I3 A3),   κ = -2 Δ3 A3 k₁ / (|L| + I3 A3)²,
    Q(τ) = (1 + k₁) ∫_0^{φ₁} sin²θ dθ / ((1 - n' sin²θ) √(1 - k₁² sin²θ)),
    n' = -k₁ I1² A1² / (|L| + I3 A3)²  (≤ 0),

where ``φ₁`` is the (unwrapped) amplitude of the transformed argument and the integral is
``sin³φ₁ R_J(cos²φ₁, Δ₁², 1, 1 - n' sin²φ₁)/3`` plus ``2j`` complete integrals after ``j``
half periods. When ``L² > 2E I2`` both terms are positive; otherwise ``κ ≤ 0`` and the
subtraction loses at most the ratio of the largest to the mean of ``ψ̇``. This avoids the
sign pitfalls of published formulae (Celledoni, Fassò, Säfström & Zanna 2008; van Zon &
Schofield 2007): it is derived here from ``q̇ = ½ q ⊗ (0, ω)`` and checked against
high-precision integration of that equation in ``tests/test_exact.py``.

*Special cases.* The separatrix ``L² = 2E I2`` is ``m = 1`` (hyperbolic functions);
symmetric bodies give ``m = 0``; a spherical body, or a spin about a principal axis, or
about any axis of the degenerate plane of a symmetric body, is a steady rotation,
``q(t) = q0 ⊗ exp(ω0 t/2)``. The inputs are rescaled by powers of two (exactly: moments
by the largest, ω by its largest component) so that nothing under- or overflows.

Derivatives: everything is ``jnp`` plus the differentiable functions of
:mod:`jrigid.special`, so ``jax.grad``/``jax.jacfwd`` work with respect to the moments,
``q0``, ``ω0`` and ``t``, and agree with finite differences also on the separatrix and at
ties of the moments (tested). At an exactly steady motion (see above) they are those of
``q0 ⊗ exp(ω0 t/2)``: right for ``q0`` and ``t``, but blind to the first-order change of
the motion when a perturbation of the moments or of ``ω0`` breaks the steadiness (for
instance ``d/dI`` at a spherical body); they are finite there.

Bad input: non-positive moments raise ``ValueError`` for concrete input and
``equinox.error_if`` under ``jit``; wrong shapes raise ``ValueError``. ``q0`` is normalized.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from jrigid import quaternion as quat
from jrigid.special._carlson import _rf_sqrt, _rj_sqrt, _safe_sqrt
from jrigid.special._jacobi import _parity_sign, jacobi_with_index

__all__ = ["ExactConstants", "evaluate", "omega_period", "prepare", "solve"]

# Duplication steps for R_J(x, y, 1, p) with x, y in [0, 1], p in [1, 2): 12 reach full
# float64 accuracy down to y = 1e-60 (distances to the separatrix far below rounding).
_RJ_STEPS = 12


class ExactConstants(NamedTuple):
    """Per-body constants of the closed-form solution (a pytree; batch shape ``B``).

    Fields are arrays of shape ``B`` unless noted; "canonical" refers to the permuted
    body frame described in the module docstring. Build with :func:`prepare`.
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


def _as_inputs(moments, q0, omega0):
    """Arrays of one floating dtype with checked trailing shapes (``ValueError`` if not)."""
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
    # numpy, not jnp: inside jit even a concrete array's comparison would be traced.
    if not isinstance(moments, jax.core.Tracer) and not np.all(np.asarray(moments) > 0):
        raise ValueError(f"exact: principal moments must be positive, got {moments}")
    return tuple(x.astype(dtype) for x in (moments, q0, omega0))


def _safe_div(a, b):
    ok = b != 0
    return jnp.where(ok, a / jnp.where(ok, b, 1.0), 0.0)


def _clip(x, lo, hi):
    """Clip against rounding; unlike ``jnp.clip`` the derivative at ``x = lo, hi`` is 1."""
    return jnp.where(x < lo, lo, jnp.where(x > hi, hi, x))


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
    p = jax.nn.one_hot(idx, 3, dtype=inertia.dtype)
    i0, i1, i2 = idx[..., 0], idx[..., 1], idx[..., 2]
    det = jnp.sign((i1 - i0) * (i2 - i0) * (i2 - i1)).astype(inertia.dtype)
    flip = jnp.stack([det, jnp.ones_like(det), jnp.ones_like(det)], axis=-1)
    return jax.lax.stop_gradient(p * flip[..., :, None]), regime_a, delta_mid


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


def _transformed_integral(sn, cn, dn, j, kp, k1, nprime, q_half):
    """``Q(τ)``: the unwrapped Landen-transformed third-kind integral at ``τ``."""
    sign = _parity_sign(j)
    sn1, args = _landen_args(sign * sn, sign * cn, dn, kp, k1, nprime)
    part = sn1**3 * _rj_sqrt(*args, steps=_RJ_STEPS) / 3.0
    full = jnp.where(j == 0, 0.0, 2.0 * j * jnp.where(j == 0, 0.0, q_half))
    return (1.0 + k1) * (part + full)


def prepare(moments: ArrayLike, q0: ArrayLike, omega0: ArrayLike) -> ExactConstants:
    """Constants of the torque-free motion of a body (batched over leading dimensions).

    Args:
        moments: ``(..., 3)`` principal moments ``(I1, I2, I3)``, positive, any order
            (the triangle inequality is not required).
        q0: ``(..., 4)`` initial orientation, body → space, scalar first (normalized here).
        omega0: ``(..., 3)`` initial body-frame angular velocity.

    Returns:
        :class:`ExactConstants` with batch shape the broadcast of the three batch shapes.
    """
    return _prepare(*_as_inputs(moments, q0, omega0))


@jax.jit
def _prepare(moments, q0, omega0):
    dtype = moments.dtype
    moments = eqx.error_if(
        moments, jnp.any(~(moments > 0)), "exact: principal moments must be positive"
    )
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
    ia, ib, ic_ = inertia[..., 0], inertia[..., 1], inertia[..., 2]
    wa, wb, wc_ = w_hat[..., 0], w_hat[..., 1], w_hat[..., 2]
    euler_rhs = jnp.stack([(ib - ic_) * wb * wc_, (ic_ - ia) * wc_ * wa, (ia - ib) * wa * wb], -1)
    steady = ~moving | jnp.all(euler_rhs == 0, axis=-1)
    # The general formulas below run on a generic dummy body when the motion is steady, so
    # that their (discarded) values and derivatives stay finite (double-where trick).
    dummy_i = jnp.asarray([1.0, 2.0, 3.0], dtype) / 3.0
    dummy_w = jnp.asarray([0.6, 0.48, 0.64], dtype)
    inertia = jnp.where(steady[..., None], dummy_i, inertia)
    w_hat = jnp.where(steady[..., None], dummy_w, w_hat)

    perm, regime_a, delta2 = _canonical_permutation(inertia, w_hat)
    ic = jnp.einsum("...ij,...j->...i", jnp.abs(perm), inertia)
    wc = jnp.einsum("...ij,...j->...i", perm, w_hat)
    i1, i2, i3 = ic[..., 0], ic[..., 1], ic[..., 2]
    w1, w2, w3 = wc[..., 0], wc[..., 1], wc[..., 2]
    d21, d31, d32 = i2 - i1, i3 - i1, i3 - i2

    lsq = jnp.sum((ic * wc) ** 2, axis=-1)
    lnorm = jnp.sqrt(lsq)
    two_e = jnp.sum(ic * wc * wc, axis=-1)
    delta1 = i2 * d21 * w2 * w2 + i3 * d31 * w3 * w3
    delta3 = -(i1 * d31 * w1 * w1 + i2 * d32 * w2 * w2)
    # Amplitudes as hypotenuses (no cancellation, no underflow).
    a1 = _hypot(w1, w2, _safe_div(i2 * d32, i1 * d31))
    a2 = _hypot(w2, w1, _safe_div(i1 * d31, i2 * d32))
    a3 = _hypot(w3, w2, _safe_div(i2 * d21, i3 * d31))
    den = d32 * delta1
    m = _clip(_safe_div(d21 * -delta3, den), 0.0, 1.0)
    m1 = _clip(_safe_div(d31 * delta2, den), 0.0, 1.0)
    lam = jnp.sqrt(_clip(den / (i1 * i2 * i3), 0.0, jnp.inf))

    s = jnp.where(regime_a, 1.0, -1.0)
    sigma, rho = _sign(w3), _sign(w1)
    amp = jnp.stack([rho * a1, s * rho * sigma * a2, sigma * a3], axis=-1)
    cn0 = _clip(_safe_div(rho * w1, a1), 0.0, 1.0)
    sn0 = _clip(_safe_div(s * rho * sigma * w2, a2), -1.0, 1.0)
    dn0 = _clip(_safe_div(sigma * w3, a3), 0.0, 1.0)
    one, zero = jnp.ones_like(cn0), jnp.zeros_like(cn0)
    # One R_F call: K(m) = R_F(0, m1, 1) and tau0 = sn0 R_F(cn0², dn0², 1).
    rf = _rf_sqrt(jnp.stack([zero, cn0]), jnp.stack([_safe_sqrt(m1), dn0]), jnp.stack([one, one]))
    kk = jnp.where(m1 > 0, rf[0], jnp.inf)
    tau0 = sn0 * rf[1]

    # Landen-transformed third-kind integral.
    kp = jnp.sqrt(m1)
    k1 = m / (1.0 + kp) ** 2
    k1c = 4.0 * kp / (1.0 + kp) ** 2
    ab = lnorm + i3 * a3
    nprime = -k1 * (i1 * a1) ** 2 / ab**2
    rate0 = (two_e + lnorm * a3) / ab
    kappa = -2.0 * delta3 * a3 * k1 / ab**2
    # One R_J call: the complete integral and Q(tau0) (tau0 in [-K, K], so j = 0).
    sn1, (x1, y1, z1, p1) = _landen_args(sn0, cn0, dn0, kp, k1, nprime)
    rj = _rj_sqrt(
        jnp.stack([zero, x1]),
        jnp.stack([_safe_sqrt(k1c), y1]),
        jnp.stack([one, z1]),
        jnp.stack([jnp.sqrt(1.0 - nprime), p1]),
        steps=_RJ_STEPS,
    )
    q_half = rj[0] / 3.0
    q_start = (1.0 + k1) * sn1**3 * rj[1] / 3.0

    qc0 = quat.multiply(q0, quat.conjugate(quat.from_matrix(perm)))
    l0 = ic * wc / lnorm[..., None]
    w0 = quat.multiply(qc0, _shortest_from_axis(l0, sigma))
    return ExactConstants(
        perm=perm,
        perm_q=jax.lax.stop_gradient(quat.from_matrix(perm)),
        amp=amp,
        inertia=ic,
        nu=nu,
        lam=lam,
        tau0=tau0,
        m=m,
        m1=m1,
        kk=kk,
        k1=k1,
        nprime=nprime,
        q_half=q_half,
        q_start=q_start,
        rate0=rate0,
        kappa=kappa,
        sigma=sigma,
        lnorm=lnorm,
        w0=w0,
        q0=q0,
        omega0=omega0,
        steady=steady,
    )


def _shortest_from_axis(lhat, sigma):
    """Quaternion of the shortest rotation taking ``σ e3`` to the unit vector ``lhat``."""
    l1, l2, l3 = lhat[..., 0], lhat[..., 1], lhat[..., 2]
    c = 1.0 + sigma * l3  # >= 1 by construction
    r = jnp.stack([c, -sigma * l2, sigma * l1, jnp.zeros_like(c)], axis=-1)
    return r / jnp.sqrt(2.0 * c)[..., None]


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


@jax.jit
def _evaluate(consts, t):
    c = _expand(consts, t.ndim)
    t = t.reshape((1,) * consts.nu.ndim + t.shape)
    shape = jnp.broadcast_shapes(c.nu.shape, t.shape)
    t = jnp.broadcast_to(t, shape)
    c = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, shape + x.shape[len(shape) :]), c)

    st = c.nu * t  # scaled time
    tau = c.lam * st + c.tau0
    sn_, cn_, dn_, _, j = jacobi_with_index(tau, c.m, c.m1, c.kk)
    omega_c = c.amp * jnp.stack([cn_, sn_, dn_], axis=-1)
    kp = jnp.sqrt(c.m1)
    qq = _transformed_integral(sn_, cn_, dn_, j, kp, c.k1, c.nprime, c.q_half)
    lam_safe = jnp.where(c.steady, 1.0, c.lam)
    psi = c.rate0 * st + c.kappa * (qq - c.q_start) / lam_safe
    half = 0.5 * psi
    zrot = jnp.stack(
        [jnp.cos(half), jnp.zeros_like(half), jnp.zeros_like(half), c.sigma * jnp.sin(half)],
        axis=-1,
    )
    lnorm_safe = jnp.where(c.steady, 1.0, c.lnorm)
    lhat = c.inertia * omega_c / lnorm_safe[..., None]
    qc = quat.multiply(
        quat.multiply(c.w0, zrot), quat.conjugate(_shortest_from_axis(lhat, c.sigma))
    )
    q_general = quat.multiply(qc, c.perm_q)
    omega_general = c.nu[..., None] * jnp.einsum("...ji,...j->...i", c.perm, omega_c)

    q_steady = quat.multiply(c.q0, quat.from_rotvec(c.omega0 * t[..., None]))
    steady = c.steady[..., None]
    q = jnp.where(steady, q_steady, q_general)
    omega = jnp.where(steady, c.omega0, omega_general)
    return q, omega


def solve(
    moments: ArrayLike, q0: ArrayLike, omega0: ArrayLike, ts: ArrayLike
) -> tuple[jax.Array, jax.Array]:
    """Exact torque-free motion (eqs. 17.35 with ``N = 0`` and 17.44) at times ``ts``.

    Args:
        moments: ``(..., 3)`` principal moments (positive, any order).
        q0: ``(..., 4)`` initial orientation, body → space, scalar first.
        omega0: ``(..., 3)`` initial body-frame angular velocity.
        ts: ``(T,)`` (or any shape ``S``) output times.

    Returns:
        ``(q, omega)``: ``(..., T, 4)`` and ``(..., T, 3)``. Equivalent to
        ``evaluate(prepare(moments, q0, omega0), ts)``; ``jit``/``vmap``/``grad``-able.
    """
    return evaluate(prepare(moments, q0, omega0), ts)


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
