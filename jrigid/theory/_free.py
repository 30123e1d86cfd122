"""Closed-form results for the torque-free body: precession (17.47), the plate's wobble,
the mean rates of any body, the flip interval and its asymptote (see :mod:`jrigid.theory`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from jrigid import exact, inertia, special
from jrigid._checks import as_floats, check_shape, fail_if

__all__ = [
    "FreeRates",
    "body_precession_rate",
    "flip_interval",
    "flip_interval_asymptotic",
    "flip_theory",
    "free_rates",
    "plate_theory",
    "rates_from_constants",
]

_TWO_PI = 2.0 * math.pi


def _distinct(moments: jax.Array) -> jax.Array:
    """``moments (..., 3)``, failing (:func:`~jrigid._checks.fail_if`) where two are equal:
    such a body has no intermediate axis, so no flips and no flip interval."""
    i = moments
    same = (i[..., 0] == i[..., 1]) | (i[..., 1] == i[..., 2]) | (i[..., 0] == i[..., 2])
    return fail_if(
        moments, same,
        "moments must be distinct: a body with two equal moments has no intermediate "
        "axis, so no flip interval", lambda: f"moments {moments}")


def _body(moments: ArrayLike, omega: ArrayLike, *, symmetric: bool = False):
    """``moments`` and ``omega`` as float arrays, checked: each ``(..., 3)``, the moments
    finite and positive and, if ``symmetric``, with ``I1 = I2`` (to ``√eps`` relative)."""
    moments, omega = as_floats(moments, omega)
    moments = inertia.checked_moments(moments, allow_nonphysical=True)
    omega = check_shape(omega, "omega (body angular velocity)", (3,))
    if symmetric:
        i1, i2 = moments[..., 0], moments[..., 1]
        tol = math.sqrt(jnp.finfo(moments.dtype).eps)
        moments = fail_if(
            moments, jnp.abs(i1 - i2) > tol * jnp.maximum(i1, i2),
            "moments must have I1 = I2 (a body symmetric about axis 3); free_rates gives "
            "the rates of any body", lambda: f"moments {moments}")
    return moments, omega


def _safe(ok, x):
    """``x`` where ``ok``, else 1 (a safe denominator for the untaken branch of a where)."""
    return jnp.where(ok, x, 1.0)


def body_precession_rate(moments: ArrayLike, omega: ArrayLike) -> jax.Array:
    """Rate ``Ω = (I3/I1 − 1) ω3`` at which ``ω`` turns about body axis 3 (eq. 17.47).

    Torque-free symmetric body (``I1 = I2``, symmetry axis 3): ``ω1 = A cos(Ωt + δ)``,
    ``ω2 = A sin(Ωt + δ)``, ``ω3`` constant. Negative for a prolate body (``I3 < I1``).

    Args:
        moments: ``(..., 3)`` principal moments with ``I1 = I2``.
        omega: ``(..., 3)`` body angular velocity at any instant.

    Returns:
        ``(...)`` rate (rad/time).

    Example:
        >>> from jrigid import theory
        >>> print(f"{float(theory.body_precession_rate([1.0, 1.0, 2.0], [0.3, 0.0, 2.0])):.3f}")
        2.000
    """
    moments, omega = _body(moments, omega, symmetric=True)
    return (moments[..., 2] / moments[..., 0] - 1.0) * omega[..., 2]


def plate_theory(moments: ArrayLike, omega: ArrayLike) -> dict:
    """Exact torque-free rates of a symmetric body (``I1 = I2``, symmetry axis 3) about ``L``.

    In Euler angles about ``L`` (:func:`~jrigid.theory.axis_angles`) the symmetry axis precesses
    ("wobbles") at ``φ̇ = |L|/I1``, the body spins about it at ``ψ̇ = ω3 (I1 − I3)/I1`` and
    ``cos θ = I3 ω3/|L|`` (from eq. 17.47 seen from space). The wobble-to-spin ratio is
    ``|φ̇/ψ̇| = I3/((I3 − I1) cos θ)``: for a disk (``I1 = m(3r² + h²)/12``, ``I3 = m r²/2``)
    ``2/((1 − h²/(3r²)) cos θ)``, and ``2/cos θ`` for a thin plate (Problem 17.4).

    Args:
        moments: ``(..., 3)`` with ``I1 = I2``.
        omega: ``(..., 3)`` body angular velocity at any instant.

    Returns:
        dict of ``(...)`` arrays: ``theta`` (axis–``L`` angle), ``precession_rate``
        ``φ̇``, ``spin_rate`` ``ψ̇``, ``ratio`` ``|φ̇/ψ̇|``, ``ratio_thin`` ``2/cos θ`` (the
        thin-plate value) and ``body_rate`` ``Ω`` (:func:`body_precession_rate`).

    Example:
        >>> from jrigid import theory
        >>> th = theory.plate_theory([1.0, 1.0, 2.0], [0.0, 0.0, 3.0])  # a thin plate, no tilt
        >>> print(f"{float(th['ratio']):.4f} {float(th['precession_rate']):.4f}")
        2.0000 6.0000
    """
    moments, omega = _body(moments, omega, symmetric=True)
    i1, i3, w3 = moments[..., 0], moments[..., 2], omega[..., 2]
    lnorm = jnp.linalg.norm(moments * omega, axis=-1)
    theta = jnp.arccos(i3 * w3 / lnorm)
    phi_dot = lnorm / i1
    psi_dot = w3 * (i1 - i3) / i1
    return dict(
        theta=theta,
        precession_rate=phi_dot,
        spin_rate=psi_dot,
        ratio=jnp.abs(phi_dot / psi_dot),
        ratio_thin=2.0 / jnp.cos(theta),
        body_rate=body_precession_rate(moments, omega),
    )


class FreeRates(NamedTuple):
    """Rates of torque-free motion (batch shape ``B``); see :func:`free_rates`.

    Attributes:
        precession_rate: ``⟨φ̇⟩``, mean rate of the encircled axis about ``L``.
        spin_rate: ``⟨ψ̇⟩``, mean rate of the body about that axis.
        ratio: ``|⟨φ̇⟩/⟨ψ̇⟩|``, the wobble-to-spin ratio.
        nutation_rate: ``4π/T``, the angular frequency of ``θ(t)``.
        tilt_min, tilt_max: range of ``θ`` (rad), the angle between the axis and ``L``.
        omega_period: ``T``, period of ω (flip and flip back near the separatrix).
        axis: index ``0, 1, 2`` of the encircled body (principal) axis (no derivative).
    """

    precession_rate: jax.Array
    spin_rate: jax.Array
    ratio: jax.Array
    nutation_rate: jax.Array
    tilt_min: jax.Array
    tilt_max: jax.Array
    omega_period: jax.Array
    axis: jax.Array


def free_rates(moments: ArrayLike, omega: ArrayLike) -> FreeRates:
    """Closed-form precession, spin, nutation and ω period of torque-free motion.

    Exact for any body, not only symmetric ones. The rates follow from the constants of
    the exact solution (:func:`jrigid.exact.prepare`, Landau & Lifshitz §37). Let ``a`` be
    the body axis that the polhode encircles (the symmetry axis of a nearly symmetric body
    spun near it), signed so that ``a·L > 0``, ``T = 4K(m)/λ`` the period of ω
    (:func:`jrigid.exact.omega_period`), and in Euler angles about ``L`` (precession ``φ``,
    nutation ``θ``, spin ``ψ`` of axis ``a``):

    - spin rate ``⟨ψ̇⟩ = −s 2π/T`` with ``s = sign(I_a − I_b)`` (``I_b`` the moment of the
      axis the polhode does not go near): the direction of ``L`` in the body goes once round
      ``a`` per period of ω;
    - precession rate ``⟨φ̇⟩ = ⟨χ̇⟩ + s 2π/T``, where ``χ`` is the angle of the exact
      solution's rotation about ``L`` (:mod:`jrigid.exact`, ``q = W Z(χ) B*``), whose mean
      rate is ``ψ̇₀ + κ (1 + k₁) Q_half / K`` in that module's notation;
    - wobble-to-spin ratio ``|⟨φ̇⟩/⟨ψ̇⟩|`` (:func:`plate_theory` for a symmetric body);
    - nutation: ``cos θ ∝ dn(λt)`` has period ``T/2``, so the nutation rate is ``4π/T``;
      ``θ`` ranges over ``[atan2(I_1 A_1, I_3 A_3), atan2(I_2 A_2, I_3 A_3 √(1−m))]``
      (canonical moments and amplitudes of :mod:`jrigid.exact`);
    - ``T`` itself: a flip and the flip back near the intermediate axis.

    Differentiable in ``moments`` and ``omega`` (``jax.grad``/``jacfwd``).

    Args:
        moments: ``(..., 3)`` principal moments (positive).
        omega: ``(..., 3)`` body angular velocity at any instant.

    Returns:
        :class:`FreeRates`. Rates and the ratio are ``NaN`` (with zero derivative) for a
        steady rotation (ω along a principal axis, a spherical body) and on the
        separatrix (``T = ∞``), where they are undefined; so are the tilts for a steady
        rotation.

    Example:
        >>> import math
        >>> from jrigid import theory
        >>> r = theory.free_rates([1.0, 1.0, 2.0], [0.3, 0.0, 2.0])
        >>> print(f"{float(r.ratio):.4f} {float(r.ratio) * math.cos(float(r.tilt_min)):.4f}")
        2.0056 2.0000
    """
    moments, omega = as_floats(moments, omega)
    q0 = jnp.array([1.0, 0.0, 0.0, 0.0], moments.dtype)
    return rates_from_constants(exact.prepare(moments, q0, omega))


@jax.jit
def rates_from_constants(c: exact.ExactConstants) -> FreeRates:
    """:func:`free_rates` from the constants of :func:`jrigid.exact.prepare` (any ``q0``)."""
    period = exact.omega_period(c)
    ok = jnp.isfinite(period) & ~c.steady
    t_safe = jnp.where(ok, period, 1.0)
    kk = jnp.where(ok, c.kk, 1.0)
    s = jnp.where(c.inertia[..., 2] >= c.inertia[..., 0], 1.0, -1.0)
    chi_rate = c.nu * (c.rate0 + c.kappa * (1.0 + c.k1) * c.q_half / kk)
    turn = _TWO_PI / t_safe
    spin = -s * turn
    prec = chi_rate + s * turn
    nan = jnp.full_like(period, jnp.nan)
    ratio = jnp.abs(prec) / jnp.abs(spin)
    a1, a2, a3 = (jnp.abs(c.amp[..., k]) for k in range(3))
    i1, i2, i3 = (c.inertia[..., k] for k in range(3))
    pos = c.m1 > 0  # k' = 0 on the separatrix (double where: finite derivative there)
    kp = jnp.where(pos, jnp.sqrt(jnp.where(pos, c.m1, 1.0)), 0.0)
    # cos θ ∝ dn: θ is smallest where sn = 0 (|cn| = 1) and largest where |sn| = 1 (dn = k')
    tilt_min = jnp.arctan2(i1 * a1, i3 * a3)
    tilt_max = jnp.arctan2(i2 * a2, i3 * a3 * kp)
    axis = jnp.argmax(jnp.abs(c.perm[..., 2, :]), axis=-1)
    return FreeRates(
        precession_rate=jnp.where(ok, prec, nan),
        spin_rate=jnp.where(ok, spin, nan),
        ratio=jnp.where(ok, ratio, nan),
        nutation_rate=jnp.where(ok, 2.0 * turn, nan),
        tilt_min=jnp.where(c.steady, nan, tilt_min),
        tilt_max=jnp.where(c.steady, nan, tilt_max),
        omega_period=period,
        axis=axis,
    )


def flip_theory(moments: ArrayLike, omega: ArrayLike) -> dict:
    """Flip interval ``2K(m)/λ`` and period ``4K(m)/λ`` of torque-free motion.

    With the moments sorted ``A < B < C``, ``2E = Σ Iᵢωᵢ²`` and ``L² = Σ Iᵢ²ωᵢ²``, Euler's
    equations are solved by Jacobi elliptic functions (Landau & Lifshitz §37): for
    ``L² > 2EB``

        λ² = (C − B)(L² − 2EA)/(ABC),   1 − m = (C − A)(L² − 2EB) / ((C − B)(L² − 2EA)),

    (``A`` and ``C`` swap when ``L² < 2EB``), and the intermediate component is
    ``ω_B ∝ sn(λt + c | m)``, which changes sign every ``2K(m)/λ``: the flip interval
    (Problem 17.6). ``L² − 2EA`` and the others are formed from the components of ``ω``
    (``Σ_k I_k (I_k − I_j) ω_k²``), and ``K`` from :func:`jrigid.special.ellipk` with the
    complementary parameter ``1 − m``, accurate close to the separatrix (``m → 1``).
    :func:`jrigid.exact.omega_period` gives the same period from the constants of the
    closed-form motion.

    Args:
        moments: ``(..., 3)`` distinct principal moments (any order), positive (two
            equal ones raise ``ValueError``; under ``jit``, at run time).
        omega: ``(..., 3)`` body angular velocity at any instant.

    Returns:
        dict of ``(...)`` arrays (the broadcast batch shape): ``flip_interval``,
        ``period``, ``m``, ``m1`` (``1 − m``), ``lam`` and ``axis`` (index of the
        intermediate axis).

    Example:
        >>> import math
        >>> from jrigid import theory
        >>> eps = 0.01  # spin about the middle axis, tilted toward the largest
        >>> th = theory.flip_theory([1.0, 2.0, 3.0], [0.0, math.cos(eps), math.sin(eps)])
        >>> print(th["axis"], f"{float(th['flip_interval']):.4f}")
        1 18.8519
    """
    moments, omega = _body(moments, omega)
    moments = _distinct(moments)
    moments, omega = jnp.broadcast_arrays(moments, omega)
    order = jnp.argsort(jax.lax.stop_gradient(moments), axis=-1)
    moments = jnp.take_along_axis(moments, order, axis=-1)
    omega = jnp.take_along_axis(omega, order, axis=-1)
    big_a, big_b, big_c = (moments[..., k] for k in range(3))
    wa, wb, wc = (omega[..., k] for k in range(3))
    # exact differences, free of cancellation
    l2_2eb = big_a * (big_a - big_b) * wa**2 + big_c * (big_c - big_b) * wc**2  # L² − 2EB
    l2_2ea = big_b * (big_b - big_a) * wb**2 + big_c * (big_c - big_a) * wc**2  # L² − 2EA
    ec2_l2 = big_a * (big_c - big_a) * wa**2 + big_b * (big_c - big_b) * wb**2  # 2EC − L²
    top = l2_2eb >= 0  # ω circulates about the axis of largest moment (else smallest)
    den = jnp.where(top, (big_c - big_b) * l2_2ea, (big_b - big_a) * ec2_l2)
    lam2 = den / (big_a * big_b * big_c)
    m1 = (big_c - big_a) * jnp.abs(l2_2eb) / _safe(den > 0, den)
    lam = jnp.sqrt(lam2)
    kk = special.ellipk(m1=m1)
    return dict(
        flip_interval=2.0 * kk / lam,
        period=4.0 * kk / lam,
        m=1.0 - m1,
        m1=m1,
        lam=lam,
        axis=order[..., 1],
    )


def flip_interval(moments: ArrayLike, omega: ArrayLike) -> jax.Array:
    """``2K(m)/λ``, the time between flips of a body spun near its intermediate axis.

    Args:
        moments: ``(..., 3)`` distinct principal moments (any order), positive (two
            equal ones raise ``ValueError``; under ``jit``, at run time).
        omega: ``(..., 3)`` body angular velocity at any instant.

    Returns:
        ``(...)`` array; :func:`flip_theory` has the formulas and the other constants.

    Example:
        >>> from jrigid import theory
        >>> print(f"{float(theory.flip_interval([1.0, 2.0, 3.0], [0.01, 1.0, 0.0])):.4f}")
        20.7546
    """
    return flip_theory(moments, omega)["flip_interval"]


def flip_interval_asymptotic(
    moments: ArrayLike, speed: ArrayLike, eps: ArrayLike, toward: str = "largest"
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Half-period between flips near the separatrix: ``T ≈ (2/λ) ln(C/ε)``.

    Spin ``|ω| = speed`` about the intermediate axis tilted by ``ε`` toward the largest
    (or smallest) axis. With sorted moments ``I1 < I2 < I3`` the exact half-period is
    ``2K(m)/λ_m`` (:func:`flip_interval`). As ``ε → 0``:
    ``λ_m → λ = |ω| √((I3−I2)(I2−I1)/(I1 I3))``, the linear growth rate about the middle
    axis, and ``1 − m = I3(I3−I1) ε²/(I2(I2−I1))`` (toward the largest axis; toward the
    smallest ``I1(I3−I1) ε²/(I2(I3−I2))``), both to ``O(ε²)``. With
    ``K(m) = ln(4/√(1−m)) + O((1−m) ln(1−m))``,

        T = (2/λ) ln(C/ε) (1 + O(ε²)),
        C = 4 √(I2(I2−I1)/(I3(I3−I1)))   (toward the largest),
        C = 4 √(I2(I3−I2)/(I1(I3−I1)))   (toward the smallest).

    Args:
        moments: ``(..., 3)`` distinct principal moments, any order, positive (two equal
            ones raise ``ValueError``; under ``jit``, at run time).
        speed: ``(...)`` ``|ω|``.
        eps: ``(...)`` tilt angle(s) in radians.
        toward: ``"largest"`` or ``"smallest"`` (static).

    Returns:
        ``(T, λ, C)``: ``T`` of the broadcast shape of the moments' batch, ``speed`` and
        ``eps``; ``λ`` of the moments' batch and ``speed``; ``C`` of the moments' batch.

    Example:
        >>> from jrigid import theory
        >>> t, lam, c = theory.flip_interval_asymptotic([1.0, 2.0, 3.0], 1.0, 0.01)
        >>> print(f"{float(t):.4f} {float(lam):.4f}")
        18.8522 0.5774
    """
    if toward not in ("largest", "smallest"):
        raise ValueError(f"toward must be 'largest' or 'smallest', got {toward!r}")
    moments, speed, eps = as_floats(moments, speed, eps)
    moments = _distinct(inertia.checked_moments(moments, allow_nonphysical=True))
    s = jnp.sort(moments, axis=-1)
    i1, i2, i3 = s[..., 0], s[..., 1], s[..., 2]
    lam = speed * jnp.sqrt((i3 - i2) * (i2 - i1) / (i1 * i3))
    if toward == "largest":
        const = 4.0 * jnp.sqrt(i2 * (i2 - i1) / (i3 * (i3 - i1)))
    else:
        const = 4.0 * jnp.sqrt(i2 * (i3 - i2) / (i1 * (i3 - i1)))
    return 2.0 / lam * jnp.log(const / eps), lam, const
