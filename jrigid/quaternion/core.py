"""Quaternion algebra, rotation of vectors, axis-angle, rotation vectors and slerp.

Conventions (see the package docstring): quaternions are ``(..., 4)`` arrays, scalar
first ``(w, x, y, z)`` = the chapter's ``(q0, q1, q2, q3)``; a unit quaternion ``q``
maps body to space, ``v_space = q ⊗ (0, v_body) ⊗ q*`` (eq. 17.26); angular velocity
is body frame unless a name says ``space``. The kinematics
(``q̇ = ½ q ⊗ (0, ω_body)``, eq. 17.44) are in :mod:`jrigid.quaternion.kinematics`.

Every function broadcasts over leading batch dimensions (explicitly, so it also works
with ``jax_numpy_rank_promotion="raise"``), and has finite gradients at the identity
and at 180° rotations (Taylor branches plus the double-``where`` trick).

Every function checks the trailing shape of its arguments while tracing (free under
``jit``) and raises ``ValueError`` naming the expected shape, e.g. ``(..., 4)`` for a
quaternion. Functions that do not depend on the scale of ``q`` (``normalize``, ``norm``,
``inverse``, the conversions) rescale by the largest component before squaring, so they
are exact for any finite non-zero norm, ``1e-300`` and ``1e300`` included.
"""

from __future__ import annotations

import operator
from collections.abc import Sequence

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from jrigid.linalg import cross, dot, rescale, safe_norm

from ._utils import as_float_pair, broadcast_batch, epsilon, quaternion_arg, unit, vector_arg

__all__ = [
    "canonicalize",
    "conjugate",
    "distance",
    "from_axis_angle",
    "from_rotvec",
    "from_xyzw",
    "identity",
    "inverse",
    "multiply",
    "norm",
    "normalize",
    "rotate",
    "rotate_inverse",
    "slerp",
    "squared_distance",
    "to_axis_angle",
    "to_rotvec",
    "to_xyzw",
]


# ---------------------------------------------------------------------------
# Algebra (17.19-17.24)
# ---------------------------------------------------------------------------


def identity(batch_shape: Sequence[int] = (), dtype=None) -> jax.Array:
    """The identity rotation ``(1, 0, 0, 0)``.

    Args:
        batch_shape: leading shape of the result.
        dtype: floating dtype; ``None`` means JAX's default float (float64 when x64 is on).

    Returns:
        ``(*batch_shape, 4)`` array.

    Raises:
        ValueError: if ``batch_shape`` is not a sequence of non-negative integers, or
            ``dtype`` is not a floating dtype.
    """
    if dtype is not None and not jnp.issubdtype(dtype, jnp.floating):
        raise ValueError(f"dtype must be a floating dtype, got {jnp.dtype(dtype)}")
    try:
        shape = tuple(operator.index(n) for n in batch_shape)
    except TypeError:
        shape = (-1,)
    if any(n < 0 for n in shape):
        raise ValueError(f"batch_shape must be a sequence of integers >= 0, got {batch_shape!r}")
    shape = shape + (4,)
    return jnp.zeros(shape, dtype=dtype).at[..., 0].set(1)


def multiply(p: ArrayLike, q: ArrayLike) -> jax.Array:
    """Hamilton product ``p ⊗ q`` (eq. 17.24).

    ``(p0, p)(q0, q) = (p0 q0 - p·q, p0 q + q0 p + p × q)``. The composition
    ``multiply(p, q)`` rotates first by ``q``, then by ``p``.

    Args:
        p: ``(..., 4)`` quaternion.
        q: ``(..., 4)`` quaternion; batch dimensions broadcast with ``p``'s.

    Returns:
        ``(..., 4)`` product.
    """
    p, q = as_float_pair(quaternion_arg(p, "p"), quaternion_arg(q, "q"))
    p, q = broadcast_batch(p, 1, q, 1)
    # Component by component: fewer kernels inside an integrator's loop on a CPU.
    p0, p1, p2, p3 = (p[..., i] for i in range(4))
    q0, q1, q2, q3 = (q[..., i] for i in range(4))
    return jnp.stack(
        [
            p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3,
            p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
            p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1,
            p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0,
        ],
        axis=-1,
    )


def conjugate(q: ArrayLike) -> jax.Array:
    """Quaternion conjugate ``(q0, -q1, -q2, -q3)`` (eq. 17.21).

    Args:
        q: ``(..., 4)``.

    Returns:
        ``(..., 4)``.
    """
    q = quaternion_arg(q)
    return jnp.concatenate([q[..., :1], -q[..., 1:]], axis=-1)


def norm(q: ArrayLike) -> jax.Array:
    """Quaternion norm ``sqrt(q q*)``; the gradient at ``q = 0`` is defined as zero.

    Args:
        q: ``(..., 4)``.

    Returns:
        ``(...)`` norms (exact for any finite scale: no overflow at ``|q| = 1e300``;
        NaN if ``q`` has a NaN or infinite entry).
    """
    return safe_norm(quaternion_arg(q))


def normalize(q: ArrayLike) -> jax.Array:
    """Scale ``q`` to unit norm.

    Any finite non-zero norm works (``1e-300`` and ``1e300`` too): ``q`` is divided by
    its largest component first when its squares would underflow or overflow. A zero
    quaternion has no direction: the result is NaN (no error is raised, so that the
    function stays traceable); non-finite input gives NaN. Use :func:`check_quaternion`
    to reject such input with a clear error. Where ``|q|`` is moderate the result is
    bit for bit :func:`jrigid.linalg.unit`'s ``q * rsqrt(q·q)``, the lean form the
    integrators use on their (already nearly unit) states.

    Args:
        q: ``(..., 4)``.

    Returns:
        ``(..., 4)`` unit quaternion.
    """
    return unit(quaternion_arg(q))


def inverse(q: ArrayLike) -> jax.Array:
    """Multiplicative inverse ``q* / |q|²`` (equals the conjugate for unit ``q``).

    A zero quaternion gives NaN (see :func:`check_quaternion`). Safe for any finite
    scale of ``q`` (the result overflows only where ``1/|q|`` does).

    Args:
        q: ``(..., 4)``.

    Returns:
        ``(..., 4)``.
    """
    q, s = rescale(quaternion_arg(q))
    return conjugate(q) / (s * dot(q, q)[..., None])


def canonicalize(q: ArrayLike) -> jax.Array:
    """The representative of ``±q`` that scipy's ``Rotation`` calls canonical.

    ``w > 0``; at a 180° rotation (``w = 0``) the first non-zero of ``x, y, z`` is made
    positive, as in ``Rotation.as_quat(canonical=True)``. So ``canonicalize(q)`` and
    ``canonicalize(-q)`` are equal, bit for bit, for every non-zero ``q`` (``-0.0`` counts
    as zero; the zero quaternion, no rotation, keeps its signs).

    Args:
        q: ``(..., 4)``.

    Returns:
        ``(..., 4)``, ``q`` or ``-q``.
    """
    q = quaternion_arg(q)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    flip = (w < 0) | (
        (w == 0) & ((x < 0) | ((x == 0) & ((y < 0) | ((y == 0) & (z < 0)))))
    )
    return jnp.where(flip[..., None], -q, q)


# ---------------------------------------------------------------------------
# Rotating vectors (17.26)
# ---------------------------------------------------------------------------


def rotate(q: ArrayLike, v: ArrayLike) -> jax.Array:
    """Active rotation ``q ⊗ (0, v) ⊗ q*`` (eq. 17.26): body → space.

    Evaluated as ``(w² - |u|²) v + 2 (u·v) u + 2 w (u × v)`` with ``q = (w, u)``,
    which is (17.26) exactly; for a non-unit ``q`` the result is scaled by ``|q|²``.

    Args:
        q: ``(..., 4)`` unit quaternion.
        v: ``(..., 3)`` vector; batch dimensions broadcast with ``q``'s.

    Returns:
        ``(..., 3)`` rotated vector.

    Example:
        A quarter turn about ``z`` takes ``x`` to ``y``; composed with itself
        (:func:`multiply`) it is a half turn, taking ``x`` to ``−x``:

        >>> import jax.numpy as jnp
        >>> from jrigid import quaternion as quat
        >>> q = quat.from_axis_angle(jnp.array([0.0, 0.0, 1.0]), jnp.pi / 2)
        >>> x = jnp.array([1.0, 0.0, 0.0])
        >>> print(jnp.round(quat.rotate(q, x), 6) + 0.0)
        [0. 1. 0.]
        >>> print(jnp.round(quat.rotate(quat.multiply(q, q), x), 6) + 0.0)
        [-1.  0.  0.]
    """
    q, v = as_float_pair(quaternion_arg(q), vector_arg(v, "v"))
    q, v = broadcast_batch(q, 1, v, 1)
    w, u = q[..., :1], q[..., 1:]
    return (
        (w * w - dot(u, u)[..., None]) * v
        + 2.0 * dot(u, v)[..., None] * u
        + 2.0 * w * cross(u, v)
    )


def rotate_inverse(q: ArrayLike, v: ArrayLike) -> jax.Array:
    """Inverse rotation ``q* ⊗ (0, v) ⊗ q``: space → body.

    Args:
        q: ``(..., 4)`` unit quaternion.
        v: ``(..., 3)`` vector in the space frame.

    Returns:
        ``(..., 3)`` the same vector in body coordinates.
    """
    return rotate(conjugate(q), v)


# ---------------------------------------------------------------------------
# Axis-angle (17.25, 17.27) and rotation vectors (exp / log)
# ---------------------------------------------------------------------------


def from_axis_angle(axis: ArrayLike, angle: ArrayLike) -> jax.Array:
    """Quaternion ``(cos θ/2, u sin θ/2)`` of a rotation by ``angle`` about ``axis`` (eq. 17.25).

    Args:
        axis: ``(..., 3)`` rotation axis; it is normalised here (any finite non-zero
            length). A zero axis gives NaN in the vector part.
        angle: ``(...)`` angle in radians (right-hand rule); broadcasts with ``axis``.

    Returns:
        ``(..., 4)`` unit quaternion.
    """
    axis, angle = as_float_pair(vector_arg(axis, "axis"), angle)
    axis, angle = broadcast_batch(axis, 1, angle, 0)
    u = unit(axis)
    half = 0.5 * angle
    return jnp.concatenate([jnp.cos(half)[..., None], jnp.sin(half)[..., None] * u], axis=-1)


def to_axis_angle(q: ArrayLike) -> tuple[jax.Array, jax.Array]:
    """Axis and angle of a rotation (eq. 17.27, in a numerically stable form).

    The chapter's ``θ = 2 arccos q0`` loses accuracy near 0 and π and has an infinite
    derivative at ``q0 = ±1``; here ``θ = 2 atan2(|(q1, q2, q3)|, |q0|)``, which is accurate
    everywhere and returns ``θ ∈ [0, π]`` (``q`` is first replaced by ``-q`` if
    ``q0 < 0``). For the identity the axis is undefined; ``(1, 0, 0)`` is returned
    and the gradient there is finite (zero: the angle, like ``|v|``, has no derivative
    at the identity, so ``angle**2`` has a zero Hessian there; :func:`to_rotvec` and
    :func:`squared_distance` are smooth). ``q`` need not be unit (any finite non-zero scale);
    the zero quaternion gives NaN.
    At exactly 180° the axis follows :func:`canonicalize`, so ``q`` and ``-q`` agree.

    Args:
        q: ``(..., 4)``.

    Returns:
        ``(axis, angle)``: ``(..., 3)`` unit axis and ``(...)`` angle in ``[0, π]``.
    """
    q = canonicalize(rescale(quaternion_arg(q))[0])
    w, v = q[..., 0], q[..., 1:]
    v, scale = rescale(v)  # (a vector part below sqrt(tiny) still has its direction)
    n2 = dot(v, v)
    nonzero = n2 > 0
    n = jnp.sqrt(jnp.where(nonzero, n2, jnp.ones_like(n2)))
    default = jnp.zeros_like(v).at[..., 0].set(1)
    axis = jnp.where(nonzero[..., None], v / n[..., None], default)
    angle = 2.0 * jnp.arctan2(jnp.where(nonzero, n * scale[..., 0], jnp.zeros_like(n)), w)
    # The zero quaternion is no rotation and a non-finite one (all NaN after rescale)
    # has no direction: NaN, like normalize.
    bad = (~nonzero & (w == 0)) | jnp.isnan(w)
    return jnp.where(bad[..., None], jnp.nan, axis), jnp.where(bad, jnp.nan, angle)


def from_rotvec(rotvec: ArrayLike) -> jax.Array:
    """Exponential map: rotation vector ``θ u`` → unit quaternion.

    Uses a Taylor expansion for ``θ² < ε`` so values and gradients are exact and
    finite at the identity. The angle is computed without overflow for any finite
    rotation vector (beyond ``θ ≈ 2π/eps`` its value modulo 2π is lost to rounding; the
    result is still a unit quaternion).

    Args:
        rotvec: ``(..., 3)`` rotation vector (axis times angle in radians).

    Returns:
        ``(..., 4)`` unit quaternion.
    """
    r = vector_arg(rotvec, "rotvec")
    r_scaled, s = rescale(r)
    s = s[..., 0]
    n2_scaled = dot(r_scaled, r_scaled)
    theta2 = s * s * n2_scaled  # overflows to inf only where θ is huge: not small then
    small = theta2 < epsilon(r.dtype)
    length = jnp.sqrt(jnp.where(small, jnp.ones_like(n2_scaled), n2_scaled))  # θ / s
    theta = s * length
    theta4 = theta2 * theta2
    w = jnp.where(small, 1.0 - theta2 / 8.0 + theta4 / 384.0, jnp.cos(0.5 * theta))
    # sin(θ/2) along the unit axis r / θ = r_scaled / length (for a huge θ, sin(θ/2) / θ
    # would be below the smallest normal number, flushed to zero on a CPU)
    vector = jnp.where(small[..., None],
                       (0.5 - theta2 / 48.0 + theta4 / 3840.0)[..., None] * r,
                       (jnp.sin(0.5 * theta) / length)[..., None] * r_scaled)
    return jnp.concatenate([w[..., None], vector], axis=-1)


def to_rotvec(q: ArrayLike) -> jax.Array:
    """Logarithm map: unit quaternion → rotation vector ``θ u`` with ``θ ∈ [0, π]``.

    ``q`` and ``-q`` give the same result (the shorter rotation); at exactly 180° the
    direction follows :func:`canonicalize` (scipy's rule), so ``to_rotvec(q)`` and
    ``to_rotvec(-q)`` are equal there too and match ``Rotation.as_rotvec``. Uses a
    Taylor expansion near the identity so the gradient is finite there; finite at 180°
    too.

    Args:
        q: ``(..., 4)``; need not be unit (the result is scale-invariant, for any finite
            non-zero norm).

    Returns:
        ``(..., 3)`` rotation vector.
    """
    q = canonicalize(rescale(quaternion_arg(q))[0])
    w, v = q[..., 0], q[..., 1:]
    n2 = dot(v, v)
    small = n2 < epsilon(q.dtype) * w * w
    n = jnp.sqrt(jnp.where(small, jnp.ones_like(n2), n2))
    w_safe = jnp.where(small, w, jnp.ones_like(w))
    k = jnp.where(
        small,  # (2 / w)(1 − n² / 3w²): no w³, which underflows for |q| below 1e-103
        (2.0 / w_safe) * (1.0 - n2 / (3.0 * w_safe * w_safe)),
        2.0 * jnp.arctan2(n, w) / n,
    )
    return k[..., None] * v


def distance(p: ArrayLike, q: ArrayLike) -> jax.Array:
    """Angle in ``[0, π]`` of the rotation taking ``q`` to ``p`` (sign-invariant).

    Args:
        p: ``(..., 4)`` unit quaternion.
        q: ``(..., 4)`` unit quaternion; batch dimensions broadcast.

    Returns:
        ``(...)`` geodesic distance in radians (scale-invariant in ``p`` and ``q``).

    At ``p = ±q`` the distance, like ``|v|`` at ``v = 0``, has no derivative: its
    gradient there is taken as zero, and so the Hessian of ``distance(p, q)**2`` there
    is zero, not the true ``2 I`` (in the rotation vector). For a loss to be
    differentiated twice (Newton steps, curvature at a perfect fit) use
    :func:`squared_distance`.
    """
    return to_axis_angle(_relative(p, q))[1]


def squared_distance(p: ArrayLike, q: ArrayLike) -> jax.Array:
    """Squared angle ``distance(p, q)**2`` of the rotation taking ``q`` to ``p``, smooth
    at ``p = ±q``.

    Computed as ``|to_rotvec(q* ⊗ p)|²``, so that its derivatives of every order are
    those of the squared angle, also where the two rotations coincide (where
    ``distance(p, q)**2`` has a zero Hessian: :func:`distance`). Sign-invariant and
    scale-invariant in ``p`` and ``q``.

    Args:
        p: ``(..., 4)`` quaternion.
        q: ``(..., 4)`` quaternion; batch dimensions broadcast.

    Returns:
        ``(...)`` squared angle in radians², in ``[0, π²]``.
    """
    r = to_rotvec(_relative(p, q))
    return dot(r, r)


def _relative(p, q) -> jax.Array:
    """``q* ⊗ p`` of ``p`` and ``q`` rescaled (any finite non-zero norm), the rotation
    taking ``q`` to ``p`` in the body frame."""
    p, q = rescale(quaternion_arg(p, "p"))[0], rescale(quaternion_arg(q))[0]
    return multiply(conjugate(q), p)


def slerp(p: ArrayLike, q: ArrayLike, t: ArrayLike) -> jax.Array:
    """Spherical linear interpolation from ``p`` (``t=0``) to ``±q`` (``t=1``), shorter arc.

    Computed as ``p ⊗ exp(t log(p* ⊗ q))``, which takes the shorter arc because the
    log map returns angles in ``[0, π]``, and is exact and differentiable for
    ``p = ±q``.

    Args:
        p: ``(..., 4)`` quaternion (any finite non-zero norm: scaled to unit first).
        q: ``(..., 4)`` quaternion (likewise).
        t: ``(...)`` interpolation parameter; all batch dimensions broadcast.

    Returns:
        ``(..., 4)`` unit quaternion.
    """
    p, q = as_float_pair(quaternion_arg(p, "p"), quaternion_arg(q))
    p, q = unit(p), unit(q)  # (any finite non-zero norm: a unit result, ±q at t = 1)
    rel = to_rotvec(multiply(conjugate(p), q))
    rel, t = as_float_pair(rel, t)
    rel, t = broadcast_batch(rel, 1, t, 0)
    return multiply(p, from_rotvec(t[..., None] * rel))


# ---------------------------------------------------------------------------
# scipy interoperability
# ---------------------------------------------------------------------------


def from_xyzw(q_xyzw: ArrayLike) -> jax.Array:
    """Scalar-last ``(x, y, z, w)`` (scipy's default) → scalar-first ``(w, x, y, z)``.

    Args:
        q_xyzw: ``(..., 4)``.

    Returns:
        ``(..., 4)``.
    """
    q = quaternion_arg(q_xyzw, "q_xyzw", order="(x, y, z, w)")
    return jnp.concatenate([q[..., 3:], q[..., :3]], axis=-1)


def to_xyzw(q: ArrayLike) -> jax.Array:
    """Scalar-first ``(w, x, y, z)`` → scalar-last ``(x, y, z, w)`` (scipy's default).

    Args:
        q: ``(..., 4)``.

    Returns:
        ``(..., 4)``.
    """
    q = quaternion_arg(q)
    return jnp.concatenate([q[..., 1:], q[..., :1]], axis=-1)



# The kinematics live in jrigid.quaternion.kinematics (which builds on this module);
# their names stay importable from here, loaded on first use.
_KINEMATICS = frozenset(
    "angular_velocity angular_velocity_space derivative derivative_space w_matrix "
    "w_matrix_space".split()
)


def __getattr__(name: str):
    if name in _KINEMATICS:
        from . import kinematics

        return getattr(kinematics, name)
    raise AttributeError(f"module 'jrigid.quaternion.core' has no attribute {name!r}")
