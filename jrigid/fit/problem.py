"""Forward models and the :class:`Problem` that ties parameters to observations.

A *forward model* maps a parameter pytree ``theta`` and times ``ts (T,)`` (``ts[0]`` the
initial time) to a :class:`~jrigid.fit.observations.Prediction`. Both models here take a
user function ``build(theta) -> (Scene, State)`` that uses the maps of
:mod:`jrigid.fit.params` to keep the scene physical:

- :class:`Simulated` — :func:`jrigid.simulate` (any scene: tops, torques);
- :class:`Exact` — the closed-form torque-free solution :func:`jrigid.exact.solve`
  (torque-free scenes only, :attr:`Scene.torque_free`; much faster, no step control);
- :class:`Invariants` — no trajectory, only the constants of torque-free motion, for
  problems whose observations are all closed-form features.

:class:`Problem` evaluates the model once on the sorted union of the observation times
and the initial time ``t0``, and stacks the whitened residuals of every observation.
Its :meth:`Problem.loss` is ``½ Σ r²``. Models and problems are ``equinox`` modules
(the builder and solver options static, the data traced), so two problems that differ
only in their data share one compiled fit.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jrigid import exact
from jrigid.fit.observations import AbstractObservation, Prediction
from jrigid.integrate import simulate
from jrigid.scene import Scene
from jrigid.state import State

__all__ = ["Exact", "Invariants", "Problem", "Simulated"]


def _built(build, theta) -> tuple[Scene, State]:
    out = build(theta)
    if not (
        isinstance(out, tuple)
        and len(out) == 2
        and isinstance(out[0], Scene)
        and isinstance(out[1], State)
    ):
        raise ValueError("build(theta) must return (Scene, State)")
    return out


class Simulated(eqx.Module):
    """Forward model through :func:`jrigid.simulate`.

    Args:
        build: ``theta -> (Scene, State)``; the state is at ``ts[0]``.
        **simulate_kwargs: passed on (``formulation``, ``solver``, ``rtol``, ``atol``,
            ``max_steps``, ``adjoint``...). ``rtol``/``atol`` default to ``1e-10``/``1e-12``
            in float64 so that finite-difference checks of gradients are meaningful.
            ``throw`` defaults to ``False``: a failed integration (e.g. at a wild trial
            point of a line search) yields ``NaN`` residuals, which the line search
            rejects (it backs off), instead of aborting the fit.

    Calling ``model(theta, ts, forward_mode=True)`` swaps the adjoint for
    ``diffrax.ForwardMode()`` (needed by ``jax.jacfwd``, used by :func:`jrigid.fit.laplace`).
    """

    build: Callable[[Any], tuple[Scene, State]] = eqx.field(static=True)
    kwargs: dict = eqx.field(static=True)

    def __init__(self, build: Callable[[Any], tuple[Scene, State]], **simulate_kwargs):
        self.build = build
        kw = dict(simulate_kwargs)
        kw.setdefault("throw", False)
        if jnp.dtype(jnp.result_type(float)).itemsize >= 8:
            kw.setdefault("rtol", 1e-10)
            kw.setdefault("atol", 1e-12)
        self.kwargs = kw

    def __call__(self, theta, ts, *, forward_mode: bool = False) -> Prediction:
        scene, state = _built(self.build, theta)
        kw = dict(self.kwargs)
        if forward_mode:
            kw["adjoint"] = diffrax.ForwardMode()
        traj = simulate(scene, state, ts, **kw)
        moments = scene.body.moments if scene.torque_free else None
        return Prediction(traj.q, traj.omega, scene.body.frame, moments)


class _TorqueFree(eqx.Module):
    """A forward model built on the closed-form torque-free motion of ``build(theta)``."""

    build: Callable[[Any], tuple[Scene, State]] = eqx.field(static=True)

    def __init__(self, build: Callable[[Any], tuple[Scene, State]]):
        self.build = build

    def _prepared(self, theta, refusal: str):
        """``(scene, state, constants)`` of ``build(theta)``; ``ValueError(refusal)`` for a
        scene that is not torque-free."""
        scene, state = _built(self.build, theta)
        if not scene.torque_free:
            raise ValueError(refusal)
        return scene, state, exact.prepare(scene.body.moments, state.q, state.omega)


class Exact(_TorqueFree):
    """Forward model through the closed-form torque-free solution :func:`jrigid.exact.solve`.

    Args:
        build: ``theta -> (Scene, State)`` with a torque-free scene
            (:attr:`~jrigid.scene.Scene.torque_free`: free rotation, or free flight under
            gravity); the state is at ``ts[0]``.
    """

    def __call__(self, theta, ts, *, forward_mode: bool = False) -> Prediction:
        scene, state, consts = self._prepared(
            theta,
            "the Exact model is for torque-free scenes (Scene.torque_free); use Simulated",
        )
        q, omega = exact.evaluate(consts, ts - ts[0])
        return Prediction(q, omega, scene.body.frame, scene.body.moments, consts)


class Invariants(_TorqueFree):
    """Forward model for closed-form features only (:mod:`jrigid.fit.features`).

    Predicts no trajectory: only the moments, the initial spin and the constants of the
    torque-free motion (:func:`jrigid.exact.prepare`), which is all that
    :class:`~jrigid.fit.WobbleRatio` and the other features with ``method="closed"``
    need — a much smaller program to compile and differentiate than :class:`Exact`.
    :class:`Problem` refuses it with any other observation.

    Args:
        build: ``theta -> (Scene, State)``, a torque-free scene
            (:attr:`~jrigid.scene.Scene.torque_free`).
    """

    def __call__(self, theta, ts, *, forward_mode: bool = False) -> Prediction:
        scene, state, consts = self._prepared(
            theta, "the Invariants model is for torque-free scenes (Scene.torque_free)"
        )
        omega = jnp.broadcast_to(state.omega, ts.shape + (3,))
        return Prediction(None, omega, scene.body.frame, scene.body.moments, consts)


class Problem(eqx.Module):
    """Observations of one motion and the model that predicts them.

    Args:
        model: a forward model (:class:`Simulated`, :class:`Exact` or any callable
            ``(theta, ts, *, forward_mode) -> Prediction``).
        observations: one observation or a sequence of them.
        t0: the time of the initial state (default: the earliest observation time).
            Every observation time must be ``≥ t0``.

    :meth:`until` gives the same problem restricted to the observations up to a time
    (``horizon``; ``inf`` here): the residuals after it are zero.

    Raises:
        ValueError: no observations, an observation that is not one, or observation
            times before ``t0``.
    """

    model: Any
    observations: tuple
    t0: jax.Array
    ts: jax.Array
    index: tuple
    horizon: jax.Array

    def __init__(
        self,
        model,
        observations: AbstractObservation | Sequence[AbstractObservation],
        *,
        t0=None,
    ):
        if isinstance(observations, AbstractObservation):
            observations = (observations,)
        observations = tuple(observations)
        if not observations:
            raise ValueError("Problem needs at least one observation")
        for obs in observations:
            if not isinstance(obs, AbstractObservation):
                raise ValueError(
                    "observations must be Gyroscope, Orientations, AxisDirections or a "
                    f"feature of jrigid.fit.features, got {obs!r}"
                )
        if isinstance(model, Invariants) and not all(
            getattr(o, "method", None) == "closed" for o in observations
        ):
            raise ValueError(
                "fit.Invariants predicts no trajectory: use it only with closed-form "
                "features (method='closed'); use fit.Exact or fit.Simulated otherwise"
            )
        all_ts = np.concatenate([np.asarray(o.ts) for o in observations])
        t0 = float(all_ts.min()) if t0 is None else float(t0)
        if not np.isfinite(t0):
            raise ValueError(f"t0 must be finite, got {t0}")
        if all_ts.min() < t0:
            raise ValueError(
                f"observation times start at {all_ts.min():.6g}, before the initial time "
                f"t0={t0:.6g}: the times do not match the model"
            )
        grid = np.unique(np.concatenate([[t0], all_ts]))
        self.model = model
        self.observations = observations
        self.t0 = jnp.asarray(t0, dtype=jnp.result_type(float))
        self.ts = jnp.asarray(grid, dtype=jnp.result_type(float))
        self.index = tuple(
            jnp.asarray(np.searchsorted(grid, np.asarray(o.ts))) for o in observations
        )
        self.horizon = jnp.asarray(np.inf, dtype=jnp.result_type(float))

    @property
    def size(self) -> int:
        """Total number of residuals."""
        return sum(o.size for o in self.observations)

    @property
    def active_size(self) -> int:
        """Degrees of freedom of the residuals up to :attr:`horizon` (all of them unless
        :meth:`until`): one per residual, except where an observation's residuals are
        tied (:meth:`AbstractObservation.degrees`, e.g. two per sample of
        :class:`~jrigid.fit.AxisDirections`). χ²/dof and the tests count these."""
        return sum(o.degrees(self.horizon) for o in self.observations)

    def until(self, t_end) -> Problem:
        """The same problem with only the observations up to ``t_end``.

        The residuals of later samples (and of features whose record ends later) are
        zero; every array keeps its shape, so a compiled fit is reused. A fit from a far
        start goes wrong less often on a short record, whose loss has fewer local optima:
        fit a short record first and lengthen it (``fit(..., horizons=...)``).

        Args:
            t_end: ``()`` the last time kept (finite, ``≥ t0``).

        Raises:
            ValueError: a non-finite ``t_end``, or one that keeps no residual.
        """
        t = float(t_end)
        if not np.isfinite(t):
            raise ValueError(f"t_end must be finite, got {t}")
        out = eqx.tree_at(lambda p: p.horizon, self, jnp.asarray(t, self.horizon.dtype))
        if out.active_size == 0:
            raise ValueError(
                f"no observation up to t_end={t:.6g} (the first sample is at "
                f"{float(self.ts[1] if self.ts.shape[0] > 1 else self.ts[0]):.6g})"
            )
        return out

    @property
    def sigma_given(self) -> bool:
        """Whether every observation was given its noise level ``sigma``."""
        return all(getattr(o, "sigma_given", True) for o in self.observations)

    def moments(self, theta) -> jax.Array | None:
        """``(3,)`` principal moments of the body the model builds from ``theta``.

        ``None`` when the model has no ``build`` (a plain callable model).
        """
        build = getattr(self.model, "build", None)
        if build is None:
            return None
        scene, _ = _built(build, theta)
        return scene.body.moments

    def predict(self, theta, *, forward_mode: bool = False) -> Prediction:
        """The model's :class:`Prediction` on the union time grid ``self.ts``."""
        return self.model(theta, self.ts, forward_mode=forward_mode)

    def residuals(self, theta, *, forward_mode: bool = False) -> jax.Array:
        """``(N,)`` whitened residuals of all observations, concatenated (zero after
        :attr:`horizon`)."""
        pred = self.predict(theta, forward_mode=forward_mode)
        closed = any(getattr(o, "method", None) == "closed" for o in self.observations)
        if closed and pred.constants is None and pred.moments is not None:
            # once for all closed-form features (they only need the invariants at t0)
            identity = jnp.zeros(4, pred.omega.dtype).at[0].set(1.0)
            pred = pred._replace(constants=exact.prepare(pred.moments, identity, pred.omega[0]))
        parts = []
        for obs, idx in zip(self.observations, self.index, strict=True):
            sub = pred._replace(q=None if pred.q is None else pred.q[idx], omega=pred.omega[idx])
            parts.append(jnp.where(obs.in_window(self.horizon), obs.residuals(sub), 0.0))
        return jnp.concatenate(parts)

    def loss(self, theta) -> jax.Array:
        """``()`` ``½ Σ r²`` (negative log-likelihood up to a constant)."""
        r = self.residuals(theta)
        return 0.5 * jnp.sum(r * r)
