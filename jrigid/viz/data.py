"""Turn a trajectory (or plain arrays) into the numpy series the plots need.

Every drawing function in :mod:`jrigid.viz` accepts ``data`` as either

* an object with attributes (a :class:`jrigid.integrate.Trajectory` or anything alike), or
* a mapping of plain arrays, e.g. ``{"ts": ts, "q": q, "omega": omega}``.

Recognised names (first found wins): times ``ts``/``t``; orientation ``q`` ``(T, 4)``
(body → space); body angular velocity ``omega``/``omega_body`` ``(T, 3)``; body angular
momentum ``L``/``L_body``; space-frame ``omega_space``, ``L_space``; ``energy``,
``kinetic_energy``; ``q_norm_error``/``norm_error``; principal ``moments``/``inertia``
``(3,)`` (or ``scene.body.moments`` of a :class:`jrigid.trajectory.Trajectory`).
Missing quantities are derived with :mod:`jrigid.quaternion` where possible
(``L = I ω`` needs the moments; pass ``moments=`` if the data lack them).

Samples with a non-finite time, a non-finite or zero quaternion or a non-finite rate
(the tail of a failed solve, the NaN padding of ``SaveAt(steps=True)``) are left out,
with a :class:`DroppedSamplesWarning`; data with no sample left raise ``ValueError``.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jrigid import quaternion as quat

from ._jit import bucket, float_dtype, pad

__all__ = ["DroppedSamplesWarning", "Series", "as_series", "resample", "turn_angles"]


class DroppedSamplesWarning(UserWarning):
    """Samples of the data were left out of a drawing: their time, orientation or rates
    were not finite (or the quaternion was zero)."""

_ALIASES = {
    "ts": ("ts", "t", "times", "time"),
    "q": ("q", "quaternion", "orientation"),
    "omega": ("omega", "omega_body", "w"),
    "omega_space": ("omega_space",),
    "L": ("L", "L_body", "angular_momentum"),
    "L_space": ("L_space", "angular_momentum_space"),
    "energy": ("energy", "total_energy"),
    "kinetic_energy": ("kinetic_energy",),
    "q_norm_error": ("q_norm_error", "norm_error"),
    "moments": ("moments", "inertia", "I", "principal_moments"),
}


def _lookup(data: Any, key: str):
    for name in _ALIASES[key]:
        if isinstance(data, Mapping):
            if data.get(name) is not None:
                return data[name]
        elif getattr(data, name, None) is not None:
            return getattr(data, name)
    return None


def _moments_of(data: Any):
    """Principal moments from the data, or from ``data.scene.body.moments`` (a Trajectory)."""
    m = _lookup(data, "moments")
    if m is None:
        body = getattr(getattr(data, "scene", None), "body", None)
        m = getattr(body, "moments", None)
    return m


def _np(x):
    return None if x is None else np.asarray(x, dtype=float)


@dataclass
class Series:
    """Numpy arrays of one trajectory; ``None`` where unknown.

    Attributes:
        ts: ``(T,)``; q: ``(T, 4)`` unit-normalised; q_raw: ``(T, 4)`` as given;
        omega, omega_space, L, L_space: ``(T, 3)``; R: ``(T, 3, 3)`` active body → space
        matrices (columns = body axes in space); energy, kinetic_energy, q_norm_error:
        ``(T,)``; moments: ``(3,)`` or ``None``.
    """

    ts: np.ndarray
    q: np.ndarray
    q_raw: np.ndarray
    R: np.ndarray
    omega: np.ndarray | None = None
    omega_space: np.ndarray | None = None
    L: np.ndarray | None = None
    L_space: np.ndarray | None = None
    energy: np.ndarray | None = None
    kinetic_energy: np.ndarray | None = None
    q_norm_error: np.ndarray | None = None
    moments: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.ts)

    def require(self, *names: str) -> None:
        """Raise ``ValueError`` naming any of ``names`` that is unknown."""
        missing = [n for n in names if getattr(self, n) is None]
        if missing:
            raise ValueError(
                f"the data lack {', '.join(missing)}; pass them (or the principal `moments`, "
                "from which L and the energy follow)"
            )

    def take(self, index) -> Series:
        """A sub-series (index array or slice over time)."""
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            out[f.name] = v if (v is None or f.name == "moments") else v[index]
        return Series(**out)


@jax.jit
def _derive(q_raw, omega, omega_space, L, L_space, moments):
    """Fill in what follows from what is given (``None`` = unknown; static under jit)."""
    qn = quat.normalize(q_raw)
    out = {"q": qn, "R": quat.to_matrix(qn), "q_norm_error": quat.norm(q_raw) - 1.0}
    if omega is None and omega_space is not None:
        omega = quat.rotate_inverse(qn, omega_space)
    if L is None and L_space is not None:
        L = quat.rotate_inverse(qn, L_space)
    if L is None and omega is not None and moments is not None:
        L = omega * moments[None, :]
    if omega is None and L is not None and moments is not None:
        omega = L / moments[None, :]
    if omega_space is None and omega is not None:
        omega_space = quat.rotate(qn, omega)
    if L_space is None and L is not None:
        L_space = quat.rotate(qn, L)
    out.update(omega=omega, omega_space=omega_space, L=L, L_space=L_space)
    if L is not None and omega is not None:
        out["kinetic_energy"] = 0.5 * jnp.sum(L * omega, axis=-1)
    return out


def as_series(data: Any, moments=None) -> Series:
    """Collect and derive the arrays of ``data`` (see the module docstring).

    Args:
        data: trajectory-like object or mapping with at least ``q`` ``(T, 4)``.
        moments: principal moments ``(3,)`` if ``data`` has none.

    Returns:
        :class:`Series`.
    """
    if isinstance(data, Series):
        return data
    q_raw = _np(_lookup(data, "q"))
    if q_raw is None or q_raw.ndim != 2 or q_raw.shape[-1] != 4:
        shape = None if q_raw is None else q_raw.shape
        raise ValueError(f"data need quaternions `q` of shape (T, 4), got {shape}")
    T = len(q_raw)
    ts = _np(_lookup(data, "ts"))
    if ts is None:
        ts = np.arange(T, dtype=float)
    if ts.shape != (T,):
        raise ValueError(f"times `ts` must have shape ({T},) to match q, got {ts.shape}")
    m = _np(moments) if moments is not None else _np(_moments_of(data))
    if m is not None and m.shape == (3, 3):
        m = np.diag(m)
    if m is not None and m.shape != (3,):
        raise ValueError(f"moments must have shape (3,) or (3, 3), got {m.shape}")
    given = {k: _np(_lookup(data, k)) for k in ("omega", "omega_space", "L", "L_space")}
    for k, v in given.items():
        if v is not None and v.shape != (T, 3):
            raise ValueError(f"`{k}` must have shape ({T}, 3) to match q, got {v.shape}")
    keep = _usable(ts, q_raw, given.values())
    if not keep.all():
        ts, q_raw = ts[keep], q_raw[keep]
        given = {k: None if v is None else v[keep] for k, v in given.items()}
    n = bucket(len(ts))
    dt = float_dtype()

    def j(x, fill=0.0):
        return None if x is None else jnp.asarray(pad(x, n, fill), dtype=dt)

    d = _derive(
        j(q_raw, [1.0, 0.0, 0.0, 0.0]),
        *(j(given[k]) for k in ("omega", "omega_space", "L", "L_space")),
        None if m is None else jnp.asarray(m, dtype=dt),
    )
    d = {k: (None if v is None else np.asarray(v, dtype=float)[: len(ts)]) for k, v in d.items()}
    out = Series(ts=ts, q_raw=q_raw, moments=m, **d)
    for key in ("energy", "kinetic_energy", "q_norm_error"):
        given_value = _np(_lookup(data, key))
        if given_value is not None:
            setattr(out, key, given_value[keep] if given_value.shape == (T,) else given_value)
    if out.energy is None:
        out.energy = out.kinetic_energy
    return out


def _usable(ts, q_raw, rates) -> np.ndarray:
    """``(T,)`` bool: the samples with a finite time, a finite non-zero quaternion and
    finite rates; warns (:class:`DroppedSamplesWarning`) when some are not, raises
    ``ValueError`` when none is."""
    keep = np.isfinite(ts) & np.all(np.isfinite(q_raw), axis=-1) & np.any(q_raw != 0, axis=-1)
    for v in rates:
        if v is not None:
            keep &= np.all(np.isfinite(v), axis=-1)
    if not keep.any():
        raise ValueError(f"data have no usable sample among {len(keep)}: every one has a "
                         "non-finite time, orientation or rate, or a zero quaternion")
    if not keep.all():
        warnings.warn(
            f"{int((~keep).sum())} of {len(keep)} samples have a non-finite time, orientation "
            "or rate (or a zero quaternion) and are left out: the tail of a failed solve, "
            "or SaveAt(steps=True)'s padding", DroppedSamplesWarning, stacklevel=4)
    return keep


@jax.jit
def _interpolate(q0, q1, frac):
    q = quat.slerp(q0, q1, frac)
    return q, quat.to_matrix(q)


@jax.jit
def _steps(q):
    return quat.distance(q[1:], q[:-1])


def turn_angles(data: Any) -> np.ndarray:
    """Rotation angle of the body between consecutive samples, ``(T - 1,)`` radians.

    With the angular velocity known this is ``max(|ω_i|, |ω_{i+1}|) Δt`` (the angle
    actually turned, which may exceed π); otherwise the geodesic distance between the
    quaternions, which folds at π and so cannot reveal faster turning.
    """
    s = as_series(data)
    if len(s) < 2:
        return np.zeros(0)
    if s.omega is not None:
        w = np.linalg.norm(s.omega, axis=-1)
        return np.maximum(w[1:], w[:-1]) * np.diff(s.ts)
    n = bucket(len(s))
    steps = _steps(jnp.asarray(pad(s.q, n, s.q[-1]), dtype=float_dtype()))
    return np.asarray(steps, dtype=float)[: len(s) - 1]


def resample(data: Any, times, moments=None) -> Series:
    """The series at new ``times``: quaternions by slerp, everything else linearly.

    Used to decouple an animation's frame rate from the solver's output steps: frames are
    drawn at evenly spaced times whatever the steps were. Slerp takes the shorter arc, so
    the input must be sampled densely enough that the body turns less than π between
    samples (``ValueError`` otherwise; checked with :func:`turn_angles`, reliable when
    ``ω`` is known).

    Args:
        data: trajectory-like or mapping (see :func:`as_series`), times increasing.
        times: ``(F,)`` new times inside ``[ts[0], ts[-1]]``.

    Returns:
        :class:`Series` at ``times``.
    """
    s = as_series(data, moments)
    times = np.asarray(times, dtype=float)
    if len(s) < 2:
        raise ValueError("resample needs at least two samples")
    if times.min() < s.ts[0] - 1e-12 or times.max() > s.ts[-1] + 1e-12:
        raise ValueError(
            f"frame times [{times.min():g}, {times.max():g}] leave the data's range "
            f"[{s.ts[0]:g}, {s.ts[-1]:g}]"
        )
    steps = turn_angles(s)
    if np.any(steps > 0.9 * np.pi):
        raise ValueError(
            f"the body turns up to {np.degrees(steps.max()):.0f}° between samples: too coarse to "
            "interpolate; save the trajectory at more times (or at the frame times directly)"
        )
    idx = np.clip(np.searchsorted(s.ts, times, side="right") - 1, 0, len(s) - 2)
    t0, t1 = s.ts[idx], s.ts[idx + 1]
    frac = np.clip((times - t0) / np.where(t1 > t0, t1 - t0, 1.0), 0.0, 1.0)
    nf, dt = bucket(len(times)), float_dtype()
    q, R = _interpolate(
        jnp.asarray(pad(s.q[idx], nf, [1.0, 0, 0, 0]), dtype=dt),
        jnp.asarray(pad(s.q[idx + 1], nf, [1.0, 0, 0, 0]), dtype=dt),
        jnp.asarray(pad(frac, nf), dtype=dt),
    )
    q = np.asarray(q, dtype=float)[: len(times)]
    R = np.asarray(R, dtype=float)[: len(times)]

    def lerp(x):
        if x is None:
            return None
        f = frac.reshape((-1,) + (1,) * (x.ndim - 1))
        return x[idx] * (1 - f) + x[idx + 1] * f

    out = Series(
        ts=times,
        q=q,
        q_raw=lerp(s.q_raw),
        R=R,
        moments=s.moments,
    )
    for key in ("omega", "omega_space", "L", "L_space", "energy", "kinetic_energy", "q_norm_error"):
        setattr(out, key, lerp(getattr(s, key)))
    return out
