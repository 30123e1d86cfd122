"""Whether an inertia is physical: :func:`validate`, :func:`check`, :func:`conditions`."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from jrigid._checks import as_float, check_shape, fail_if, is_traced
from jrigid._folds import every

__all__ = [
    "conditions",
    "check",
    "checked_moments",
    "validate",
]


def _check_tensor(inertia: jax.Array, name: str = "inertia") -> None:
    hint = ""
    if inertia.ndim >= 1 and inertia.shape[-1] == 3 and inertia.shape[-2:] != (3, 3):
        hint = " (a tensor; use to_tensor for principal moments)"
    check_shape(inertia, name, (3, 3), why=hint)


def _check_moments(moments: jax.Array, name: str = "moments") -> None:
    check_shape(moments, name, (3,))


def _kind(inertia: jax.Array, kind: str | None) -> str:
    if kind is None:
        kind = "tensor" if inertia.ndim >= 2 and inertia.shape[-2:] == (3, 3) else "moments"
    if kind == "tensor":
        _check_tensor(inertia)
    elif kind == "moments":
        _check_moments(inertia)
    else:
        raise ValueError(f"kind must be None, 'moments' or 'tensor', got {kind!r}")
    return kind


def _conditions(inertia: jax.Array, kind: str, allow_nonphysical: bool, rtol):
    """``[(name, bad (...), label, values), ...]`` in the order they are reported."""
    eps = jnp.finfo(inertia.dtype).eps
    rtol = jnp.sqrt(eps) if rtol is None else rtol
    core = (-2, -1) if kind == "tensor" else (-1,)
    finite = every(jnp.isfinite(inertia), axis=-1)
    if kind == "tensor":
        finite = every(finite, axis=-1)
    clean = jnp.where(jnp.isfinite(inertia), inertia, 0.0)
    out = [("values not finite", ~finite, "values", inertia)]
    ok = finite  # each element is reported under its first failed condition only
    if kind == "tensor":
        scale = jnp.max(jnp.abs(clean), axis=core)
        asym = jnp.max(jnp.abs(clean - jnp.swapaxes(clean, -1, -2)), axis=core)
        symmetric = asym <= rtol * scale
        out.append(("tensor not symmetric", ok & ~symmetric, "tensor", inertia))
        ok = ok & symmetric
        sym = 0.5 * (clean + jnp.swapaxes(clean, -1, -2))
        moments = jnp.linalg.eigvalsh(sym)
        pd = _positive_definite(sym)
    else:
        moments = _sorted3(clean)
        pd = moments[..., 0] > 0  # exact: the moments are given
    lo, mid, hi = moments[..., 0], moments[..., 1], moments[..., 2]
    out.append(("not positive definite", ok & ~pd, "principal moments", moments))
    ok = ok & pd
    if not allow_nonphysical:
        tri = lo + mid >= hi * (1 - rtol)
        out.append(
            (
                "triangle inequality Ia + Ib >= Ic violated",
                ok & ~tri,
                "principal moments",
                moments,
            )
        )
    return out


def _sorted3(m: jax.Array) -> jax.Array:
    """``(..., 3)`` sorted along the last axis by ``min``/``max`` (exact, like ``jnp.sort``).

    XLA:CPU runs a ``sort`` as a separate library call, and a loop or computation
    holding one cannot be compiled into a single kernel; these are elementwise.
    """
    a, b, c = m[..., 0], m[..., 1], m[..., 2]
    lo = jnp.minimum(jnp.minimum(a, b), c)
    hi = jnp.maximum(jnp.maximum(a, b), c)
    mid = jnp.maximum(jnp.minimum(a, b), jnp.minimum(jnp.maximum(a, b), c))
    return jnp.stack([lo, mid, hi], axis=-1)


def _positive_definite(sym: jax.Array) -> jax.Array:
    """Whether a symmetric ``(..., 3, 3)`` is positive definite, independent of units.

    The test runs on ``D^-1/2 I D^-1/2`` (``D`` the diagonal), which is positive definite
    exactly when ``I`` is and whose eigenvalues lie in ``[0, 3]`` whatever the scale of
    each axis, so a needle such as ``diag(1e-12, 1e12, 1e12)`` passes: its smallest
    moment is not compared with the largest. The smallest scaled eigenvalue must exceed
    its rounding error, ``3 eps`` times the largest.
    """
    eps = jnp.finfo(sym.dtype).eps
    d = jnp.diagonal(sym, axis1=-2, axis2=-1)
    positive = jnp.all(d > 0, axis=-1)
    r = jax.lax.rsqrt(jnp.where(d > 0, d, jnp.ones_like(d)))
    scaled = sym * r[..., :, None] * r[..., None, :]
    ev = jnp.linalg.eigvalsh(scaled)
    return positive & (ev[..., 0] > 3 * eps * ev[..., -1])


def conditions(inertia, *, allow_nonphysical: bool = False, kind: str | None = None, rtol=None):
    """The checks of :func:`validate` as traced flags: ``[(name, bad, label, values), ...]``.

    Args:
        inertia: moments ``(..., 3)`` or tensor ``(..., 3, 3)``.
        allow_nonphysical, kind, rtol: as :func:`validate`.

    Returns:
        One entry per condition, in report order: its name, ``bad (...)`` (batch
        shape), and the label and values a message would quote.
    """
    inertia = as_float(inertia)
    return _conditions(inertia, _kind(inertia, kind), allow_nonphysical, rtol)


def check(inertia, *, allow_nonphysical: bool = False, kind: str | None = None, rtol=None):
    """Jit-safe version of :func:`validate`: returns ``inertia``, errors at run time.

    Uses ``equinox.error_if``; under ``jax.jit`` a violated condition raises a runtime
    error whose message names the condition (values are not available there).

    Args:
        inertia: moments ``(..., 3)`` or tensor ``(..., 3, 3)``.
        allow_nonphysical: skip the triangle inequality.
        kind: ``"moments"``, ``"tensor"`` or ``None`` (a trailing ``(3, 3)`` means tensor).
        rtol: relative tolerance of the symmetry and triangle tests; default ``sqrt(eps)``.

    Returns:
        ``inertia`` unchanged (as a float array).
    """
    inertia = as_float(inertia)
    kind = _kind(inertia, kind)
    for name, bad, _, _ in _conditions(inertia, kind, allow_nonphysical, rtol):
        inertia = eqx.error_if(inertia, bad, f"inertia is not valid: {name}")
    return inertia


def validate(inertia, *, allow_nonphysical: bool = False, kind: str | None = None, rtol=None):
    """Check that ``inertia`` is a physical inertia; raise ``ValueError`` otherwise.

    Conditions, in order: finite; symmetric (tensor only, ``|I − Iᵀ| ≤ rtol·max|I|``);
    positive definite (moments: the smallest ``> 0``; tensor: positive diagonal and,
    after scaling to unit diagonal, the smallest eigenvalue above its rounding error
    ``3 eps ×`` the largest; both tests are independent of the units of each axis, so
    ``(1e-12, 1e12, 1e12)``, a needle, is accepted); triangle inequality
    ``Ia + Ib ≥ Ic (1 − rtol)`` of the principal moments, which every real mass
    distribution satisfies (skipped with ``allow_nonphysical=True``, e.g. for the
    Hairer–Lubich–Wanner test body ``(2, 1, 2/3)``). Flat bodies meet it with equality.

    Each batch element is reported under the first condition it violates (a
    non-symmetric tensor as "not symmetric", never as "not positive definite"). The
    message names the first violated condition, the first offending batch index and
    its values. Under a JAX transformation (jit, vmap, grad) this defers to :func:`check`.

    Args:
        inertia: moments ``(..., 3)`` or tensor ``(..., 3, 3)``.
        allow_nonphysical: skip the triangle inequality.
        kind: ``"moments"``, ``"tensor"`` or ``None`` (a trailing ``(3, 3)`` means tensor;
            pass ``"moments"`` for a batch of three moment vectors).
        rtol: relative tolerance of the symmetry and triangle tests; default ``sqrt(eps)``.

    Returns:
        ``inertia`` unchanged (as a float array).
    """
    inertia = as_float(inertia)
    kind = _kind(inertia, kind)
    if is_traced(inertia):
        return check(inertia, allow_nonphysical=allow_nonphysical, kind=kind, rtol=rtol)
    with jax.ensure_compile_time_eval():  # concrete even inside an enclosing jit
        for name, bad, label, values in _conditions(inertia, kind, allow_nonphysical, rtol):
            if bool(jnp.any(bad)):
                where = ""
                if bad.ndim:
                    idx = tuple(int(i) for i in jnp.argwhere(bad)[0])
                    values = values[idx]
                    where = f" at batch index {idx}"
                raise ValueError(f"inertia is not valid: {name}{where}; {label} {values}")
    return inertia


def _mass(m, name: str = "mass") -> jax.Array:
    m = as_float(m, weak=True)  # (a Python scalar takes the dtype it meets)
    return fail_if(
        m, ~(jnp.isfinite(m) & (m > 0)), f"{name} must be finite and > 0", lambda: f"{m}"
    )


def _size(x, name: str) -> jax.Array:
    x = as_float(x, weak=True)  # (a Python scalar takes the dtype it meets)
    return fail_if(
        x, ~(jnp.isfinite(x) & (x >= 0)), f"{name} must be finite and >= 0", lambda: f"{x}"
    )


def checked_moments(moments, *, allow_nonphysical: bool = False) -> jax.Array:
    """Principal moments checked as every closed form needs them: shape ``(..., 3)``
    (``ValueError`` naming ``moments`` otherwise), then :func:`validate`.

    Args:
        moments: ``(..., 3)`` principal moments (a float array: convert first).
        allow_nonphysical: skip the triangle inequality (as :func:`validate`).

    Returns:
        ``moments`` (as an array; under a transformation, with :func:`check`'s run-time
        checks attached).
    """
    moments = check_shape(moments, "moments (principal moments)", (3,))
    return validate(moments, kind="moments", allow_nonphysical=allow_nonphysical)
