"""Input checks for quaternions and rotation matrices.

The conversion functions themselves never raise on bad values (a zero quaternion
gives NaN, see :func:`~jrigid.quaternion.normalize`), so that they stay cheap and
traceable. Call these checks at the edge of your program:

* outside any JAX transformation (concrete arrays) they raise :class:`ValueError`
  with a message naming the problem;
* inside ``jit`` / ``vmap`` / ``grad`` (traced arrays) they use
  :func:`equinox.error_if`: running the compiled function then raises an error
  whose message contains the same text. Under ``equinox.filter_jit`` it is an
  ``equinox.EquinoxRuntimeError`` (a ``RuntimeError``); under ``jax.jit`` JAX wraps
  it in its own runtime error (usually ``jax.errors.JaxRuntimeError``). The returned
  array must be used for the check to run.

Shape errors are static and always raise :class:`ValueError`.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from jrigid._checks import fail_if
from jrigid.linalg import safe_norm

from ._utils import matrix_arg, quaternion_arg

__all__ = ["check_quaternion", "check_rotation_matrix", "default_atol"]


def default_atol(dtype) -> float:
    """Default tolerance of the checks: ``1e-6`` for float64, ``1e-4`` for float32."""
    return 1e-4 if jnp.finfo(dtype).bits <= 32 else 1e-6


def check_quaternion(q: ArrayLike, *, unit: bool = True, atol: float | None = None) -> jax.Array:
    """Check that ``q`` is a finite, non-zero (and, by default, unit) quaternion.

    Args:
        q: ``(..., 4)`` quaternion(s).
        unit: also require ``| |q| - 1 | <= atol``.
        atol: tolerance on the norm; default :func:`default_atol` of ``q``'s dtype.

    Returns:
        ``q`` unchanged (as a float array). Inside a transformation, use the returned
        array so the check is part of the computation.

    Raises:
        ValueError: wrong shape (always), or, for concrete input, non-finite entries,
            zero norm, or (``unit=True``) a norm further than ``atol`` from one.
    """
    q = quaternion_arg(q)
    tol = default_atol(q.dtype) if atol is None else atol
    n = safe_norm(q)
    q = fail_if(q, ~jnp.all(jnp.isfinite(q)), "quaternion has non-finite (NaN or inf) entries")
    q = fail_if(q, n == 0, "zero quaternion: it represents no rotation")
    if unit:
        q = fail_if(
            q,
            jnp.abs(n - 1) > tol,
            f"quaternion is not unit length (tolerance {_show(tol)}); "
            "normalise it with jrigid.quaternion.normalize",
        )
    return q


def check_rotation_matrix(matrix: ArrayLike, *, atol: float | None = None) -> jax.Array:
    """Check that ``matrix`` is a proper rotation: ``Rᵀ R = 1`` and ``det R = +1`` within ``atol``.

    Args:
        matrix: ``(..., 3, 3)``.
        atol: tolerance on the entries of ``Rᵀ R - 1`` and on ``det R - 1``; default
            :func:`default_atol` of the dtype.

    Returns:
        ``matrix`` unchanged (as a float array).

    Raises:
        ValueError: wrong shape (always), or, for concrete input, non-finite entries,
            a non-orthogonal matrix, or a reflection (``det R = -1``).
    """
    m = matrix_arg(matrix)
    tol = default_atol(m.dtype) if atol is None else atol
    m = fail_if(m, ~jnp.all(jnp.isfinite(m)), "rotation matrix has non-finite entries")
    gram = jnp.swapaxes(m, -1, -2) @ m
    eye = jnp.broadcast_to(jnp.eye(3, dtype=m.dtype), gram.shape)
    ortho_err = jnp.max(jnp.abs(gram - eye), axis=(-2, -1))
    m = fail_if(
        m,
        ortho_err > tol,
        f"matrix is not orthogonal (tolerance {_show(tol)}); "
        "use jrigid.quaternion.project_to_rotation for the nearest rotation",
    )
    det = jnp.linalg.det(m)
    m = fail_if(m, jnp.abs(det - 1) > tol, "matrix is not a proper rotation (det R != +1)")
    return m


def _show(tol) -> str:
    """``tol`` for a message: its value if concrete, else ``atol`` (traced under ``jit``)."""
    if isinstance(tol, jax.core.Tracer):
        return "atol"
    return f"{float(tol):g}"
