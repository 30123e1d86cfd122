"""Constants of the heavy symmetric top: :func:`~jrigid.lagrange_top.prepare`.

The integrals and the vertical, the roots of the cubic and the distances to the poles, the
elliptic parameters, and the constants of the phases ``χ± = φ ± ψ`` (the method is in
:mod:`jrigid.lagrange_top`).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from jrigid import quaternion as quat
from jrigid import special
from jrigid._checks import fail_if
from jrigid.batching import power_of_two_scale, sign
from jrigid.special.kernels import safe_sqrt

from ._phases import (
    _complete,
    _complete_args,
    _partial,
    _partial_args,
    _quarter_shift,
    _reduce_4pi,
    _rj,
    _safe_rsqrt,
    _unit_complex,
)
from ._roots import _roots, _safe_inv

__all__ = ["TopConstants", "prepare"]


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
    # NaN gravity read as none (|g| through a guarded square root): refused, as NaN elsewhere
    com, g, q0, omega0 = (
        fail_if(x, ~jnp.all(jnp.isfinite(x), axis=-1),
                f"lagrange_top: {name} has non-finite entries (NaN or inf)")
        for name, x in (("com", com), ("g", g), ("q0", q0), ("omega0", omega0))
    )
    return moments, mass, com, g, q0, omega0


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
            the symmetry axis, a zero ``q0``, a non-finite ``com``, ``g``, ``q0`` or
            ``omega0`` (``equinox.error_if`` under ``jit``).
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
    # |g| and |l| enter as plain square roots: the motion is smooth in g at g = 0 and in
    # l at l = 0, but these constants (beta ~ |g||l|, zhat ~ sign(l) g/|g|) are not, so a
    # derivative there would come out wrong (zero); it comes out NaN instead
    gnorm = jnp.sqrt(g2)
    down = g / jnp.where(g2 > 0, gnorm, 1.0)[..., None]
    ez = jnp.zeros_like(g).at[..., 2].set(1.0)
    zhat = jnp.where((g2 > 0)[..., None], -sign(lever)[..., None] * down, ez)
    beta = 2.0 * mass * gnorm * jnp.sqrt(lever * lever) / big_a
    q_vert = _vertical_frame(zhat)

    # ---- scaled variables (time unit 1/nu, a power of two)
    w = omega0
    a_spin = big_c * w[..., 2] / big_a
    rate = jnp.maximum(jnp.maximum(jnp.max(jnp.abs(w), axis=-1), jnp.abs(a_spin)), safe_sqrt(beta))
    moving = rate > 0
    scale = power_of_two_scale(jnp.where(moving, rate, 1.0))
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
    wn = 0.5 * safe_sqrt(den)
    timed = wn > 0
    wn_safe = jnp.where(timed, wn, 1.0)
    kp = jnp.sqrt(m1)
    zero, one = jnp.zeros_like(m1), jnp.ones_like(m1)
    # sn0, cn0 >= 0 and the sign of udot0 (as sn0 cn0), linear in udot0 where it vanishes
    sigma_u = sign(udot0)
    inv_sq = _safe_inv(sq)
    sn0_r = udot0 * _safe_rsqrt(cpr * x2 * sq)
    cn0_r = safe_sqrt(x2 * inv_sq)
    sn0_l = sigma_u * safe_sqrt(-x1 * inv_sq)
    cn0_l = sigma_u * udot0 * _safe_rsqrt(cpr * (-x1) * sq)
    sn0 = jnp.where(moving_u, jnp.where(right, sn0_r, sn0_l), 0.0)
    cn0 = jnp.where(moving_u, jnp.where(right, cn0_r, cn0_l), 1.0)
    dn0 = jnp.where(den > 0, safe_sqrt(cpr * inv_den), 1.0)
    rf = special.elliprf_sqrt(jnp.stack([zero, cn0]), jnp.stack([kp, dn0]), jnp.stack([one, one]))
    kk = rf[0]
    tau0 = sn0 * rf[1]
    period = 2.0 * kk / wn_safe

    # ---- chi- = phi - psi, and chi+ = phi + psi at the quarter-shifted tau0 - K
    n_m = sq * inv_omu1
    e_m_b = dm * inv_omu1 * _safe_rsqrt(gm)
    e_m_a = sign(dm) * safe_sqrt(omu2_a * inv_omu1)
    e_m = jnp.where(use_b, e_m_b, e_m_a)
    v_m = jnp.where(use_b | (e_m == 0), safe_sqrt(gm), dm * inv_omu1 * _safe_inv(e_m))
    wt_m = v_m * n_m / wn_safe
    rate_m = (a_spin - w3) + dm * inv_omu1
    n_p = (opu1 * m + sq) * inv_opu2
    gp_sqrt = safe_sqrt(gpl)
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
    phase_m = _phase("m", rate_m, wt_m, egc_m, eg0_m, period, timed)
    phase_p = _phase("p", rate_p, wt_p, egc_p, eg0_p, period, timed)

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
        n_p=n_p,
        e_p=e_p,
        gp_sqrt=gp_sqrt,
        **phase_m,
        **phase_p,
        anchor_m=jnp.stack([jnp.real(anchor_m), jnp.imag(anchor_m)], axis=-1),
        anchor_p=jnp.stack([jnp.real(anchor_p), jnp.imag(anchor_p)], axis=-1),
    )


def _phase(name, rate, weight, complete, start, period, timed):
    """The fields ``rate_*, wt_*, egc_*, eg0_*, adv_*`` of one phase (``name`` ``"m"`` for
    ``χ₋``, ``"p"`` for ``χ₊``): its linear rate, the weight of ``e G``, ``e G`` over a
    quarter period and at ``τ0``, and its advance per nutation period modulo ``4π``. The
    weight and the advance do not exist for an equilibrium (``ω_n = 0``): zero there."""
    advance = _reduce_4pi(rate * period + 2.0 * weight * complete)
    return {
        f"rate_{name}": rate,
        f"wt_{name}": jnp.where(timed, weight, 0.0),
        f"egc_{name}": complete,
        f"eg0_{name}": start,
        f"adv_{name}": jnp.where(timed, advance, 0.0),
    }


def _vertical_frame(zhat):
    """A rotation ``Q_v`` with ``Q_v e_z = ẑ`` (shortest arc from ``±e_z``), ``(..., 4)``."""
    x, y, z = zhat[..., 0], zhat[..., 1], zhat[..., 2]
    upper = z >= 0
    # z >= 0: shortest arc e_z -> zhat; z < 0: (shortest arc -e_z -> zhat) ⊗ (π about x)
    w_up = jnp.stack([1.0 + z, -y, x, jnp.zeros_like(z)], axis=-1)
    w_dn = jnp.stack([-y, 1.0 - z, jnp.zeros_like(z), x], axis=-1)  # (1-z, y, -x, 0) ⊗ (0, 1, 0, 0)
    q = jnp.where(upper[..., None], w_up, w_dn)
    return q / jnp.sqrt(jnp.sum(q * q, axis=-1, keepdims=True))
