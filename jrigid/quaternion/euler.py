"""Euler angles for all 12 sequences, with scipy's meaning.

A sequence is three letters from ``x, y, z`` with no two consecutive letters equal:
upper case means intrinsic rotations (about the moving body axes), lower case
extrinsic (about the fixed space axes). ``"ZXZ"`` is the chapter's precession φ,
nutation θ, spin ψ (section 17.3.1, eq. 17.10). Angles are in radians.

:func:`to_euler` follows Bernardes & Viollet (2022), "Quaternion to Euler angles
conversion: a direct, general and computationally efficient method", as scipy does,
and returns the same angles as ``Rotation.as_euler``: the first and third angles in
``[-π, π)``, the second in ``[0, π]`` for proper Euler (symmetric) sequences and in
``[-π/2, π/2]`` for Tait-Bryan sequences.

Gimbal lock: when the second angle is within ``eps`` of a singular value (0 or π for
symmetric sequences, ±π/2 for Tait-Bryan ones) only the sum or difference of the first
and third angles is defined. Then, as in scipy, the **third angle is set to zero** and
the first angle carries the whole rotation. No warning is issued (the functions run
under ``jit``); use :func:`gimbal_lock` to detect the case. At gimbal lock the result
contains no NaN and its gradient is finite (though, at the singularity, not meaningful);
only the zero quaternion, which is no rotation, gives NaN angles.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from jrigid._checks import check_tolerance
from jrigid.linalg import rescale

from ._utils import quaternion_arg, vector_arg
from .core import multiply

__all__ = ["EULER_SEQUENCES", "from_euler", "gimbal_lock", "to_euler"]

_PROPER = ("XYX", "XZX", "YXY", "YZY", "ZXZ", "ZYZ")
_TAIT_BRYAN = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")
EULER_SEQUENCES: tuple[str, ...] = tuple(
    s for group in (_TAIT_BRYAN, _PROPER) for s in (*group, *(x.lower() for x in group))
)
"""All 24 accepted sequence strings (12 intrinsic upper case, 12 extrinsic lower case)."""


def _parse(seq: str) -> tuple[list[int], bool]:
    """Axis indices and ``extrinsic`` flag of a sequence; raises ValueError if invalid."""
    if not isinstance(seq, str) or seq not in EULER_SEQUENCES:
        valid = ", ".join(_TAIT_BRYAN + _PROPER)
        raise ValueError(
            f"invalid Euler sequence {seq!r}: expected one of {valid} (intrinsic) "
            "or the same in lower case (extrinsic)"
        )
    return ["xyz".index(c) for c in seq.lower()], seq.islower()


#: The largest gimbal-lock tolerance accepted: angles returned as locked represent the
#: rotation only to within about the tolerance (in radians).
MAX_EPS = 1e-2


def _eps(eps, dtype):
    """The gimbal-lock tolerance: the dtype's default for ``None``, else ``eps`` checked
    to be a number in ``[0, MAX_EPS]`` (``ValueError`` naming ``eps`` otherwise)."""
    if eps is None:
        return 1e-5 if jnp.finfo(dtype).bits <= 32 else 1e-7
    check_tolerance("eps (the gimbal-lock tolerance)", eps, MAX_EPS)
    return eps


def _elementary(axis: int, angle: jax.Array) -> jax.Array:
    half = 0.5 * angle
    zero = jnp.zeros_like(half)
    parts = [jnp.cos(half), zero, zero, zero]
    parts[1 + axis] = jnp.sin(half)
    return jnp.stack(parts, axis=-1)


def from_euler(seq: str, angles: ArrayLike) -> jax.Array:
    """Unit quaternion of Euler angles (scipy's ``Rotation.from_euler`` meaning).

    Intrinsic ``"ABC"``: ``q = q_A(α) ⊗ q_B(β) ⊗ q_C(γ)``; extrinsic ``"abc"``:
    ``q = q_c(γ) ⊗ q_b(β) ⊗ q_a(α)``. ``from_euler("ZXZ", (φ, θ, ψ))`` is the active
    form of the chapter's eq. 17.10.

    Args:
        seq: one of :data:`EULER_SEQUENCES` (static).
        angles: ``(..., 3)`` angles in radians, in sequence order.

    Returns:
        ``(..., 4)`` unit quaternion.

    Raises:
        ValueError: for an invalid sequence or if ``angles.shape[-1] != 3``.
    """
    axes, extrinsic = _parse(seq)
    angles = vector_arg(angles, "angles")
    q0, q1, q2 = (_elementary(ax, angles[..., n]) for n, ax in enumerate(axes))
    if extrinsic:
        return multiply(q2, multiply(q1, q0))
    return multiply(q0, multiply(q1, q2))


def _components(seq: str, q: jax.Array):
    """Bernardes-Viollet quantities ``(a, b, c, d)`` and the sequence's flags."""
    axes, extrinsic = _parse(seq)
    if not extrinsic:
        axes = axes[::-1]
    i, j, k = axes
    symmetric = i == k
    if symmetric:
        k = 3 - i - j
    sign = (i - j) * (j - k) * (k - i) // 2  # +1 for an even permutation, -1 for odd
    w, qi, qj, qk = q[..., 0], q[..., 1 + i], q[..., 1 + j], q[..., 1 + k]
    if symmetric:
        a, b, c, d = w, qi, qj, sign * qk
    else:
        a, b, c, d = w - qj, qi + sign * qk, qj + w, sign * qk - qi
    return a, b, c, d, extrinsic, symmetric, sign


def _safe_hypot(x: jax.Array, y: jax.Array) -> jax.Array:
    r2 = x * x + y * y
    positive = r2 > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, r2, jnp.ones_like(r2))), 0.0)


def _middle_and_cases(a, b, c, d, eps):
    middle = 2.0 * jnp.arctan2(_safe_hypot(c, d), _safe_hypot(a, b))
    case1 = jnp.abs(middle) <= eps  # second angle ~ 0: only the half sum is defined
    case2 = jnp.abs(middle - math.pi) <= eps  # second angle ~ π: only the half difference
    return middle, case1, case2


def gimbal_lock(seq: str, q: ArrayLike, eps: float | None = None) -> jax.Array:
    """Whether ``to_euler(seq, q)`` is at gimbal lock (second angle within ``eps`` of singular).

    Args:
        seq: one of :data:`EULER_SEQUENCES`.
        q: ``(..., 4)`` quaternion.
        eps: tolerance in radians on the second angle; default ``1e-7`` (float64,
            scipy's value) or ``1e-5`` (float32); at most ``1e-2`` (angles returned as
            locked stand for ``q`` only to within about ``eps``).

    Returns:
        ``(...)`` boolean array.
    """
    q, _ = rescale(quaternion_arg(q))
    eps = _eps(eps, q.dtype)
    a, b, c, d, *_ = _components(seq, q)
    _, case1, case2 = _middle_and_cases(a, b, c, d, eps)
    return (case1 | case2) & _rotation(q)


def _rotation(q: jax.Array) -> jax.Array:
    """``(...)``: whether the rescaled ``q`` stands for a rotation (finite and non-zero)."""
    return jnp.all(jnp.isfinite(q), axis=-1) & jnp.any(q != 0, axis=-1)


def to_euler(seq: str, q: ArrayLike, eps: float | None = None) -> jax.Array:
    """Euler angles of a rotation (scipy's ``Rotation.as_euler`` values).

    Bernardes & Viollet's direct method: ``q`` is permuted into ``(a, b, c, d)``, the
    second angle is ``2 atan2(|(c, d)|, |(a, b)|)`` (minus π/2 for Tait-Bryan
    sequences), and the others are ``atan2(b, a) ± atan2(d, c)``. At gimbal lock the
    third angle is set to zero (see the module docstring). ``q`` need not be unit (any
    finite non-zero scale); a zero or non-finite quaternion gives NaN angles. The first
    and third angles are wrapped as scipy wraps them, to ``[-π, π)``: an angle within
    rounding of ±π may come out as π in one library and −π in the other.

    Args:
        seq: one of :data:`EULER_SEQUENCES` (static).
        q: ``(..., 4)`` quaternion.
        eps: gimbal-lock tolerance on the second angle, as in :func:`gimbal_lock`.

    Returns:
        ``(..., 3)`` angles in radians, in sequence order.

    Raises:
        ValueError: for an invalid sequence or if ``q.shape[-1] != 4``.
    """
    q, _ = rescale(quaternion_arg(q))
    eps = _eps(eps, q.dtype)
    a, b, c, d, extrinsic, symmetric, sign = _components(seq, q)
    middle, case1, case2 = _middle_and_cases(a, b, c, d, eps)
    case0 = ~(case1 | case2)
    # Double where: the undefined half angle is evaluated at a harmless point.
    ones, zeros = jnp.ones_like(a), jnp.zeros_like(a)
    half_sum = jnp.arctan2(jnp.where(case2, zeros, b), jnp.where(case2, ones, a))
    half_diff = jnp.arctan2(jnp.where(case1, zeros, d), jnp.where(case1, ones, c))

    locked = jnp.where(case1, 2.0 * half_sum, 2.0 * half_diff * (-1.0 if extrinsic else 1.0))
    # Bernardes-Viollet is written for extrinsic sequences; an intrinsic one is the
    # reversed extrinsic sequence with the first and third angles swapped. At gimbal
    # lock the output's third angle is zero and its first carries the rotation.
    if extrinsic:
        first = jnp.where(case0, half_sum - half_diff, locked)
        third = jnp.where(case0, half_sum + half_diff, zeros)
        if not symmetric:
            third = sign * third
    else:
        first = jnp.where(case0, half_sum + half_diff, locked)
        third = jnp.where(case0, half_sum - half_diff, zeros)
        if not symmetric:
            first = sign * first
    if not symmetric:
        middle = middle - 0.5 * math.pi
    # Only the first and third angles wrap to [-π, π); the middle one already lies in
    # [0, π] (symmetric) or [-π/2, π/2] (Tait-Bryan), and wrapping it would turn π into -π.
    first, third = (jnp.remainder(a + math.pi, 2.0 * math.pi) - math.pi for a in (first, third))
    angles = jnp.stack([first, middle, third], axis=-1)
    # no rotation (a zero or non-finite quaternion): NaN, as in normalize
    return jnp.where(_rotation(q)[..., None], angles, jnp.nan)
