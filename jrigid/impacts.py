"""The mechanics of one impact: contact points, the collision matrix, the impulse.

Pure functions of one body's state (``jit``/``vmap``/``grad``-able), used by
:func:`jrigid.contact.simulate_bounces` at every contact. Their arguments' shapes are
checked (one body: use ``jax.vmap`` for a batch), and so are their values when they are
concrete (a positive mass and moments, ``e`` in ``[0, 1]``, ``μ ≥ 0``, a non-zero
normal): ``ValueError``. Traced values are not checked (no cost inside a solver's loop).

**Impulse model** (space frame; ``r`` from the centre of mass to the contact point,
``n = e_z`` the floor normal, ``u = v + ω_s × r`` the velocity of the contact point).
An impulse ``P`` at ``r`` changes ``v`` by ``P/M`` and ``ω_s`` by ``I_s⁻¹ (r × P)``, hence
``Δu = K P`` with the collision matrix ``K = 1/M − [r]× I_s⁻¹ [r]×`` (``I_s = R I Rᵀ``).
Newton's restitution asks ``u_n⁺ = −e u_n⁻``. With Coulomb friction coefficient ``μ``
the impulse is first sought with sticking, ``u_t⁺ = 0``: ``P = K⁻¹(−(1+e) u_n n − u_t)``;
if it lies in the friction cone ``|P_t| ≤ μ P_n`` it is taken. Otherwise the contact
slides: ``P = P_n (n + μ t̂)`` along the tangential direction ``t̂`` of the sticking impulse
(the direction friction pushes to stop the slip), with ``P_n = −(1+e) u_n / (n·K(n + μ t̂))``
from the restitution condition. (In 3D the slip direction may turn during a real impact;
taking it once, from the sticking impulse, is the usual algebraic simplification, and in a
few per cent of sliding impacts the slip comes out reversed.) With friction, Newton's
restitution can return energy (Kane's paradox): with ``e = 1``, in 20–45 % of random
impacts of a box, by up to half its kinetic energy. Where the impulse would raise the
kinetic energy it is moved towards the frictionless one, ``P0 + α (P − P0)``, just far
enough that it does not (the normal velocity after the impact and the friction cone
are kept): an impact never creates energy (tested over random impacts).
Frictionless (``μ = 0``): ``P = m_eff (1+e) |u_n| n`` with
``m_eff = 1/(n·K n)``, and the kinetic energy drops by ``(1 − e²) ½ m_eff u_n²`` (zero
for ``e = 1``). Every impulse at a point conserves the angular momentum about that
point and changes the linear momentum by ``P``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from jrigid import linalg
from jrigid import quaternion as quat
from jrigid._checks import as_float, is_traced

__all__ = [
    "apply_impulse",
    "box_corners",
    "collision_matrix",
    "contact_impulse",
    "effective_mass",
    "point_positions",
    "point_velocities",
]


# --------------------------------------------------------------------------- geometry


def box_corners(size: ArrayLike, planar: bool = False) -> jax.Array:
    """Corners of a box centred on its centre of mass, body frame.

    Args:
        size: ``(3,)`` full side lengths ``(a, b, c)`` along body ``x, y, z``.
        planar: static; if true return the 4 corners of the ``a × c`` rectangle in the
            plane ``y = 0`` (midpoints of the edges along ``y``), the contact points of a
            box moving in the ``xz`` plane and turning about ``y``.

    Returns:
        ``(8, 3)`` (or ``(4, 3)`` if ``planar``) points ``(±a/2, ±b/2, ±c/2)``.
    """
    half = 0.5 * as_float(size)
    signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
    if planar:
        signs = np.array([[i, 0, k] for i in (-1, 1) for k in (-1, 1)], float)
    return jnp.asarray(signs, dtype=half.dtype) * half[None, :]


def point_positions(q: ArrayLike, x: ArrayLike, points: ArrayLike) -> jax.Array:
    """Space positions ``x + R(q) p`` of body-frame points.

    Args:
        q: ``(4,)`` unit orientation (body → space).
        x: ``(3,)`` centre of mass.
        points: ``(K, 3)`` body-frame points relative to the centre of mass.

    Returns:
        ``(K, 3)``.
    """
    return jnp.asarray(x)[None, :] + quat.rotate(jnp.asarray(q)[None, :], points)


def point_velocities(q: ArrayLike, omega: ArrayLike, v: ArrayLike, points: ArrayLike) -> jax.Array:
    """Space velocities ``v + ω_s × (R p)`` of body-frame points.

    Args:
        q: ``(4,)`` unit orientation.
        omega: ``(3,)`` body angular velocity.
        v: ``(3,)`` centre-of-mass velocity.
        points: ``(K, 3)`` body-frame points.

    Returns:
        ``(K, 3)``.
    """
    q = jnp.asarray(q)
    r = quat.rotate(q[None, :], points)
    w = quat.rotate(q, omega)
    return jnp.asarray(v)[None, :] + jnp.cross(jnp.broadcast_to(w, r.shape), r)


# --------------------------------------------------------------------------- impulses


def _skew(r: jax.Array) -> jax.Array:
    z = jnp.zeros((), r.dtype)
    return jnp.array([[z, -r[2], r[1]], [r[2], z, -r[0]], [-r[1], r[0], z]])


def _inverse_inertia_space(moments: jax.Array, q: jax.Array) -> jax.Array:
    R = quat.to_matrix(q)
    return (R / moments[None, :]) @ R.T


def _checked(**args) -> dict:
    """``args`` as float arrays of their exact shapes (``mass``, ``restitution``,
    ``friction``: ``()``; ``moments``, vectors: ``(3,)``; ``q``: ``(4,)``), their values
    checked where concrete. ``ValueError`` naming the first that fails."""
    shapes = {"mass": (), "restitution": (), "friction": (), "q": (4,)}
    out = {}
    for name, x in args.items():
        x = as_float(x)
        shape = shapes.get(name, (3,))
        if x.shape != shape:
            raise ValueError(f"impacts: {name} must have shape {shape} (one body; "
                             f"jax.vmap for a batch), got {x.shape}")
        out[name] = x
    values = {k: np.asarray(v) for k, v in out.items() if not is_traced(v)}
    rules = {
        "mass": (lambda m: np.isfinite(m) & (m > 0), "finite and > 0"),
        "moments": (lambda m: np.all(np.isfinite(m) & (m > 0)), "finite and > 0"),
        "restitution": (lambda e: (e >= 0) & (e <= 1), "in [0, 1]"),
        "friction": (lambda f: np.isfinite(f) & (f >= 0), "finite and >= 0"),
        "normal": (lambda n: np.all(np.isfinite(n)) & np.any(n != 0), "finite and non-zero"),
    }
    for name, (ok, what) in rules.items():
        if name in values and not bool(ok(values[name])):
            raise ValueError(f"impacts: {name} must be {what}, got {values[name]}")
    return out


def collision_matrix(mass, moments, q, r) -> jax.Array:
    """``K = 1/M − [r]× I_s⁻¹ [r]×``: contact-point velocity change per unit impulse.

    Args:
        mass: ``()`` mass ``M``.
        moments: ``(3,)`` principal moments about the centre of mass.
        q: ``(4,)`` unit orientation (principal body frame → space).
        r: ``(3,)`` contact point relative to the centre of mass, space frame.

    Returns:
        ``(3, 3)`` symmetric positive definite ``K`` with ``Δu = K P``.
    """
    a = _checked(mass=mass, moments=moments, q=q, r=r)
    S = _skew(a["r"])
    eye = jnp.eye(3, dtype=S.dtype)
    return eye / a["mass"] - S @ _inverse_inertia_space(a["moments"], a["q"]) @ S


def effective_mass(mass, moments, q, r, normal) -> jax.Array:
    """``m_eff = 1 / (n·K n)``, the mass the floor feels at the contact point.

    ``1/m_eff = 1/M + (r × n)·I_s⁻¹ (r × n)``: ``M`` for a contact below the centre of
    mass, ``M/4`` for a thin rod (``I = M ℓ²/12``) touching with one end while level.

    Args:
        mass, moments, q, r: as :func:`collision_matrix`.
        normal: ``(3,)`` unit normal.

    Returns:
        ``()``.
    """
    n = _checked(normal=normal)["normal"]
    return 1.0 / jnp.dot(n, collision_matrix(mass, moments, q, r) @ n)


def contact_impulse(mass, moments, q, v, omega, r, normal, restitution, friction) -> jax.Array:
    """Impulse at a contact point: Newton restitution plus Coulomb friction with sticking.

    See the module docstring for the model. Zero if the point is separating (``u_n ≥ 0``).

    Args:
        mass: ``()`` mass.
        moments: ``(3,)`` principal moments about the centre of mass.
        q: ``(4,)`` unit orientation.
        v: ``(3,)`` centre-of-mass velocity (space).
        omega: ``(3,)`` body angular velocity.
        r: ``(3,)`` contact point relative to the centre of mass, space frame.
        normal: ``(3,)`` unit normal, pointing out of the floor.
        restitution: ``()`` ``e`` in ``[0, 1]``.
        friction: ``()`` ``μ ≥ 0``.

    Returns:
        ``(3,)`` impulse on the body, space frame (batch with ``jax.vmap``).
    """
    a = _checked(q=q, v=v, omega=omega, r=r, normal=normal, restitution=restitution,
                 friction=friction)
    q, v, omega, r, n = (a[k] for k in ("q", "v", "omega", "r", "normal"))
    restitution, friction = a["restitution"], a["friction"]
    K = collision_matrix(mass, moments, q, r)
    u = v + jnp.cross(quat.rotate(q, omega), r)
    un = jnp.dot(u, n)
    ut = u - un * n
    stick = linalg.solve3(K, -(1.0 + restitution) * un * n - ut)
    pn = jnp.dot(stick, n)
    pt = stick - pn * n
    pt2 = jnp.dot(pt, pt)
    nonzero = pt2 > 0
    t_hat = pt / jnp.sqrt(jnp.where(nonzero, pt2, 1.0))  # double where: finite gradients
    d = n + friction * t_hat
    slide = (-(1.0 + restitution) * un / jnp.dot(n, K @ d)) * d
    inside = jnp.sqrt(jnp.where(nonzero, pt2, 0.0)) <= friction * pn
    P = _no_energy_gain(jnp.where(inside, stick, slide), K, u, un, n, restitution)
    return jnp.where(un < 0, P, jnp.zeros_like(P))


def _no_energy_gain(P, K, u, un, n, restitution):
    """``P``, or where it would raise the kinetic energy (Newton's restitution with friction
    can: Kane's paradox) the point ``P0 + α (P − P0)`` nearest to it that does not, with
    ``P0 = (1 + e) m_eff |u_n| n`` the frictionless impulse.

    An impulse ``P`` at a point moving at ``u`` changes the kinetic energy by
    ``ΔT(P) = P·u + ½ P·K P``; ``ΔT(P0) = −(1 − e²) ½ m_eff u_n² ≤ 0``. Both impulses leave
    the point at ``u_n⁺ = −e u_n`` and lie in the friction cone, so every ``α ∈ [0, 1]``
    does too; ``α`` is the root of the quadratic ``ΔT(α) = 0`` in ``[0, 1]``.
    """
    p0 = (-(1.0 + restitution) * un / jnp.dot(n, K @ n)) * n
    d, kp0 = P - p0, K @ p0
    a = 0.5 * jnp.dot(d, K @ d)
    b = jnp.dot(d, u + kp0)
    c = jnp.dot(p0, u + 0.5 * kp0)  # ΔT(P0) ≤ 0
    # ΔT(P) = a + b + c; where P is P0 (no friction: a = 0) there is nothing to move
    gains = (a + b + c > 0) & (a > 0)
    a, b = jnp.where(gains, a, 1.0), jnp.where(gains, b, 0.0)
    c = jnp.where(gains, jnp.minimum(c, 0.0), -1.0)
    s = jnp.sqrt(b * b - 4.0 * a * c)  # ≥ |b|
    alpha = jnp.where(b > 0, -2.0 * c / (b + s), (s - b) / (2.0 * a))
    return jnp.where(gains, p0 + jnp.clip(alpha, 0.0, 1.0) * d, P)


def apply_impulse(mass, moments, q, v, omega, r, impulse) -> tuple[jax.Array, jax.Array]:
    """Velocities after an impulse ``P`` at ``r``: ``v + P/M``, ``ω + I⁻¹ Rᵀ(r × P)``.

    Args:
        mass, moments, q, v, omega, r: as :func:`contact_impulse`.
        impulse: ``(3,)`` impulse, space frame.

    Returns:
        ``(v (3,), ω (3,) body frame)``.
    """
    a = _checked(mass=mass, moments=moments, q=q, v=v, omega=omega, r=r, impulse=impulse)
    q, v, omega, r, impulse = (a[k] for k in ("q", "v", "omega", "r", "impulse"))
    dL_body = quat.rotate_inverse(q, jnp.cross(r, impulse))
    return v + impulse / a["mass"], omega + dL_body / a["moments"]
