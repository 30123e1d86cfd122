"""Evaluation of the closed-form torque-free motion: ω(t) by the addition theorem, the
angle ψ(t) about ``L`` by Legendre's third integral, and q(t) (the method is in
:mod:`jrigid.exact`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from jrigid import quaternion as quat
from jrigid._checks import fail_if
from jrigid.batching import over_times
from jrigid.special.kernels import jacobi_with_index, rj_sqrt, safe_sqrt

from ._arith import _clip, _safe_div, _unstack
from ._constants import (
    _RJ_STEPS,
    ExactConstants,
    _shortest_from_axis,
    _third_kind_args,
    prepare,
)
from ._taylor import _SLOW, _series

__all__ = ["evaluate", "omega_period", "solve"]


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
    # The half-period index j (τ - 2jK in [-K, K]) has the parity for which
    # (-1)^j cn(τ) ≥ 0, so the parity is read from cn and j is the nearest integer of that
    # parity: far from a tie of the rounding. Rounding τ/2K itself ties where cn = 0, and
    # there the compiled program did not use one rounding for both the sign and the
    # unwrapped angles (which one it took depended on the number of output times, and an
    # optimization barrier on j did not stop it): an orientation 1.9 rad off at whole
    # periods of ω from a start with ω1 = 0.
    odd = finite & (cnt < 0)
    j0 = odd.astype(tau.dtype)
    j = jnp.where(finite, 2.0 * jnp.round(0.5 * (tau / (2.0 * k_safe) - j0)) + j0, 0.0)
    sign = jnp.where(odd, -1.0, 1.0)
    sr = _clip(sign * snt, -1.0, 1.0)
    cr = _clip(jnp.abs(cnt), 0.0, 1.0)
    kp = safe_sqrt(c.m1)
    s, args = _third_kind_args(sr, cr, dnt, c.psi_third, kp, c.k1, c.psi_n)
    full = jnp.where(j == 0, 0.0, 2.0 * j * jnp.where(j == 0, 0.0, c.p_complete))
    p = s**3 * rj_sqrt(*args, steps=_RJ_STEPS) + full
    theta = j * jnp.pi + jnp.arctan2(c.psi_k * sr, cr)
    corr = c.psi_coef * (p - c.p_start) - c.psi_angle * (theta - c.theta_start)
    return c.psi_rate * st + corr / c.lam


@jax.jit
def _evaluate(consts, t):
    c, t = over_times(consts, t, consts.nu.ndim)
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
