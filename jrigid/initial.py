"""Initial-condition helpers: build a :class:`~jrigid.state.State` from physical data.

- :func:`from_omega` — an orientation and a body- or space-frame angular velocity;
- :func:`from_euler_rates` — ZXZ Euler angles ``(φ, θ, ψ)`` and their rates (eq. 17.36),
  the natural description of a top;
- :func:`from_momentum_energy` — a space-frame angular momentum and a kinetic energy
  (picks a point of the polhode);
- :func:`tilted` — spin about a principal axis tilted by a small angle, for stability
  studies (Problem 17.3).

Every helper returns ``x, v`` only when given them (free-flight scenes need both).
Concrete bad input raises ``ValueError``; inside a JAX transformation the same
conditions are checked with ``equinox.error_if``.

Batches: :func:`from_omega`, :func:`from_euler_rates` and :func:`tilted` broadcast the
leading batch dimensions of all their array arguments (numpy rules) and return a state
whose ``q``, ``q̇`` (and ``x``, ``v``) all carry that one batch shape, ready for
:func:`jrigid.ensemble.simulate_many`; batch shapes that do not broadcast raise
``ValueError``. :func:`from_momentum_energy` takes one state only.
"""

from __future__ import annotations

import numbers

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from jrigid import quaternion as quat
from jrigid._checks import as_float, check_shape, fail_if
from jrigid.scene import Scene
from jrigid.state import State

__all__ = ["from_euler_rates", "from_momentum_energy", "from_omega", "tilted"]

# The helpers' arithmetic as compiled programs: run op by op, a process's first call
# compiled one small program per operation (from_euler_rates: about 1 s).
_derivative = jax.jit(quat.derivative)
_rotate_inverse = jax.jit(quat.rotate_inverse)
_normalize = jax.jit(quat.normalize)


def unit_quaternion(q: ArrayLike, name: str = "q") -> jax.Array:
    """Validate and normalise an orientation quaternion.

    Args:
        q: ``(..., 4)`` quaternion, any finite non-zero norm (``1e-300`` and ``1e300``
            included; subnormal numbers count as zero).
        name: name used in error messages.

    Returns:
        ``(..., 4)`` unit quaternion.

    Raises:
        ValueError: wrong shape, non-finite entries, or zero norm.
    """
    q = check_shape(as_float(q), name, (4,), why=", a quaternion (w, x, y, z)")
    nonfinite, zero = _quaternion_flags(q)
    q = fail_if(q, nonfinite, f"{name} has non-finite entries (NaN or inf)")
    q = fail_if(q, zero, f"{name} is the zero quaternion: it represents no rotation")
    return _normalize(q)


@jax.jit
def _quaternion_flags(q):
    return ~jnp.all(jnp.isfinite(q)), ~jnp.all(quat.norm(q) > 0)


@jax.jit
def _nonfinite(x):
    return ~jnp.all(jnp.isfinite(x))


def _vector(x: ArrayLike, name: str) -> jax.Array:
    x = check_shape(as_float(x), name, (3,))
    return fail_if(x, _nonfinite(x), f"{name} has non-finite entries (NaN or inf)")


def _translation(x, v):
    if (x is None) != (v is None):
        raise ValueError("give both x and v (free flight) or neither")
    if x is None:
        return None, None
    return _vector(x, "x"), _vector(v, "v")


def _broadcast(where: str, **arrays):
    """Broadcast the batch shapes (all but the last axis) of the named arrays.

    ``None`` entries are passed through. Raises ``ValueError`` naming each batch shape
    when they do not broadcast.
    """
    given = {k: a for k, a in arrays.items() if a is not None}
    try:
        batch = jnp.broadcast_shapes(*(a.shape[:-1] for a in given.values()))
    except ValueError:
        shapes = ", ".join(f"{k} {a.shape[:-1]}" for k, a in given.items())
        raise ValueError(f"{where}: batch shapes do not broadcast: {shapes}") from None
    return [
        None if a is None else jnp.broadcast_to(a, batch + a.shape[-1:]) for a in arrays.values()
    ]


def from_omega(
    q0: ArrayLike | None = None,
    omega: ArrayLike | None = None,
    *,
    frame: str = "body",
    x: ArrayLike | None = None,
    v: ArrayLike | None = None,
) -> State:
    """State from an orientation and an angular velocity, ``q̇ = ½ q ⊗ (0, ω)`` (17.44).

    Args:
        q0: ``(..., 4)`` orientation (principal body frame → space); normalised.
            Default identity.
        omega: ``(..., 3)`` angular velocity. Default zero (in the dtype of ``q0``).
        frame: ``"body"`` (default) or ``"space"``, the frame ``omega`` is given in.
        x, v: ``(..., 3)`` centre-of-mass position and velocity, for free flight only.

    Returns:
        :class:`~jrigid.state.State` whose fields share the broadcast batch shape of the
        arguments (see the module docstring).
    """
    if frame not in ("body", "space"):
        raise ValueError(f"frame must be 'body' or 'space', got {frame!r}")
    if omega is None:
        q0 = quat.identity() if q0 is None else unit_quaternion(q0, "q0")
        omega = jnp.zeros(3, q0.dtype)
    else:
        omega = _vector(omega, "omega")
        q0 = quat.identity(dtype=omega.dtype) if q0 is None else unit_quaternion(q0, "q0")
    x, v = _translation(x, v)
    q0, omega, x, v = _broadcast("from_omega", q0=q0, omega=omega, x=x, v=v)
    if frame == "space":
        omega = _rotate_inverse(q0, omega)
    return State(q0, _derivative(q0, omega), x, v)


def euler_rates_to_omega(angles: ArrayLike, rates: ArrayLike) -> jax.Array:
    """Body angular velocity from ZXZ Euler angles and their rates (eq. 17.36).

    ``ω = φ̇ (sθ sψ, sθ cψ, cθ) + θ̇ (cψ, −sψ, 0) + ψ̇ (0, 0, 1)`` for the rotation
    ``quaternion.from_euler("ZXZ", (φ, θ, ψ))``.

    Args:
        angles: ``(..., 3)`` ``(φ, θ, ψ)``.
        rates: ``(..., 3)`` ``(φ̇, θ̇, ψ̇)``.

    Returns:
        ``(..., 3)`` body angular velocity; the batch shapes of ``angles`` and ``rates``
        broadcast.
    """
    angles = check_shape(as_float(angles), "angles", (3,))
    rates = check_shape(as_float(rates), "rates", (3,))
    angles, rates = _broadcast("euler_rates_to_omega", angles=angles, rates=rates)
    _, th, ps = angles[..., 0], angles[..., 1], angles[..., 2]
    dph, dth, dps = rates[..., 0], rates[..., 1], rates[..., 2]
    st, ct, sp, cp = jnp.sin(th), jnp.cos(th), jnp.sin(ps), jnp.cos(ps)
    return jnp.stack(
        [dph * st * sp + dth * cp, dph * st * cp - dth * sp, dph * ct + dps], axis=-1
    )


def from_euler_rates(
    angles: ArrayLike,
    rates: ArrayLike,
    *,
    x: ArrayLike | None = None,
    v: ArrayLike | None = None,
) -> State:
    """State from ZXZ Euler angles (precession φ, nutation θ, spin ψ) and their rates.

    For a symmetric top with its axis along body 3 and gravity along ``−z``, ``θ`` is
    the tilt of the axis from the vertical, ``φ̇`` the precession rate and
    ``ω3 = ψ̇ + φ̇ cos θ`` the spin.

    Args:
        angles: ``(..., 3)`` ``(φ, θ, ψ)`` in radians (scipy ``"ZXZ"``).
        rates: ``(..., 3)`` ``(φ̇, θ̇, ψ̇)``.
        x, v: ``(..., 3)`` centre-of-mass position and velocity, for free flight only.

    Returns:
        :class:`~jrigid.state.State` (batch shapes broadcast).
    """
    angles, rates = _vector(angles, "angles"), _vector(rates, "rates")
    angles, rates = _broadcast("from_euler_rates", angles=angles, rates=rates)
    q0, omega = _euler_pose(angles, rates)
    return from_omega(q0, omega, x=x, v=v)


@jax.jit
def _euler_pose(angles, rates):
    """``(q, ω)`` of ZXZ Euler angles and their rates, as one compiled program."""
    return quat.from_euler("ZXZ", angles), euler_rates_to_omega(angles, rates)


def _shortest_arc(a: jax.Array, b: jax.Array) -> jax.Array:
    """Unit quaternion rotating unit vector ``a`` onto unit vector ``b`` (minimal angle).

    ``q ∝ (1 + a·b, a × b)``, written with the half vector ``h = a + b`` as
    ``(h·h / 2, a × h)``: near antiparallel vectors ``a + b`` is computed exactly (its
    components cancel), so ``q a q* = b`` to rounding at every angle, where ``1 + a·b``
    lost ``eps / |a + b|`` (and, to first order, ``h·h / 2`` is ``1 + a·b`` also for a
    ``b`` whose norm is one only to rounding).
    """
    h = a + b
    n2 = jnp.dot(h, h)
    anti = n2 <= jnp.finfo(a.dtype).eps ** 2  # antiparallel to rounding: any normal axis
    trial = jnp.where(jnp.abs(a[0]) < 0.9, jnp.array([1.0, 0.0, 0.0]), jnp.array([0.0, 1.0, 0.0]))
    normal = jnp.cross(a, trial.astype(a.dtype))
    q = jnp.where(
        anti,
        jnp.concatenate([jnp.zeros(1, a.dtype), normal]),
        jnp.concatenate([0.5 * n2[None], jnp.cross(a, h)]),
    )
    return q / jnp.linalg.norm(q)


def from_momentum_energy(
    scene: Scene,
    momentum: ArrayLike,
    energy: ArrayLike,
    *,
    x: ArrayLike | None = None,
    v: ArrayLike | None = None,
) -> State:
    """State with a given space-frame angular momentum and rotational kinetic energy.

    For a torque-free body ``L`` and ``T = ½ ω·Iω`` fix the polhode; this helper picks
    its point where the body-frame ``L`` has no component along the axis of
    intermediate moment, solving ``L_a² + L_c² = |L|²``, ``L_a²/I_a + L_c²/I_c = 2T``
    for the smallest and largest moments (``L_a, L_c ≥ 0``), and orients the body so
    that ``q ⊗ L_body ⊗ q* = momentum`` (shortest arc).

    Args:
        scene: the scene (its inertia about the rotation centre is used; principal).
        momentum: ``(3,)`` angular momentum in the space frame, non-zero.
        energy: ``()`` rotational kinetic energy, with
            ``|L|²/(2 I_max) ≤ T ≤ |L|²/(2 I_min)``.
        x, v: ``(3,)`` centre-of-mass position and velocity, for free flight only.

    Returns:
        :class:`~jrigid.state.State`.

    Raises:
        ValueError: energy outside the admissible range, zero momentum, or a pivoted
            scene whose centre of mass is off the principal axes (non-diagonal inertia).
    """
    momentum = _vector(momentum, "momentum")
    energy = as_float(energy)
    if momentum.shape != (3,) or energy.shape != ():
        raise ValueError(
            "from_momentum_energy builds one state: momentum must have shape (3,) and "
            f"energy shape (); got {momentum.shape} and {energy.shape} (use jax.vmap "
            "for a batch)"
        )
    tensor = scene.inertia()
    moments = jnp.diagonal(tensor)
    off = jnp.max(jnp.abs(tensor - jnp.diag(moments)))
    l2 = jnp.dot(momentum, momentum)
    order = jnp.argsort(moments)
    i_lo, i_hi = moments[order[0]], moments[order[2]]
    two_t = 2.0 * energy
    lo, hi = l2 / i_hi, l2 / i_lo
    slack = 1e-12 * hi
    two_t = fail_if(
        two_t,
        off > 1e-12 * jnp.max(moments),
        "from_momentum_energy: inertia about the rotation centre is not diagonal",
    )
    two_t = fail_if(two_t, l2 <= 0, "from_momentum_energy: momentum must be non-zero")
    two_t = fail_if(
        two_t,
        (two_t < lo - slack) | (two_t > hi + slack),
        "from_momentum_energy: energy is outside [|L|²/(2 I_max), |L|²/(2 I_min)] "
        "for this momentum",
    )
    # Solve the 2x2 linear system for (L_lo², L_hi²); degenerate when I_lo == I_hi.
    denom = 1.0 / i_lo - 1.0 / i_hi
    safe = jnp.where(denom > 0, denom, 1.0)
    a2 = jnp.where(denom > 0, (two_t - l2 / i_hi) / safe, l2)
    a2 = jnp.clip(a2, 0.0, l2)
    c2 = l2 - a2
    body_l = jnp.zeros(3, dtype=momentum.dtype)
    body_l = body_l.at[order[0]].set(jnp.sqrt(a2)).at[order[2]].set(jnp.sqrt(c2))
    norm = jnp.sqrt(l2)
    q0 = _shortest_arc(body_l / norm, momentum / norm)
    return from_omega(q0, body_l / moments, x=x, v=v)


def _is_axis(i) -> bool:
    return isinstance(i, numbers.Integral) and not isinstance(i, bool) and i in (0, 1, 2)


def tilted(
    axis: int,
    angle: ArrayLike,
    rate: ArrayLike,
    *,
    toward: int | None = None,
    q0: ArrayLike | None = None,
    x: ArrayLike | None = None,
    v: ArrayLike | None = None,
) -> State:
    """Spin of magnitude ``rate`` about principal ``axis`` tilted by ``angle`` toward another.

    ``ω_body = rate (cos(angle) e_axis + sin(angle) e_toward)``: the classic perturbed
    spin of a stability study (stable about the axes of largest and smallest moment,
    unstable about the intermediate one, Problem 17.3).

    Args:
        axis: static principal axis index ``0, 1, 2`` (body axes 1, 2, 3).
        angle: ``(...)`` tilt in radians.
        rate: ``(...)`` angular speed ``|ω|``.
        toward: static axis the tilt leans toward; default ``(axis + 1) % 3``.
        q0: ``(..., 4)`` orientation; default identity.
        x, v: ``(..., 3)`` centre-of-mass position and velocity, for free flight only.

    Returns:
        :class:`~jrigid.state.State` (batch shapes broadcast).
    """
    if not _is_axis(axis):
        raise ValueError(f"axis must be the integer 0, 1 or 2, got {axis!r}")
    toward = (axis + 1) % 3 if toward is None else toward
    if not _is_axis(toward) or toward == axis:
        raise ValueError(f"toward must be an axis index other than {axis}, got {toward!r}")
    axis, toward = int(axis), int(toward)
    angle, rate = as_float(angle), as_float(rate)
    dtype = jnp.result_type(angle, rate)
    try:
        batch = jnp.broadcast_shapes(angle.shape, rate.shape)
    except ValueError:
        raise ValueError(
            f"tilted: batch shapes do not broadcast: angle {angle.shape}, rate {rate.shape}"
        ) from None
    angle, rate = jnp.broadcast_to(angle, batch), jnp.broadcast_to(rate, batch)
    omega = jnp.zeros(batch + (3,), dtype=dtype)
    omega = omega.at[..., axis].set(rate * jnp.cos(angle))
    omega = omega.at[..., toward].set(rate * jnp.sin(angle))
    return from_omega(q0, omega, x=x, v=v)
