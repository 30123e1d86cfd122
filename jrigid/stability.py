"""Principal-axis stability of torque-free rotation: maps over the sphere of spin directions.

A body spun about its axis of largest or smallest moment keeps spinning about it; spun
near the intermediate axis it turns over again and again (Problem 17.3, the Dzhanibekov
effect). This module holds the pure, per-member functions behind a *stability map*: one
initial angular velocity per direction on the sphere, one trajectory each, a few numbers
per trajectory. Everything here is written for one member and ``vmap``-ped (or run with
:func:`jrigid.ensemble.run`); nothing imports matplotlib (the drawing is in
:mod:`jrigid.viz.stability`).

Directions and scaling
    :func:`fibonacci_sphere` (nearly uniform points), :func:`omega_at_energy`
    (``ω = s d`` with ``2E = ω·Iω``, from :mod:`jrigid.polhode`).
Per trajectory
    :func:`axis_angle` / :func:`trajectory_summary`: the largest angle the principal axis
    nearest to the initial ω moves from its initial direction in space, the number of flips
    and the first flip time. A *flip* is a sign change of ``ω_k``, the body component of ω
    along that axis ``k``. Since ``L_body = I ω`` in principal axes, ``sign ω_k =
    sign(e_k · L)``: a flip is exactly the moment the body axis crosses the plane normal to
    the conserved angular momentum, i.e. turns over relative to ``L`` — the two criteria of
    a flip (body component of ω, projection of the axis on ``L``) coincide, and the first
    needs no orientation.
    :func:`ftle_exact` / :func:`ftle_simulate`: the finite-time Lyapunov exponent
    ``log(σ_max(∂ω(T)/∂ω(0)))/T`` by forward-mode autodiff, from :mod:`jrigid.ftle`
    (re-exported here).
Closed form
    :func:`flips_expected` (the nearest axis is not the one the polhode encircles: it
    must turn over), :func:`flip_time_asymptotic` (half-period between flips near the
    separatrix). The polhodes drawn over a map (:func:`polhode`, :func:`polhode_family`)
    and :func:`encircled_axis` are in :mod:`jrigid.polhode` (re-exported here).
Lockstep efficiency
    :func:`lockstep_efficiency` and :func:`difficulty_order` live in
    :mod:`jrigid.ensemble.schedule` and are re-exported here.

Flip time near the separatrix (derived in :func:`flip_time_asymptotic`): spun at ``|ω|``
about the middle axis tilted by ``ε`` toward axis 3 (moments ``I1 < I2 < I3``), the time
between flips is ``T ≈ (2/λ) ln(C/ε)`` with ``λ = |ω| √((I3−I2)(I2−I1)/(I1 I3))`` and
``C = 4 √(I2(I2−I1)/(I3(I3−I1)))`` (toward axis 1: ``C = 4 √(I2(I3−I2)/(I1(I3−I1)))``);
the relative error is ``O(ε²)``.

Bad input: :func:`fibonacci_sphere` raises ``ValueError``; the other functions are meant
for traced per-member use and do not check values (``jrigid.simulate`` checks its own).
"""

from __future__ import annotations

import math

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from jrigid import initial
from jrigid import quaternion as quat
from jrigid._checks import float_dtype
from jrigid.body import RigidBody
from jrigid.ensemble.schedule import difficulty_order, lockstep_efficiency
from jrigid.ftle import ftle_exact, ftle_simulate
from jrigid.integrate import simulate
from jrigid.polhode import (
    encircled_axis,
    omega_at_energy,
    polhode,
    polhode_family,
    separatrix_offset,
)
from jrigid.scene import Scene
from jrigid.solve import validate_shared
from jrigid.trajectory import Result

__all__ = [
    "axis_angle",
    "difficulty_order",
    "encircled_axis",
    "fibonacci_sphere",
    "flip_interval",
    "flip_summary",
    "flip_time_asymptotic",
    "flips_expected",
    "ftle_exact",
    "ftle_simulate",
    "lockstep_efficiency",
    "map_member",
    "nearest_axis",
    "omega_at_energy",
    "polhode",
    "polhode_family",
    "trajectory_summary",
]


# --------------------------------------------------------------------------- directions


def fibonacci_sphere(n: int, dtype=None) -> jax.Array:
    """``n`` nearly uniform unit vectors: the Fibonacci (golden-angle) lattice.

    Point ``i`` has ``z = 1 − (2i + 1)/n`` and longitude ``i·π(3 − √5)``; every point
    carries the area ``4π/n`` (equal-area in ``z``), none lies on a coordinate axis.

    Args:
        n: number of points, ``n ≥ 1``.
        dtype: floating dtype (default: JAX's default float).

    Returns:
        ``(n, 3)`` unit vectors.
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"fibonacci_sphere needs a positive int n, got {n!r}")
    n = int(n)
    dtype = jnp.result_type(float) if dtype is None else dtype
    i = jnp.arange(n, dtype=dtype)
    z = 1.0 - (2.0 * i + 1.0) / n
    r = jnp.sqrt(jnp.maximum(1.0 - z * z, 0.0))
    phi = i * (math.pi * (3.0 - math.sqrt(5.0)))
    return jnp.stack([r * jnp.cos(phi), r * jnp.sin(phi), z], axis=-1)


def nearest_axis(omega: ArrayLike) -> jax.Array:
    """Index ``0, 1, 2`` of the principal axis nearest to ``±ω`` (largest ``|ω_k|``).

    Args:
        omega: ``(..., 3)`` body angular velocity.

    Returns:
        ``(...)`` int32.
    """
    return jnp.argmax(jnp.abs(jnp.asarray(omega)), axis=-1).astype(jnp.int32)


def flips_expected(moments: ArrayLike, omega: ArrayLike) -> jax.Array:
    """Whether the axis nearest to ``ω`` must turn over relative to ``L`` (closed form).

    True when the nearest principal axis is not the one the polhode encircles: its body
    component of ω then oscillates about zero (``cn`` or ``sn``) and changes sign twice
    per period of ω. This is the classification a long enough simulation must reproduce.
    False where ``L² = 2E I_mid`` exactly: a steady spin (about a principal axis, the
    intermediate one included; any spin of a sphere; a symmetric body spun in its
    equatorial plane) or the separatrix itself, where no axis turns over periodically.

    Args:
        moments: ``(..., 3)`` principal moments, any order, positive (equal ones
            allowed: a symmetric body's equatorial axes turn over about its symmetry
            axis, a sphere's never).
        omega: ``(..., 3)`` body angular velocity.

    Returns:
        ``(...)`` bool (the broadcast batch shape); False where ``omega`` is not finite
        (under ``jit``/``vmap``; concrete non-finite input raises ``ValueError``).
    """
    offset = separatrix_offset(moments, omega)
    turning = (nearest_axis(omega) != encircled_axis(moments, omega)) & (offset != 0)
    return turning & jnp.isfinite(offset)  # (False for a non-finite omega under jit)


# --------------------------------------------------------------------------- per trajectory


def axis_angle(q: ArrayLike, q0: ArrayLike, axis: ArrayLike) -> jax.Array:
    """Angle between body axis ``axis`` in space at orientation ``q`` and at ``q0``.

    Args:
        q: ``(..., 4)`` orientations (body → space).
        q0: ``(4,)`` initial orientation.
        axis: ``()`` int, principal axis index.

    Returns:
        ``(...)`` angle in ``[0, π]`` (``atan2(|a×a0|, a·a0)``, accurate at both ends).
    """
    q, q0 = jnp.asarray(q), jnp.asarray(q0)
    e = jax.nn.one_hot(axis, 3, dtype=q.dtype)
    a0 = quat.rotate(q0, e)
    a = quat.rotate(q, jnp.broadcast_to(e, q.shape[:-1] + (3,)))
    a0 = jnp.broadcast_to(a0, a.shape)
    return jnp.arctan2(jnp.linalg.norm(jnp.cross(a, a0), axis=-1), jnp.sum(a * a0, axis=-1))


def _sign_changes(a, b):
    """Consecutive samples on different sides of zero (``0`` counts as positive; a
    non-finite sample never counts)."""
    return ((a >= 0) != (b >= 0)) & jnp.isfinite(a) & jnp.isfinite(b)


def flip_summary(ts: ArrayLike, x: ArrayLike) -> tuple[jax.Array, jax.Array]:
    """Number of sign changes of the samples ``x`` and the first one's time.

    Args:
        ts: ``(T,)`` sample times.
        x: ``(T,)`` samples (``NaN`` samples never count; ``0`` counts as positive).

    Returns:
        ``(count, first)``: ``()`` int32 and ``()`` float, the first crossing time by
        linear interpolation between samples (``inf`` if there is none).
    """
    ts, x = jnp.asarray(ts), jnp.asarray(x)
    a, b = x[:-1], x[1:]
    change = _sign_changes(a, b)
    count = jnp.sum(change).astype(jnp.int32)
    k = jnp.argmax(change)
    den = jnp.where(b[k] != a[k], b[k] - a[k], 1.0)
    t_cross = ts[k] - a[k] * (ts[k + 1] - ts[k]) / den
    return count, jnp.where(count > 0, t_cross, jnp.inf)


def flip_interval(ts: ArrayLike, x: ArrayLike) -> tuple[jax.Array, jax.Array]:
    """Mean spacing of the sign changes of the samples ``x`` (the time between flips).

    Crossing times are interpolated linearly between samples; the spacing is
    ``(last − first)/(count − 1)``.

    Args:
        ts: ``(T,)`` sample times.
        x: ``(T,)`` samples.

    Returns:
        ``(interval, count)``: ``()`` float (``NaN`` with fewer than two crossings) and
        ``()`` int32.
    """
    ts, x = jnp.asarray(ts), jnp.asarray(x)
    a, b = x[:-1], x[1:]
    change = _sign_changes(a, b)
    den = jnp.where(change, b - a, 1.0)
    t_cross = ts[:-1] - a * (ts[1:] - ts[:-1]) / den
    count = jnp.sum(change).astype(jnp.int32)
    first = jnp.min(jnp.where(change, t_cross, jnp.inf))
    last = jnp.max(jnp.where(change, t_cross, -jnp.inf))
    ok = count >= 2
    interval = jnp.where(ok, (last - first) / jnp.where(ok, count - 1, 1), jnp.nan)
    return interval, count


def trajectory_summary(ts: ArrayLike, q: ArrayLike, omega: ArrayLike) -> dict[str, jax.Array]:
    """Stability numbers of one sampled trajectory, about the axis nearest to ``ω(0)``.

    Args:
        ts: ``(T,)`` times.
        q: ``(T, 4)`` orientations.
        omega: ``(T, 3)`` body angular velocities.

    Returns:
        dict of scalars: ``axis`` (nearest principal axis to ``ω(0)``), ``max_axis_angle``
        (largest angle in rad that axis moves from its initial direction in space, over the
        samples), ``flips`` (sign changes of ``ω_axis``, i.e. of the axis' projection on
        ``L``) and ``first_flip`` (time of the first, ``inf`` if none).
    """
    q, omega = jnp.asarray(q), jnp.asarray(omega)
    k = nearest_axis(omega[0])
    angle = axis_angle(q, q[0], k)
    w_k = jnp.take_along_axis(omega, jnp.broadcast_to(k, (omega.shape[0], 1)), axis=1)[:, 0]
    count, first = flip_summary(ts, w_k)
    return dict(axis=k, max_axis_angle=jnp.max(angle), flips=count, first_flip=first)


def map_member(
    moments: ArrayLike,
    omega0: ArrayLike,
    ts: ArrayLike,
    ftle_time: ArrayLike,
    *,
    rtol: ArrayLike | None = None,
    atol: ArrayLike | None = None,
    solver: diffrax.AbstractSolver | None = None,
    max_steps: int = 100_000,
) -> dict[str, jax.Array]:
    """Everything a stability map records for one initial angular velocity.

    Simulates the torque-free body (:func:`jrigid.simulate`, identity initial orientation,
    ``throw=False``), summarises the samples (:func:`trajectory_summary`), adds the FTLE
    over ``ftle_time`` (:func:`ftle_exact`), the closed-form classification
    (:func:`flips_expected`) and the solver's step count.

    Args:
        moments: ``(3,)`` principal moments.
        omega0: ``(3,)`` initial body angular velocity.
        ts: ``(T,)`` output times (flips and angles are read at these samples).
        ftle_time: ``()`` FTLE horizon.
        rtol, atol, solver, max_steps: passed to :func:`jrigid.simulate` (default
            tolerances: simulate's, ``1e-8``/``1e-10`` in float64).

    Returns:
        dict of scalars: the keys of :func:`trajectory_summary` plus ``ftle``,
        ``flips_expected``, ``num_steps`` (accepted + rejected) and ``result``
        (:class:`jrigid.integrate.Result` code). A member whose solve failed
        (``result != 0``) has ``flips = -1`` and NaN ``first_flip`` and
        ``max_axis_angle``; ``ftle`` and ``flips_expected`` are closed forms, kept.

    Raises:
        ValueError: concrete ``ts``, ``rtol`` or ``atol`` that no solve can run with (as
            :func:`jrigid.simulate`'s message), before anything is traced.

    Example: a map of two directions, near the intermediate and the largest axis of a
    body with moments 1, 2, 3 (for thousands, run it with :func:`jrigid.ensemble.run`)::

        >>> import jax, jax.numpy as jnp
        >>> jax.config.update("jax_enable_x64", True)
        >>> from jrigid import stability
        >>> moments = jnp.array([1.0, 2.0, 3.0])
        >>> directions = jnp.array([[0.05, 1.0, 0.05], [0.05, 0.05, 1.0]])
        >>> ts = jnp.linspace(0.0, 30.0, 61)
        >>> def member(d):
        ...     omega0 = stability.omega_at_energy(d, moments, 1.0)
        ...     return stability.map_member(moments, omega0, ts, 10.0)
        >>> out = jax.jit(jax.vmap(member))(directions)
        >>> out["axis"].tolist(), out["flips"].tolist(), out["flips_expected"].tolist()
        ([1, 2], [2, 0], [True, False])
        >>> bool(out["ftle"][0] > 5 * out["ftle"][1])
        True
    """
    moments, omega0 = jnp.asarray(moments), jnp.asarray(omega0)
    dtype = moments.dtype if jnp.issubdtype(moments.dtype, jnp.floating) else float_dtype()
    validate_shared(ts, rtol, atol, dtype)  # settings no member can run with: raise now
    traj = simulate(
        Scene(RigidBody(moments)),
        initial.from_omega(None, omega0),
        ts,
        rtol=rtol,
        atol=atol,
        solver=solver,
        max_steps=max_steps,
        throw=False,
    )
    out = trajectory_summary(traj.ts, traj.q, traj.omega)
    # a member whose solve failed has no flips to count: -1 and NaN, not "stable"
    failed = traj.result != Result.success
    out["flips"] = jnp.where(failed, -1, out["flips"])
    out["first_flip"] = jnp.where(failed, jnp.nan, out["first_flip"])
    out["max_axis_angle"] = jnp.where(failed, jnp.nan, out["max_axis_angle"])
    out["ftle"] = ftle_exact(moments, omega0, ftle_time)
    out["flips_expected"] = flips_expected(moments, omega0)
    out["num_steps"] = traj.stats["num_steps"]
    out["result"] = traj.result
    return out


# --------------------------------------------------------------------------- closed form


def flip_time_asymptotic(
    moments: ArrayLike, speed: ArrayLike, eps: ArrayLike, toward: str = "largest"
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Half-period between flips near the separatrix: ``T ≈ (2/λ) ln(C/ε)``.

    :func:`jrigid.theory.flip_interval_asymptotic` (the derivation is there): spin
    ``|ω| = speed`` about the intermediate axis tilted by ``ε`` toward the largest (or
    smallest) axis; arguments and result as there: ``(T, λ, C)``, ``T`` of the shape of
    ``eps``.
    """
    from jrigid.theory import flip_interval_asymptotic

    return flip_interval_asymptotic(moments, speed, eps, toward)
