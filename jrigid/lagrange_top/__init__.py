"""The heavy symmetric (Lagrange) top in closed form: q(t) and ω(t) at any time, without stepping.

A body with central moments ``I1 = I2`` and its centre of mass on the symmetry axis
(``body.com = (0, 0, l)``), on a fixed frictionless pivot under uniform gravity ``g`` (the
chapter's Problem 17.2; :class:`~jrigid.scene.Pivot` with :class:`~jrigid.scene.Gravity`).
``prepare`` computes a pytree of per-top constants once; ``evaluate`` then costs the same
at every time (one Jacobi triple and two Carlson ``R_J``), however far out; ``solve`` does
both. ``applies``/``check_scene`` say whether a :class:`~jrigid.scene.Scene` is such a top.

Method
------
*Integrals.* With ``A = I1 + M l²`` (the transverse moment about the pivot), ``C = I3``,
the vertical ``ẑ = −sign(l) g/|g|`` (so that the potential is ``+M|g||l| u``) and
``u = cos θ = ẑ·(R e3)``, energy, ``L·ẑ = A b`` and ``L·e3 = C ω3 = A a`` give the
classical (Goldstein §5.7) ``u̇² = f(u) = (1−u²)(α−βu) − (b−au)²`` with ``β = 2M|g||l|/A``.
Its roots are ``u1 ≤ u(t) ≤ u2 ≤ 1 ≤ u3`` and

    u(t) = u1 + (u2 − u1) sn²(τ | m),  τ = ω_n t + τ0,
    m = (u2 − u1)/(u3 − u1),  ω_n = ½ √(β (u3 − u1)),   nutation period 2K(m)/ω_n.

Everything is formed from the body-frame vertical ``n = (n1, n2, u0)`` and ``ω`` without
cancellation: ``f(u0) = u̇0² = (n1 ω2 − n2 ω1)²``, ``b − a u0 = n1 ω1 + n2 ω2``,
``α − β u0 = ω1² + ω2²``, so that ``f(u0 + x) = β x³ + f2 x² + f1 x + f0``. ``c' = β (u3 − u0)``
is the largest root of ``c³ + f2 c² + β f1 c + β² f0`` (trigonometric formula polished by
Newton; the last step carries the derivative of the implicit function), which stays
well-defined as ``β → 0`` (no gravity, or the pivot at the centre of mass); then
``x1 x2 = −f0/c'`` (≤ 0) and ``x1 + x2 = (f1 + β f0/c')/c'`` give the other two roots
without cancellation. Near the separatrix of the sleeping top ``u2`` and ``u3`` are close
and the smallest root is found first instead. Distances to the poles, ``1 − u2`` and
``1 + u1``, come from ``(b ∓ a)² = β (1 ∓ u1)(1 ∓ u2)(u3 ∓ 1)``, so that they stay
consistent with ``b ∓ a`` however close the top comes to the vertical (or to hanging
straight down).

*Orientation without gimbal lock.* In a space frame whose ``z`` axis is ``ẑ`` (fixed
rotation ``Q_v``), with ZXZ angles ``φ, θ, ψ``, the quaternion is
``(C₊ cos(χ₊/2), S₋ cos(χ₋/2), S₋ sin(χ₋/2), C₊ sin(χ₊/2))`` with ``C₊ = cos(θ/2) =
√((1+u)/2)``, ``S₋ = sin(θ/2) = √((1−u)/2)`` and ``χ± = φ ± ψ``. The two phases have rates

    χ̇₊ = ω3 − a + (b + a)/(1 + u),   χ̇₋ = a − ω3 + (b − a)/(1 − u),

each singular only at the pole where its amplitude ``C₊`` or ``S₋`` vanishes, so ``θ = 0``
and ``θ = π`` are ordinary points. Their integrals are Legendre's third-kind integrals in
Carlson's form, ``∫ dτ/(1 − u) = (τ + n₋ G(τ))/(1 − u1)`` with ``n₋ = (u2 − u1)/(1 − u1)``
and ``G = sn³ R_J(cn², dn², 1, 1 − n sn²)/3`` unwrapped over half periods, and, after the
quarter-period shift ``τ' = τ − K`` (``sn τ = cd τ'``), ``∫ dτ/(1 + u) = (τ' + (N − m) G(τ'))
/(1 + u2)`` with ``N = ((1 + u1) m + u2 − u1)/(1 + u2)``; both characteristics lie in
``[m, 1]``. The weight of ``G`` is proportional to ``e = ±√(1 − n)`` (``e₋ ∝ b − a``,
``e₊ ∝ b + a``), so each phase is carried as ``W̃ · (e G)``: as the top passes ever closer to
the vertical, ``χ₋`` steps by ``±2π`` at each passage (the half-angle components change
sign; likewise ``χ₊`` near the bottom), and at exactly ``b = a`` that step is taken from the
closed-form limit ``e R_J(0, m1, 1, e²)/3 → ±π/(2√m1) − e E(m)/m1``. A start exactly at a
pole takes the phase of the departure direction (``ż₋ = ½ z₊ (ω1 + iω2)`` at ``θ = 0``).

*Angular velocity.* ``ω3`` is constant; ``ω1 + iω2 = e^{−iψ}(θ̇ + i φ̇ sin θ)`` is written as
``½ e^{i(χ₋−χ₊)/2}(C₊ R₋ − S₋ R̄₊)`` with ``R₋ = (−u̇ + i(b − a))/S₋`` and
``R₊ = (u̇ + i(b + a))/C₊``, both bounded and evaluated in the reduced elliptic variables.

*Long times.* ``τ`` is reduced modulo the period ``2K`` (index ``j``) and each phase is
``Ω t_r + W̃ (e G(r) − e G(τ0)) + j Δ`` with ``t_r`` the reduced time and ``Δ`` the phase
advance per nutation period (taken modulo ``4π``): the cost and the size of every argument
are independent of ``t``; the error grows like the rounding of the time itself,
``eps·t·|ω|``. Inputs are rescaled by a power of two (time unit ``1/ν``).

Degenerate motions: an exactly steady ``u`` (steady precession, the sleeping top, a top at
rest upright or hanging) goes through the same formulas (``u2 = u1``). A motion exactly on
the separatrix of the sleeping top (``u2 = u3 = 1`` to the last bit) is evaluated with
``m1`` replaced by the smallest normal number, i.e. as a very long but finite period.

Derivatives: everything is ``jnp`` plus the differentiable functions of
:mod:`jrigid.special`, so ``jax.grad``/``jax.jacfwd`` work with respect to the moments, the
mass, ``com``, ``g``, ``q0``, ``ω0`` and ``t`` (checked against finite differences and
forward-mode integration in ``tests/test_lagrange_top.py``). They are derivatives within
the family of symmetric tops: the transverse moment is ``(I1 + I2)/2``, so ``∂/∂I1`` and
``∂/∂I2`` are each half the derivative with respect to a common change of both (their sum
is exact); ``com_x, com_y`` do not enter (an off-axis centre of mass is not a Lagrange
top). At instants where the axis is exactly vertical or exactly hanging (always, for a
sleeping top) the derivatives are finite but miss the first-order tilt, whose size is not
a differentiable function of the state there. Without gravity (``g = 0``) the derivatives
with respect to ``g``, and with the pivot at the centre of mass (``l = 0``) those with
respect to ``com``, are NaN: the motion is smooth there, but the closed form's constants
(``β ∝ |g| |l|`` and the axis ``±g/|g|``) are not (the numerical solvers give them).
In forward mode, a call that differentiates with respect to ``g`` (or ``com``) there
together with other inputs (``jax.jacfwd(f, argnums=(0, 1))``) is NaN in every column,
because the NaN partial multiplies a zero change of ``g`` in the other columns: take the
other derivatives in a call of their own, or in reverse mode, where they stay finite.

Bad input: non-positive moments or mass, ``I1 ≠ I2``, an off-axis centre of mass, a zero
quaternion or non-finite ``com``, ``g``, ``q0`` or ``ω0`` raise ``ValueError`` for
concrete input and ``equinox.error_if`` under ``jit``.
"""

from __future__ import annotations

from jrigid.lagrange_top import _constants, _evaluate, _scenes  # noqa: I001
from jrigid.lagrange_top._constants import *  # noqa: F403
from jrigid.lagrange_top._evaluate import *  # noqa: F403
from jrigid.lagrange_top._scenes import *  # noqa: F403

# The package's names: each listed once, in the ``__all__`` of the module defining it.
__all__: list[str] = []
__all__ += _constants.__all__
__all__ += _evaluate.__all__
__all__ += _scenes.__all__
