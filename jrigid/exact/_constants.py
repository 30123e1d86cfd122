"""Constants of the closed-form torque-free motion: :func:`~jrigid.exact.prepare`.

The canonical frame, the elliptic constants (amplitudes, ``λ``, ``m``, ``1 − m``, ``K``,
``τ0``), the constants of the angle ``ψ`` about ``L`` (Landen or third-kind form) and the
Taylor coefficients, for a batch of bodies (the method is in :mod:`jrigid.exact`).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from jrigid import inertia as inertia_checks
from jrigid import quaternion as quat
from jrigid._checks import fail_if
from jrigid.batching import power_of_two_scale, sign
from jrigid.special.kernels import rf_sqrt, rj_sqrt, safe_sqrt

from ._arith import _clip, _distance_to_separatrix, _hypot, _safe_div, _unstack
from ._taylor import _SERIES_ORDER, _SLOW, _taylor

__all__ = ["ExactConstants", "prepare"]

# Duplication steps for R_J(x, y, 1, p) with x, y in [0, 1], p in [1, 10⁴]: 12 reach full
# float64 accuracy down to y = 1e-60 (distances to the separatrix far below rounding).
_RJ_STEPS = 12
# The third-kind form of ψ needs a = 1 - c² ≥ this (so p ≤ 1 + 1/a stays within the
# accuracy of _RJ_STEPS) and is used where k' < a/8 (where Landen's k₁ loses smoothness).
_THIRD_KIND_MIN_A = 1e-4
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


def _as_inputs(moments, q0, omega0, allow_nonphysical, checked=True):
    """Checked arrays of one floating dtype (``ValueError`` now, or ``error_if`` if traced;
    with ``checked=False`` the values are not checked, only the shapes)."""
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
    if not checked:
        return moments, q0, omega0
    try:
        moments = _now_if_concrete(
            lambda x: inertia_checks.validate(
                x, kind="moments", allow_nonphysical=allow_nonphysical
            ),
            moments,
        )
    except ValueError as err:
        if moments.shape[-2:] != (3, 3):
            raise
        raise ValueError(
            f"{err} (a (..., 3, 3) array is read as a batch of principal-moment vectors; "
            "for an inertia tensor, take its moments and frame with "
            "jrigid.inertia.principal_axes, or simulate RigidBody.from_tensor(tensor))"
        ) from None
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
    sigma, rho = sign(w3), sign(w1)
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


def prepare(
    moments: ArrayLike, q0: ArrayLike, omega0: ArrayLike, *, allow_nonphysical: bool = True,
    checked: bool = True,
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
        checked: ``False``: the values are not checked (non-finite input gives NaN
            constants), for a caller that checks its own inputs and flags non-finite
            results (the splitting integrator, whose state may diverge under a torque).

    Returns:
        :class:`ExactConstants` with batch shape the broadcast of the three batch shapes.

    Raises:
        ValueError: wrong shapes, or, for concrete input, invalid values (above). Under
            ``jit`` invalid values raise an ``equinox`` runtime error naming the problem.

    Derivatives near a spin about the intermediate axis: exactly on the axis (the other
    two components zero) they are those of the linearised motion, exact; within a small
    angle ``δ`` of it they come from elliptic constants near the separatrix and carry an
    error of about ``eps / δ`` relative (measured: 2e-6 at ``δ = 1e-10``, 2e-2 at
    ``1e-14``, and of order one at ``1e-17``; values are accurate), which grows with the
    number of flips: after about ten (moments 1, 2, 3, t = 60) the derivative of ``q``
    with respect to the moments was 1.6e-5 off at ``δ = 1e-6`` and 10 % off at
    ``δ = 1e-8`` (against finite differences of the values). ``simulate(...,
    solver="exact")`` sets components at the level of rounding (``8 eps |ω|``) to zero.
    """
    return _prepare(*_as_inputs(moments, q0, omega0, allow_nonphysical, checked))


@jax.jit
def _prepare(moments, q0, omega0):
    dtype = moments.dtype
    batch = jnp.broadcast_shapes(moments.shape[:-1], q0.shape[:-1], omega0.shape[:-1])
    moments = jnp.broadcast_to(moments, batch + (3,))
    q0 = quat.normalize(jnp.broadcast_to(q0, batch + (4,)))
    omega0 = jnp.broadcast_to(omega0, batch + (3,))

    # Scale-free variables, scaled by powers of two (exactly): moments by the largest, omega
    # by its largest component; nu is the time unit.
    inertia = moments * power_of_two_scale(jnp.max(moments, axis=-1))[..., None]
    w_max = jnp.max(jnp.abs(omega0), axis=-1)
    moving = w_max > 0
    w_scale = power_of_two_scale(jnp.where(moving, w_max, 1.0))
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
    sigma = sign(w3)
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
        ic, s_wc, s_lnorm, s_two_e, sign(s_wc[..., 2]), scale, _SERIES_ORDER
    )

    # the elliptic constants (g) under their field names, and the others
    return ExactConstants(
        **g,
        perm=perm,
        perm_q=perm_q,
        inertia=ic,
        nu=nu,
        sigma=sigma,
        lnorm=lnorm,
        w0=w0,
        q0=q0,
        omega0=omega0,
        steady=steady,
        omega_c=wc,
        coupling=jnp.stack([d32 / i1, d31 / i2, d21 / i3], axis=-1),
        series_omega=coef_w,
        series_psi=coef_psi,
        series_scale=scale,
        slow_rate=slow_rate,
        spin=spin,
        spin_rate2=jnp.where(spin, lam2, 0.0),
        rest=~moving,
    )
