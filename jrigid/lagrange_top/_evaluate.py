"""Evaluation of the heavy symmetric top at any times, and its nutation period and range
(the method is in :mod:`jrigid.lagrange_top`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from jrigid import quaternion as quat
from jrigid import special
from jrigid.batching import over_times, sign
from jrigid.special.kernels import parity_sign, safe_sqrt

from ._constants import TopConstants, prepare
from ._phases import _partial, _partial_args, _quarter_shift, _reduce_4pi, _rj, _safe_rsqrt

__all__ = ["evaluate", "nutation_period", "nutation_range", "solve"]


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
    c, t = over_times(consts, t, consts.nu.ndim)

    st = c.nu * t
    timed = c.wn > 0
    wn_safe = jnp.where(timed, c.wn, 1.0)
    tau = c.wn * st + c.tau0
    sn, cn, dn, _, j = special.jacobi_with_index(tau, c.m, c.m1, c.kk)
    parity = parity_sign(j)
    sr, cr = parity * sn, parity * cn  # at the reduced argument r in [-K, K]
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
    half_s = safe_sqrt(0.5 * (c.omu2 + c.sq * cr2))  # sin(theta/2)
    half_c = safe_sqrt(0.5 * (c.opu1 + c.sq * sr2))  # cos(theta/2)
    zm = half_s * rot_m
    zp = half_c * rot_p
    q_rel = jnp.stack([jnp.real(zp), jnp.real(zm), jnp.imag(zm), jnp.imag(zp)], axis=-1)
    q = quat.multiply(c.q_vert, q_rel)

    # R- = (-udot + i(b - a))/S-,  R+ = (udot + i(b + a))/C+  (bounded; see docstring)
    d_m2 = c.e_m * c.e_m + c.n_m * cr2
    ok_m = d_m2 > 0
    d_m = jnp.sqrt(jnp.where(ok_m, d_m2, 1.0))
    re_m = -2.0 * c.wn * sr * dn * jnp.where(ok_m, c.n_m * cr / d_m, safe_sqrt(c.n_m))
    im_m = c.v_m * jnp.where(ok_m, c.e_m / d_m, 0.0)
    big_r_m = safe_sqrt(2.0 * c.omu1) * jax.lax.complex(re_m, im_m)
    d_p2 = c.e_p * c.e_p + c.n_p * (c.kp * sr / dn) ** 2
    ok_p = d_p2 > 0
    d_p = jnp.sqrt(jnp.where(ok_p, d_p2, 1.0))
    # sr/d_p -> sign(sr) dn/(sqrt(N) k') where e+ = sr = 0 (exactly at the bottom)
    re_p = (
        2.0
        * c.wn
        * cr
        * jnp.where(ok_p, c.sq * c.kp * sr / d_p, sign(sr) * dn * c.sq * _safe_rsqrt(c.n_p))
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
