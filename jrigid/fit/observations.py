"""Observations of a rotating body and their (whitened) residuals and losses.

Each observation holds sample times ``ts (T,)``, data and a noise level ``sigma``, and
turns a :class:`Prediction` at those times into whitened residuals ``r`` (independent,
unit variance if the model is right). Its negative log-likelihood is ``½ Σ r²``
(:meth:`AbstractObservation.loss`); the Gauss–Newton covariance of
:func:`jrigid.fit.laplace` is built from the Jacobian of ``r``. A new kind of data
subclasses :class:`AbstractObservation` (the extension point; also named
``Observation``).

- :class:`Gyroscope` — angular velocity (body principal frame, the body's reference
  frame, or space), residual ``(ω − ω̂)/σ``;
- :class:`Orientations` — orientation quaternions, compared sign-invariantly:
  ``r = 2 sign(w) vec(q̂* ⊗ q)/σ`` with ``w = q̂·q``, so that ``|r|² σ² / 4 = 1 − (q̂·q)²``
  (:func:`orientation_loss`) and ``σ`` is the noise of the rotation angle about each axis;
- :class:`AxisDirections` — the direction in space of a marked body axis (a camera
  tracking it), residual ``(R e − û)/σ``.

Construction validates the data and raises ``ValueError`` naming the problem (wrong
shapes, NaN/inf, fewer than ``2`` samples, times not strictly increasing, a
non-positive ``sigma``, a zero quaternion or direction). Construct observations outside
``jit``.

``sigma`` is the noise's standard deviation. Left out (``None``), the residuals are
unweighted (``σ = 1``) and the observation records that its noise level is unknown
(:attr:`AbstractObservation.sigma_given` is ``False``): :func:`jrigid.fit.fit` then does not
test χ², and :func:`jrigid.fit.laplace` scales the covariance by ``χ²/dof``.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from jrigid import quaternion as quat

__all__ = [
    "AbstractObservation",
    "AxisDirections",
    "Gyroscope",
    "Observation",
    "Orientations",
    "Prediction",
    "axis_loss",
    "gyroscope_loss",
    "orientation_loss",
    "sample_times",
    "sigma_array",
]

_FRAMES = ("principal", "reference", "space")


class Prediction(NamedTuple):
    """What a forward model predicts at ``T`` times.

    Attributes:
        q: ``(T, 4)`` unit orientation of the principal frame (body → space), or ``None``.
        omega: ``(T, 3)`` body angular velocity in the principal frame.
        frame: ``(4,)`` principal → reference-frame rotation (``RigidBody.frame``).
        moments: ``(3,)`` principal moments when the motion is torque-free (the
            closed-form features of :mod:`jrigid.fit.features` use them), else ``None``.
        constants: the :class:`jrigid.exact.ExactConstants` of that torque-free motion
            when already computed (by :class:`~jrigid.fit.Exact`, or once per evaluation
            by :class:`~jrigid.fit.Problem` for closed-form features), else ``None``.
    """

    q: jax.Array | None
    omega: jax.Array
    frame: jax.Array
    moments: jax.Array | None = None
    constants: Any = None


# --------------------------------------------------------------------------- plain losses


def gyroscope_loss(omega: ArrayLike, omega_obs: ArrayLike, sigma: ArrayLike = 1.0) -> jax.Array:
    """``½ Σ |(ω − ω̂)/σ|²``: Gaussian negative log-likelihood of a gyroscope record.

    Args:
        omega: ``(T, 3)`` predicted angular velocity.
        omega_obs: ``(T, 3)`` observed.
        sigma: noise standard deviation, broadcastable to ``(T, 3)``.

    Returns:
        ``()`` loss.
    """
    r = (jnp.asarray(omega) - jnp.asarray(omega_obs)) / jnp.asarray(sigma)
    return 0.5 * jnp.sum(r * r)


def _orientation_residual(q: jax.Array, q_obs: jax.Array) -> jax.Array:
    """``(..., 3)`` ``2 sign(q̂·q) vec(q̂* ⊗ q)``: sign-invariant, ≈ the rotation vector error."""
    rel = quat.multiply(quat.conjugate(q_obs), q)
    sign = jnp.where(rel[..., :1] >= 0, 1.0, -1.0)
    return 2.0 * sign * rel[..., 1:]


def orientation_loss(q: ArrayLike, q_obs: ArrayLike) -> jax.Array:
    """Mean of ``1 − (q·q̂)²`` over samples: sign-invariant (``q ≡ −q``), zero iff equal.

    ``1 − (q·q̂)² = sin²(θ/2)`` with ``θ`` the angle of the rotation taking one
    orientation to the other.

    Args:
        q: ``(T, 4)`` predicted unit quaternions.
        q_obs: ``(T, 4)`` observed unit quaternions.

    Returns:
        ``()`` loss in ``[0, 1]``.
    """
    d = jnp.sum(jnp.asarray(q) * jnp.asarray(q_obs), axis=-1)
    return jnp.mean(1.0 - d * d)


def axis_loss(
    directions: ArrayLike, directions_obs: ArrayLike, sigma: ArrayLike = 1.0
) -> jax.Array:
    """``½ Σ |(u − û)/σ|²`` for unit direction vectors.

    Args:
        directions: ``(T, 3)`` predicted unit vectors.
        directions_obs: ``(T, 3)`` observed unit vectors.
        sigma: noise per component, broadcastable to ``(T, 3)``.

    Returns:
        ``()`` loss.
    """
    r = (jnp.asarray(directions) - jnp.asarray(directions_obs)) / jnp.asarray(sigma)
    return 0.5 * jnp.sum(r * r)


# --------------------------------------------------------------------------- validation


def sample_times(ts) -> jax.Array:
    """Validated sample times: ``(T,)`` finite, strictly increasing, ``T ≥ 2``.

    Raises:
        ValueError: naming what is wrong.
    """
    ts_np = np.asarray(ts, dtype=float)
    if ts_np.ndim != 1:
        raise ValueError(f"ts must be a 1-D array of sample times, got shape {ts_np.shape}")
    if ts_np.shape[0] < 2:
        raise ValueError(f"too few samples: need at least 2 times, got {ts_np.shape[0]}")
    if not np.all(np.isfinite(ts_np)):
        bad = np.flatnonzero(~np.isfinite(ts_np))[:5].tolist()
        raise ValueError(f"ts has non-finite entries at indices {bad}")
    if np.any(np.diff(ts_np) <= 0):
        i = int(np.flatnonzero(np.diff(ts_np) <= 0)[0])
        raise ValueError(f"ts must be strictly increasing (ts[{i + 1}] <= ts[{i}])")
    return jnp.asarray(ts_np, dtype=jnp.result_type(float))


def _data(x, ts, width: int, name: str) -> jax.Array:
    if np.iscomplexobj(x):
        raise ValueError(f"{name} must be real, got complex values")
    x_np = np.asarray(x, dtype=float)
    if x_np.ndim != 2 or x_np.shape[1] != width:
        raise ValueError(f"{name} must have shape (T, {width}), got {x_np.shape}")
    if x_np.shape[0] != ts.shape[0]:
        raise ValueError(
            f"{name} has {x_np.shape[0]} samples but ts has {ts.shape[0]} times: they must match"
        )
    bad = ~np.all(np.isfinite(x_np), axis=1)
    if bad.any():
        raise ValueError(
            f"{name} has NaN or inf at samples {np.flatnonzero(bad)[:5].tolist()}; "
            "drop those samples (and their times)"
        )
    return jnp.asarray(x_np, dtype=jnp.result_type(float))


def sigma_array(sigma, n: int, width: int) -> jax.Array:
    """Validated noise levels ``(n, width)`` from ``sigma`` (``None`` means ``1``).

    Args:
        sigma: a scalar, ``(width,)``, ``(n, 1)`` or ``(n, width)``; finite and > 0.
        n: number of samples; width: residual components per sample.

    Raises:
        ValueError: a shape that does not broadcast, or an entry that is not finite and
            positive (naming the first such sample).
    """
    if sigma is None:
        return jnp.ones((n, width), dtype=jnp.result_type(float))
    try:
        s = np.asarray(sigma, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"sigma must be a number or an array of numbers, got {sigma!r}") from None
    try:
        s = np.broadcast_to(s, (n, width))
    except ValueError:
        hint = (
            f"; for one σ per sample pass sigma[:, None] of shape ({n}, 1)"
            if s.shape == (n,)
            else ""
        )
        raise ValueError(
            f"sigma must broadcast to (T, {width}) = ({n}, {width}), got shape {s.shape}{hint}"
        ) from None
    bad = ~(np.isfinite(s) & (s > 0))
    if bad.any():
        i, k = (int(x) for x in np.argwhere(bad)[0])
        raise ValueError(f"sigma must be finite and > 0, got {s[i, k]} at sample {i}")
    return jnp.asarray(s, dtype=jnp.result_type(float))


def _unit_rows(x: jax.Array, name: str) -> jax.Array:
    n = np.linalg.norm(np.asarray(x), axis=1)
    if np.any(n <= 1e-12):
        raise ValueError(
            f"{name} has zero-length rows at samples {np.flatnonzero(n <= 1e-12)[:5].tolist()}"
        )
    return x / jnp.asarray(n)[:, None]


# --------------------------------------------------------------------------- observations


class AbstractObservation(eqx.Module):
    """What a :class:`~jrigid.fit.Problem` compares with a prediction: the extension point.

    Subclass it for a new kind of data (also available as ``Observation``). A
    subclass is an ``equinox.Module`` that holds ``ts (T,)``, its data and noise levels,
    validates them on construction (outside ``jit``; :func:`sample_times` and
    :func:`sigma_array` check the common parts), and implements

    - :meth:`residuals` — ``(size,)`` whitened residuals from a :class:`Prediction`
      (differentiable: fits differentiate through it),
    - :attr:`size` — their number;

    it sets ``sigma_given`` (whether its noise level was stated), and overrides
    :meth:`in_window` if its residuals are not laid out sample by sample. :meth:`loss`
    follows. The derived features of :mod:`jrigid.fit.features` are subclasses too.
    """

    sigma_given: bool = eqx.field(static=True, default=True, kw_only=True)

    def loss(self, pred: Prediction) -> jax.Array:
        """``()`` ``½ Σ r²``, the Gaussian negative log-likelihood up to a constant."""
        r = self.residuals(pred)
        return 0.5 * jnp.sum(r * r)

    @property
    def size(self) -> int:
        """Number of residuals."""
        raise NotImplementedError

    def residuals(self, pred: Prediction) -> jax.Array:
        """``(size,)`` whitened residuals."""
        raise NotImplementedError

    def in_window(self, t_end: jax.Array) -> jax.Array:
        """``(size,)`` which residuals belong to samples at times ``≤ t_end``.

        This default suits residuals laid out sample by sample, ``size / T`` per sample.
        """
        per = self.size // self.ts.shape[0]
        return jnp.repeat(self.ts <= t_end, per, total_repeat_length=self.size)

    def degrees(self, t_end) -> int:
        """Degrees of freedom of the residuals of samples at times ``≤ t_end``: how many
        independent normal variables their χ² sums under the noise model. By default
        one per residual; fewer where residuals are tied (:class:`AxisDirections`: the
        difference of two unit vectors lies in a plane, two per sample)."""
        return int(np.sum(np.asarray(self.in_window(t_end))))


#: The name the base class has always had; :class:`AbstractObservation` itself.
Observation = AbstractObservation


class _PerSample(AbstractObservation):
    """Three whitened residuals a sample: ``ts (T,)`` and noise levels ``sigma (T, 3)``."""

    @property
    def size(self) -> int:
        return 3 * self.ts.shape[0]

    def _noise(self, sigma) -> None:
        """Set ``sigma`` (validated, ``(T, 3)``) and ``sigma_given``; in ``__init__``."""
        self.sigma = sigma_array(sigma, self.ts.shape[0], 3)
        self.sigma_given = sigma is not None

    def _whitened(self, difference: jax.Array) -> jax.Array:
        """``(3T,)`` ``difference / σ``, sample by sample."""
        return (difference / self.sigma).reshape(-1)


class Gyroscope(_PerSample):
    """A gyroscope record: angular velocity samples with Gaussian noise.

    Attributes:
        ts: ``(T,)`` strictly increasing times.
        omega: ``(T, 3)`` measured angular velocity.
        sigma: ``(T, 3)`` noise standard deviation (a scalar, ``(3,)`` or ``(T, 1)``
            broadcasts; ``None``: unknown, unit weights).
        frame: static, the frame of ``omega``: ``"principal"`` (default; the body's
            principal axes), ``"reference"`` (the frame the body's tensor was given in,
            ``RigidBody.frame``) or ``"space"``.
    """

    ts: jax.Array
    omega: jax.Array
    sigma: jax.Array
    frame: str = eqx.field(static=True)

    def __init__(
        self,
        ts: ArrayLike,
        omega: ArrayLike,
        sigma: ArrayLike | None = None,
        *,
        frame: str = "principal",
    ):
        if frame not in _FRAMES:
            raise ValueError(f"frame must be one of {_FRAMES}, got {frame!r}")
        self.ts = sample_times(ts)
        self.omega = _data(omega, self.ts, 3, "omega")
        self._noise(sigma)
        self.frame = frame

    def predicted(self, pred: Prediction) -> jax.Array:
        """``(T, 3)`` angular velocity in this record's frame."""
        if self.frame == "principal":
            return pred.omega
        if self.frame == "reference":
            return quat.rotate(
                jnp.broadcast_to(pred.frame, pred.omega.shape[:-1] + (4,)), pred.omega
            )
        if pred.q is None:
            raise ValueError("a space-frame gyroscope needs a model that predicts q")
        return quat.rotate(pred.q, pred.omega)

    def residuals(self, pred: Prediction) -> jax.Array:
        """``(3T,)`` whitened residuals ``(ω − ω̂)/σ``."""
        return self._whitened(self.predicted(pred) - self.omega)


class Orientations(_PerSample):
    """Orientation samples (quaternions, any sign, normalised here).

    Attributes:
        ts: ``(T,)`` times.
        q: ``(T, 4)`` measured orientations, body → space.
        sigma: ``(T, 3)`` angle noise in radians about each axis (scalar broadcasts;
            ``None``: unknown, unit weights).
        frame: static, ``"principal"`` (default) or ``"reference"``: whose orientation
            ``q`` is (the reference frame's is ``q_principal ⊗ frame*``).
    """

    ts: jax.Array
    q: jax.Array
    sigma: jax.Array
    frame: str = eqx.field(static=True)

    def __init__(
        self,
        ts: ArrayLike,
        q: ArrayLike,
        sigma: ArrayLike | None = None,
        *,
        frame: str = "principal",
    ):
        if frame not in _FRAMES[:2]:
            raise ValueError(f"frame must be 'principal' or 'reference', got {frame!r}")
        self.ts = sample_times(ts)
        self.q = _unit_rows(_data(q, self.ts, 4, "q"), "q")
        self._noise(sigma)
        self.frame = frame

    def predicted(self, pred: Prediction) -> jax.Array:
        """``(T, 4)`` predicted orientation of this record's frame."""
        if pred.q is None:
            raise ValueError("orientation observations need a model that predicts q")
        if self.frame == "reference":
            return quat.multiply(pred.q, quat.conjugate(jnp.broadcast_to(pred.frame, pred.q.shape)))
        return pred.q

    def residuals(self, pred: Prediction) -> jax.Array:
        """``(3T,)`` whitened residuals ``2 sign(q̂·q) vec(q̂* ⊗ q)/σ``."""
        return self._whitened(_orientation_residual(self.predicted(pred), self.q))


class AxisDirections(_PerSample):
    """Directions in space of one body-fixed axis (a camera tracking a mark).

    Attributes:
        ts: ``(T,)`` times.
        directions: ``(T, 3)`` measured directions in space (normalised here).
        sigma: ``(T, 3)`` noise per component (scalar broadcasts; ``None``: unknown): for
            a scalar σ, the angular noise in radians in each direction across ``û``. The
            three residuals of a sample count as two degrees of freedom (:meth:`degrees`).
        axis: ``(3,)`` the marked axis in principal body coordinates (an int ``i`` means
            principal axis ``i + 1``); normalised.
    """

    ts: jax.Array
    directions: jax.Array
    sigma: jax.Array
    axis: jax.Array

    def __init__(
        self, ts: ArrayLike, directions: ArrayLike, sigma: ArrayLike | None = None, *, axis=2
    ):
        self.ts = sample_times(ts)
        self.directions = _unit_rows(_data(directions, self.ts, 3, "directions"), "directions")
        self._noise(sigma)
        if isinstance(axis, bool):
            raise ValueError(f"axis must be 0, 1, 2 or a 3-vector, got {axis}")
        if isinstance(axis, (int, np.integer)):
            if axis not in (0, 1, 2):
                raise ValueError(f"axis must be 0, 1, 2 or a 3-vector, got {axis}")
            axis = np.eye(3)[axis]
        a = np.asarray(axis, dtype=float)
        if a.shape != (3,) or not np.all(np.isfinite(a)) or not np.linalg.norm(a) > 0:
            raise ValueError(f"axis must be a finite non-zero 3-vector, got {a.tolist()}")
        self.axis = jnp.asarray(a / np.linalg.norm(a), dtype=jnp.result_type(float))

    def predicted(self, pred: Prediction) -> jax.Array:
        """``(T, 3)`` predicted direction of the axis in space."""
        if pred.q is None:
            raise ValueError("axis observations need a model that predicts q")
        return quat.rotate(pred.q, jnp.broadcast_to(self.axis, pred.q.shape[:-1] + (3,)))

    def residuals(self, pred: Prediction) -> jax.Array:
        """``(3T,)`` whitened residuals ``(R a − û)/σ``."""
        return self._whitened(self.predicted(pred) - self.directions)

    def degrees(self, t_end) -> int:
        """Two per sample: ``R a`` and ``û`` are unit vectors, so to first order their
        difference lies in the plane perpendicular to ``û``, and its χ² has two degrees
        of freedom, not three (the noise model: σ the same in the two directions across
        ``û``, in radians)."""
        return super().degrees(t_end) * 2 // 3
