"""Closed-form results for the heavy symmetric top: steady precession (17.51) and the
nutation of a fast top (see :mod:`jrigid.theory`).
"""

from __future__ import annotations

import jax.numpy as jnp
from jax.typing import ArrayLike

from jrigid._checks import as_floats

__all__ = ["fast_top_nutation", "gyroscope_rates"]


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
        dict of ``(...)`` arrays: ``slow``, ``fast`` (the exact roots, the slow one the
        nearer to zero, both of the sign of ``ω3`` for an upright top; NaN where the top
        spins too slowly to precess steadily) and ``slow_approx``, ``fast_approx``.

    Example:
        >>> from jrigid import theory
        >>> r = theory.gyroscope_rates(1.0, 0.5, 1.0, 1.0, 20.0)
        >>> print(f"{float(r['slow']):.4f} {float(r['slow_approx']):.4f}")
        0.1005 0.1000
    """
    i1, i3, mgl, theta, omega3 = as_floats(i1, i3, mgl, theta, omega3)
    a, b = i1 * jnp.cos(theta), i3 * omega3
    disc = jnp.sqrt(b * b - 4.0 * a * mgl)
    big = b + jnp.where(b < 0, -disc, disc)  # no cancellation, for either sense of spin
    return dict(
        slow=2.0 * mgl / big,
        fast=big / (2.0 * a),
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
        >>> from jrigid.theory import fast_top_nutation
        >>> nut = fast_top_nutation(i1=1.0, i3=0.5, mgl=1.0, theta=1.0, omega3=20.0)
        >>> round(float(nut["frequency"]), 1), round(float(nut["dip"]), 4)
        (10.0, 0.0168)
    """
    i1, i3, mgl, theta, omega3 = as_floats(i1, i3, mgl, theta, omega3)
    spin = i3 * omega3
    return dict(frequency=spin / i1, dip=2.0 * mgl * i1 * jnp.sin(theta) / spin**2)
