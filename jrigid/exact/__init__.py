"""The torque-free rigid body in closed form: ω(t) and q(t) at any time, without stepping.

Solves Euler's equations with no torque (eqs. 17.34-17.35, ``N = 0``) together with the
quaternion kinematics ``q̇ = ½ q ⊗ (0, ω)`` (eq. 17.44). ``prepare`` computes a pytree of
per-body constants once; ``evaluate`` then costs the same at every time (one Jacobi
triple and one Carlson ``R_J``), however far out. ``solve`` does both.

Method
------
*Canonical frame.* The body axes are permuted (with one sign flip when the permutation
is odd, so the frame stays right-handed) so that axis 3 is the axis the polhode
encircles (largest moment if ``L² > 2E I_mid``, smallest otherwise), axis 2 the middle
one. In that frame (Landau & Lifshitz §37), with ``Δj = L² - 2E Ij``,

    ω1 = ρ A1 cn τ,  ω2 = s ρ σ A2 sn τ,  ω3 = σ A3 dn τ,   τ = λ t + τ0,
    λ² = (I3 - I2) Δ1 / (I1 I2 I3),  m = (I2 - I1)(-Δ3) / ((I3 - I2) Δ1),
    1 - m = (I3 - I1) Δ2 / ((I3 - I2) Δ1),

with ``σ = sign ω3``, ``ρ = sign ω1(0)``, ``s = sign(I3 - I1)``. Every ``Δj`` and amplitude
is formed from ω directly, ``Δj = Σ_k I_k (I_k - I_j) ω_k²``, so that only ``Δ2`` (the
distance to the separatrix) subtracts numbers of like size; it is evaluated with
error-free transformations (double-double arithmetic), exactly rounded, because its
relative error becomes that of ``1 - m`` and of the period. ``1 - m`` is computed from
``Δ2`` and never as ``1 - m``.

*Angular velocity from the initial one.* The addition theorem of ``sn, cn, dn``
(DLMF 22.8.1-3) with ``u = λ t`` writes the solution through ``ω(0) = (w1, w2, w3)``
itself, without ``τ0``::

    ω1 = (w1 cn u - e1 w2 w3 S dn u) / D,   e1 = (I3 - I2)/I1,   S = sn(u)/λ,
    ω2 = (w2 cn u dn u + e2 w1 w3 S) / D,   e2 = (I3 - I1)/I2,
    ω3 = (w3 dn u - e3 w1 w2 S cn u) / D,   e3 = (I2 - I1)/I3,
    D = 1 - m sn²τ0 sn²u = cn²u + dn²τ0 sn²u,

(the first form of ``D`` when ``m sn²τ0 ≤ ½``, the second, free of cancellation,
otherwise), with ``m sn²τ0 = (I2 - I1) I2 w2²/Δ1`` and ``dn²τ0 = I3 (I3 - I1) w3²/Δ1``.
Unlike the amplitude-phase form, this is a smooth function of the moments and of ``ω(0)``
at a spin about a principal axis (where the phase ``τ0`` is undefined) and near one.
``sn τ, cn τ, dn τ`` for the orientation below are ``ω_k(t)`` divided by the amplitudes;
only the index ``j = round(τ / 2K)`` of the half period uses ``τ0``.

*Orientation.* ``q(t) = W ⊗ Z(ψ(t)) ⊗ B(t)*`` where ``B(t)`` is the shortest rotation
taking the fixed body axis ``a = σ e3`` to ``l(t) = L_body(t)/|L|`` (never antipodal,
since ``a·l = I3 |ω3| / |L| ≥ 0``), ``Z(ψ)`` the rotation by ``ψ`` about ``a`` and
``W = q0 ⊗ B(0)`` fixed. Differentiating gives ``ψ̇ = (2E/|L| + a·ω) / (1 + a·l)``
``= β + (α - β)/(1 + c dn τ)`` with ``α = 2E/|L|``, ``β = |L|/I3``, ``c = I3 A3/|L|``.
Its integral takes one of two forms, both ``rate·t + (coef/λ)(P(τ) - P(τ0))`` with
``P(τ) = s³ R_J(x², y², 1, p²) + 2j P_complete`` after ``j`` half periods:

- away from the separatrix, the descending Landen (Gauss) transformation (DLMF
  22.7.1-3), ``1 + dn(z|k) = 2/(1 + k₁ sn²(z/(1+k₁)|k₁²))`` with ``k₁ = (1 - k')/(1 + k')``,
  turns ``1/(1 + c dn)`` into a rational function of ``sn²`` without cancellation::

      ψ(t) = ψ̇₀ t + κ (Q(τ) - Q(τ0)) / λ,
      ψ̇₀ = (2E + |L| A3) / (|L| + I3 A3),   κ = -2 Δ3 A3 k₁ / (|L| + I3 A3)²,
      Q(τ) = (1 + k₁) ∫_0^{φ₁} sin²θ dθ / ((1 - n' sin²θ) √(1 - k₁² sin²θ)),
      n' = -k₁ I1² A1² / (|L| + I3 A3)²  (≤ 0),

  where ``φ₁`` is the (unwrapped) amplitude of the transformed argument and the integral
  is ``sin³φ₁ R_J(cos²φ₁, Δ₁², 1, 1 - n' sin²φ₁)/3`` plus ``2j`` complete integrals;
- near the separatrix (``k' < (1 - c²)/8``), where the Landen modulus ``k₁`` is not a
  smooth function of ``m``, the third-kind integral in ``m`` itself:
  ``1/(1 + c dn) = (1 - c dn)/(a + b sn²)`` with ``a = 1 - c² = -I1 Δ3/((I3 - I1) L²)``,
  ``b = c² m``, ``n = -b/a``, so that, by ``Π(n; φ|m) = F + (n/3) sin³φ R_J(..)`` and
  ``F(am τ) = τ``,

      ψ(t) = (β + (α-β)/a) t + (α-β) n/(3 a λ) (P(τ) - P(τ0))
             - (α-β) c/(λ √(a(a+b))) (Θ(τ) - Θ(τ0)),
      P(τ) = sin³φ R_J(cos²φ, dn²τ, 1, 1 - n sin²φ),   Θ = jπ + atan2(k sin φ, cos φ),
      k = √((a + b)/a),   φ = am τ reduced to [-π/2, π/2].

  The two terms cancel to a factor ``1/a`` (``a ≥ I1 (I3 - I2)/(2 I2 (I3 - I1))`` near the
  separatrix), so this form is used only for ``a ≥ 10⁻⁴``.

This avoids the sign pitfalls of published formulae (Celledoni, Fassò, Säfström & Zanna
2008; van Zon & Schofield 2007): it is derived here from ``q̇ = ½ q ⊗ (0, ω)`` and checked
against high-precision integration of that equation in ``tests/test_exact.py``.

*Slow motion and short times.* Near a spherical body, or a symmetric one spun in its
degenerate plane, ``λ → 0`` and ``m`` depends on the direction from which the degenerate
body is approached, so the amplitude-phase constants are not smooth functions of the
moments there although the motion is. For ``λ |t| ≤ 1/32`` (every ``t`` when ``λ = 0``)
``ω`` and ``ψ`` are instead Taylor polynomials in ``t`` of degree 10 and 11, whose
coefficients follow from Euler's equations by the Cauchy-product recursion
``ω⁽ⁿ⁺¹⁾/(n+1)! = I⁻¹ Σ_k (I ω⁽ᵏ⁾/k!) × ω⁽ⁿ⁻ᵏ⁾/(n-k)!``, and from ``ψ̇ = f(ω3)`` by series
division (in the variable ``32 λ t``, so that no coefficient under- or overflows).
``ω(t)`` is analytic for ``|λ t| < K(1-m)``, and ``K(1-m) ≥ π/2``, so the truncation
error is of order ``(2/(32π))¹¹ ≈ 2e-19`` (both branches agree to rounding where they
meet; tested). When ``λ = 0`` exactly the motion is steady and the first-order change of
it under any perturbation is a polynomial of degree 2 in ``t`` (3 for ``ψ``), which those
terms carry exactly; the higher ones, zero with their derivatives, are left out there so
that large ``t`` cannot overflow them.

*Spins about a body axis.* If two components of ``ω0`` are exactly zero the spin is
steady for any moments; the frame is then chosen with axis 3 along the spin, ``m = 0``,
and the addition theorem above becomes ``cn u → cos(√μ t)``, ``S → sin(√μ t)/√μ``
(``cosh``/``sinh`` for ``μ < 0``, the middle axis; ``cos``/``sin`` from the same
Jacobi call with ``m = 0``), ``dn u = D = 1``, with ``μ = (I3 - I2)(I3 - I1) w3²/(I1 I2)``:
exact, and exact to first order in any perturbation. The derivatives of a spin about the
middle axis grow like ``e^{√-μ t}``; ``√-μ t`` is capped at ``0.45 ln(max float)`` (320
in float64, 40 in float32), beyond which they stay at about ``1e139`` (``1e17``) instead
of overflowing (on the separatrix itself they overflow near ``λ t = 700``).
``ψ = ψ̇(ω0) t``, which with ``a``
along the spin is also exact to first order. At rest, ``q = q0 ⊗ (1, ω0 t/2)``,
``ω = ω0``.

The inputs are rescaled by powers of two (exactly: moments by the largest, ω by its
largest component) so that nothing under- or overflows.

Derivatives: everything is ``jnp`` plus the differentiable kernels of
:mod:`jrigid.special`, so ``jax.grad``/``jax.jacfwd``/``jax.jacrev`` work with respect to
the moments, ``q0``, ``ω0`` and ``t``. The branches are joined with the double-``where``
pattern (an untaken branch runs on safe inputs), so no NaN or infinity reaches a
derivative. They are right also at the degenerate motions: spherical bodies, ties of
the moments (symmetric bodies), spins about any principal axis, the separatrix, and
nearby (tested against forward-mode diffrax and finite differences of high-precision
solutions). Known loss of accuracy: near a spin about the *middle* axis, at a relative
distance ``ε`` from it, the derivatives of ``q`` lose about ``log10(1/ε)`` digits (a
relative error of order ``1e-16/ε``; the values are unaffected).

Bad input: a non-finite or non-positive-definite inertia, a non-finite or zero ``q0`` and
a non-finite ``ω0`` raise ``ValueError`` for concrete input (the checks of
:func:`jrigid.inertia.validate` and :func:`jrigid.quaternion.check_quaternion`) and
``equinox.error_if`` runtime errors under ``jit``; wrong shapes raise ``ValueError``.
``q0`` is normalized. The triangle inequality of physical moments is not required (the
closed form holds for any positive moments) unless asked for with
``allow_nonphysical=False``.
"""

from __future__ import annotations

from jrigid.exact import _constants, _evaluate  # noqa: I001
from jrigid.exact._constants import *  # noqa: F403
from jrigid.exact._evaluate import *  # noqa: F403

# The package's names: each listed once, in the ``__all__`` of the module defining it.
__all__: list[str] = []
__all__ += _constants.__all__
__all__ += _evaluate.__all__
