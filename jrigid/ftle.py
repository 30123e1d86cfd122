"""Finite-time Lyapunov exponents of Euler's equations, by forward-mode autodiff.

``FTLE = log σ_max(J)/T`` with ``J = ∂ω(T)/∂ω(0)``, the ``3×3`` sensitivity of the body
angular velocity after a time ``T`` to its initial value, taken with ``jax.jacfwd``
through the closed-form motion (:func:`ftle_exact`, :mod:`jrigid.exact`) or through
:func:`jrigid.simulate` with ``diffrax.ForwardMode`` (:func:`ftle_simulate`). Large near
the separatrix of the intermediate axis, small about the stable axes: one of the numbers
of a stability map (:func:`jrigid.stability.map_member`).
"""

from __future__ import annotations

import diffrax
import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from jrigid import exact, inertia, initial
from jrigid import quaternion as quat
from jrigid._checks import as_floats, check_shape, is_traced
from jrigid.body import RigidBody
from jrigid.integrate import simulate
from jrigid.scene import Scene

__all__ = ["ftle_exact", "ftle_simulate"]


def _log_sigma_max(jac: jax.Array) -> jax.Array:
    return jnp.log(jnp.linalg.svd(jac, compute_uv=False)[0])


def _inputs(moments: ArrayLike, omega0: ArrayLike, t: ArrayLike):
    """``(moments (3,), omega0 (3,), t (), ok ())`` as arrays of one floating dtype,
    checked: a physical inertia, a finite ω0 and a finite horizon ``t > 0``. Concrete
    values raise ``ValueError``; traced ones (a member of a sweep under ``vmap``) give
    ``ok`` False instead, with stand-in values, so that one bad member gets NaN and does
    not stop the others."""
    moments, omega0, t = as_floats(moments, omega0, t)
    moments = check_shape(moments, "moments (principal moments)", (3,))
    omega0 = check_shape(omega0, "omega0 (initial body angular velocity)", (3,))
    if jnp.ndim(t) != 0:
        raise ValueError(f"t must be a scalar horizon, got shape {jnp.shape(t)}")
    with jax.ensure_compile_time_eval():  # concrete values: checked now, even inside a jit
        bad_inertia = [bad for _, bad, _, _ in inertia.conditions(moments, kind="moments")]
        bad = {"omega0 must be finite": ~jnp.all(jnp.isfinite(omega0)),
               "t must be a finite horizon > 0": ~(jnp.isfinite(t) & (t > 0))}
    if not is_traced(moments, omega0, t):
        inertia.validate(moments, kind="moments")
        for text, flag in bad.items():
            if bool(flag):
                raise ValueError(f"{text}, got omega0 {omega0}, t {t}")
        return moments, omega0, t, jnp.asarray(True)
    ok = ~jnp.any(jnp.stack([*bad_inertia, *bad.values()]))
    # the member that fails is computed at a harmless stand-in (then NaN), so that the
    # solvers' own run-time checks do not stop the batch
    stand_in = jnp.asarray([1.0, 2.0, 3.0], moments.dtype)
    return (jnp.where(ok, moments, stand_in), jnp.where(ok, omega0, stand_in),
            jnp.where(ok, t, 1.0), ok)


def ftle_exact(moments: ArrayLike, omega0: ArrayLike, t: ArrayLike) -> jax.Array:
    """Finite-time Lyapunov exponent of Euler's equations from the closed-form motion.

    ``FTLE = log σ_max(J)/t`` with ``J = ∂ω(t)/∂ω(0)`` (``3×3``, dimensionless) by
    ``jax.jacfwd`` through :func:`jrigid.exact.solve`. In the stable regions ``J`` grows
    at most linearly (the period depends on the amplitude), so the FTLE decays like
    ``log(t)/t``; near the separatrix it is close to the saddle's rate
    ``λ = |ω| √((I3−I2)(I2−I1)/(I1 I3))`` for times up to the first flip.
    Only ω is used, not the orientation: the orientation's phase grows linearly in ``t``
    for every direction and would add the same ``log(t)/t`` floor everywhere.

    Args:
        moments: ``(3,)`` principal moments.
        omega0: ``(3,)`` initial body angular velocity (not exactly on a principal axis,
            where the closed form's derivative is that of the steady spin).
        t: ``()`` horizon ``> 0``.

    Returns:
        ``()`` FTLE in 1/time; NaN for a traced input that fails the checks below (one
        member of a sweep does not stop the others).

    Raises:
        ValueError: (concrete inputs) a non-physical inertia (as :func:`ftle_simulate`),
            a non-finite ``omega0``, or a horizon ``t`` that is not finite and ``> 0``.
    """
    moments, omega0, t, ok = _inputs(moments, omega0, t)
    q0 = quat.identity(dtype=omega0.dtype)
    # Tie the moments to the traced ω0, so exact.prepare sees a tracer (not a concrete
    # array captured by jit) and skips its concrete-value check.
    moments = moments * jnp.ones_like(omega0)

    def final(w):
        return exact.solve(moments, q0, w, t[None])[1][0]

    return jnp.where(ok, _log_sigma_max(jax.jacfwd(final)(omega0)) / t, jnp.nan)


def ftle_simulate(
    moments: ArrayLike,
    omega0: ArrayLike,
    t: ArrayLike,
    *,
    rtol: ArrayLike = 1e-10,
    atol: ArrayLike = 1e-12,
    solver: diffrax.AbstractSolver | None = None,
    max_steps: int = 100_000,
    formulation: str = "body_omega",
) -> jax.Array:
    """:func:`ftle_exact` computed by forward-mode autodiff through :func:`jrigid.simulate`.

    ``jax.jacfwd`` of ``ω(t)`` with respect to ``ω(0)`` through the adaptive solve with
    ``adjoint=diffrax.ForwardMode()`` (three tangent solves alongside the primal).

    Args:
        moments: ``(3,)`` principal moments.
        omega0: ``(3,)`` initial body angular velocity.
        t: ``()`` horizon ``> 0``.
        rtol, atol: tolerances of the solve.
        solver: diffrax solver (default: :func:`jrigid.simulate`'s).
        max_steps: step budget.
        formulation: static, :func:`jrigid.simulate`'s formulation; the default
            ``"body_omega"`` integrates Euler's equations alone (ω needs no orientation).

    Returns:
        ``()`` FTLE in 1/time; NaN if the solve failed (``max_steps`` exhausted, the step
        size collapsed), or for a traced input that fails the checks below.

    Raises:
        ValueError: (concrete inputs) a non-physical inertia, a non-finite ``omega0``,
            or a horizon ``t`` that is not finite and ``> 0``.
    """
    moments, omega0, t, ok = _inputs(moments, omega0, t)
    scene = Scene(RigidBody(moments))
    ts = jnp.stack([jnp.zeros_like(t), t])

    def final(w):
        traj = simulate(
            scene,
            initial.from_omega(None, w),
            ts,
            rtol=rtol,
            atol=atol,
            solver=solver,
            adjoint=diffrax.ForwardMode(),
            max_steps=max_steps,
            formulation=formulation,
            throw=False,
        )
        return traj.omega[-1], traj.result

    jac, result = jax.jacfwd(final, has_aux=True)(omega0)
    # a failed solve (step budget, step-size collapse) has no FTLE: NaN, not the -inf of
    # its zero tangents, which a map would show as the most stable direction of all
    return jnp.where(ok & (result == 0), _log_sigma_max(jac) / t, jnp.nan)
