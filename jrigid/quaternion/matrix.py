"""Rotation matrices: quaternion ↔ active matrix, Rodrigues, and the chapter's passive forms.

Active matrices map body to space, ``v_space = R @ v_body``, and agree with
``scipy.spatial.transform.Rotation.from_quat(q, scalar_first=True).as_matrix()``.
The chapter's (17.8), (17.10) and (17.28) are passive (coordinate-change) matrices,
the transposes of the active ones; the functions reproducing them say ``passive``.
"""

from __future__ import annotations

import numbers

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from jrigid._checks import as_float, check_tolerance, is_traced
from jrigid.linalg import cross, dot, rescale

from ._utils import (
    as_float_all,
    as_float_pair,
    broadcast_batch,
    matrix_arg,
    quaternion_arg,
    unit,
    vector_arg,
)
from .validate import default_atol

__all__ = [
    "from_matrix",
    "passive_axis_matrix",
    "passive_matrix",
    "passive_zxz_matrix",
    "project_to_rotation",
    "rodrigues_matrix",
    "to_matrix",
]


def to_matrix(q: ArrayLike) -> jax.Array:
    """Active rotation matrix of a quaternion (the transpose of the chapter's eq. 17.28).

    ``q`` need not be unit: it is normalised implicitly (the factor ``2/|q|²``), as
    scipy does, for any finite non-zero scale (``q`` is divided by its largest
    component first where squaring it would overflow or underflow). A zero quaternion
    gives NaN (see :func:`check_quaternion`).

    Args:
        q: ``(..., 4)`` quaternion ``(w, x, y, z)``.

    Returns:
        ``(..., 3, 3)`` matrix ``R`` with ``R @ v = rotate(q, v)`` for unit ``q``.
    """
    q, _ = rescale(quaternion_arg(q))
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    s = 2.0 / (w * w + x * x + y * y + z * z)
    xx, yy, zz = s * x * x, s * y * y, s * z * z
    xy, xz, yz = s * x * y, s * x * z, s * y * z
    wx, wy, wz = s * w * x, s * w * y, s * w * z
    rows = [
        jnp.stack([1.0 - yy - zz, xy - wz, xz + wy], axis=-1),
        jnp.stack([xy + wz, 1.0 - xx - zz, yz - wx], axis=-1),
        jnp.stack([xz - wy, yz + wx, 1.0 - xx - yy], axis=-1),
    ]
    return jnp.stack(rows, axis=-2)


def _det3(m: jax.Array) -> jax.Array:
    """Determinant of ``(..., 3, 3)`` by cofactors (cheap, differentiable)."""
    a, b, c = m[..., 0, :], m[..., 1, :], m[..., 2, :]
    return dot(a, cross(b, c))


#: The largest orthogonality tolerance :func:`from_matrix` accepts: beyond it a matrix is
#: too far from a rotation for its normalised Shepperd estimate to mean anything.
MAX_ATOL = 0.1


def from_matrix(matrix: ArrayLike, *, atol: float | None = None) -> jax.Array:
    """Unit quaternion of an active rotation matrix (Shepperd's method).

    Of the four equivalent expressions (pivoting on ``w``, ``x``, ``y`` or ``z``)
    the one with the largest pivot ``max(tr R, R00, R11, R22)`` is used, so every
    proper rotation, 180° rotations included, is converted accurately; the other
    branches are kept finite so that gradients never contain NaN.

    Input that is not a rotation is refused, never turned silently into one:

    * orthogonal within ``atol`` (``max |RᵀR - 1| ≤ atol``) and ``det R > 0``: converted.
      A slightly non-orthogonal input (accumulated rounding) is first brought to the
      nearest rotation (the polar factor, :func:`project_to_rotation`'s) by three
      Newton–Schulz steps, ``R ← R (3 − RᵀR) / 2``, which converge quadratically: its
      quaternion is that of the nearest rotation to about ``(atol)⁸`` (scipy's
      ``Rotation.from_matrix`` to rounding at the default ``atol``), and its derivative
      along a direction off the rotations is zero;
    * further from orthogonal (e.g. a scaled or sheared matrix): not converted. Call
      :func:`project_to_rotation` first to use the nearest rotation instead;
    * a reflection (orthogonal with ``det R = -1``): not converted; no rotation
      corresponds to it.

    "Not converted" means: with concrete input, ``ValueError`` naming the problem;
    under a JAX transformation (``jit``, ``vmap``, ``grad``: traced input, where no
    Python error can depend on values) the result is NaN for those matrices. Non-finite
    input (NaN or inf anywhere) gives an all-NaN quaternion.

    Args:
        matrix: ``(..., 3, 3)`` rotation matrix.
        atol: orthogonality tolerance, in ``[0, 0.1]``; default
            :func:`~jrigid.quaternion.default_atol` of the dtype (``1e-6`` in float64).

    Returns:
        ``(..., 4)`` unit quaternion (sign not canonicalised: where two of Shepperd's
        pivots tie, a tiny change of ``matrix`` can flip it from ``q`` to ``−q``; a loss
        on quaternion components should use a sign-invariant distance such as
        :func:`~jrigid.quaternion.distance`).

    Raises:
        ValueError: wrong shape or an ``atol`` outside ``[0, 0.1]`` (always); with
            concrete input, a matrix that is not orthogonal within ``atol`` or that is a
            reflection.
    """
    m = matrix_arg(matrix)
    if atol is not None:
        check_tolerance("from_matrix: atol (the orthogonality tolerance)", atol, MAX_ATOL)
    tol = default_atol(m.dtype) if atol is None else atol
    gram = jnp.swapaxes(m, -1, -2) @ m
    eye = jnp.broadcast_to(jnp.eye(3, dtype=m.dtype), gram.shape)
    ortho_err = jnp.max(jnp.abs(gram - eye), axis=(-2, -1))
    finite = jnp.all(jnp.isfinite(m), axis=(-2, -1))  # (an inf entry makes ortho_err NaN)
    skewed = finite & (ortho_err > tol)
    reflection = finite & ~skewed & (_det3(m) < 0)
    if not is_traced(m):
        for bad, what in (
            (skewed, f"is not orthogonal (max |RᵀR - 1| > {tol:g}); use "
             "jrigid.quaternion.project_to_rotation for the nearest rotation"),
            (reflection, "is a reflection (det R = -1), not a rotation"),
        ):
            if bool(jnp.any(bad)):
                where = f" at batch index {tuple(int(i) for i in jnp.argwhere(bad)[0])}"
                raise ValueError(f"from_matrix: matrix{where if bad.ndim else ''} {what}")
    q = _shepperd(_polar_steps(m))
    return jnp.where((skewed | reflection | ~finite)[..., None], jnp.nan, q)


def _polar_steps(m: jax.Array, steps: int = 3) -> jax.Array:
    """``m (..., 3, 3)`` after ``steps`` Newton–Schulz iterations toward its polar factor
    (the nearest orthogonal matrix), ``m ← m (3 − mᵀm) / 2``: each squares the distance
    ``|mᵀm − 1|`` (up to a constant) while it is below 1; a rotation is a fixed point."""
    for _ in range(steps):
        m = m + 0.5 * (m - m @ (jnp.swapaxes(m, -1, -2) @ m))
    return m


def _shepperd(m: jax.Array) -> jax.Array:
    m00, m01, m02 = m[..., 0, 0], m[..., 0, 1], m[..., 0, 2]
    m10, m11, m12 = m[..., 1, 0], m[..., 1, 1], m[..., 1, 2]
    m20, m21, m22 = m[..., 2, 0], m[..., 2, 1], m[..., 2, 2]
    trace = m00 + m11 + m22
    # Each candidate equals 4 * (pivot component) * (w, x, y, z).
    cand_w = jnp.stack([1.0 + trace, m21 - m12, m02 - m20, m10 - m01], axis=-1)
    cand_x = jnp.stack([m21 - m12, 1.0 + 2.0 * m00 - trace, m01 + m10, m02 + m20], axis=-1)
    cand_y = jnp.stack([m02 - m20, m01 + m10, 1.0 + 2.0 * m11 - trace, m12 + m21], axis=-1)
    cand_z = jnp.stack([m10 - m01, m02 + m20, m12 + m21, 1.0 + 2.0 * m22 - trace], axis=-1)
    pivots = jnp.stack([trace, m00, m11, m22], axis=-1)
    choice = jnp.argmax(pivots, axis=-1)[..., None]
    cand = jnp.where(
        choice == 0,
        cand_w,
        jnp.where(choice == 1, cand_x, jnp.where(choice == 2, cand_y, cand_z)),
    )
    # The chosen pivot entry is >= 1 for a rotation, so this norm is never zero.
    return cand / jnp.sqrt(jnp.sum(cand * cand, axis=-1, keepdims=True))


@jax.custom_jvp
def _special_polar(m: jax.Array) -> jax.Array:
    u, _, vt = jnp.linalg.svd(m)
    d = _det_sign(u, vt)
    return (u * _flip(d)[..., None, :]) @ vt


def _det_sign(u: jax.Array, vt: jax.Array) -> jax.Array:
    d = jnp.sign(jnp.linalg.det(u @ vt))
    return jnp.where(d == 0, jnp.ones_like(d), d)


def _flip(d: jax.Array) -> jax.Array:
    """``(1, 1, d)`` along a new last axis."""
    return jnp.concatenate([jnp.ones(d.shape + (2,), dtype=d.dtype), d[..., None]], axis=-1)


@_special_polar.defjvp
def _special_polar_jvp(primals, tangents):
    # With M = U' S' Vᵀ (U' = U D, S' = D S, D = diag(1, 1, det UVᵀ)) and Q = U' Vᵀ:
    # dQ = U' X Vᵀ, X_ij = (A_ij - A_ji) / (s'_i + s'_j), A = U'ᵀ dM V.
    # JAX's SVD derivative divides by s_i² - s_j² and is NaN for repeated singular
    # values (e.g. at any exact rotation); this formula only needs s'_i + s'_j != 0.
    (m,), (dm,) = primals, tangents
    u, s, vt = jnp.linalg.svd(m)
    flip = _flip(_det_sign(u, vt))
    u = u * flip[..., None, :]
    s = s * flip
    q = u @ vt
    a = jnp.swapaxes(u, -1, -2) @ dm @ jnp.swapaxes(vt, -1, -2)
    denom = s[..., :, None] + s[..., None, :]
    ok = denom != 0
    x = jnp.where(ok, (a - jnp.swapaxes(a, -1, -2)) / jnp.where(ok, denom, 1.0), 0.0)
    return q, u @ x @ vt


def project_to_rotation(matrix: ArrayLike) -> jax.Array:
    """Nearest proper rotation in the Frobenius norm (special orthogonal Procrustes).

    With ``M = U S Vᵀ`` the result is ``U diag(1, 1, det(U Vᵀ)) Vᵀ``. The derivative
    is implemented analytically, so it is finite even where singular values repeat
    (e.g. when ``M`` is already a rotation); it is undefined only where the smallest
    two (sign-adjusted) singular values sum to zero.

    Args:
        matrix: ``(..., 3, 3)`` any real matrix.

    Returns:
        ``(..., 3, 3)`` rotation matrix; NaN for a matrix with a NaN or infinite entry
        (which is kept away from the SVD: LAPACK's SVD does not return on infinite input).
    """
    m = matrix_arg(matrix)
    finite = jnp.all(jnp.isfinite(m), axis=(-2, -1))[..., None, None]
    eye = jnp.broadcast_to(jnp.eye(3, dtype=m.dtype), m.shape)
    return jnp.where(finite, _special_polar(jnp.where(finite, m, eye)), jnp.nan)


def rodrigues_matrix(axis: ArrayLike, angle: ArrayLike) -> jax.Array:
    """Active rotation matrix about ``axis`` by ``angle`` (Rodrigues, eqs. 17.16-17.17).

    ``R v = (1 - c)(v·r) r + s (r × v) + c v`` with ``c = cos θ``, ``s = sin θ`` and
    ``r`` the unit axis; equal to ``to_matrix(from_axis_angle(axis, angle))``.

    Args:
        axis: ``(..., 3)`` rotation axis; normalised here (any finite non-zero length; a
            zero axis gives NaN entries).
        angle: ``(...)`` angle in radians; broadcasts with ``axis``.

    Returns:
        ``(..., 3, 3)`` active rotation matrix.
    """
    axis, angle = as_float_pair(vector_arg(axis, "axis"), angle)
    axis, angle = broadcast_batch(axis, 1, angle, 0)
    r = unit(axis)
    rx, ry, rz = r[..., 0], r[..., 1], r[..., 2]
    c, s = jnp.cos(angle), jnp.sin(angle)
    t = 1.0 - c
    rows = [
        jnp.stack([t * rx * rx + c, t * rx * ry - s * rz, t * rx * rz + s * ry], axis=-1),
        jnp.stack([t * rx * ry + s * rz, t * ry * ry + c, t * ry * rz - s * rx], axis=-1),
        jnp.stack([t * rx * rz - s * ry, t * ry * rz + s * rx, t * rz * rz + c], axis=-1),
    ]
    return jnp.stack(rows, axis=-2)


_AXIS_INDEX = {"x": 0, "y": 1, "z": 2, 0: 0, 1: 1, 2: 2}


def passive_axis_matrix(axis: int | str, angle: ArrayLike) -> jax.Array:
    """The chapter's coordinate-axis rotation matrix (eq. 17.8), passive.

    For the z axis this is ``[[c, s, 0], [-s, c, 0], [0, 0, 1]]``: it gives the
    coordinates of a fixed vector in axes rotated by ``angle`` about z. It is the
    transpose of the active ``rodrigues_matrix(e_axis, angle)``.

    Args:
        axis: ``0``/``1``/``2`` or ``"x"``/``"y"``/``"z"`` (case-insensitive); static.
        angle: ``(...)`` angle in radians.

    Returns:
        ``(..., 3, 3)`` passive rotation matrix.

    Raises:
        ValueError: if ``axis`` is not one of the above.
    """
    key = axis.lower() if isinstance(axis, str) else axis
    valid_type = isinstance(key, str) or (
        isinstance(key, numbers.Integral) and not isinstance(key, bool)
    )
    if not valid_type or key not in _AXIS_INDEX:
        raise ValueError(f"axis must be one of 0, 1, 2, 'x', 'y', 'z'; got {axis!r}")
    i = _AXIS_INDEX[key]
    j, k = (i + 1) % 3, (i + 2) % 3
    angle = as_float(angle, weak=True)
    c, s = jnp.cos(angle), jnp.sin(angle)
    one, zero = jnp.ones_like(c), jnp.zeros_like(c)
    m = [[None] * 3 for _ in range(3)]
    m[i][i], m[i][j], m[i][k] = one, zero, zero
    m[j][i], m[k][i] = zero, zero
    m[j][j], m[j][k] = c, s
    m[k][j], m[k][k] = -s, c
    return jnp.stack([jnp.stack(row, axis=-1) for row in m], axis=-2)


def passive_zxz_matrix(phi: ArrayLike, theta: ArrayLike, psi: ArrayLike) -> jax.Array:
    """The chapter's Euler-angle matrix ``R_z(ψ) R_x(θ) R_z(φ)`` (eq. 17.10), passive.

    ``φ`` precession, ``θ`` nutation, ``ψ`` spin, each factor the passive (17.8). The
    result is the transpose of the active matrix of ``from_euler("ZXZ", (φ, θ, ψ))``.
    The printed (17.10) has scan errors in its last two rows; this is the corrected
    matrix::

        [[ cψcφ - cθsφsψ,   cψsφ + cθcφsψ,  sψsθ],
         [-sψcφ - cθsφcψ,  -sψsφ + cθcφcψ,  cψsθ],
         [ sθsφ,           -sθcφ,           cθ  ]]

    Args:
        phi: ``(...)`` precession angle.
        theta: ``(...)`` nutation angle.
        psi: ``(...)`` spin angle; the three broadcast (same rank or scalars).

    Returns:
        ``(..., 3, 3)`` passive rotation matrix.
    """
    phi, theta, psi = as_float_all(phi, theta, psi)
    shape = jnp.broadcast_shapes(phi.shape, theta.shape, psi.shape)
    phi, theta, psi = (jnp.broadcast_to(a, shape) for a in (phi, theta, psi))
    cf, sf = jnp.cos(phi), jnp.sin(phi)
    ct, st = jnp.cos(theta), jnp.sin(theta)
    cp, sp = jnp.cos(psi), jnp.sin(psi)
    rows = [
        jnp.stack([cp * cf - ct * sf * sp, cp * sf + ct * cf * sp, sp * st], axis=-1),
        jnp.stack([-sp * cf - ct * sf * cp, -sp * sf + ct * cf * cp, cp * st], axis=-1),
        jnp.stack([st * sf, -st * cf, ct], axis=-1),
    ]
    return jnp.stack(rows, axis=-2)


def passive_matrix(q: ArrayLike) -> jax.Array:
    """The chapter's quaternion matrix (eq. 17.28), passive: the transpose of :func:`to_matrix`.

    Written as printed: ``2 [[½ - q2² - q3², q1q2 + q0q3, q1q3 - q0q2], ...]``.
    It maps space coordinates to body coordinates:
    ``v_body = passive_matrix(q) @ v_space``.

    Args:
        q: ``(..., 4)`` quaternion (normalised implicitly, as in :func:`to_matrix`).

    Returns:
        ``(..., 3, 3)``.
    """
    q = unit(quaternion_arg(q))
    q0, q1, q2, q3 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    rows = [
        [0.5 - q2 * q2 - q3 * q3, q1 * q2 + q0 * q3, q1 * q3 - q0 * q2],
        [q1 * q2 - q0 * q3, 0.5 - q1 * q1 - q3 * q3, q2 * q3 + q0 * q1],
        [q1 * q3 + q0 * q2, q2 * q3 - q0 * q1, 0.5 - q1 * q1 - q2 * q2],
    ]
    return 2.0 * jnp.stack([jnp.stack(row, axis=-1) for row in rows], axis=-2)
