"""Exact-flow splitting integrators for a body under an orientation-dependent torque.

``simulate(scene, state, ts, solver=Splitting(...))``. The motion of a body turning about a
fixed point (a :class:`~jrigid.scene.Pivot`, or its centre of mass) is split into two
parts that are each solved exactly:

- the *free flow*: the torque-free rotation about the fixed point, Euler's equations
  (17.34–17.35 with ``N = 0``) and ``q̇ = ½ q ⊗ (0, ω)`` (17.44), in closed form by
  :mod:`jrigid.exact`, in the principal frame of the inertia about the fixed point (the
  parallel-axis tensor of a pivoted body is diagonalised once, with
  :func:`jrigid.inertia.principal_axes`, so any centre of mass and any moments work:
  asymmetric, symmetric or spherical);
- the *kick*: for a torque that depends only on the orientation and time (gravity about a
  pivot, a user :class:`~jrigid.scene.Torque` that does not read ``kin.omega``), the
  angular momentum changes at fixed orientation, ``L ← L + τ N(q, t)`` (body frame, which
  is fixed during the kick), which is the exact flow of ``L̇ = N``.

The Strang composition kick(h/2) – free flow(h) – kick(h/2) is second order, time
reversible and, for a conservative torque (``N`` from a potential, e.g. gravity),
symplectic: energy and the conserved momentum components stay within a bounded band
with no drift (Dullweber, Leimkuhler & McLachlan 1997 give this splitting of the rigid
body; Celledoni, Fassò, Säfström & Zanna 2008 use it with the exact free flow). Symmetric
compositions of it with steps ``γ_1 h, …, γ_s h`` (Hairer, Lubich & Wanner, *Geometric
Numerical Integration*, 2nd ed., §V.3, eqs. 3.5–3.14) raise the order while keeping those
properties (:data:`COMPOSITIONS`): Yoshida's triple jump and Suzuki's five-stage method
(order 4), Kahan & Li's ``s = 9`` (order 6) and ``s = 15`` (order 8) methods. Adjacent
kicks merge, so a step costs ``s`` free flows and ``s + 1`` torque evaluations. A time
dependence of the torque is handled in the extended phase space: the free flow advances
``t``, the kick holds it.

Steps are fixed (adaptivity would break the structure): each output interval
``[ts[i], ts[i+1]]`` is cut into ``n_i`` equal steps, ``n_i = steps`` or
``⌈(ts[i+1] − ts[i])/dt⌉``. The loop is a ``jax.lax.scan`` of static length (the bound
``max_steps`` per interval; steps past ``n_i`` are skipped by ``lax.cond``, in chunks, so a
generous bound costs little), each step under ``jax.checkpoint``: reverse-mode gradients
store one state per step, forward mode and ``vmap`` work, and ``dt`` is traced (changing
it does not recompile). Under ``vmap`` with a batched ``dt`` or ``ts`` every member steps
as often as the member that needs most, its extra steps masked.

Cost: a step evaluates one closed-form free flow (:func:`jrigid.exact.prepare` then
:func:`jrigid.exact.evaluate`, elliptic functions) per stage, several times what a stage of
an adaptive Runge–Kutta step costs; the benchmarks page of the documentation ("Under
torque: splitting against adaptive methods") says where that pays and where it does not.

Derivatives inherit :mod:`jrigid.exact`'s one blind spot: where a free flow is exactly
steady (ω along a principal axis, or a symmetric body with ω exactly in its equatorial
plane, e.g. a symmetric top released from rest without spin) they miss the first-order
change of a perturbation that breaks the steadiness.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp
import numpy as np

from jrigid import exact, inertia
from jrigid import quaternion as quat
from jrigid._checks import check_interval_steps, is_traced
from jrigid.scene import Scene
from jrigid.solve import finish_sampled, input_checks, normalised, screen
from jrigid.state import Kinematics, State
from jrigid.trajectory import Result

__all__ = ["CAUSES", "COMPOSITIONS", "Composition", "Splitting", "check_scene", "solve"]

#: The failure texts that differ from the adaptive solver's
#: (:data:`jrigid.trajectory.CAUSES`): the step bound is per output interval and the
#: splitting's own, and it has no tolerances.
CAUSES = {
    Result.max_steps: (
        "an output interval needs more than Splitting(max_steps={max_steps}) steps of its dt",
        "raise the Splitting's max_steps or dt, or add output times in the long interval",
    ),
}


class Composition(NamedTuple):
    """A symmetric composition of the Strang step: ``Φ_{γ_s h} ∘ … ∘ Φ_{γ_1 h}``.

    Attributes:
        order: its classical order.
        gammas: the step fractions ``γ_1 … γ_s`` (palindromic, summing to one).
        source: where the coefficients come from.
    """

    order: int
    gammas: tuple[float, ...]
    source: str


def _palindrome(half: tuple[float, ...]) -> tuple[float, ...]:
    """``(γ_1 … γ_k, 1 − 2 Σγ, γ_k … γ_1)``: a symmetric composition from its first half."""
    return (*half, 1.0 - 2.0 * math.fsum(half), *half[::-1])


_TRIPLE = 1.0 / (2.0 - 2.0 ** (1.0 / 3.0))
_SUZUKI = 1.0 / (4.0 - 4.0 ** (1.0 / 3.0))

#: The compositions :class:`Splitting` offers, by name.
COMPOSITIONS: dict[str, Composition] = {
    "strang": Composition(2, (1.0,), "Strang splitting (HLW eq. II.5.6)"),
    "yoshida4": Composition(
        4, _palindrome((_TRIPLE,)), "Yoshida 1990 triple jump, γ1 = 1/(2 − 2^(1/3)) (HLW 3.5)"
    ),
    "suzuki4": Composition(
        4, _palindrome((_SUZUKI, _SUZUKI)), "Suzuki 1990 fractal, γ1 = 1/(4 − 4^(1/3)) (HLW 3.6)"
    ),
    "kahan_li6": Composition(
        6,
        _palindrome((
            0.39216144400731413927925056,
            0.33259913678935943859974864,
            -0.70624617255763935980996482,
            0.08221359629355080023149045,
        )),
        "Kahan & Li 1997, s = 9 (HLW eq. V.3.12)",
    ),
    "kahan_li8": Composition(
        8,
        _palindrome((
            0.74167036435061295344822780,
            -0.40910082580003159399730010,
            0.19075471029623837995387626,
            -0.57386247111608226665638773,
            0.29906418130365592384446354,
            0.33462491824529818378495798,
            0.31529309239676659663205666,
        )),
        "Kahan & Li 1997, s = 15 (HLW eq. V.3.14)",
    ),
}


def _as_dt(dt):
    return None if dt is None else jnp.asarray(dt, dtype=jnp.result_type(float))


class Splitting(eqx.Module):
    """The splitting solver: pass it as ``simulate(..., solver=Splitting(...))``.

    Attributes:
        method: static, a key of :data:`COMPOSITIONS` (``"strang"``, ``"yoshida4"``,
            ``"suzuki4"``, ``"kahan_li6"``, ``"kahan_li8"``); default ``"kahan_li6"``.
        dt: ``()`` largest step: interval ``i`` gets ``⌈(ts[i+1] − ts[i])/dt⌉`` equal
            steps. Traced (changing it does not recompile). Give ``dt`` or ``steps``.
        steps: static, the number of equal steps per output interval instead.
        max_steps: static bound on the steps per output interval, the length of the
            compiled loop. Default: ``steps``, or computed from ``dt`` and ``ts`` when both
            are concrete (a traced ``dt`` or ``ts`` needs it). An interval that needs
            more ends the solve with :attr:`~jrigid.trajectory.Result.max_steps`.

    Example:
        >>> import jax.numpy as jnp, jrigid
        >>> from jrigid.splitting import Splitting
        >>> body = jrigid.RigidBody(jnp.array([1.0, 2.0, 3.0]), com=jnp.array([0.0, 0.0, 1.0]))
        >>> scene = jrigid.Scene(body, jrigid.Pivot(), jrigid.Gravity(1.0))
        >>> state = jrigid.initial.from_omega(omega=jnp.array([0.1, 0.2, 5.0]))
        >>> traj = jrigid.simulate(scene, state, jnp.linspace(0.0, 10.0, 11),
        ...                        solver=Splitting("yoshida4", dt=0.01))
        >>> int(traj.stats["num_steps"]), int(traj.result)
        (1000, 0)
    """

    method: str = eqx.field(static=True, default="kahan_li6")
    dt: jax.Array | None = eqx.field(default=None, converter=_as_dt)
    steps: int | None = eqx.field(static=True, default=None, kw_only=True)
    max_steps: int | None = eqx.field(static=True, default=None, kw_only=True)

    def __check_init__(self):
        if self.method not in COMPOSITIONS:
            raise ValueError(
                f"Splitting method must be one of {sorted(COMPOSITIONS)}, got {self.method!r}"
            )
        if (self.dt is None) == (self.steps is None):
            raise ValueError("Splitting needs exactly one of dt (the step) or steps (per interval)")
        for name in ("steps", "max_steps"):
            value = getattr(self, name)
            if value is not None and (
                isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1
            ):
                raise ValueError(f"Splitting {name} must be a positive int, got {value!r}")
        if self.dt is not None:
            if self.dt.shape != ():
                raise ValueError(f"Splitting dt must be a scalar, got shape {self.dt.shape}")
            if not is_traced(self.dt) and not bool(jnp.isfinite(self.dt) & (self.dt > 0)):
                raise ValueError(f"Splitting dt must be finite and > 0, got {self.dt}")

    @property
    def composition(self) -> Composition:
        """The :class:`Composition` of :attr:`method`."""
        return COMPOSITIONS[self.method]

    def bound(self, ts) -> int:
        """The static number of loop iterations per output interval for output times ``ts``.

        Raises:
            ValueError: ``dt`` or ``ts`` traced and no ``max_steps`` given.
        """
        if self.max_steps is not None:
            return int(self.max_steps)
        if self.steps is not None:
            return int(self.steps)
        if is_traced(self.dt, ts):
            raise ValueError(
                "Splitting with a traced dt or ts needs max_steps, the static bound on the "
                "steps per output interval"
            )
        spans = np.diff(np.asarray(ts, dtype=np.float64))
        counts = np.ceil(spans / float(self.dt) - 1e-9)
        counts = counts[np.isfinite(counts)]
        check_interval_steps(float(counts.max(initial=1)), self.dt)
        return max(1, int(counts.max(initial=1)))


# --------------------------------------------------------------------------- scene checks


def _reads_omega(scene: Scene) -> bool:
    """Whether the scene's torque depends on the angular velocity (dataflow of its jaxpr)."""
    dtype = jnp.result_type(float)

    def torque(omega, scene, t, q):
        return scene.wrench(t, Kinematics(q, omega))[1]

    closed, _, _ = eqx.filter_make_jaxpr(torque)(
        jnp.zeros(3, dtype), scene, jnp.zeros((), dtype), jnp.array([1.0, 0.0, 0.0, 0.0], dtype)
    )
    jaxpr = closed.jaxpr
    tainted = {id(v) for v in jaxpr.invars[:1]}
    for eqn in jaxpr.eqns:
        if any(id(v) in tainted for v in eqn.invars):
            tainted.update(id(v) for v in eqn.outvars)
    return any(id(v) in tainted for v in jaxpr.outvars)


def check_scene(scene: Scene) -> None:
    """Raise ``ValueError`` unless the splitting applies to ``scene``.

    It applies to a body on a :class:`~jrigid.scene.Pivot` or in
    :class:`~jrigid.scene.FreeRotation` whose torque depends on the orientation and time
    only: :class:`~jrigid.scene.Gravity`, or a :class:`~jrigid.scene.Torque` whose
    function does not read ``kin.omega`` (checked on its traced program).
    """
    if scene.translates:
        raise ValueError(
            "the splitting solver needs a body turning about a fixed point (Pivot or "
            "FreeRotation); for FreeFlight use a diffrax solver"
        )
    if any(load.impulsive for load in scene.loads):
        raise ValueError("the splitting solver cannot apply impulsive loads (Floor)")
    if _reads_omega(scene):
        raise ValueError(
            "the splitting solver needs a torque that depends on the orientation and time "
            "only (its kick holds q fixed); this scene's torque reads kin.omega: use a "
            "diffrax solver"
        )


# --------------------------------------------------------------------------- one step


class _Frame(NamedTuple):
    """Principal frame of the inertia about the fixed point: moments and ``v`` (frame → body)."""

    moments: jax.Array
    v: jax.Array

    @classmethod
    def of(cls, scene: Scene) -> _Frame:
        moments, v = inertia.principal_axes(scene.inertia())
        return cls(moments, v)

    def to_body(self, q, omega):
        return quat.multiply(q, quat.conjugate(self.v)), quat.rotate(self.v, omega)

    def from_body(self, q, omega):
        return quat.multiply(q, self.v), quat.rotate_inverse(self.v, omega)


def _kick(scene, frame, t, q, omega, tau):
    """``L ← L + τ N(q, t)`` at fixed ``q`` (principal-frame ``q, ω``)."""
    q_body, omega_body = frame.to_body(q, omega)
    _, torque = scene.wrench(t, Kinematics(q_body, omega_body))
    return omega + tau * quat.rotate_inverse(frame.v, torque) / frame.moments


def _free_flow(frame, q, omega, tau):
    """The torque-free motion over ``τ`` in closed form (principal-frame ``q, ω``)."""
    # unchecked: a state that diverged under the torque is flagged by the solve's result
    return exact.evaluate(exact.prepare(frame.moments, q, omega, checked=False), tau)


def _stage_table(composition: Composition, dtype):
    """``(kick0, γ (s,), kick (s,))``: kick fractions ``(γ_j + γ_{j+1})/2`` merge neighbours."""
    g = np.asarray(composition.gammas, np.float64)
    kicks = 0.5 * (g + np.append(g[1:], 0.0))
    return 0.5 * g[0], jnp.asarray(g, dtype), jnp.asarray(kicks, dtype)


def _step(scene, frame, composition, t, q, omega, h):
    """One composed step of size ``h`` from ``t`` (principal-frame ``q, ω``)."""
    kick0, gammas, kicks = _stage_table(composition, h.dtype)
    omega = _kick(scene, frame, t, q, omega, kick0 * h)

    def stage(carry, coeffs):
        t, q, omega = carry
        gamma, kick = coeffs
        q, omega = _free_flow(frame, q, omega, gamma * h)
        t = t + gamma * h
        return (t, q, _kick(scene, frame, t, q, omega, kick * h)), None

    (_, q, omega), _ = jax.lax.scan(stage, (t, q, omega), (gammas, kicks))
    return q, omega


# --------------------------------------------------------------------------- the solve


def _counts(spans, dt, steps, bound):
    """``(T − 1,)`` int32 steps per interval, ``bound + 1`` standing for "too many"."""
    if dt is None:
        return jnp.full(spans.shape, steps, jnp.int32)
    good = jnp.isfinite(dt) & (dt > 0) & jnp.isfinite(spans) & (spans > 0)
    ratio = jnp.where(good, spans / jnp.where(good, dt, 1.0), 1.0)
    return jnp.clip(jnp.ceil(ratio - 1e-9), 1.0, bound + 1.0).astype(jnp.int32)


@eqx.filter_jit
def solve(scene, state, ts, rtol, atol, formulation, splitting: Splitting, bound: int):
    """The split :class:`~jrigid.trajectory.Trajectory` at ``ts``, and the check cause.

    Args:
        scene, state, ts, rtol, atol: as prepared by :func:`jrigid.solve.prepare`
            (``rtol``/``atol`` only take part in the input checks).
        formulation: the formulation whose variables fill ``Trajectory.y``.
        splitting: the :class:`Splitting` settings.
        bound: static steps per interval, :meth:`Splitting.bound`.

    Returns:
        ``(trajectory, cause, messages)`` as :func:`jrigid.closed_form.solve`;
        ``stats["num_steps"]`` counts composed steps.
    """
    dtype = ts.dtype
    dt = None if splitting.dt is None else splitting.dt.astype(dtype)
    checks = input_checks(formulation, scene, state, ts, rtol, atol)
    if dt is not None:
        checks.append((~(jnp.isfinite(dt) & (dt > 0)), "Splitting dt must be finite and > 0"))
    messages = tuple(m for _, m in checks)
    # Step counts from the user's ts and dt, before screening: under vmap they stay
    # unbatched when ts and dt are shared, so the skip below stays a real branch.
    counts = _counts(jnp.diff(ts), dt, splitting.steps, bound)
    over = counts > bound
    counts = jnp.minimum(counts, bound)
    every = splitting.steps is not None and splitting.steps == bound
    invalid, cause, scene, state, ts, rtol, atol = screen(checks, scene, state, ts, rtol, atol)
    state = normalised(state)
    spans = jnp.diff(ts)

    frame = _Frame.of(scene)
    composition = splitting.composition
    one = jax.checkpoint(
        lambda t, q, omega, h: _step(scene, frame, composition, t, q, omega, h)
    )

    # Steps k ≥ n are skipped in chunks of about √bound (a short interval under a large
    # bound costs O(√bound) skipped iterations). Each branch predicate is reduced over any
    # vmap batch (`unvmap_any`), so the branches stay real branches: members that are done
    # are masked with `where`, never run on the zero-filled residuals of an untaken branch.
    chunk = bound if every else math.isqrt(bound - 1) + 1
    n_chunks = -(-bound // chunk)

    def interval(carry, i):
        n = counts[i]
        h = spans[i] / n.astype(dtype)

        def advance(y, k):
            moved = one(ts[i] + k.astype(dtype) * h, *y, h)
            return jax.tree_util.tree_map(lambda a, b: jnp.where(k < n, a, b), moved, y)

        def inner(y, k):
            if every:
                return one(ts[i] + k.astype(dtype) * h, *y, h), None
            return jax.lax.cond(eqxi.unvmap_any(k < n), advance, lambda y, k: y, y, k), None

        def outer(y, c):
            ks = c * chunk + jnp.arange(chunk)
            run = lambda y: jax.lax.scan(inner, y, ks)[0]  # noqa: E731
            return jax.lax.cond(eqxi.unvmap_any(c * chunk < n), run, lambda y: y, y), None

        y, _ = jax.lax.scan(outer, carry, jnp.arange(n_chunks))
        return y, y

    y0 = frame.from_body(state.q, state.omega)
    _, (qs, ws) = jax.lax.scan(interval, y0, jnp.arange(spans.shape[0]))
    qs = jnp.concatenate([y0[0][None], qs])
    ws = jnp.concatenate([y0[1][None], ws])
    qs, ws = jax.vmap(frame.to_body)(qs, ws)

    # An interval that needs more than `bound` steps ends the solve before it.
    failed = jnp.any(over)
    first = jnp.argmax(over)
    reached = jnp.arange(ts.shape[0]) <= jnp.where(failed, first, ts.shape[0])
    qs = jnp.where(reached[:, None], qs, jnp.nan)
    ws = jnp.where(reached[:, None], ws, jnp.nan)
    ys = jax.vmap(lambda q, w: formulation.from_state(scene, State(q, quat.derivative(q, w))))(
        qs, ws
    )
    steps = jnp.sum(jnp.where(jnp.arange(spans.shape[0]) < jnp.where(failed, first, spans.shape[0]),
                              counts, 0)).astype(jnp.int32)
    traj = finish_sampled(scene, formulation, ts, ys, invalid, None, steps=steps)
    stop = failed & ~invalid
    traj = eqx.tree_at(
        lambda tr: (tr.result, tr.t_stop),
        traj,
        (jnp.where(stop, jnp.int32(Result.max_steps), traj.result),
         jnp.where(stop, ts[first], traj.t_stop)),
    )
    return traj, cause, messages
