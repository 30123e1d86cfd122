"""Restoring a motion's conserved quantities after each step (projection methods).

An explicit Runge–Kutta step conserves neither the energy nor the angular momentum of a
rigid body, and for rotation the damage compounds: an error in the invariants changes
the period of the motion, so the phase error grows with time, fastest near the
separatrix of the intermediate axis. The scene knows what its exact motion conserves
(:meth:`jrigid.scene.Scene.conserved`); :func:`project` moves a state back onto those
values with the smallest correction, as the standard projection method does (Hairer,
Lubich & Wanner, *Geometric Numerical Integration*, §IV.4, Algorithm 4.2): simplified
Newton iterations on ``g(y + Wᵀ J λ) = c`` with the Jacobian ``J`` of the invariants
taken once at the step's result.

The correction acts on the orientation through a small body-frame rotation ``δθ``
(``q ← q ⊗ (1, δθ/2)``, renormalised) and on the angular velocity through ``δω``; the
metric weighs ``|δθ|² + |δω|²/ν²`` with ``ν² = |ω|² + ν_g²`` (``ν_g² = M|g||r|/I_max``
for a body on a pivot), so that a relative change of ω costs as much as the same
rotation angle. For a torque-free body the invariants (energy, ``|L|²``) do not depend
on the orientation, and only ω moves.

Derivatives (forward and reverse mode) are those of the projected step, with one
exception: a top's momentum about its lever (``L·r̂``) is conserved only while the body
is symmetric about that line (two equal moments, the centre of mass on the third axis),
so derivatives with respect to what breaks that symmetry (one of the two moments, the
centre of mass off the axis) must let it change. Its value is restored, but not its
derivative (its residual enters the correction without one): restored in value and
derivative, such a derivative came out wrong (3.6× too large, or of the wrong sign, for
the centre of mass off the axis of a heavy symmetric top), whereas the other invariants
hold for every value of the parameters. Where the
invariants become dependent (a spin about a principal axis, a spherical body, a
symmetric one spinning about an equatorial axis) the normal equations are regularised
row by row (:data:`RIDGE`) so that rounding is not amplified: without that the
derivatives there were wrong by O(1). Near a sphere (moments a relative ``δ`` apart)
the derivative of the energy-like invariant is a difference of O(1) terms over a
gradient of size ``δ``, so derivatives carry an error of about ``eps / δ`` per step;
``project="manifold"`` does not have it.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from jrigid import linalg
from jrigid import quaternion as quat
from jrigid._folds import largest, total
from jrigid.scene import Scene, TopConstants
from jrigid.state import Kinematics

__all__ = ["Invariants", "project"]


class Invariants(eqx.Module):
    """The conserved quantities of one motion: the values to restore after each step.

    Attributes:
        values: ``(4,)`` the scene's conserved quantities at the initial state (see
            :meth:`jrigid.scene.Scene.conserved`).
        top: for a conservative top, what its invariants need of the scene
            (:meth:`jrigid.scene.Scene.top_constants`), computed once; ``None`` otherwise
            (or to have :func:`project` compute it from the scene).
    """

    values: jax.Array
    top: TopConstants | None = None

    @classmethod
    def of(cls, scene: Scene, q: jax.Array, omega: jax.Array) -> Invariants | None:
        """The invariants of ``scene`` at orientation ``q (4,)`` (unit) and body ``omega (3,)``.

        ``None`` when the scene conserves nothing that is restored (a user torque).
        """
        if scene.conservative_top:
            top = scene.top_constants()
            return cls(top.conserved(q, omega).values, top)
        conserved = scene.conserved(Kinematics(q, omega))
        if conserved is None:
            return None
        return cls(conserved.values)


def _rotate_body(q: jax.Array, dtheta: jax.Array) -> jax.Array:
    """``q ⊗ (1, δθ/2)``: turn ``q`` by the small body-frame rotation vector ``δθ``."""
    half = 0.5 * dtheta
    return quat.multiply(q, jnp.concatenate([jnp.ones(1, q.dtype), half]))


#: Relative ridge of the normal equations: in directions where the invariants are
#: dependent to within this (a sleeping top, whose energy and momenta are then functions
#: of the spin alone; a torque-free sphere, or a symmetric body spinning about an axis of
#: its equator, where ``|L|²`` and the energy are functions of one amplitude), the
#: correction is damped instead of amplifying rounding errors (by at most
#: ``eps / (2 √RIDGE)`` per step, about 5e-13 in float64); so are their derivatives,
#: which without it were wrong by O(1) there.
RIDGE = 1e-8


def _ridge(diagonal: list[jax.Array], relative) -> jax.Array:
    widest = diagonal[0]
    for d in diagonal[1:]:
        widest = jnp.maximum(widest, d)
    return relative * widest + jnp.finfo(widest.dtype).tiny


def _solve_spd3(a: list[list[jax.Array]], b: list[jax.Array]) -> jax.Array:
    """``a⁻¹ b`` for a symmetric positive definite ``3 × 3`` (Cholesky, written out).

    Backward stable, unlike the adjugate, when a ridge is all that keeps ``a`` regular.
    """
    l00 = jnp.sqrt(a[0][0])
    l10 = a[1][0] / l00
    l20 = a[2][0] / l00
    l11 = jnp.sqrt(a[1][1] - l10 * l10)
    l21 = (a[2][1] - l20 * l10) / l11
    l22 = jnp.sqrt(a[2][2] - l20 * l20 - l21 * l21)
    z0 = b[0] / l00
    z1 = (b[1] - l10 * z0) / l11
    z2 = (b[2] - l20 * z0 - l21 * z1) / l22
    x2 = z2 / l22
    x1 = (z1 - l21 * x2) / l11
    x0 = (z0 - l10 * x1 - l20 * x2) / l00
    return jnp.stack([x0, x1, x2])


def free_gradients(moments: jax.Array, omega: jax.Array, axis: jax.Array):
    """Gradients in ω of the torque-free invariants ``|L|²`` and ``Δ_k`` (``k = axis``).

    Args:
        moments: ``(3,)`` principal moments ``I``.
        omega: ``(3,)`` body angular velocity.
        axis: ``(3,)`` one-hot selector of ``k``.

    Returns:
        ``(∇|L|², ∇Δ_k)``, each ``(3,)``: ``2 I² ω`` and ``2 I (I_k − I) ω``.
    """
    i_k = linalg.dot(axis, moments)
    return 2.0 * moments * moments * omega, 2.0 * moments * (i_k - moments) * omega


def _project_free(scene: Scene, targets: jax.Array, omega: jax.Array) -> jax.Array:
    """ω restored onto ``|L|²`` and the nearest axis's ``Δ_k`` (one Newton step)."""
    here = scene.conserved(Kinematics(None, omega))
    axis = here.active[1:].astype(omega.dtype)
    moving = targets[0] > 0  # a body at rest has nothing to restore
    scale = jnp.where(moving, targets[0], 1.0)
    r1 = (here.values[0] - targets[0]) / scale
    r2 = linalg.dot(axis, here.values[1:] - targets[1:]) / scale
    a, b = free_gradients(scene.body.moments, omega, axis)
    a, b = a / scale, b / scale
    g11, g12, g22 = linalg.dot(a, a), linalg.dot(a, b), linalg.dot(b, b)
    # Each row's own ridge keeps dependent rows (a sphere, a symmetric body spinning
    # about an equatorial axis) from amplifying rounding; the floor drops a row whose
    # gradient is at rounding level (an exact spin about a principal axis, where Δ_k has
    # a double zero) but keeps the small, decisive one of a spin near the separatrix.
    floor = _ridge([g11, g22], jnp.finfo(omega.dtype).eps)
    g11, g22 = g11 * (1 + RIDGE) + floor, g22 * (1 + RIDGE) + floor
    det = g11 * g22 - g12 * g12
    det = jnp.where(moving, det, 1.0)
    lam1 = jnp.where(moving, (g22 * r1 - g12 * r2) / det, 0.0)
    lam2 = jnp.where(moving, (g11 * r2 - g12 * r1) / det, 0.0)
    return omega - (lam1 * a + lam2 * b)


def top_gradients(scene: Scene, q: jax.Array, omega: jax.Array,
                  top: TopConstants | None = None):
    """Gradients of a top's invariants (energy, ``L·ĝ``, ``L·r̂``) in ``(δθ, δω)``.

    ``δθ`` is a body-frame rotation of ``q`` (``q ⊗ (1, δθ/2)``), ``δω`` a change of ω.
    With ``g_b = Rᵀ g``, ``L = I_p ω``: ``∂E = (M g_b × r, L)``,
    ``∂(L·ĝ) = (L × ĝ_b, I_p ĝ_b)``, ``∂(L·r̂) = (0, I_p r̂)``.

    Args:
        scene: a conservative top (:attr:`~jrigid.scene.Scene.conservative_top`).
        q: ``(4,)`` unit orientation.
        omega: ``(3,)`` body angular velocity.
        top: ``scene.top_constants()``, if already at hand.

    Returns:
        ``[(∂θ (3,), ∂ω (3,)), ...]`` for the three slots.
    """
    top = scene.top_constants() if top is None else top
    d_theta, d_omega = _top_rows(top, quat.rotate_inverse(q, top.g_hat), omega)
    return [(d_theta[i], d_omega[i]) for i in range(3)]


def _top_rows(top: TopConstants, g_body: jax.Array, omega: jax.Array):
    """:func:`top_gradients` from the body-frame direction of gravity ``g_body (3,)``."""
    L = total(top.tensor * omega[None, :])
    d_theta = jnp.stack([linalg.cross(g_body, top.lever_weight), linalg.cross(L, g_body),
                         jnp.zeros_like(omega)])
    d_omega = jnp.stack([L, total(top.tensor * g_body[None, :]),
                         total(top.tensor * top.r_hat[None, :])])
    return d_theta, d_omega


def _project_top(top: TopConstants, targets: jax.Array, q: jax.Array, omega: jax.Array):
    """``(q, ω)`` restored onto a top's energy and momenta (one Newton step).

    Written with sums over whole vectors (written out, ``jrigid._folds``) and the
    ``3 × 3`` normal equations as arrays: the projection runs after every step, and in
    this form it compiles in a third of the time of the same algebra written entry by
    entry."""
    g_body = quat.rotate_inverse(q, top.g_hat)
    here = top.conserved_at(g_body, omega)
    weight = jnp.where(here.active, 1.0 / jnp.where(here.active, here.scales, 1.0),
                       0.0).astype(omega.dtype)[:3]
    residual = (here.values[:3] - targets[:3]) * weight
    # L·r̂ is conserved only while the body is symmetric about its lever: its value is
    # restored, its derivative is not (see the module docstring)
    residual = residual.at[2].set(jax.lax.stop_gradient(residual[2]))
    nu2 = jnp.maximum(linalg.norm2(omega) + top.pendulum2,
                      jnp.sqrt(jnp.finfo(omega.dtype).tiny))
    d_theta, d_omega = _top_rows(top, g_body, omega)
    d_theta, d_omega = d_theta * weight[:, None], d_omega * weight[:, None]
    gram = (total(d_theta[:, None, :] * d_theta[None, :, :])
            + nu2 * total(d_omega[:, None, :] * d_omega[None, :, :]))
    ridge = RIDGE * largest(jnp.diagonal(gram)) + jnp.finfo(omega.dtype).tiny
    ridge = jnp.where(here.active[:3], ridge, 1.0)
    lam = _solve_spd3([[gram[i, j] + (ridge[i] if i == j else 0.0) for j in range(3)]
                       for i in range(3)], [residual[0], residual[1], residual[2]])
    step_theta = -total(lam[:, None] * d_theta, axis=0)
    step_omega = -nu2 * total(lam[:, None] * d_omega, axis=0)
    return linalg.unit(_rotate_body(q, step_theta)), omega + step_omega


def project(
    scene: Scene, invariants: Invariants, q: jax.Array, omega: jax.Array
) -> tuple[jax.Array, jax.Array]:
    """Nearest ``(q, ω)`` on which the scene's invariants take ``invariants.values``.

    One simplified Newton step on the relative residuals (divided by the scene's
    scales) of the slots :meth:`~jrigid.scene.Scene.conserved` marks active at
    ``(q, ω)``, with the metric ``|δθ|² + |δω|²/ν²`` and a ridge of :data:`RIDGE` (times
    the largest diagonal entry of the normal equations for a top; each diagonal entry's
    own, plus ``eps`` times the largest, torque free). One step leaves a residual of the
    order of the square of the correction, which the next step's projection removes
    with the rest: the invariants never drift.

    Args:
        scene: the :class:`~jrigid.scene.Scene` (one, unbatched; torque free or a top).
        invariants: the target values (:meth:`Invariants.of` at the initial state).
        q: ``(4,)`` unit orientation.
        omega: ``(3,)`` body angular velocity.

    Returns:
        ``(q, ω)`` corrected; ``q`` unit.
    """
    if scene.torque_free:
        return q, _project_free(scene, invariants.values, omega)
    top = scene.top_constants() if invariants.top is None else invariants.top
    return _project_top(top, invariants.values, q, omega)


def restore(scene: Scene, invariants: Invariants | None, q, omega):
    """:func:`project` when there is something to restore, else ``(q, ω)`` unchanged."""
    if invariants is None:
        return q, omega
    return project(scene, invariants, q, omega)
