"""Polhodes: the curves body ω follows in torque-free motion, and the axis each goes round.

A torque-free body keeps its kinetic energy ``2E = ω·Iω`` and ``L² = |Iω|²``, so its body
angular velocity stays on the intersection of the energy ellipsoid and the momentum
sphere: a closed curve, the *polhode*, that goes round the axis of largest moment when
``L² > 2E I_mid`` and round the smallest when ``L² < 2E I_mid``; the *separatrix*
``L² = 2E I_mid`` through the intermediate axis divides the two families (Landau &
Lifshitz §37). Computed in closed form, for drawing over stability maps
(:mod:`jrigid.stability`, :mod:`jrigid.viz.stability`):

- :func:`omega_at_energy` — the point of the energy ellipsoid along a direction;
- :func:`encircled_axis` — the axis the polhode through ``ω`` goes round;
- :func:`polhode`, :func:`polhode_family` — one polhode, or a family with the separatrix.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from jrigid import inertia
from jrigid._checks import as_floats, check_shape, fail_if, is_traced

__all__ = ["encircled_axis", "omega_at_energy", "polhode", "polhode_family", "separatrix_offset"]


def _moments(moments: ArrayLike, *, single: bool = False) -> jax.Array:
    """``moments`` checked: ``(..., 3)`` (``(3,)`` if ``single``), finite and positive."""
    moments = inertia.checked_moments(as_floats(moments)[0], allow_nonphysical=True)
    if single and moments.ndim != 1:
        raise ValueError("moments must have shape (3,) (one body; vmap for a batch); got "
                         f"shape {moments.shape}")
    return moments


def _omega(omega: ArrayLike, name: str, *, single: bool = False) -> jax.Array:
    omega = check_shape(omega, f"{name} (body angular velocity)", (3,))
    if single and omega.ndim != 1:
        raise ValueError(f"{name} must have shape (3,) (one polhode; vmap for a batch); "
                         f"got shape {omega.shape}")
    return omega


def omega_at_energy(direction: ArrayLike, moments: ArrayLike, energy: ArrayLike) -> jax.Array:
    """Angular velocity along ``direction`` with kinetic energy ``energy``: ``2E = ω·Iω``.

    Args:
        direction: ``(..., 3)`` non-zero body-frame direction (need not be unit).
        moments: ``(..., 3)`` principal moments.
        energy: ``(...)`` kinetic energy ``E > 0``.

    Returns:
        ``(..., 3)`` ``ω = d √(2E / (d·I d))``.
    """
    i = _moments(moments)
    d, i, e = as_floats(check_shape(direction, "direction", (3,)), i, energy)
    d = fail_if(d, jnp.all(d == 0, axis=-1), "direction must not be zero")
    e = fail_if(e, ~(e >= 0) | ~jnp.isfinite(e), "energy must be finite and >= 0",
                lambda: f"energy {e}")
    return d * jnp.sqrt(2.0 * e / jnp.sum(i * d * d, axis=-1))[..., None]


def _invariants(moments, omega):
    """``(2E, L²)`` of body angular velocity ``omega``."""
    i, w = jnp.asarray(moments), jnp.asarray(omega)
    return jnp.sum(i * w * w, axis=-1), jnp.sum((i * w) ** 2, axis=-1)


def encircled_axis(moments: ArrayLike, omega: ArrayLike) -> jax.Array:
    """Index of the principal axis the polhode through ``omega`` goes round (closed form).

    The axis of largest moment when ``L² > 2E I_mid``, the smallest when ``L² < 2E I_mid``
    (Landau & Lifshitz §37). ``L² − 2E I_mid = Σ_k I_k (I_k − I_mid) ω_k²``; on the
    separatrix (``= 0``) the largest is returned.

    Args:
        moments: ``(..., 3)`` principal moments, any order, positive.
        omega: ``(..., 3)`` body angular velocity, finite.

    Returns:
        ``(...)`` int32 (the broadcast batch shape); ``-1`` where ``omega`` is not finite
        (under ``jit``/``vmap``; concrete input raises).

    Raises:
        ValueError: concrete ``omega`` with a NaN or infinite entry.
    """
    delta, order = _offset(moments, omega)
    finite = jnp.isfinite(delta)
    if not is_traced(finite) and not bool(jnp.all(finite)):
        raise ValueError(f"encircled_axis: omega must be finite, got {omega}")
    axis = jnp.where(delta >= 0, order[..., 2], order[..., 0])
    return jnp.where(finite, axis, -1).astype(jnp.int32)


def separatrix_offset(moments: ArrayLike, omega: ArrayLike) -> jax.Array:
    """``L² − 2E I_mid = Σ_k I_k (I_k − I_mid) ω_k²`` (closed form, free of cancellation).

    Positive where the polhode through ``omega`` goes round the axis of largest moment,
    negative round the smallest, zero on the separatrix and for every steady spin whose
    axis is not isolated (about the intermediate axis; any spin of a sphere; a symmetric
    body spun in its equatorial plane).

    Args:
        moments: ``(..., 3)`` principal moments, any order, positive.
        omega: ``(..., 3)`` body angular velocity.

    Returns:
        ``(...)`` (the broadcast batch shape).
    """
    return _offset(moments, omega)[0]


def _offset(moments, omega):
    """``(L² − 2E I_mid, argsort of the moments)``."""
    i, w = as_floats(_moments(moments), _omega(omega, "omega"))
    i, w = jnp.broadcast_arrays(i, w)
    order = jnp.argsort(i, axis=-1)
    i_mid = jnp.take_along_axis(i, order[..., 1:2], axis=-1)
    return jnp.sum(i * (i - i_mid) * w * w, axis=-1), order


def polhode(moments: ArrayLike, omega0: ArrayLike, n: int = 200) -> jax.Array:
    """The polhode through ``omega0``: ``n`` points of ``{ω·Iω = 2E, |Iω|² = L²}``.

    With ``c`` the encircled axis (:func:`encircled_axis`) and ``a, b`` the other two,
    eliminating ``ω_c`` from the two quadrics leaves the ellipse
    ``I_a(I_c−I_a) ω_a² + I_b(I_c−I_b) ω_b² = 2E I_c − L²``, parametrised
    ``ω_a = A cos φ``, ``ω_b = B sin φ``; then ``ω_c = σ √((2E − I_a ω_a² − I_b ω_b²)/I_c)``
    with ``σ = sign ω0_c``. Closed curve, ``φ ∈ [0, 2π]`` (first point = last). A steady
    rotation (``ω0`` along a principal axis, or any ``ω0`` of a spherical body, or of a
    symmetric one in its equatorial plane) has the single point ``ω0`` as its polhode,
    repeated ``n`` times.

    Args:
        moments: ``(3,)`` principal moments (positive; ``vmap`` for a batch).
        omega0: ``(3,)`` a point of the polhode (body angular velocity).
        n: static number of points (``>= 2``).

    Returns:
        ``(n, 3)`` body angular velocities on both surfaces.
    """
    if not isinstance(n, int) or isinstance(n, bool) or n < 2:
        raise ValueError(f"n must be an int >= 2, got {n!r}")
    i = _moments(moments, single=True)
    i, w = as_floats(i, _omega(omega0, "omega0", single=True))
    return _polhode(i, w, n)


@functools.partial(jax.jit, static_argnames=("n",))
def _polhode(i: jax.Array, w: jax.Array, n: int) -> jax.Array:
    two_e, l2 = _invariants(i, w)
    c = encircled_axis(i, w)
    a, b = (c + 1) % 3, (c + 2) % 3
    ia, ib, ic = i[a], i[b], i[c]
    rhs = two_e * ic - l2
    # I_a = I_c or I_b = I_c only for a steady rotation (a sphere; a symmetric body spun
    # in the plane of its two equal moments, which are then the largest and encircled)
    den_a, den_b = ia * (ic - ia), ib * (ic - ib)
    steady = (den_a == 0) | (den_b == 0)
    amp_a = jnp.sqrt(jnp.maximum(rhs / jnp.where(steady, 1.0, den_a), 0.0))
    amp_b = jnp.sqrt(jnp.maximum(rhs / jnp.where(steady, 1.0, den_b), 0.0))
    phi = jnp.linspace(0.0, 2.0 * math.pi, n, dtype=w.dtype)
    wa, wb = amp_a * jnp.cos(phi), amp_b * jnp.sin(phi)
    sigma = jnp.where(w[c] >= 0, 1.0, -1.0)
    wc = sigma * jnp.sqrt(jnp.maximum((two_e - ia * wa * wa - ib * wb * wb) / ic, 0.0))
    cols = jnp.stack([wa, wb, wc], axis=-1)  # columns for axes a, b, c
    perm = jnp.stack([a, b, c])
    inv = jnp.argsort(perm)
    return jnp.where(steady, w, cols[:, inv])


def polhode_family(moments: ArrayLike, levels: int = 7, n: int = 200) -> jax.Array:
    """Polhodes at unit energy for drawing, with the separatrix.

    Every polhode crosses the plane of the smallest and largest axes, so the seeds lie
    there: ``levels`` angles between the smallest axis and the separatrix's crossing
    (``tan α = √(I1(I2−I1)/(I3(I3−I2)))`` from the smallest axis), ``levels`` between it
    and the largest axis, and the crossing itself; each seed and its negative.

    Args:
        moments: ``(3,)`` principal moments (any order, positive, not all equal).
        levels: static number of polhodes per side of the separatrix.
        n: static number of points per curve.

    Returns:
        ``(4 levels + 2, n, 3)`` body angular velocities (``2E = 1``); curves
        ``2 levels`` and ``4 levels + 1`` are the separatrix (two arcs each, meeting at
        ``±`` the intermediate axis).
    """
    if not isinstance(levels, int) or isinstance(levels, bool) or levels < 1:
        raise ValueError(f"levels must be an int >= 1, got {levels!r}")
    if not isinstance(n, int) or isinstance(n, bool) or n < 2:
        raise ValueError(f"n must be an int >= 2, got {n!r}")
    i = _moments(moments, single=True)
    i = fail_if(i, (i[0] == i[1]) & (i[1] == i[2]),
                "moments must not all be equal: a spherical body has no polhodes (every "
                "rotation is steady)")
    return _family(i, levels, n)


@functools.partial(jax.jit, static_argnames=("levels", "n"))
def _family(i: jax.Array, levels: int, n: int) -> jax.Array:
    order = jnp.argsort(i)
    lo, hi = order[0], order[2]
    i1, i2, i3 = i[lo], i[order[1]], i[hi]
    sep = jnp.arctan(jnp.sqrt(i1 * (i2 - i1) / (i3 * (i3 - i2))))  # angle from the lo axis
    frac = (jnp.arange(levels, dtype=i.dtype) + 0.5) / levels
    angles = jnp.concatenate([sep * frac, sep + (0.5 * math.pi - sep) * frac, sep[None]])
    e_lo = jax.nn.one_hot(lo, 3, dtype=i.dtype)
    e_hi = jax.nn.one_hot(hi, 3, dtype=i.dtype)
    seeds = jnp.cos(angles)[:, None] * e_lo[None, :] + jnp.sin(angles)[:, None] * e_hi[None, :]
    seeds = jnp.concatenate([seeds, -seeds])
    seeds = omega_at_energy(
        seeds, jnp.broadcast_to(i, seeds.shape), jnp.full(seeds.shape[:1], 0.5, i.dtype)
    )
    return jax.vmap(lambda w: _polhode(i, w, n))(seeds)
