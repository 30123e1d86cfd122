"""A solve's inputs: conversion, value checks, stand-ins for bad members, precision warnings.

Every jrigid integrator converts and shape-checks its inputs with :func:`prepare`
(``ValueError`` before anything is compiled), then checks their values with
:func:`input_checks`: a list of ``(bad, message)`` pairs that are traced, so the same
checks run inside ``jit``/``vmap``. The checks are applied up front (:func:`validate`),
as a runtime error (:func:`guard`), or as a per-member
:attr:`~jrigid.trajectory.Result.invalid_input` code with benign stand-in inputs
(:func:`screen`), so that one bad member of a sweep does not stop the others. In
float32, :func:`warn_precision` warns (:class:`PrecisionWarning`) when the horizon is too
long for the tolerance.
"""

from __future__ import annotations

import functools
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jrigid import quaternion as quat
from jrigid._checks import is_traced
from jrigid._folds import every, first_true, some
from jrigid.scene import Gravity, Scene
from jrigid.state import State

__all__ = [
    "TOLERANCE_CHECKS",
    "PrecisionWarning",
    "default_tolerances",
    "guard",
    "input_checks",
    "message",
    "normalised",
    "precision_problem",
    "prepare",
    "screen",
    "shared_checks",
    "validate",
    "validate_shared",
    "warn_precision",
]


def default_tolerances(dtype) -> tuple[float, float]:
    """``(rtol, atol)`` defaults: ``(1e-8, 1e-10)`` in float64, ``(1e-5, 1e-7)`` in float32."""
    if jnp.dtype(dtype).itemsize >= 8:
        return 1e-8, 1e-10
    return 1e-5, 1e-7


@functools.cache
def _default_array(dtype, which: int) -> np.ndarray:
    """The default ``rtol`` (0) or ``atol`` (1) of ``dtype`` (a NumPy scalar array: a
    literal when traced, never a captured device array)."""
    return np.asarray(default_tolerances(dtype)[which], dtype=dtype)


def _converted(x, dtype, name: str):
    """``x`` as an array of ``dtype``: a JAX array (or tracer) through ``jnp``, anything
    else (a Python float, a list, a NumPy array) through NumPy. ``jnp.asarray`` of a Python
    scalar dispatches an XLA operation, about 25 µs, which a plain call in a loop paid
    for each tolerance; the compiled solve takes the NumPy array as it would a JAX one."""
    if isinstance(x, jax.Array):
        return x if x.dtype == dtype else jnp.asarray(x, dtype=dtype)
    try:
        return np.asarray(x, dtype=dtype)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name} must be numeric, got {x!r}") from error


def _as(x, dtype, name: str, shape: tuple[int, ...]) -> jax.Array:
    x = _converted(x, dtype, name)
    if x.shape != shape:
        raise ValueError(
            f"{name} must have shape {shape}, got {x.shape} (use jax.vmap for batches)"
        )
    return x


def prepare(scene: Scene, state: State, ts, rtol, atol, dtype):
    """Static checks (types, shapes) and dtype conversion of a solve's inputs.

    Args:
        scene: the :class:`~jrigid.scene.Scene`.
        state: one :class:`~jrigid.state.State` (``q (4,)``, ``qdot (4,)``, ``x, v (3,)``
            in free flight).
        ts: ``(T,)`` output times, ``T ≥ 2``.
        rtol, atol: scalars or ``None`` (:func:`default_tolerances`).
        dtype: the floating dtype everything is converted to.

    Returns:
        ``(state, ts, rtol, atol)`` as arrays of ``dtype``.

    Raises:
        ValueError: a wrong type, shape or holder/state mismatch (values are checked by
            :func:`input_checks`).
    """
    if not isinstance(scene, Scene):
        raise ValueError(f"scene must be a jrigid Scene, got {type(scene).__name__}")
    if not isinstance(state, State):
        raise ValueError(
            f"initial_state must be a jrigid State (see jrigid.initial), got {type(state).__name__}"
        )
    moments_shape = jnp.shape(scene.body.moments)
    if moments_shape != (3,):
        raise ValueError(
            f"scene has a batch axis (body.moments has shape {moments_shape}): a solve takes "
            "one scene; for many, jax.vmap over the scenes, or jrigid.ensemble.simulate_many "
            "with a function params -> Scene"
        )
    q, qdot, x, v = state.q, state.qdot, state.x, state.v  # (module fields: slow to read)
    translates = scene.translates
    if translates and (x is None or v is None):
        raise ValueError("a FreeFlight scene needs x and v in the initial state")
    if not translates and (x is not None or v is not None):
        raise ValueError("x and v are only for FreeFlight scenes; this scene does not translate")
    ts = _converted(ts, dtype, "ts")
    if ts.ndim != 1 or ts.shape[0] < 2:
        raise ValueError(f"ts must be a 1-D array of at least 2 times, got shape {ts.shape}")
    rtol = _default_array(dtype, 0) if rtol is None else _as(rtol, dtype, "rtol", ())
    atol = _default_array(dtype, 1) if atol is None else _as(atol, dtype, "atol", ())
    fields = (
        _as(q, dtype, "initial_state.q", (4,)),
        _as(qdot, dtype, "initial_state.qdot", (4,)),
        None if x is None else _as(x, dtype, "initial_state.x", (3,)),
        None if v is None else _as(v, dtype, "initial_state.v", (3,)),
    )
    if fields[0] is not q or fields[1] is not qdot or fields[2] is not x or fields[3] is not v:
        state = State(*fields)
    return state, ts, rtol, atol


#: Indices of the tolerance checks in :func:`input_checks` (their messages get the values).
TOLERANCE_CHECKS = (0, 1, 2)


def shared_checks(ts, rtol, atol) -> list[tuple[jax.Array, str]]:
    """The first entries of :func:`input_checks`: the tolerances ``rtol``, ``atol`` (``()``
    arrays) and the output times ``ts (T,)``, which the members of a batch share."""
    eps = jnp.finfo(rtol.dtype).eps
    name = jnp.dtype(rtol.dtype).name
    return [
        (~jnp.isfinite(rtol) | (rtol <= 0) | (rtol >= 1),
         "rtol must be finite, > 0 and < 1 (a relative error of 1 or more controls nothing)"),
        (
            rtol < 10 * eps,
            f"rtol is below 10 machine epsilons ({10 * float(eps):.3g}) of {name}: the error "
            "control cannot meet it; raise rtol"
            + (" (or enable float64)" if jnp.finfo(rtol.dtype).bits < 64 else ""),
        ),
        (~jnp.isfinite(atol) | (atol < 0), "atol must be finite and >= 0"),
        (~every(jnp.isfinite(ts)), "ts has non-finite entries"),
        (some(jnp.diff(ts) <= 0), "ts must be strictly increasing"),
    ]


def validate_shared(ts, rtol, atol, dtype) -> None:
    """``ValueError`` (:func:`input_checks`' message) for concrete output times ``ts
    (T,)`` or tolerances (``None``: the default) that no solve in ``dtype`` can run with:
    for the settings of a batch (a sweep), checked once, before they are traced, and
    not blamed on one member."""
    rtol = _default_array(dtype, 0) if rtol is None else _as(rtol, dtype, "rtol", ())
    atol = _default_array(dtype, 1) if atol is None else _as(atol, dtype, "atol", ())
    ts = _converted(ts, dtype, "ts")
    if is_traced((ts, rtol, atol)):
        return
    with jax.ensure_compile_time_eval():  # concrete even when called inside a jit
        checks = shared_checks(np.asarray(ts), np.asarray(rtol), np.asarray(atol))
    for index, (bad, _) in enumerate(checks):
        if bool(bad):
            raise ValueError(message(checks, index, rtol, atol))


def input_checks(formulation, scene, state: State, ts, rtol, atol) -> list[tuple[jax.Array, str]]:
    """``[(bad, message), ...]``: every value check of a solve's inputs, in report order.

    The ``bad`` flags are ``()`` boolean arrays (traced under ``jit``/``vmap``): the
    tolerances, the output times, the initial state (finite, a nonzero quaternion), the
    body (:meth:`jrigid.body.RigidBody.problems`) and the formulation's domain (e.g.
    gimbal lock of Euler angles).
    """
    finite = lambda a: every(jnp.isfinite(a))  # noqa: E731
    n = quat.norm(state.q)  # scale-safe: |q| = 1e-300 or 1e300 is a valid orientation
    out = [
        *shared_checks(ts, rtol, atol),
        (~finite(state.q), "initial_state.q has non-finite entries (NaN or inf)"),
        (
            ~(n > 0) & finite(state.q),
            "initial_state.q is the zero quaternion: it represents no rotation",
        ),
        (~finite(state.qdot), "initial_state.qdot is not finite (NaN or inf)"),
    ]
    if state.x is not None:
        out.append((~(finite(state.x) & finite(state.v)), "initial_state.x or .v is not finite"))
    out.extend(scene.body.problems())
    for load in scene.loads:  # (concrete values are checked when a Gravity is made)
        if isinstance(load, Gravity):
            out.append((~finite(load.g), "Gravity.g is not finite (NaN or inf)"))
    domain = formulation.domain_error(scene, normalised(state))
    if domain is not None:
        out.append(domain)
    return out


def normalised(state: State) -> State:
    """``state`` with ``q`` scaled to unit norm (``q̇`` by the same factor).

    Exact for any finite non-zero ``|q|`` (:func:`jrigid.quaternion.norm`), so an
    orientation given as ``1e300 q`` or ``1e-300 q`` integrates as ``q``.
    """
    n = quat.norm(state.q)
    n = jnp.where(n > 0, n, 1.0)
    return State(state.q / n, state.qdot / n, state.x, state.v)


@eqx.filter_jit
def _flags(formulation, scene, state, ts, rtol, atol):
    return jnp.stack([bad for bad, _ in input_checks(formulation, scene, state, ts, rtol, atol)])


def message(checks_or_messages, index: int, rtol=None, atol=None) -> str:
    """The message of check ``index``, with the tolerances' values for a tolerance check."""
    entry = checks_or_messages[index]
    text = entry[1] if isinstance(entry, tuple) else entry
    if index in TOLERANCE_CHECKS and rtol is not None:
        text += f" (got rtol={float(rtol):.3g}, atol={float(atol):.3g})"
    return text


class PrecisionWarning(UserWarning):
    """A solve runs in a floating-point precision that cannot meet its tolerance."""


def precision_problem(state: State, ts, rtol) -> str | None:
    """Why a float32 solve cannot meet ``rtol`` over ``ts``, or ``None``.

    In float32 the time itself is resolved only to ``|t| eps / 2`` (``eps = 1.2e-7``),
    so at the end of the horizon the orientation is uncertain by about
    ``|ω| max(|t0|, |t1|) eps`` radians whatever the step size (``ω`` the initial
    angular velocity, from ``q`` and ``q̇``); rounding in every step adds to that. When
    this floor exceeds ``rtol`` no float32 setting can give outputs as accurate as asked.
    (Below ``10 eps``, ``rtol`` itself is refused by :func:`input_checks`.) The floor is
    a bound, not a forecast: the invariant projection keeps float32's error close to
    float64's at the same ``rtol``, and without it the error is several times larger
    (the README's "What float32 can and cannot do" has the measurements).

    Only float32 inputs are examined (float64 returns ``None`` without any work), and
    only concrete ones: under ``jit``/``vmap`` there are no values to look at.

    Args:
        state: the initial :class:`~jrigid.state.State` (``q (..., 4)``, ``qdot (..., 4)``:
            a batch is judged by its fastest member).
        ts: ``(T,)`` output times.
        rtol: ``()`` relative tolerance; its dtype is the solve's.

    Returns:
        The message, or ``None``.
    """
    dtype = jnp.dtype(rtol.dtype)
    if dtype.itemsize >= 8 or is_traced((state.q, state.qdot, ts, rtol)):
        return None
    q, qdot, ts, rtol = (
        np.asarray(a, np.float64) for a in jax.device_get((state.q, state.qdot, ts, rtol))
    )
    eps = float(jnp.finfo(dtype).eps)
    with np.errstate(all="ignore"):  # |ω| (|q ⊗ q̇| = |q| |q̇|), the largest of a batch
        rates = 2.0 * np.linalg.norm(qdot, axis=-1) / np.linalg.norm(q, axis=-1)
        rate = float(np.max(rates, initial=0.0, where=np.isfinite(rates)))
    horizon = max(abs(ts[0]), abs(ts[-1]))
    floor = rate * horizon * eps
    if not (np.isfinite(floor) and floor > rtol) or rtol < 10 * eps:  # (else refused)
        return None
    return (
        f"{dtype.name} resolves times near t = {horizon:.4g} only to ±{horizon * eps / 2:.2g}: "
        f"at |ω| = {rate:.3g} the orientation there cannot be resolved to better than "
        f"~{floor:.2g} rad, coarser than rtol = {float(rtol):.3g} asks (rounding also "
        "accumulates over the steps, most where no invariants are projected); for accuracy "
        "beyond this floor enable float64 (jax.config.update('jax_enable_x64', True)) and "
        "tighten rtol, or shorten the horizon"
    )


def warn_precision(state: State, ts, rtol, stacklevel: int = 3) -> None:
    """Issue a :class:`PrecisionWarning` if :func:`precision_problem` finds one.

    ``stacklevel`` as in :func:`warnings.warn`, counted from the caller of this
    function (the default points at the caller's caller: the user's call of a solver).
    """
    text = precision_problem(state, ts, rtol)
    if text is not None:
        warnings.warn(text, PrecisionWarning, stacklevel=stacklevel)


def validate(formulation, scene, state, ts, rtol, atol) -> None:
    """Raise ``ValueError`` for the first failed value check (concrete inputs; else nothing)."""
    if is_traced((scene, state, ts, rtol, atol)):
        return
    # concrete inputs inside a jit traced over something else (a leapfrog's dt): checked now
    with jax.ensure_compile_time_eval():
        flags = jax.device_get(_flags(formulation, scene, state, ts, rtol, atol))
    if flags.any():
        checks = input_checks(formulation, scene, state, ts, rtol, atol)
        raise ValueError(message(checks, int(flags.argmax()), rtol, atol))


def guard(tree, checks: list[tuple[jax.Array, str]]):
    """``tree``, with one ``equinox.branched_error_if`` over a list of ``(bad, message)``."""
    bad = jnp.stack([b for b, _ in checks])
    return eqx.branched_error_if(tree, some(bad), first_true(bad), [m for _, m in checks])


def screen(checks, scene: Scene, state: State, ts, rtol, atol):
    """Stand-in inputs for a member whose inputs fail a check (traced, ``vmap``-safe).

    Returns ``(invalid, cause, scene, state, ts, rtol, atol)``: ``invalid ()`` bool,
    ``cause ()`` the index of the first failed check, and the inputs with every array
    of an invalid member replaced by a benign one (a unit sphere at rest, no gravity, the
    identity orientation, ``ts`` spread evenly over ``[0, 1]``, the default tolerances), so that
    its solve is quick and finite; its outputs are then set to NaN and its result to
    :attr:`~jrigid.trajectory.Result.invalid_input` by :func:`~jrigid.solve.outcome.finish`.
    """
    bad = jnp.stack([b for b, _ in checks])
    invalid = some(bad)
    cause = first_true(bad)
    dtype = rtol.dtype
    pick = lambda good, a: jnp.where(invalid, jnp.asarray(good, a.dtype), a)  # noqa: E731
    body = scene.body
    body = eqx.tree_at(
        lambda b: (b.moments, b.mass, b.com, b.frame),
        body,
        (
            pick(jnp.ones(3), body.moments),
            pick(1.0, body.mass),
            pick(jnp.zeros(3), body.com),
            pick(jnp.array([1.0, 0.0, 0.0, 0.0]), body.frame),
        ),
    )
    loads = tuple(
        eqx.tree_at(lambda g: g.g, load, pick(jnp.zeros(3), load.g))
        if isinstance(load, Gravity) else load for load in scene.loads
    )
    scene = eqx.tree_at(lambda s: (s.body, s.loads), scene, (body, loads))
    identity = jnp.array([1.0, 0.0, 0.0, 0.0], dtype)
    state = State(
        pick(identity, state.q),
        pick(jnp.zeros(4), state.qdot),
        None if state.x is None else pick(jnp.zeros(3), state.x),
        None if state.v is None else pick(jnp.zeros(3), state.v),
    )
    ts = pick(jnp.linspace(0.0, 1.0, ts.shape[0], dtype=dtype), ts)
    default_rtol, default_atol = default_tolerances(dtype)
    return invalid, cause, scene, state, ts, pick(default_rtol, rtol), pick(default_atol, atol)
