"""Simple cameras: orthographic and pinhole projection of world points, and the view matrix.

Implements the projections of chapter section 17.2 (parallel projection along a
coordinate axis) and a pinhole camera built on the rigid view transform of 17.9
(:func:`look_at`, a :mod:`jrigid.affine` transform). Points are ``(..., 3)`` world
coordinates; the image coordinates come with a depth for drawing back to front.

Errors follow :mod:`jrigid.affine`: wrong shapes raise ``ValueError`` while tracing; bad
values (a zero-length look direction, non-finite camera positions, a field of view
outside ``(0, π)``, an aspect ratio that is not positive) raise ``ValueError`` when the
arguments are concrete and an ``equinox`` runtime error under ``jit``/``vmap``.
"""

from __future__ import annotations

import numbers

import jax
import jax.numpy as jnp

from jrigid._checks import as_float, check_shape, fail_if
from jrigid.affine import apply_to_points, from_blocks
from jrigid.linalg import rescale, safe_norm

__all__ = ["look_at", "orthographic", "perspective"]


def _vector3(x: jax.Array, name: str) -> None:
    check_shape(x, name, (3,))


def orthographic(points, axis: int = 2) -> tuple[jax.Array, jax.Array]:
    """Orthographic parallel projection along a coordinate axis (section 17.2).

    The viewer sits on the positive side of ``axis`` looking toward the origin. The
    image coordinates are the other two coordinates in cyclic order, ``(u, v) = (y, z)``,
    ``(z, x)`` or ``(x, y)`` for ``axis`` 0, 1, 2, so that ``u × v`` points to the viewer.

    Args:
        points: ``(..., 3)``.
        axis: 0, 1 or 2 (static).

    Returns:
        ``(uv, depth)``: ``uv (..., 2)`` and ``depth = -points[..., axis]`` ``(...)``,
        larger depth is farther away: draw in order of decreasing depth (back to front).
    """
    points = as_float(points)
    _vector3(points, "points")
    if not isinstance(axis, numbers.Integral) or isinstance(axis, bool) or axis not in (0, 1, 2):
        raise ValueError(f"axis must be the integer 0, 1 or 2, got {axis!r}")
    axis = int(axis)
    uv = jnp.stack([points[..., (axis + 1) % 3], points[..., (axis + 2) % 3]], axis=-1)
    return uv, -points[..., axis]


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> jax.Array:
    """World → camera view matrix of a camera at ``eye`` looking at ``target``.

    Camera frame: ``x`` to the right, ``y`` up, and the camera looks along ``-z``
    (the OpenGL convention). The matrix is rigid: ``[[Rᵀ, -Rᵀ eye], [0, 1]]`` with the
    columns of ``R`` the camera axes in world coordinates (17.9).

    Args:
        eye, target: ``(..., 3)`` finite; must differ (by any amount: the direction of
            their difference is computed without overflow or underflow).
        up: ``(..., 3)`` finite approximate up direction, not parallel to ``target - eye``.

    Returns:
        ``(..., 4, 4)``.
    """
    eye, target, up = as_float(eye), as_float(target), as_float(up)
    for name, x in (("eye", eye), ("target", target), ("up", up)):
        _vector3(x, name)
    eye, target, up = jnp.broadcast_arrays(eye, target, up)
    finite = jnp.all(jnp.isfinite(eye) & jnp.isfinite(target) & jnp.isfinite(up), axis=-1)
    eye = fail_if(
        eye,
        ~finite,
        "look_at: eye, target and up must be finite",
        lambda: f"eye {eye}, target {target}, up {up}",
    )
    # eye and target scaled by one power of two (exactly), so that neither their
    # difference nor its norm overflows or underflows: any two distinct points have a
    # direction, 1e-20 apart or 1e308 from the origin
    both = rescale(jnp.concatenate([eye, target], axis=-1))[0]
    forward = both[..., 3:] - both[..., :3]
    dist = safe_norm(forward)
    forward = fail_if(
        forward,
        ~(dist > 0),
        "look_at: zero-length look direction (eye == target)",
        lambda: f"eye {eye}, target {target}",
    )
    f = forward / jnp.where(dist == 0, 1.0, dist)[..., None]
    up_scaled = rescale(up)[0]
    right = jnp.cross(f, up_scaled)
    rnorm = safe_norm(right)
    unorm = safe_norm(up_scaled)
    right = fail_if(
        right,
        ~(rnorm > 1e3 * jnp.finfo(right.dtype).eps * unorm),
        "look_at: `up` is zero or parallel to the look direction",
        lambda: f"up {up}, look direction {f}",
    )
    r = right / jnp.where(rnorm == 0, 1.0, rnorm)[..., None]
    u = jnp.cross(r, f)
    rows = jnp.stack([r, u, -f], axis=-2)  # = Rᵀ
    return from_blocks(rows, -(rows @ eye[..., None])[..., 0])


def perspective(
    points, eye, target, fov, *, up=(0.0, 0.0, 1.0), aspect=1.0
) -> tuple[jax.Array, jax.Array]:
    """Pinhole camera: project world points to normalised image coordinates and depth.

    With camera coordinates ``(x, y, z)`` from :func:`look_at` and ``depth = -z``
    (distance in front of the eye along the view axis), ``f = 1 / tan(fov / 2)``:
    ``u = f x / (aspect · depth)``, ``v = f y / depth``. The target maps to ``(0, 0)``,
    the image edges to ``±1``. Points at or behind the eye (``depth ≤ 0``) get ``nan``
    image coordinates; cull them with ``depth > 0``. Draw faces in order of decreasing
    depth (back to front).

    Args:
        points: ``(..., 3)`` world coordinates.
        eye, target: ``(..., 3)``, finite and distinct.
        fov: vertical field of view in radians, in ``(0, π)``; ``(...)``.
        up: ``(..., 3)`` approximate up direction.
        aspect: image width / height, finite and ``> 0``, ``(...)``. ``fov`` and
            ``aspect`` broadcast against the batch shape of the points (numpy rules).

    Returns:
        ``(uv, depth)``: ``uv (..., 2)`` and ``depth (...)``; batches broadcast.

    Raises:
        ValueError: wrong shapes; for concrete values, ``fov`` outside ``(0, π)``,
            ``aspect`` not finite and positive, and the conditions of :func:`look_at`.
    """
    points = as_float(points)
    _vector3(points, "points")
    fov, aspect = as_float(fov), as_float(aspect)
    fov = fail_if(
        fov,
        ~((fov > 0) & (fov < jnp.pi)),
        "perspective: fov must be in (0, π) radians",
        lambda: f"fov {fov}",
    )
    aspect = fail_if(
        aspect,
        ~(jnp.isfinite(aspect) & (aspect > 0)),
        "perspective: aspect (width / height) must be finite and > 0",
        lambda: f"aspect {aspect}",
    )
    V = look_at(eye, target, up)
    try:
        jnp.broadcast_shapes(points.shape[:-1], V.shape[:-2])
    except ValueError:
        raise ValueError(
            f"perspective: the batch shapes of points {points.shape[:-1]} and of the camera "
            f"(eye, target, up) {V.shape[:-2]} do not broadcast") from None
    pc = apply_to_points(V, points)
    depth = -pc[..., 2]
    batch = jnp.broadcast_shapes(depth.shape, fov.shape, aspect.shape)
    depth, fov, aspect = (jnp.broadcast_to(x, batch) for x in (depth, fov, aspect))
    pc = jnp.broadcast_to(pc, batch + (3,))
    in_front = depth > 0
    f = 1.0 / jnp.tan(0.5 * fov)
    scale = f / jnp.where(in_front, depth, 1.0)
    uv = jnp.stack([pc[..., 0] * scale / aspect, pc[..., 1] * scale], axis=-1)
    uv = jnp.where(in_front[..., None], uv, jnp.nan)
    return uv, depth
