"""Input helpers shared by every layer: float conversion, shapes, error reporting.

Errors follow one rule across jrigid: a wrong shape raises ``ValueError`` while tracing
(:func:`check_shape`, free under ``jit``); with concrete values a bad value raises
``ValueError`` naming the problem; under ``jit``/``vmap``/``grad`` (traced values) the
same message is raised at run time through ``equinox.error_if``.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from jrigid._folds import every


def as_float(x: ArrayLike, *, weak: bool = False) -> jax.Array:
    """``x`` as a floating array (ints become the default float).

    By default the result is strongly typed: strong typing keeps Python scalars from
    changing a compiled signature. ``weak=True`` keeps a Python scalar weakly typed, so
    that it takes the dtype of the arrays it meets (the quaternion functions: a float32
    quaternion interpolated with ``t=0.5`` stays float32 with float64 enabled).
    """
    x = jnp.asarray(x)
    if weak:
        if not jnp.issubdtype(x.dtype, jnp.inexact):
            x = x.astype(jnp.result_type(float))
        return x
    dtype = x.dtype if jnp.issubdtype(x.dtype, jnp.inexact) else jnp.result_type(float)
    return jnp.asarray(x, dtype=jax.dtypes.canonicalize_dtype(dtype))


def as_floats(*xs: ArrayLike, broadcast: bool = False) -> list[jax.Array]:
    """The arguments as arrays of one floating dtype (ints become the default float;
    Python scalars stay weak, so float32 arrays stay float32), broadcast to one shape
    if ``broadcast``."""
    arrays = [as_float(x, weak=True) for x in xs]
    dtype = jnp.result_type(*arrays)
    arrays = [a.astype(dtype) for a in arrays]
    return jnp.broadcast_arrays(*arrays) if broadcast else arrays


def _shape_text(trailing: tuple[int, ...]) -> str:
    return "(" + ", ".join(["...", *(str(n) for n in trailing)]) + ")"


def check_shape(x, name: str, *trailing: tuple[int, ...], why: str = "") -> jax.Array:
    """Return ``x`` as an array if its trailing axes match one of ``trailing``.

    A static check (shapes are known while tracing), so it costs nothing under ``jit``.

    Args:
        x: array-like.
        name: what ``x`` is, for the message (e.g. ``"q (a quaternion)"``).
        *trailing: accepted trailing shapes, e.g. ``(4,)`` or ``(2,), (3,)``.
        why: appended to the expected shape, e.g. ``" to match T of shape (4, 4)"``.

    Returns:
        ``jnp.asarray(x)``.

    Raises:
        ValueError: naming the expected trailing shape(s) and the shape received, e.g.
            ``"q (a quaternion) must have shape (..., 4); got shape (3,)"``.
    """
    x = jnp.asarray(x)
    for shape in trailing:
        if x.ndim >= len(shape) and x.shape[x.ndim - len(shape) :] == tuple(shape):
            return x
    expected = " or ".join(_shape_text(tuple(s)) for s in trailing)
    raise ValueError(f"{name} must have shape {expected}{why}; got shape {x.shape}")


def all_arrays(*trees) -> bool:
    """True if every leaf of the arguments is an array (what ``jax.jit`` accepts as an
    argument; ``equinox.filter_jit`` takes the other leaves, such as a string, as static)."""
    return all(eqx.is_array(x) for x in jax.tree_util.tree_leaves(trees))


def all_finite(tree) -> jax.Array:
    """``()`` bool: every entry of every array leaf of ``tree`` is finite (True for a
    tree without leaves)."""
    flags = [every(jnp.isfinite(a)) for a in jax.tree_util.tree_leaves(tree)]
    return every(jnp.stack(flags)) if flags else jnp.array(True)


def float_dtype() -> np.dtype:
    """JAX's default floating dtype: ``float64`` with ``jax_enable_x64``, else ``float32``
    (what ``jnp.result_type(float)`` returns, in a tenth of its time)."""
    return np.dtype(np.float64 if jax.config.jax_enable_x64 else np.float32)


def check_number(name: str, value, low: float) -> None:
    """``ValueError`` naming ``name`` unless ``value`` (a static option) is a finite real
    number, not a bool, ``>= low``."""
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if not (number and math.isfinite(value) and value >= low):
        raise ValueError(f"{name} must be a number >= {low}, got {value!r}")


def check_tolerance(name: str, value, high: float) -> None:
    """``ValueError`` naming ``name`` unless ``value`` (a tolerance: a number, or a
    concrete scalar array) is finite and in ``[0, high]``. A traced value is not
    checked (it has no value yet)."""
    if is_traced(value):
        return
    array = np.asarray(value)
    number = float(array) if array.ndim == 0 and array.dtype.kind in "fiu" else None
    if isinstance(value, bool) or number is None or not 0 <= number <= high:
        raise ValueError(f"{name} must be a number in [0, {high:g}], got {value!r}")


#: The most steps a fixed-step loop takes in one output interval (its counters are int32).
MAX_INTERVAL_STEPS = 2**31 - 1


def check_interval_steps(count: float, dt) -> None:
    """``ValueError`` naming ``dt`` when ``count`` steps per output interval (a concrete
    number) exceed ``MAX_INTERVAL_STEPS``."""
    if np.isfinite(count) and count > MAX_INTERVAL_STEPS:
        raise ValueError(f"dt={float(dt):g} needs {count:.3g} steps in an output interval, "
                         f"more than {MAX_INTERVAL_STEPS} (a step counter's range): raise dt")


def is_traced(*trees) -> bool:
    """True if any leaf of the arguments is a JAX tracer (inside jit, vmap, grad, ...)."""
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(trees))


def fail_if(x, bad: ArrayLike, message: str, detail: Callable[[], str] | None = None):
    """Return ``x``, or fail with ``message`` where ``bad`` holds.

    Concrete ``bad``: raise ``ValueError(message)`` now, even inside ``jit`` (with
    ``detail()`` appended when given, so the offending values can be named). Traced
    ``bad``: ``equinox.error_if`` raises at run time.
    """
    if is_traced(bad):
        return eqx.error_if(x, bad, message)
    if np.any(np.asarray(bad)):  # NumPy: no program compiled for the test itself
        raise ValueError(message + (f" ({detail()})" if detail is not None else ""))
    return x
