"""Homogeneous affine transforms in 2D (3×3) and 3D (4×4).

Implements chapter 17.1–17.7 (2D), 17.9 (3D) and, through :mod:`jrigid.quaternion`,
the rotations of 17.11–17.17.

Conventions
-----------
* A transform ``T`` of shape ``(..., n+1, n+1)`` (``n`` = 2 or 3) acts on homogeneous
  column vectors: ``X' = T @ X``. Its blocks are ``T = [[A, d], [0, 1]]`` (17.7, 17.9):
  ``A`` rotates, scales and shears, ``d`` translates.
* ``compose(A, B)`` is the matrix product ``A @ B``: ``B`` is applied first.
* Points carry ``w = 1`` and feel the translation; vectors (differences of points)
  carry ``w = 0`` and do not (text after 17.7).
* Rotation matrices are active, ``v' = R @ v``; a positive 2D angle turns
  counter-clockwise (17.1).
* Leading batch dimensions broadcast. Every function is jit/vmap/grad-able.

The cameras (orthographic and pinhole projection, :func:`~jrigid.camera.look_at`) are in
:mod:`jrigid.camera`; ``jrigid.affine.look_at``, ``.orthographic`` and ``.perspective``
still name them.

Errors
------
Wrong shapes raise ``ValueError`` naming the expected trailing shape while tracing, so
also inside ``jax.jit``. Bad values (a singular matrix passed to :func:`inverse`) raise
``ValueError`` when the arguments are concrete; under ``jax.jit``/``vmap`` the same
check runs through ``equinox.error_if`` and raises a runtime error carrying the message.
Non-finite points, vectors and matrix entries propagate as NaN/inf.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp

from jrigid import quaternion as quat
from jrigid._checks import as_float, as_floats, check_shape, fail_if

__all__ = [
    "about_point",
    "apply",
    "apply_to_points",
    "apply_to_vectors",
    "compose",
    "from_blocks",
    "from_homogeneous",
    "inverse",
    "inverse_rigid",
    "rotation_2d",
    "rotation_3d",
    "rotation_3d_axis_angle",
    "rotation_3d_euler",
    "scaling",
    "shear_2d",
    "shear_3d",
    "to_blocks",
    "to_homogeneous",
    "translation",
]


# --------------------------------------------------------------------------- helpers


def _matrix(rows) -> jax.Array:
    """Stack a nested list of equally batched scalars ``(...)`` into ``(..., r, c)``."""
    flat = as_floats(*[e for row in rows for e in row], broadcast=True)
    ncol = len(rows[0])
    stacked = jnp.stack(flat, axis=-1)
    return stacked.reshape(stacked.shape[:-1] + (len(rows), ncol))


def _dim_of_vector(x: jax.Array, name: str) -> int:
    return check_shape(x, name, (2,), (3,)).shape[-1]


def _dim_of_transform(T: jax.Array, name: str = "T") -> int:
    return check_shape(T, name, (3, 3), (4, 4)).shape[-1] - 1


def _check_vector3(x: jax.Array, name: str) -> None:
    check_shape(x, name, (3,))


def _check_dim(x: jax.Array, n: int, name: str, T: jax.Array) -> None:
    check_shape(x, name, (n,), why=f" to match T of shape {T.shape}")


# --------------------------------------------------------------------------- building blocks


def from_blocks(A, d) -> jax.Array:
    """Assemble the homogeneous matrix ``[[A, d], [0, 1]]`` (17.7, 17.9).

    Args:
        A: linear part, ``(..., n, n)`` with ``n`` = 2 or 3.
        d: translation, ``(..., n)``.

    Returns:
        ``(..., n+1, n+1)``; batch dimensions of ``A`` and ``d`` broadcast.
    """
    A, d = as_floats(A, d)
    n = _dim_of_vector(d, "d")
    check_shape(A, "A", (n, n), why=f" to match d of shape {d.shape}")
    batch = jnp.broadcast_shapes(A.shape[:-2], d.shape[:-1])
    dtype = jnp.result_type(A, d)
    A = jnp.broadcast_to(A, batch + (n, n)).astype(dtype)
    d = jnp.broadcast_to(d, batch + (n,)).astype(dtype)
    top = jnp.concatenate([A, d[..., None]], axis=-1)
    bottom = jnp.broadcast_to(jnp.eye(1, n + 1, n, dtype=dtype), batch + (1, n + 1))
    return jnp.concatenate([top, bottom], axis=-2)


def to_blocks(T) -> tuple[jax.Array, jax.Array]:
    """Split ``T`` of shape ``(..., n+1, n+1)`` into ``A (..., n, n)`` and ``d (..., n)`` (17.7)."""
    T = as_float(T)
    n = _dim_of_transform(T)
    return T[..., :n, :n], T[..., :n, n]


def translation(d) -> jax.Array:
    """Translation by ``d`` (17.3 in homogeneous form, 17.5; 3D: 17.9 with ``R = 1``).

    Args:
        d: ``(..., 2)`` or ``(..., 3)``.

    Returns:
        ``(..., 3, 3)`` or ``(..., 4, 4)``.
    """
    d = as_float(d)
    n = _dim_of_vector(d, "d")
    return from_blocks(jnp.eye(n, dtype=d.dtype), d)


def scaling(s) -> jax.Array:
    """Scaling of the coordinates by the factors ``s`` about the origin (17.2, homogeneous).

    Args:
        s: per-axis factors ``(..., 2)`` or ``(..., 3)``.

    Returns:
        ``(..., 3, 3)`` or ``(..., 4, 4)``.
    """
    s = as_float(s)
    n = _dim_of_vector(s, "s")
    A = s[..., :, None] * jnp.broadcast_to(jnp.eye(n, dtype=s.dtype), s.shape[:-1] + (n, n))
    return from_blocks(A, jnp.zeros(n, dtype=s.dtype))


def shear_2d(kx, ky=0.0) -> jax.Array:
    """2D shear (skew): ``x' = x + kx y``, ``y' = y + ky x`` (17.6 has ``kx = 0.2``).

    Args:
        kx, ky: shear factors, ``(...)``; they broadcast.

    Returns:
        ``(..., 3, 3)``.
    """
    kx, ky = as_floats(kx, ky)
    one, zero = jnp.ones_like(kx), jnp.zeros_like(kx)
    return _matrix([[one, kx, zero], [ky, one, zero], [zero, zero, one]])


def shear_3d(xy=0.0, xz=0.0, yx=0.0, yz=0.0, zx=0.0, zy=0.0) -> jax.Array:
    """3D shear, the extension of 17.6: ``x' = x + xy·y + xz·z``, ``y' = y + yx·x + yz·z``, ….

    Args:
        xy, xz, yx, yz, zx, zy: shear factors, ``(...)``; they broadcast.

    Returns:
        ``(..., 4, 4)``.
    """
    xy, xz, yx, yz, zx, zy = as_floats(xy, xz, yx, yz, zx, zy)
    one, zero = jnp.ones_like(xy), jnp.zeros_like(xy)
    return _matrix(
        [
            [one, xy, xz, zero],
            [yx, one, yz, zero],
            [zx, zy, one, zero],
            [zero, zero, zero, one],
        ]
    )


def about_point(T, pivot) -> jax.Array:
    """Make the linear part of ``T`` act about ``pivot`` instead of the origin.

    Returns ``translation(pivot) @ T @ translation(-pivot)``: translate the pivot to the
    origin, apply ``T``, translate back (Exercise 17.2b). For a rotation the pivot is fixed.

    Args:
        T: ``(..., n+1, n+1)``.
        pivot: ``(..., n)``.

    Returns:
        ``(..., n+1, n+1)``.
    """
    T, pivot = as_floats(T, pivot)
    n = _dim_of_transform(T)
    _check_dim(pivot, n, "pivot", T)
    return translation(pivot) @ T @ translation(-pivot)


def _maybe_about(T: jax.Array, pivot) -> jax.Array:
    return T if pivot is None else about_point(T, pivot)


def rotation_2d(angle, pivot=None) -> jax.Array:
    """Counter-clockwise rotation by ``angle`` (17.1 in homogeneous form, 17.7).

    Args:
        angle: radians, ``(...)``. The chapter's "30° clockwise" is ``-π/6``.
        pivot: optional centre of rotation ``(..., 2)``; default the origin.

    Returns:
        ``(..., 3, 3)``.
    """
    angle = as_float(angle)
    c, s = jnp.cos(angle), jnp.sin(angle)
    one, zero = jnp.ones_like(c), jnp.zeros_like(c)
    T = _matrix([[c, -s, zero], [s, c, zero], [zero, zero, one]])
    return _maybe_about(T, pivot)


def rotation_3d(q, pivot=None) -> jax.Array:
    """Rotation by the unit quaternion ``q`` (17.9 with the active form of 17.28).

    Args:
        q: ``(..., 4)`` scalar first, body → space; finite and non-zero (any norm: the
            rotation of ``q / |q|``).
        pivot: optional centre of rotation ``(..., 3)``; default the origin.

    Returns:
        ``(..., 4, 4)`` whose upper-left block is ``quaternion.to_matrix(q)``.

    Raises:
        ValueError: (a runtime error under ``jit``) ``q`` is zero or not finite.
    """
    return _rotation_3d(quat.check_quaternion(q, unit=False), pivot)


def _rotation_3d(q, pivot) -> jax.Array:
    """:func:`rotation_3d` without the check of ``q`` (a NaN angle gives a NaN matrix)."""
    R = quat.to_matrix(q)
    T = from_blocks(R, jnp.zeros(3, dtype=R.dtype))
    return _maybe_about(T, pivot)


def rotation_3d_axis_angle(axis, angle, pivot=None) -> jax.Array:
    """Rotation by ``angle`` about ``axis`` (the Rodrigues matrix 17.17, via quaternions 17.25).

    Args:
        axis: ``(..., 3)``, need not be normalised (finite, not zero).
        angle: radians, ``(...)``; right-hand rule about ``axis``.
        pivot: optional point on the rotation axis ``(..., 3)``; default the origin.

    Returns:
        ``(..., 4, 4)``.
    """
    axis, angle = as_floats(axis, angle)
    _check_vector3(axis, "axis")
    axis = fail_if(axis, ~jnp.all(jnp.isfinite(axis), axis=-1) | jnp.all(axis == 0, axis=-1),
                   "rotation_3d_axis_angle: axis must be finite and not zero")
    return _rotation_3d(quat.from_axis_angle(axis, angle), pivot)


def rotation_3d_euler(seq: str, angles, pivot=None) -> jax.Array:
    """Rotation from Euler angles with scipy's meaning of ``seq`` (17.10 is the passive "ZXZ").

    Args:
        seq: three axes, upper case intrinsic, lower case extrinsic, e.g. ``"ZXZ"``.
        angles: radians ``(..., 3)``.
        pivot: optional centre of rotation ``(..., 3)``.

    Returns:
        ``(..., 4, 4)``.
    """
    angles = as_float(angles)
    _check_vector3(angles, "angles")
    return _rotation_3d(quat.from_euler(seq, angles), pivot)


# --------------------------------------------------------------------------- algebra


def compose(*transforms) -> jax.Array:
    """Matrix product ``T1 @ T2 @ … @ Tk``: the rightmost transform is applied first.

    Args:
        *transforms: one or more ``(..., n+1, n+1)`` of the same ``n``; batches broadcast.

    Returns:
        ``(..., n+1, n+1)``.

    Example:
        Turn a quarter about the origin, then move one unit along ``x``: the point
        ``(1, 0)`` lands on ``(1, 1)``, while the vector ``(1, 0)`` only turns:

        >>> import jax.numpy as jnp
        >>> from jrigid import affine
        >>> T = affine.compose(affine.translation(jnp.array([1.0, 0.0])),
        ...                    affine.rotation_2d(jnp.pi / 2))
        >>> print(jnp.round(affine.apply_to_points(T, jnp.array([1.0, 0.0])), 6) + 0.0)
        [1. 1.]
        >>> print(jnp.round(affine.apply_to_vectors(T, jnp.array([1.0, 0.0])), 6) + 0.0)
        [0. 1.]
    """
    if not transforms:
        raise ValueError("compose needs at least one transform")
    Ts = [as_float(T) for T in transforms]
    dims = {_dim_of_transform(T, f"transform {i}") for i, T in enumerate(Ts)}
    if len(dims) != 1:
        raise ValueError(f"cannot compose 2D and 3D transforms: shapes {[T.shape for T in Ts]}")
    out = Ts[0]
    for T in Ts[1:]:
        out = out @ T
    return out


def inverse(T) -> jax.Array:
    """General inverse of a homogeneous (affine or projective) matrix.

    An affine matrix (last row ``(0, …, 0, 1)``) is inverted by blocks,
    ``[[A⁻¹, −A⁻¹ d], [0, 1]]``, and counts as singular when the smallest singular value
    of its linear part ``A`` is below ``n · eps`` times the largest: the size of the
    translation does not enter (a translation by 1e4 in float32 is as invertible as
    one by 1). Any other (projective) matrix is singular when the smallest singular
    value of the whole matrix is below ``(n + 1) · eps`` times the largest. A singular
    or non-finite matrix raises ``ValueError`` (or a runtime error under jit).

    Args:
        T: ``(..., n+1, n+1)``.

    Returns:
        ``(..., n+1, n+1)``.
    """
    T = as_float(T)
    n = _dim_of_transform(T)
    last = T[..., n, :]
    affine = jnp.all(last == jnp.broadcast_to(jnp.eye(1, n + 1, n, dtype=T.dtype)[0], last.shape),
                     axis=-1)
    eps = jnp.finfo(T.dtype).eps
    sv_a = jax.lax.stop_gradient(jnp.linalg.svd(T[..., :n, :n], compute_uv=False))
    sv_t = jax.lax.stop_gradient(jnp.linalg.svd(T, compute_uv=False))
    sv = jnp.where(affine[..., None], sv_a[..., jnp.array([0, n - 1])],
                   sv_t[..., jnp.array([0, n])])
    ratio = jnp.where(sv[..., 0] > 0, sv[..., 1] / jnp.where(sv[..., 0] > 0, sv[..., 0], 1), 0)
    regular = ratio > jnp.where(affine, n, n + 1) * eps
    singular = ~(regular & jnp.all(jnp.isfinite(T), axis=(-2, -1)))
    T = fail_if(
        T,
        singular,
        "inverse: matrix is singular (or not finite)",
        lambda: "singular values: smallest / largest = "
        f"{ratio[singular] if singular.ndim else ratio} (of the linear part if affine)",
    )
    # The branch not taken inverts an identity, so that its derivative stays finite.
    # The affine branch is the Schur-complement inverse, exact in value for the last row
    # (0, …, 0, 1) and with the general inverse's derivative in every entry.
    pick = lambda a, b: jnp.where(affine[..., None, None], a, b)  # noqa: E731
    A = pick(T[..., :n, :n], jnp.eye(n, dtype=T.dtype))
    d, c, s = T[..., :n, n:], T[..., n:, :n], T[..., n:, n:]
    A_inv = jnp.linalg.inv(A)
    A_inv_d, c_A_inv = A_inv @ d, c @ A_inv
    s_inv = 1.0 / jnp.where(affine[..., None, None], s - c @ A_inv_d, 1.0)
    by_blocks = jnp.concatenate([
        jnp.concatenate([A_inv + A_inv_d @ (s_inv * c_A_inv), -A_inv_d * s_inv], axis=-1),
        jnp.concatenate([-s_inv * c_A_inv, s_inv], axis=-1)], axis=-2)
    general = jnp.linalg.inv(pick(jnp.eye(n + 1, dtype=T.dtype), T))
    return pick(by_blocks, general)


def inverse_rigid(T) -> jax.Array:
    """Closed-form inverse of a rigid transform: ``[[Rᵀ, -Rᵀ d], [0, 1]]`` (Exercise 17.6).

    Args:
        T: ``(..., n+1, n+1)`` with orthogonal ``A`` and last row ``(0, …, 0, 1)``, both
            to within :func:`jrigid.quaternion.default_atol` of the dtype.

    Returns:
        ``(..., n+1, n+1)``.

    Raises:
        ValueError: (a runtime error under ``jit``) ``T`` is not finite, its linear block
            is not orthogonal (a scaling or shear: use :func:`inverse`), or its last row
            is not ``(0, …, 0, 1)`` (a projective matrix).
    """
    T = as_float(T)
    n = _dim_of_transform(T)
    R, d = to_blocks(T)
    Rt = jnp.swapaxes(R, -1, -2)
    tol = quat.default_atol(T.dtype)
    gram = Rt @ R
    gram_error = jnp.max(jnp.abs(gram - jnp.broadcast_to(jnp.eye(n, dtype=T.dtype), gram.shape)),
                         axis=(-2, -1))
    last = T[..., n, :]
    row_error = jnp.max(jnp.abs(last - jnp.broadcast_to(
        jnp.eye(1, n + 1, n, dtype=T.dtype)[0], last.shape)), axis=-1)
    T = fail_if(T, ~jnp.all(jnp.isfinite(T), axis=(-2, -1)),
                "inverse_rigid: T has non-finite entries")
    T = fail_if(T, gram_error > tol,
                f"inverse_rigid: the linear block of T is not orthogonal (|AᵀA − 1| > {tol:g}); "
                "use affine.inverse for a scaling or shear",
                lambda: f"largest |AᵀA − 1| {jnp.max(gram_error):.3g}")
    T = fail_if(T, row_error > tol,
                "inverse_rigid: the last row of T is not (0, …, 0, 1) (a projective matrix); "
                "use affine.inverse")
    R, d = to_blocks(T)
    Rt = jnp.swapaxes(R, -1, -2)
    return from_blocks(Rt, -(Rt @ d[..., None])[..., 0])


# --------------------------------------------------------------------------- application


def to_homogeneous(x, w) -> jax.Array:
    """Append the homogeneous coordinate: ``w = 1`` for points, ``w = 0`` for vectors.

    Args:
        x: ``(..., n)``.
        w: scalar or ``(...)``.

    Returns:
        ``(..., n+1)``.
    """
    x = as_float(x)
    _dim_of_vector(x, "x")
    w = jnp.asarray(w, dtype=x.dtype)
    try:
        w = jnp.broadcast_to(w, x.shape[:-1])
    except ValueError:
        raise ValueError(f"to_homogeneous: w must be a scalar or of x's batch shape "
                         f"{x.shape[:-1]}; got shape {w.shape}") from None
    return jnp.concatenate([x, w[..., None]], axis=-1)


def from_homogeneous(X) -> jax.Array:
    """Homogenise ``(..., n+1) -> (..., n)`` by dividing by ``w`` (text before 17.4).

    ``w = 0`` (a vector or a point at infinity) gives ``inf``/``nan``.
    """
    X = check_shape(as_float(X), "X", (3,), (4,))
    return X[..., :-1] / X[..., -1:]


def apply(T, X) -> jax.Array:
    """Apply ``T`` to homogeneous coordinates: ``X' = T @ X`` (17.4, 17.9).

    Args:
        T: ``(..., n+1, n+1)``.
        X: ``(..., n+1)``; batches broadcast.

    Returns:
        ``(..., n+1)``.
    """
    T, X = as_floats(T, X)
    n = _dim_of_transform(T)
    _check_dim(X, n + 1, "X", T)
    return (T @ X[..., None])[..., 0]


def _check_cartesian(T: jax.Array, x: jax.Array, name: str) -> int:
    n = _dim_of_transform(T)
    _check_dim(x, n, name, T)
    return n


def apply_to_points(T, p) -> jax.Array:
    """Transform Cartesian points: append ``w = 1``, apply ``T``, homogenise (17.4, 17.9).

    For an affine ``T`` the result has ``w = 1`` already; a projective ``T`` divides by ``w``.

    Args:
        T: ``(..., n+1, n+1)``.
        p: ``(..., n)``; batches broadcast.

    Returns:
        ``(..., n)``.
    """
    T, p = as_floats(T, p)
    n = _check_cartesian(T, p, "p")
    Y = (T @ to_homogeneous(p, 1.0)[..., None])[..., 0]
    return Y[..., :n] / Y[..., n:]


def apply_to_vectors(T, v) -> jax.Array:
    """Transform Cartesian vectors (``w = 0``): only the linear block acts, ``v' = A v``.

    Vectors such as displacements do not translate (text after 17.7).

    Args:
        T: ``(..., n+1, n+1)``.
        v: ``(..., n)``; batches broadcast.

    Returns:
        ``(..., n)``.
    """
    T, v = as_floats(T, v)
    n = _check_cartesian(T, v, "v")
    return (T[..., :n, :n] @ v[..., None])[..., 0]


# The cameras live in jrigid.camera (which builds on this module); their names stay
# importable from here, loaded on first use.
_CAMERA = ("look_at", "orthographic", "perspective")


def __getattr__(name: str):
    if name in _CAMERA:
        from jrigid import camera

        return getattr(camera, name)
    raise AttributeError(f"module 'jrigid.affine' has no attribute {name!r}")


if TYPE_CHECKING:
    from jrigid.camera import look_at, orthographic, perspective  # noqa: F401
