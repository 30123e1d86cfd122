"""Derived features of a motion — wobble-to-spin ratio, precession, nutation, flip period —
as observations for a :class:`~jrigid.fit.Problem`.

The features are computed by :mod:`jrigid.theory` (re-exported here:
:func:`~jrigid.theory.free_rates`, :func:`~jrigid.theory.rates_from_constants`,
:func:`~jrigid.theory.axis_angles`, :func:`~jrigid.theory.angle_rate`,
:func:`~jrigid.theory.trajectory_rates`, :func:`~jrigid.theory.omega_phase_rate`,
:func:`~jrigid.theory.unwrap`), in one of two ways, both differentiable (no zero-crossing
counting):

**Closed form** (``method="closed"``, the default; torque-free motion only): the mean
rates of the Euler angles about ``L`` of the axis the polhode encircles, from the moments
and ω at one instant through the constants of the exact solution
(:func:`jrigid.theory.free_rates`). The flip period is ``T = 4K(m)/λ`` (a flip and the flip
back); ``T`` grows like ``log(1/ε)`` as the spin approaches the separatrix and is infinite
on it.

**Trajectory** (``method="trajectory"``; any model, tops and torques included): the Euler
angles of a body axis about a fixed space direction (``L`` for a torque-free body, the
vertical for a top), unwrapped, and their least-squares slopes
(:func:`jrigid.theory.trajectory_rates`; use records of many periods). The flip period
from a trajectory is ``2π`` over the slope of the unwrapped phase of the two ω components
across the encircled axis (a non-uniform phase near the separatrix: biased unless the
record spans many flips).

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

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from jrigid import quaternion as quat
from jrigid.fit.observations import Observation, Prediction, sample_times
from jrigid.theory import (
    FreeRates,
    angle_rate,
    axis_angles,
    free_rates,
    omega_phase_rate,
    rates_from_constants,
    trajectory_rates,
    unwrap,
)

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
        if isinstance(axis, bool) or not isinstance(axis, (int, np.integer)) or axis not in (
                0, 1, 2):
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
    (:func:`jrigid.theory.free_rates`, :func:`jrigid.exact.omega_period`) or from a
    trajectory ``2π/|phase rate|`` (:func:`omega_phase_rate`; biased unless the record
    spans many periods).
    """

    def predicted(self, pred: Prediction) -> jax.Array:
        if self.method == "closed":
            return self._closed(pred).omega_period
        return _TWO_PI / jnp.abs(omega_phase_rate(self.ts, pred.omega, self.axis))
