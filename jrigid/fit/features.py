"""Derived features of a motion — wobble-to-spin ratio, precession, nutation, flip period —
as differentiable functions and as observations for a :class:`~jrigid.fit.Problem`.

Two ways to compute a feature, both differentiable (no zero-crossing counting):

**Closed form** (``method="closed"``, the default; torque-free motion only). The rates
follow from the moments and ω at one instant through the constants of the exact solution
(:func:`jrigid.exact.prepare`, Landau & Lifshitz §37). Let ``a`` be the body axis that
the polhode encircles (the symmetry axis of a nearly symmetric body spun near it),
signed so that ``a·L > 0``, ``T = 4K(m)/λ`` the period of ω
(:func:`jrigid.exact.omega_period`), and in Euler angles about ``L`` (precession ``φ``,
nutation ``θ``, spin ``ψ`` of axis ``a``):

- spin rate ``⟨ψ̇⟩ = −s 2π/T`` with ``s = sign(I_a − I_b)`` (``I_b`` the moment of the
  axis the polhode does not go near): the direction of ``L`` in the body goes once round
  ``a`` per period of ω, and ``ψ = π/2 −`` its azimuth;
- precession rate ``⟨φ̇⟩ = ⟨χ̇⟩ + s 2π/T``, where ``χ`` is the angle of the exact
  solution's rotation about ``L`` (:mod:`jrigid.exact`, ``q = W Z(χ) B*``), whose mean
  rate is ``ψ̇₀ + κ (1 + k₁) Q_half / K`` in that module's notation (``φ = χ − ψ + const``);
- wobble-to-spin ratio ``|⟨φ̇⟩/⟨ψ̇⟩|``. For a symmetric body (``I1 = I2``, axis 3) this
  is ``|φ̇/ψ̇| = I3/((I3 − I1) cos θ)`` with ``φ̇ = |L|/I1`` and ``ψ̇ = ω3 (I1 − I3)/I1``:
  ``2/((1 − h²/3r²) cos θ)`` for a plate of radius ``r`` and thickness ``h``, ``2/cos θ``
  for a thin one (Feynman's plate; chapter Problem 17.4, :func:`jrigid.demo.plate_theory`);
- nutation: ``cos θ ∝ dn(λt)`` has period ``T/2``, so the nutation rate is ``4π/T``;
  ``θ`` ranges over ``[atan2(I_1 A_1, I_3 A_3), atan2(I_2 A_2, I_3 A_3 √(1−m))]``
  (canonical moments and amplitudes of :mod:`jrigid.exact`); the two coincide for a
  symmetric body;
- flip period near the intermediate-axis separatrix: ``T`` (flip and flip back); the
  body flips every ``T/2``. ``T`` grows like ``log(1/ε)`` as the spin approaches the
  separatrix and is infinite on it.

**Trajectory** (``method="trajectory"``; any model, tops and torques included). Smooth
estimators from the sampled orientation: the Euler angles of a body axis about a fixed
space direction (``L`` for a torque-free body, the vertical for a top) are unwrapped
(:func:`unwrap`: the ``2π`` corrections are piecewise constant, so the derivative is
that of the raw angles) and their mean rates are least-squares slopes
(:func:`angle_rate`). This is exact for uniform rotation (a symmetric torque-free body
about ``L``); a periodic modulation of amplitude ``A`` (rad) on top of the mean rate biases
the slope by ``O(A/D)`` for a record of length ``D``, so use records of many periods.
The samples must be dense enough that no angle moves by more than ``π`` between two of
them. The flip period from a trajectory is ``2π`` over the slope of the unwrapped phase of the two ω
components across the encircled axis (a non-uniform phase near the separatrix: biased
unless the record spans many flips).

The observation classes (:class:`WobbleRatio`, :class:`PrecessionRate`,
:class:`SpinRate`, :class:`NutationRate`, :class:`Tilt`, :class:`FlipPeriod`) hold the
record's times ``ts`` (the window the feature was measured on; the closed form uses
only its first instant), the observed ``value`` and ``sigma`` (``None``: unknown, unit
weight, as for :mod:`jrigid.fit.observations`); their residual is ``(f̂ − value)/σ``
(one number). The closed form needs a model that predicts the
moments (:class:`~jrigid.fit.Exact`, or :class:`~jrigid.fit.Simulated` of a torque-free
scene); otherwise ``ValueError``. Inside ``jit`` the closed form checks with
``equinox.error_if`` that the requested axis is the encircled one.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from jrigid import exact
from jrigid import quaternion as quat
from jrigid.fit.observations import Observation, Prediction, sample_times

__all__ = [
    "FlipPeriod",
    "FreeRates",
    "NutationRate",
    "PrecessionRate",
    "SpinRate",
    "Tilt",
    "WobbleRatio",
    "angle_rate",
    "axis_angles",
    "free_rates",
    "omega_phase_rate",
    "rates_from_constants",
    "trajectory_rates",
    "unwrap",
]

_TWO_PI = 2.0 * math.pi


# --------------------------------------------------------------------------- closed form


class FreeRates(NamedTuple):
    """Rates of torque-free motion (batch shape ``B``); see the module docstring.

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

    Exact for any body (not only symmetric ones): the rates are the mean rates of the
    Euler angles about ``L`` of the axis the polhode encircles (module docstring).
    Differentiable in ``moments`` and ``omega`` (``jax.grad``/``jacfwd``).

    Args:
        moments: ``(..., 3)`` principal moments (positive).
        omega: ``(..., 3)`` body angular velocity at any instant.

    Returns:
        :class:`FreeRates`. Rates and the ratio are ``NaN`` (with zero derivative) for a
        steady rotation (ω along a principal axis, a spherical body) and on the
        separatrix (``T = ∞``), where they are undefined; so are the tilts for a steady
        rotation (a plate spun exactly about its axis: start fits off it).
    """
    moments, omega = jnp.asarray(moments), jnp.asarray(omega)
    dtype = jnp.result_type(moments, omega, float)
    moments, omega = moments.astype(dtype), omega.astype(dtype)
    return rates_from_constants(exact.prepare(moments, jnp.array([1.0, 0, 0, 0], dtype), omega))


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


# --------------------------------------------------------------------------- trajectory


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
    """
    ts, a = jnp.asarray(ts), jnp.asarray(angle)
    tc = ts - jnp.mean(ts)
    ac = a - jnp.mean(a, axis=-1, keepdims=True)
    return jnp.sum(tc * ac, axis=-1) / jnp.sum(tc * tc)


def _frame_about(n: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Right-handed orthonormal ``(x, y, n̂)`` about ``n (3,)``; differentiable in ``n``."""
    n = n / jnp.linalg.norm(n)
    e = jax.nn.one_hot(jnp.argmin(jnp.abs(jax.lax.stop_gradient(n))), 3, dtype=n.dtype)
    x = jnp.cross(n, e)
    x = x / jnp.linalg.norm(x)
    return x, jnp.cross(n, x), n


def axis_angles(q: ArrayLike, direction: ArrayLike, axis: int = 2) -> jax.Array:
    """Euler angles (precession ``φ``, nutation ``θ``, spin ``ψ``) of a body axis about a
    fixed space direction (the chapter's ZXZ angles, eq. 17.10, taken about ``direction``).

    Args:
        q: ``(T, 4)`` body → space orientations (principal frame).
        direction: ``(3,)`` fixed space direction (``L``, or the vertical for a top).
        axis: body axis ``0, 1, 2``; ``ψ`` is measured about it from the line of nodes,
            with the body axes ``(axis+1, axis+2, axis)`` right-handed.

    Returns:
        ``(T, 3)``: ``φ`` and ``ψ`` unwrapped (:func:`unwrap`), ``θ = atan2(|u × n|, u·n)``.
    """
    if axis not in (0, 1, 2):
        raise ValueError(f"axis must be 0, 1 or 2, got {axis!r}")
    q = jnp.asarray(q)
    x, y, n = _frame_about(jnp.asarray(direction, dtype=q.dtype))
    eye = jnp.eye(3, dtype=q.dtype)
    u = quat.rotate(q, jnp.broadcast_to(eye[axis], q.shape[:-1] + (3,)))
    phi = jnp.arctan2(u @ y, u @ x)
    theta = jnp.arctan2(jnp.linalg.norm(jnp.cross(u, n), axis=-1), u @ n)
    nb = quat.rotate_inverse(q, jnp.broadcast_to(n, q.shape[:-1] + (3,)))
    psi = 0.5 * math.pi - jnp.arctan2(nb[..., (axis + 2) % 3], nb[..., (axis + 1) % 3])
    return jnp.stack([unwrap(phi), theta, unwrap(psi)], axis=-1)


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


def omega_phase_rate(ts: ArrayLike, omega: ArrayLike, axis: int) -> jax.Array:
    """Mean rate of the phase of ``(ω_{axis+1}, ω_{axis+2})``: ``±2π/T`` when the polhode
    encircles ``axis`` (:func:`unwrap` and :func:`angle_rate`).

    Args:
        ts: ``(T,)``; omega: ``(T, 3)`` principal-frame angular velocity; axis: ``0, 1, 2``.

    Returns:
        ``()`` rate (rad/time).
    """
    omega = jnp.asarray(omega)
    phase = jnp.arctan2(omega[:, (axis + 2) % 3], omega[:, (axis + 1) % 3])
    return angle_rate(ts, unwrap(phase))


# --------------------------------------------------------------------------- observations

_METHODS = ("closed", "trajectory")
_MIN_TRAJECTORY_SAMPLES = 8


def _scalar(x, name: str) -> jax.Array:
    a = np.asarray(x, dtype=float)
    if a.size != 1:
        raise ValueError(f"{name} must be a single number, got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name} is NaN or inf ({a.item()}): drop this observation")
    return jnp.asarray(a.reshape(1), dtype=jnp.result_type(float))


class _Feature(Observation):
    """One derived number measured on a record; residual ``(f̂ − value)/σ``."""

    ts: jax.Array
    value: jax.Array
    sigma: jax.Array
    about: jax.Array | None
    axis: int = eqx.field(static=True)
    method: str = eqx.field(static=True)

    def __init__(
        self,
        ts: ArrayLike,
        value: ArrayLike,
        sigma: ArrayLike | None = None,
        *,
        axis: int = 2,
        method: str = "closed",
        about: ArrayLike | None = None,
    ):
        if method not in _METHODS:
            raise ValueError(f"method must be one of {_METHODS}, got {method!r}")
        if axis not in (0, 1, 2):
            raise ValueError(f"axis must be 0, 1 or 2, got {axis!r}")
        self.ts = sample_times(ts)
        if method == "trajectory" and self.ts.shape[0] < _MIN_TRAJECTORY_SAMPLES:
            raise ValueError(
                f"too few samples for a trajectory estimate: need at least "
                f"{_MIN_TRAJECTORY_SAMPLES} times, got {self.ts.shape[0]}"
            )
        self.value = _scalar(value, "value")
        self.sigma_given = sigma is not None
        self.sigma = _scalar(1.0 if sigma is None else sigma, "sigma")
        if not float(self.sigma[0]) > 0:
            raise ValueError(f"sigma must be > 0, got {float(self.sigma[0])}")
        if about is None:
            self.about = None
        else:
            a = np.asarray(about, dtype=float)
            if a.shape != (3,) or not np.all(np.isfinite(a)) or not np.linalg.norm(a) > 0:
                raise ValueError(f"about must be a finite non-zero 3-vector, got {a.tolist()}")
            self.about = jnp.asarray(a / np.linalg.norm(a), dtype=jnp.result_type(float))
        self.axis = axis
        self.method = method

    @property
    def size(self) -> int:
        return 1

    # -- the two routes ------------------------------------------------------------
    def _closed(self, pred: Prediction) -> FreeRates:
        if pred.moments is None:
            raise ValueError(
                f"{type(self).__name__}(method='closed') needs a torque-free model that "
                "predicts the moments (fit.Exact, or fit.Simulated of a FreeRotation scene "
                "without loads); use method='trajectory' with about=<space direction>"
            )
        if pred.constants is not None:
            rates = rates_from_constants(pred.constants)
        else:
            rates = free_rates(pred.moments, pred.omega[0])
        # the closed form describes the encircled axis only
        if not isinstance(rates.axis, jax.core.Tracer) and int(rates.axis) != self.axis:
            raise ValueError(
                f"closed-form feature about axis {self.axis}, but the polhode encircles "
                f"axis {int(rates.axis)}: the closed form describes that axis only"
            )
        axis_ok = rates.axis == self.axis
        return jax.tree_util.tree_map(
            lambda x: eqx.error_if(
                x,
                ~axis_ok,
                "closed-form feature: the polhode does not encircle the requested axis",
            ),
            rates,
        )

    def _direction(self, pred: Prediction) -> jax.Array:
        if self.about is not None:
            return self.about
        if pred.moments is None or pred.q is None:
            raise ValueError(
                f"{type(self).__name__}(method='trajectory') without `about` measures angles "
                "about L, which needs a torque-free model predicting q and the moments; "
                "pass about=<fixed space direction> (e.g. the vertical for a top)"
            )
        return quat.rotate(pred.q[0], pred.moments * pred.omega[0])

    def _trajectory(self, pred: Prediction) -> dict:
        if pred.q is None:
            name = type(self).__name__
            raise ValueError(f"{name}(method='trajectory') needs a model that predicts q")
        return trajectory_rates(self.ts, pred.q, self._direction(pred), self.axis)

    def predicted(self, pred: Prediction) -> jax.Array:
        """``()`` the feature's predicted value."""
        raise NotImplementedError

    def in_window(self, t_end: jax.Array) -> jax.Array:
        """``(1,)`` whether the feature's record ends by ``t_end``."""
        return jnp.reshape(self.ts[-1] <= t_end, (1,))

    def residuals(self, pred: Prediction) -> jax.Array:
        """``(1,)`` whitened residual ``(f̂ − value)/σ``."""
        return (jnp.reshape(self.predicted(pred), (1,)) - self.value) / self.sigma


class WobbleRatio(_Feature):
    """Wobble-to-spin ratio ``|⟨φ̇⟩/⟨ψ̇⟩|`` of body axis ``axis`` (Feynman's plate: ``≈ 2/cos θ``).

    Args:
        ts: ``(T,)`` times of the record (the closed form uses ``ts[0]`` only).
        value: observed ratio; sigma: its standard deviation.
        axis: the body (principal) axis, ``2`` by default.
        method: ``"closed"`` (torque-free) or ``"trajectory"`` (line fits of the angles).
        about: trajectory method only: fixed space direction of the Euler angles
            (default ``L``, torque-free models).
    """

    def predicted(self, pred: Prediction) -> jax.Array:
        if self.method == "closed":
            return self._closed(pred).ratio
        return self._trajectory(pred)["ratio"]


class PrecessionRate(_Feature):
    """Mean precession rate ``⟨φ̇⟩`` (rad/time) of the axis about ``L`` (or ``about``).

    Arguments as :class:`WobbleRatio`. Signed: positive is right-handed about ``L``.
    """

    def predicted(self, pred: Prediction) -> jax.Array:
        if self.method == "closed":
            return self._closed(pred).precession_rate
        return self._trajectory(pred)["precession_rate"]


class SpinRate(_Feature):
    """Mean spin rate ``⟨ψ̇⟩`` (rad/time) of the body about the axis (signed, about the
    axis as oriented with ``a·L > 0`` in the closed form, about ``+axis`` from a trajectory).

    Arguments as :class:`WobbleRatio`.
    """

    def predicted(self, pred: Prediction) -> jax.Array:
        if self.method == "closed":
            return self._closed(pred).spin_rate
        return self._trajectory(pred)["spin_rate"]


class Tilt(_Feature):
    """Angle ``θ`` (rad) between the axis and ``L`` (or ``about``).

    Closed form: the midpoint of its range ``(θ_min + θ_max)/2`` (the constant ``θ`` of a
    symmetric body); trajectory: its mean over the samples. Arguments as :class:`WobbleRatio`.
    """

    def predicted(self, pred: Prediction) -> jax.Array:
        if self.method == "closed":
            r = self._closed(pred)
            return 0.5 * (r.tilt_min + r.tilt_max)
        return self._trajectory(pred)["tilt"]


class NutationRate(_Feature):
    """Angular frequency of the nutation ``θ(t)`` of a torque-free body, ``4π/T``.

    Closed form, or from a trajectory twice the phase rate of ω across the axis
    (:func:`omega_phase_rate`). Arguments as :class:`WobbleRatio` (``about`` unused).
    """

    def predicted(self, pred: Prediction) -> jax.Array:
        if self.method == "closed":
            return self._closed(pred).nutation_rate
        return 2.0 * jnp.abs(omega_phase_rate(self.ts, pred.omega, self.axis))


class FlipPeriod(_Feature):
    """Period ``T = 4K(m)/λ`` of ω: a flip and the flip back (the body flips every ``T/2``).

    ``axis`` is the axis the polhode encircles (for a spin near the intermediate axis:
    the largest-moment axis if ``L² > 2E I_mid``, else the smallest). Closed form
    (:func:`jrigid.exact.omega_period`) or from a trajectory ``2π/|phase rate|``
    (:func:`omega_phase_rate`; biased unless the record spans many periods).
    """

    def predicted(self, pred: Prediction) -> jax.Array:
        if self.method == "closed":
            return self._closed(pred).omega_period
        return _TWO_PI / jnp.abs(omega_phase_rate(self.ts, pred.omega, self.axis))
