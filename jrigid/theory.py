"""The chapter's closed-form results, and the rate measurements that test them.

Each result is implemented once, in JAX, differentiable in its inputs; the demo, the
experiments, the fit features and the tests call these functions.

Closed form:

- :func:`body_precession_rate` — a torque-free symmetric body (``I1 = I2``): ``ω`` turns
  about body axis 3 at ``Ω = (I3/I1 − 1) ω3`` (eq. 17.47, Problem 17.5);
- :func:`plate_theory` — the same body seen from space, in Euler angles about ``L``:
  precession ``φ̇ = |L|/I1``, spin ``ψ̇ = ω3 (I1 − I3)/I1``, ``|L| cos θ = I3 ω3``, so the
  wobble-to-spin ratio is ``|φ̇/ψ̇| = I3/((I3 − I1) cos θ) = 2/((1 − h²/3r²) cos θ)`` for a
  plate of radius ``r`` and thickness ``h``, ``2/cos θ`` for a thin one (Feynman's plate,
  Problem 17.4);
- :func:`free_rates` — the mean precession, spin and nutation rates and the tilt range of
  any torque-free body, from the constants of :mod:`jrigid.exact` (Landau & Lifshitz §37);
- :func:`flip_theory` / :func:`flip_interval` — the flip interval ``2K(m)/λ`` near the
  intermediate axis (Problem 17.6, the Dzhanibekov effect), and
  :func:`flip_interval_asymptotic`, its ``(2/λ) ln(C/ε)`` form near the separatrix;
- :func:`gyroscope_rates` — the slow and fast steady precession of the heavy top, the roots
  of ``I1 Ω² cos θ − I3 ω3 Ω + M g l = 0`` and their fast-top limits (eq. 17.51), and
  :func:`fast_top_nutation`, the nutation of a fast top released with ``φ̇ = θ̇ = 0``. The
  nutation period and range of any heavy symmetric top are
  :func:`jrigid.lagrange_top.nutation_period` and :func:`jrigid.lagrange_top.nutation_range`
  (they read that module's constants).

Measurements on a sampled motion (:func:`axis_angles`, :func:`angle_rate`,
:func:`trajectory_rates`, :func:`wobble_to_spin`, :func:`omega_phase_rate`,
:func:`zero_crossings`): Euler angles of a body axis about a fixed space direction (``L``
for a torque-free body, the vertical for a top), unwrapped (:func:`unwrap`: the ``2π``
corrections are piecewise constant, so the derivative is that of the raw angles), and
their mean rates as least-squares slopes. This is exact for uniform rotation; a periodic
modulation of amplitude ``A`` (rad) biases the slope by ``O(A/D)`` for a record of length
``D``, so use records of many periods. The samples must be dense enough that no angle moves
by more than ``π`` between two of them.

No matplotlib here (``jrigid.viz`` draws these angles; :func:`jrigid.viz.euler_about` is
:func:`axis_angles` returning numpy).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from jrigid import exact, special
from jrigid import quaternion as quat

__all__ = [
    "FreeRates",
    "angle_rate",
    "axis_angles",
    "body_precession_rate",
    "fast_top_nutation",
    "flip_interval",
    "flip_interval_asymptotic",
    "flip_theory",
    "frame_about",
    "free_rates",
    "gyroscope_rates",
    "omega_phase_rate",
    "plate_theory",
    "rates_from_constants",
    "trajectory_rates",
    "unwrap",
    "wobble_to_spin",
    "zero_crossings",
]

_TWO_PI = 2.0 * math.pi


def _float(*xs):
    """The arguments as arrays of one floating dtype."""
    arrays = [jnp.asarray(x) for x in xs]
    dtype = jnp.result_type(*arrays, float)
    return [a.astype(dtype) for a in arrays]


def _safe(ok, x):
    """``x`` where ``ok``, else 1 (a safe denominator for the untaken branch of a where)."""
    return jnp.where(ok, x, 1.0)


def _check_axis(axis) -> None:
    if axis not in (0, 1, 2):
        raise ValueError(f"axis must be 0, 1 or 2, got {axis!r}")


# --------------------------------------------------------------------------- symmetric body


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
    moments, omega = _float(moments, omega)
    return (moments[..., 2] / moments[..., 0] - 1.0) * omega[..., 2]


def plate_theory(moments: ArrayLike, omega: ArrayLike) -> dict:
    """Exact torque-free rates of a symmetric body (``I1 = I2``, symmetry axis 3) about ``L``.

    In Euler angles about ``L`` (:func:`axis_angles`) the symmetry axis precesses
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
    moments, omega = _float(moments, omega)
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


# --------------------------------------------------------------------------- any free body


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
    moments, omega = _float(moments, omega)
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


# --------------------------------------------------------------------------- the flip


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
        moments: ``(3,)`` distinct principal moments (any order).
        omega: ``(3,)`` body angular velocity at any instant.

    Returns:
        dict of ``()`` arrays: ``flip_interval``, ``period``, ``m``, ``m1`` (``1 − m``),
        ``lam`` and ``axis`` (index of the intermediate axis).

    Example:
        >>> import math
        >>> from jrigid import theory
        >>> eps = 0.01  # spin about the middle axis, tilted toward the largest
        >>> th = theory.flip_theory([1.0, 2.0, 3.0], [0.0, math.cos(eps), math.sin(eps)])
        >>> print(th["axis"], f"{float(th['flip_interval']):.4f}")
        1 18.8519
    """
    moments, omega = _float(moments, omega)
    order = jnp.argsort(jax.lax.stop_gradient(moments))
    big_a, big_b, big_c = (moments[order[k]] for k in range(3))
    wa, wb, wc = (omega[order[k]] for k in range(3))
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
        axis=order[1],
    )


def flip_interval(moments: ArrayLike, omega: ArrayLike) -> jax.Array:
    """``2K(m)/λ``, the time between flips of a body spun near its intermediate axis.

    Args:
        moments: ``(3,)`` distinct principal moments (any order).
        omega: ``(3,)`` body angular velocity at any instant.

    Returns:
        ``()`` array; :func:`flip_theory` has the formulas and the other constants.

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
        moments: ``(3,)`` distinct principal moments, any order.
        speed: ``()`` ``|ω|``.
        eps: ``(...)`` tilt angle(s) in radians.
        toward: ``"largest"`` or ``"smallest"`` (static).

    Returns:
        ``(T, λ, C)``: ``T`` of the shape of ``eps``, ``λ`` and ``C`` scalars.

    Example:
        >>> from jrigid import theory
        >>> t, lam, c = theory.flip_interval_asymptotic([1.0, 2.0, 3.0], 1.0, 0.01)
        >>> print(f"{float(t):.4f} {float(lam):.4f}")
        18.8522 0.5774
    """
    if toward not in ("largest", "smallest"):
        raise ValueError(f"toward must be 'largest' or 'smallest', got {toward!r}")
    s = jnp.sort(jnp.asarray(moments))
    i1, i2, i3 = s[0], s[1], s[2]
    lam = jnp.asarray(speed) * jnp.sqrt((i3 - i2) * (i2 - i1) / (i1 * i3))
    if toward == "largest":
        const = 4.0 * jnp.sqrt(i2 * (i2 - i1) / (i3 * (i3 - i1)))
    else:
        const = 4.0 * jnp.sqrt(i2 * (i3 - i2) / (i1 * (i3 - i1)))
    return 2.0 / lam * jnp.log(const / jnp.asarray(eps)), lam, const


# --------------------------------------------------------------------------- heavy top


def gyroscope_rates(
    i1: ArrayLike, i3: ArrayLike, mgl: ArrayLike, theta: ArrayLike, omega3: ArrayLike
) -> dict:
    """Slow and fast steady precession of a heavy symmetric top (eq. 17.51).

    In ZXZ Euler angles (``θ`` the axle's angle from the vertical, ``φ̇ = Ω``,
    ``ω3 = ψ̇ + Ω cos θ``) the ``θ`` equation of the heavy top with ``θ̇ = θ̈ = 0`` is
    ``I1 Ω² cos θ − I3 ω3 Ω + M g l = 0``, whose two roots are the steady rates (the small
    one formed without cancellation). For a fast top (``I3² ω3² ≫ 4 I1 M g l cos θ``)

        slow  Ω ≈ M g l / (I3 ω3)          (17.51b),
        fast  Ω ≈ I3 ω3 / (I1 cos θ)       (17.51a; the chapter's ``Is`` is ``I1``).

    Args:
        i1: ``(...)`` transverse moment about the pivot (``I1c + M l²``).
        i3: ``(...)`` moment about the symmetry axis.
        mgl: ``(...)`` ``M |g| l``, the gravity torque at ``θ = π/2``.
        theta: ``(...)`` tilt of the axle from the vertical (rad).
        omega3: ``(...)`` spin ``ω3`` about the axle.

    Returns:
        dict of ``(...)`` arrays: ``slow``, ``fast`` (the exact roots; NaN where the top
        spins too slowly to precess steadily) and ``slow_approx``, ``fast_approx``.

    Example:
        >>> from jrigid import theory
        >>> r = theory.gyroscope_rates(1.0, 0.5, 1.0, 1.0, 20.0)
        >>> print(f"{float(r['slow']):.4f} {float(r['slow_approx']):.4f}")
        0.1005 0.1000
    """
    i1, i3, mgl, theta, omega3 = _float(i1, i3, mgl, theta, omega3)
    a, b = i1 * jnp.cos(theta), i3 * omega3
    disc = jnp.sqrt(b * b - 4.0 * a * mgl)
    return dict(
        slow=2.0 * mgl / (b + disc),
        fast=(b + disc) / (2.0 * a),
        slow_approx=mgl / b,
        fast_approx=b / a,
    )


def fast_top_nutation(
    i1: ArrayLike, i3: ArrayLike, mgl: ArrayLike, theta: ArrayLike, omega3: ArrayLike
) -> dict:
    """Nutation of a fast top released at ``θ0`` with ``φ̇ = θ̇ = 0`` (section 17.6).

    ``θ`` oscillates between ``θ0`` and about ``θ0 + 2 M g l I1 sin θ0 / (I3 ω3)²`` at the
    angular frequency ``I3 ω3 / I1``, and the axle precesses on average at the slow rate of
    :func:`gyroscope_rates`. (The exact nutation of any heavy symmetric top:
    :func:`jrigid.lagrange_top.nutation_period` and :func:`jrigid.lagrange_top.nutation_range`.)

    Args:
        i1, i3, mgl, theta, omega3: as :func:`gyroscope_rates` (``theta`` is ``θ0``).

    Returns:
        dict of ``(...)`` arrays: ``frequency`` and ``dip`` (the depth of the nutation, rad).

    Example:
        >>> from jrigid import theory
        >>> r = theory.fast_top_nutation(1.0, 0.5, 1.0, 1.0, 20.0)
        >>> print(f"{float(r['frequency']):.1f} {float(r['dip']):.4f}")
        10.0 0.0168
    """
    i1, i3, mgl, theta, omega3 = _float(i1, i3, mgl, theta, omega3)
    spin = i3 * omega3
    return dict(frequency=spin / i1, dip=2.0 * mgl * i1 * jnp.sin(theta) / spin**2)


# --------------------------------------------------------------------------- measurement


def unwrap(angle: ArrayLike) -> jax.Array:
    """Continuous angle along the last axis: each step reduced to ``(−π, π]``.

    The ``2π`` corrections are piecewise constant, so the derivative is that of the
    raw angles (unlike zero-crossing counts).

    Args:
        angle: ``(..., T)`` angles (rad).

    Returns:
        ``(..., T)`` unwrapped angles, equal to ``angle`` at the first sample.
    """
    a = jnp.asarray(angle)
    d = jnp.diff(a, axis=-1)
    d = d - _TWO_PI * jax.lax.stop_gradient(jnp.round(d / _TWO_PI))
    zero = jnp.zeros_like(a[..., :1])
    return a[..., :1] + jnp.concatenate([zero, jnp.cumsum(d, axis=-1)], axis=-1)


def angle_rate(ts: ArrayLike, angle: ArrayLike) -> jax.Array:
    """Least-squares slope ``Σ (t − t̄)(a − ā) / Σ (t − t̄)²`` of an unwrapped angle.

    Args:
        ts: ``(T,)`` times; angle: ``(..., T)`` continuous (unwrapped) angles.

    Returns:
        ``(...)`` mean rate (rad/time).

    Example:
        >>> import jax.numpy as jnp
        >>> from jrigid import theory
        >>> ts = jnp.linspace(0.0, 2.0, 21)
        >>> print(f"{float(theory.angle_rate(ts, 3.0 * ts + 1.0)):.4f}")
        3.0000
    """
    ts, a = jnp.asarray(ts), jnp.asarray(angle)
    tc = ts - jnp.mean(ts)
    ac = a - jnp.mean(a, axis=-1, keepdims=True)
    return jnp.sum(tc * ac, axis=-1) / jnp.sum(tc * tc)


def frame_about(n: ArrayLike) -> jax.Array:
    """Right-handed rotation matrix ``(3, 3)`` whose third column is ``n / |n|``.

    The first column is the unit vector along ``n̂ × e`` with ``e`` the coordinate axis
    least aligned with ``n`` (a fixed, reproducible choice). Differentiable in ``n``.

    Args:
        n: ``(3,)`` nonzero vector.

    Raises:
        ValueError: for a concrete zero (or non-finite) ``n``.
    """
    if not isinstance(n, jax.core.Tracer) and not np.linalg.norm(np.asarray(n, float)) > 0:
        raise ValueError("frame_about: the axis vector is zero")
    n = jnp.asarray(n)
    n = n.astype(jnp.result_type(n, float))
    z = n / jnp.linalg.norm(n)
    e = jax.nn.one_hot(jnp.argmin(jnp.abs(jax.lax.stop_gradient(z))), 3, dtype=z.dtype)
    x = jnp.cross(z, e)
    x = x / jnp.linalg.norm(x)
    return jnp.stack([x, jnp.cross(z, x), z], axis=-1)


def axis_angles(
    q: ArrayLike, direction: ArrayLike, axis: int = 2, unwrapped: bool = True
) -> jax.Array:
    """Precession ``φ``, nutation ``θ`` and spin ``ψ`` of a body axis about a fixed direction.

    The chapter's ZXZ Euler angles (eq. 17.10, active form) with the space ``Z`` axis along
    ``direction``: with ``A = [x, y, n̂]`` (:func:`frame_about`) and ``P`` the cyclic
    permutation that makes body axis ``axis`` play the role of ``z``,
    ``R = A · Rz(φ) Rx(θ) Rz(ψ) · Pᵀ``. ``φ`` is the azimuth of the line of nodes (the axis
    ``u`` itself is at ``φ − π/2``), ``θ = atan2(|u × n|, u·n)`` and ``ψ`` the spin about
    ``u``. For a symmetric torque-free body about ``L`` these are straight lines
    (:func:`plate_theory`). At ``θ = 0`` (axis along the direction) only ``φ + ψ`` is
    defined.

    Args:
        q: ``(T, 4)`` body → space orientations (principal frame).
        direction: ``(3,)`` fixed space direction (``L``, or the vertical for a top).
        axis: body axis ``0, 1, 2``; ``ψ`` is measured about it from the line of nodes,
            with the body axes ``(axis+1, axis+2, axis)`` right-handed.
        unwrapped: unwrap ``φ`` and ``ψ`` in time (:func:`unwrap`; continuous angles, for
            rates); else each in ``(−π, π]``.

    Returns:
        ``(T, 3)`` array of ``(φ, θ, ψ)`` (rad).

    Example:
        >>> import jax.numpy as jnp
        >>> from jrigid import quaternion as quat, theory
        >>> q = quat.from_axis_angle(jnp.array([1.0, 0.0, 0.0]), jnp.array([0.3]))
        >>> ang = theory.axis_angles(q, jnp.array([0.0, 0.0, 1.0]))  # tilted by 0.3 rad
        >>> print(jnp.round(ang[:, 1:], 4))
        [[0.3 0. ]]
    """
    _check_axis(axis)
    q = jnp.asarray(q)
    q = q.astype(jnp.result_type(q, float))
    frame = frame_about(jnp.asarray(direction, dtype=q.dtype))
    x, y, n = frame[:, 0], frame[:, 1], frame[:, 2]
    eye = jnp.eye(3, dtype=q.dtype)
    u = quat.rotate(q, jnp.broadcast_to(eye[axis], q.shape[:-1] + (3,)))
    phi = jnp.arctan2(u @ x, -(u @ y))
    theta = jnp.arctan2(jnp.linalg.norm(jnp.cross(u, n), axis=-1), u @ n)
    nb = quat.rotate_inverse(q, jnp.broadcast_to(n, q.shape[:-1] + (3,)))
    psi = jnp.arctan2(nb[..., (axis + 1) % 3], nb[..., (axis + 2) % 3])
    if unwrapped:
        phi, psi = unwrap(phi), unwrap(psi)
    return jnp.stack([phi, theta, psi], axis=-1)


def trajectory_rates(ts: ArrayLike, q: ArrayLike, direction: ArrayLike, axis: int = 2) -> dict:
    """Mean precession and spin rates and mean tilt of a body axis from sampled orientations.

    Args:
        ts: ``(T,)`` times; q: ``(T, 4)``; direction: ``(3,)``; axis: as :func:`axis_angles`.

    Returns:
        dict of ``()`` arrays: ``precession_rate``, ``spin_rate``, ``ratio``
        ``|φ̇/ψ̇|`` and ``tilt`` (the mean of ``θ``).
    """
    ang = axis_angles(q, direction, axis)
    prec = angle_rate(ts, ang[:, 0])
    spin = angle_rate(ts, ang[:, 2])
    return dict(
        precession_rate=prec,
        spin_rate=spin,
        ratio=jnp.abs(prec) / jnp.abs(spin),
        tilt=jnp.mean(ang[:, 1]),
    )


def wobble_to_spin(ts: ArrayLike, q: ArrayLike, L_space: ArrayLike, axis: int = 2) -> dict:
    """Measured precession and spin rates of body axis ``axis`` about ``L`` (line fits).

    :func:`trajectory_rates` about ``L``; compare with :func:`plate_theory`.

    Args:
        ts: ``(T,)`` times; q: ``(T, 4)`` body → space orientations.
        L_space: ``(3,)`` or ``(T, 3)`` angular momentum in space; a series is averaged
            (it is constant for torque-free motion) to fix the reference frame.
        axis: body axis ``0, 1, 2``.

    Returns:
        dict of ``()`` arrays: ``precession_rate``, ``spin_rate``, ``ratio`` ``|φ̇/ψ̇|``
        and the mean nutation ``theta``.
    """
    L = jnp.asarray(L_space)
    if L.ndim == 2:
        L = jnp.mean(L, axis=0)
    r = trajectory_rates(ts, q, L, axis)
    return dict(
        precession_rate=r["precession_rate"],
        spin_rate=r["spin_rate"],
        ratio=r["ratio"],
        theta=r["tilt"],
    )


def omega_phase_rate(ts: ArrayLike, omega: ArrayLike, axis: int) -> jax.Array:
    """Mean rate of the phase of ``(ω_{axis+1}, ω_{axis+2})``: ``±2π/T`` when the polhode
    encircles ``axis`` (:func:`unwrap` and :func:`angle_rate`); for a symmetric body the
    rate ``Ω`` of :func:`body_precession_rate`.

    Args:
        ts: ``(T,)``; omega: ``(T, 3)`` principal-frame angular velocity; axis: ``0, 1, 2``.

    Returns:
        ``()`` rate (rad/time).
    """
    omega = jnp.asarray(omega)
    phase = jnp.arctan2(omega[:, (axis + 2) % 3], omega[:, (axis + 1) % 3])
    return angle_rate(ts, unwrap(phase))


def zero_crossings(ts: ArrayLike, x: ArrayLike) -> jax.Array:
    """Times where the samples ``x`` change sign (linear interpolation between samples).

    Which intervals hold a crossing is read from the concrete samples (their number is
    data-dependent, so this does not ``jit``); the crossing times are differentiable in
    ``ts`` and ``x``.

    Args:
        ts: ``(T,)`` times; x: ``(T,)`` samples.

    Returns:
        ``(C,)`` crossing times, in order.

    Example:
        >>> import jax.numpy as jnp
        >>> from jrigid import theory
        >>> ts = jnp.linspace(0.0, 7.0, 701)
        >>> print(jnp.round(theory.zero_crossings(ts, jnp.sin(ts)), 3))
        [3.142 6.283]
    """
    ts, x = _float(ts, x)
    xs = np.asarray(jax.lax.stop_gradient(x))
    i = np.nonzero(np.sign(xs[:-1]) * np.sign(xs[1:]) < 0)[0]
    return ts[i] - x[i] * (ts[i + 1] - ts[i]) / (x[i + 1] - x[i])
