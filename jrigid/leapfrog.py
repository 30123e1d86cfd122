"""The chapter's leapfrog (eqs. 17.45–17.46): a fixed-step baseline stepper.

The space-frame angular momentum is kicked by the torque,
``L(t + Δt/2) = L(t − Δt/2) + N(t) Δt`` (17.45), and the quaternion is drifted with
the rate at the half step, ``q(t + Δt) = q(t) + q̇(t + Δt/2) Δt`` (17.46), then
renormalised. Written as kick–drift–kick:

1. ``L_½ = L_n + ½Δt N(t_n)`` (space frame; ``v_½ = v_n + ½Δt F/M`` in free flight);
2. drift: ``q̇(q, L) = ½ q ⊗ (0, ω)`` with ``ω = I⁻¹ (q* ⊗ L_½ ⊗ q)``. The chapter's
   listing evaluates ``q̇`` at ``q_n`` (``variant="chapter"``): this is first order in
   ``Δt``. The default ``variant="midpoint"`` takes ``q̇(t + Δt/2)`` literally, at a
   predicted ``q_½ = normalize(q_n + ½Δt q̇(q_n, L_½))``, which makes the scheme
   second order (tested);
3. ``L_{n+1} = L_½ + ½Δt N(t_{n+1})`` (one corrector pass, so torques that depend on
   ω keep the order).

Each output interval ``[ts[i], ts[i+1]]`` is cut into ``⌈Δ/dt⌉`` equal steps. With
``ts`` and ``dt`` concrete the loops have fixed lengths and both forward and reverse mode
(``jax.grad``) work; with either traced the trip counts are computed in the program and
only forward mode works (see :func:`leapfrog`).
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from jrigid import linalg
from jrigid import quaternion as quat
from jrigid._checks import check_interval_steps
from jrigid.formulations import AbstractFormulation
from jrigid.scene import Scene
from jrigid.solve import finish_sampled, guard, input_checks, normalised, prepare, validate
from jrigid.state import Kinematics, State
from jrigid.trajectory import Trajectory

__all__ = ["LeapfrogState", "leapfrog", "leapfrog_step"]


class LeapfrogState(eqx.Module):
    """Leapfrog variables: ``q (4,)``, space-frame angular momentum ``L (3,)``, ``x, v``."""

    q: jax.Array
    L: jax.Array
    x: jax.Array | None = None
    v: jax.Array | None = None


def _omega(scene: Scene, q: jax.Array, L: jax.Array) -> jax.Array:
    return scene.omega_from_momentum(quat.rotate_inverse(q, L))


class _LeapfrogVariables(AbstractFormulation):
    """Kinematics of :class:`LeapfrogState` (used to build the :class:`Trajectory`)."""

    name: ClassVar[str] = "leapfrog"

    def kinematics(self, scene, y):
        return Kinematics(y.q, _omega(scene, y.q, y.L), y.x, y.v)

    def raw_quaternion(self, y):
        return y.q


def leapfrog_step(
    scene: Scene, t: ArrayLike, y: LeapfrogState, dt: ArrayLike, variant: str = "midpoint"
) -> LeapfrogState:
    """One kick–drift–kick step of the leapfrog (17.45–17.46) with renormalisation.

    Args:
        scene: the scene (one, unbatched).
        t: ``()`` time at the start of the step.
        y: :class:`LeapfrogState` at ``t``.
        dt: ``()`` step.
        variant: ``"midpoint"`` (second order, default) or ``"chapter"`` (``q̇`` at
            ``q(t)``, first order). Static.

    Returns:
        :class:`LeapfrogState` at ``t + dt``.
    """
    mass = scene.body.mass
    half = 0.5 * dt

    def wrench(tt, q, L, x, v):
        force, torque = scene.wrench(tt, Kinematics(q, _omega(scene, q, L), x, v))
        return force, quat.rotate(q, torque)

    f0, n0 = wrench(t, y.q, y.L, y.x, y.v)
    L_half = y.L + half * n0
    v_half = None if y.v is None else y.v + half * f0 / mass
    rate = lambda q: quat.derivative(q, _omega(scene, q, L_half))
    if variant == "chapter":
        q1 = linalg.unit(y.q + dt * rate(y.q))
    elif variant == "midpoint":
        q_mid = linalg.unit(y.q + half * rate(y.q))
        q1 = linalg.unit(y.q + dt * rate(q_mid))
    else:
        raise ValueError(f"variant must be 'midpoint' or 'chapter', got {variant!r}")
    x1 = None if y.x is None else y.x + dt * v_half
    f1, n1 = wrench(t + dt, q1, L_half, x1, v_half)
    L1 = L_half + half * n1
    v1 = None if v_half is None else v_half + half * f1 / mass
    f1, n1 = wrench(t + dt, q1, L1, x1, v1)  # corrector: ω-dependent torques
    L1 = L_half + half * n1
    v1 = None if v_half is None else v_half + half * f1 / mass
    return LeapfrogState(q1, L1, x1, v1)


_VARIABLES = _LeapfrogVariables()


@eqx.filter_jit
def _run(scene, state, ts, rtol, atol, dt, variant, steps_bound):
    state, ts = guard((state, ts), input_checks(_VARIABLES, scene, state, ts, rtol, atol))
    dt = eqx.error_if(dt, ~(jnp.isfinite(dt) & (dt > 0)), "leapfrog: dt must be finite and > 0")
    state = normalised(state)
    L0 = quat.rotate(state.q, scene.inertia() @ state.omega)
    y0 = LeapfrogState(state.q, L0, state.x, state.v)
    ys, steps = _intervals(scene, ts, dt, variant, y0, steps_bound)
    ys = jax.tree_util.tree_map(lambda a0, a: jnp.concatenate([a0[None], a]), y0, ys)
    return finish_sampled(scene, _VARIABLES, ts, ys, steps=steps)


def _intervals(scene, ts, dt, variant, y0, steps_bound):
    """The states at ``ts[1:]`` and the step count.

    Each interval takes ``⌈Δ/dt⌉`` equal steps. With ``steps_bound`` (``(longest,
    uniform)``: the largest of those counts and whether they are all equal, known
    before tracing) every loop has a fixed length, which reverse mode can enter; an
    interval with fewer steps than the longest skips the rest. With ``None`` (``ts`` or
    ``dt`` traced) the loops' lengths are traced: forward-mode derivatives only.
    """
    longest, uniform = (None, False) if steps_bound is None else steps_bound

    def interval(carry, i):
        y, steps = carry
        span = ts[i + 1] - ts[i]
        if uniform:
            n = jnp.int32(longest)
        else:
            n = _step_counts(span, dt, jnp).astype(jnp.int32)
            if longest is not None:  # (equal to the count computed before tracing)
                n = jnp.minimum(n, longest)
        h = span / n.astype(span.dtype)

        def step(k, yk):
            return leapfrog_step(scene, ts[i] + k * h, yk, h, variant)

        if longest is None:
            y = jax.lax.fori_loop(0, n, step, y)
        elif uniform:
            y = jax.lax.fori_loop(0, longest, step, y)
        else:
            y = jax.lax.fori_loop(
                0, longest, lambda k, yk: jax.lax.cond(k < n, step, lambda k, yk: yk, k, yk), y
            )
        return (y, steps + n), y

    (_, steps), ys = jax.lax.scan(interval, (y0, jnp.int32(0)), jnp.arange(ts.shape[0] - 1))
    return ys, steps


def _steps_bound(ts, dt) -> tuple[int, bool] | None:
    """``(longest, uniform)`` of the intervals' step counts ``⌈Δ/dt⌉`` (at least 1), as
    :func:`_intervals` computes them, or ``None`` if ``ts`` or ``dt`` is traced."""
    if isinstance(ts, jax.core.Tracer) or isinstance(dt, jax.core.Tracer):
        return None
    counts = _step_counts(np.diff(np.asarray(ts)), np.asarray(dt), np)
    check_interval_steps(float(np.max(counts, initial=1.0)), dt)
    return int(counts.max()), bool(counts.min() == counts.max())


def _step_counts(span, dt, xnp):
    """``⌈span/dt⌉`` steps (at least 1) per output interval, with NumPy or JAX (``xnp``)."""
    return xnp.maximum(xnp.ceil(span / dt - 1e-9), 1.0)


def leapfrog(
    scene: Scene,
    initial_state: State,
    ts: ArrayLike,
    *,
    dt: ArrayLike,
    variant: str = "midpoint",
) -> Trajectory:
    """Integrate ``scene`` with the fixed-step leapfrog and sample at ``ts``.

    Args:
        scene: the :class:`~jrigid.scene.Scene`.
        initial_state: :class:`~jrigid.state.State` at ``ts[0]``.
        ts: ``(T,)`` strictly increasing output times.
        dt: ``()`` largest step; each output interval uses ``⌈Δ/dt⌉`` equal steps.
            With ``ts`` and ``dt`` concrete the loops' lengths are fixed before
            tracing, and ``jax.grad`` works through the steps (a ``dt`` that changes
            the longest interval's count compiles anew); with either traced (under
            ``jax.jit``: changing ``dt`` does not recompile) they are computed in the
            program, and only forward mode (``jax.jacfwd``) differentiates it.
        variant: ``"midpoint"`` (default, second order) or ``"chapter"`` (first order).

    Returns:
        :class:`~jrigid.trajectory.Trajectory` (formulation name ``"leapfrog"``;
        ``stats["num_steps"]`` counts the steps; ``result`` flags non-finite values).
    """
    if variant not in ("midpoint", "chapter"):
        raise ValueError(f"variant must be 'midpoint' or 'chapter', got {variant!r}")
    dtype = jnp.result_type(float)
    state, ts, rtol, atol = prepare(scene, initial_state, ts, None, None, dtype)
    dt = jnp.asarray(dt, dtype=dtype)
    if dt.shape != ():
        raise ValueError(f"dt must be a scalar, got shape {dt.shape}")
    validate(_VARIABLES, scene, state, ts, rtol, atol)
    if not isinstance(dt, jax.core.Tracer) and not bool(jnp.isfinite(dt) & (dt > 0)):
        raise ValueError(f"dt must be finite and > 0, got {dt}")
    return _run(scene, state, ts, rtol, atol, dt, variant, _steps_bound(ts, dt))
