"""Impulsive contact with a horizontal floor: a :class:`Floor` load and :func:`simulate_bounces`.

A body in free flight (:class:`~jrigid.scene.FreeFlight`, usually with
:class:`~jrigid.scene.Gravity`) falls onto the plane ``z = height``. Its shape enters
only through a set of body-frame contact points (the corners of a box,
:func:`jrigid.impacts.box_corners`): between contacts the motion is integrated by
diffrax; a contact is the moment the lowest point reaches the floor, located by a
terminating :class:`diffrax.Event` whose root finder (``optimistix.Bisection``, robust
where the lowest point changes) solves ``min_k z_k(t) = height − contact_tol`` on the
dense output; there the velocities jump by an impulse and the integration starts again.

The impulse at a contact (Newton restitution with Coulomb friction) is computed by
:mod:`jrigid.impacts`, whose docstring states the model.

Several points near the floor at once (a box landing on an edge or face) get their
impulses together: each point's target is Newton's ``u_n⁺ = −e u_n⁻`` of its own velocity
before the contact, and sweeps over the points (projected Gauss–Seidel on the accumulated
impulses, normal parts ``≥ 0``, tangential parts in the friction cone) converge to
impulses that meet every target at once. A box landing flat leaves the floor at ``e``
times its speed, without spin.

:func:`simulate_bounces` drives the segments from Python (each segment and each contact
resolution is one compiled call), so it is not itself ``jit``/``grad``-able; the pure
functions of :mod:`jrigid.impacts` are. It stops at the final time, after
``max_bounces`` contacts, or when contacts pile up: ``rapid_bounces`` consecutive
contacts each less than ``min_gap`` after the previous one ("too many bounces in too
short a time", status ``"resting"``); the body is then held still and the kinetic energy
left is reported as dropped. The model has impulses only, no sustained contact,
so this is also where it stops when a body would go on sliding or rolling along the
floor, or pivoting on an edge while it tips over: then the dropped energy is not small,
and a :class:`RestingWarning` says so (more than :data:`RESTING_ENERGY` of the largest
kinetic energy at a contact).

Errors: with concrete values bad input raises ``ValueError`` (:class:`Floor` at
construction, :func:`simulate_bounces` before compiling).
"""

from __future__ import annotations

import math
import warnings
from typing import Any, ClassVar, NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jax.typing import ArrayLike

from jrigid import quaternion as quat
from jrigid._checks import as_float, is_traced
from jrigid.formulations import check_scene, get_formulation
from jrigid.impacts import (  # the impact mechanics, also importable from here
    apply_impulse,
    box_corners,  # noqa: F401
    collision_matrix,
    contact_impulse,
    effective_mass,  # noqa: F401
    point_positions,
    point_velocities,  # noqa: F401
)
from jrigid.scene import AbstractLoad, Scene
from jrigid.solve import (
    DEFAULT_SOLVER,
    ProjectedSolver,
    classify,
    controller,
    prepare,
    validate,
)
from jrigid.state import State
from jrigid.trajectory import Result, Trajectory

__all__ = ["BounceRun", "Floor", "RestingWarning", "simulate_bounces"]

#: The kinetic energy a ``"resting"`` stop may drop, relative to the largest kinetic
#: energy the body had at a contact, before :class:`RestingWarning` says it was moving.
RESTING_ENERGY = 1e-6


class RestingWarning(UserWarning):
    """A body held still at a ``"resting"`` stop was still moving along the floor (or
    turning): the model has no sustained contact, so its sliding, rolling or tipping over
    is not simulated."""


# --------------------------------------------------------------------------- the floor


class Floor(AbstractLoad):
    """A horizontal floor ``z = height`` the body bounces on (space ``z`` up).

    Exerts no force between contacts (``wrench`` and ``potential`` are zero); contacts are
    impulses handled by :func:`simulate_bounces` (:func:`jrigid.simulate` rejects scenes
    with a floor). Needs a :class:`~jrigid.scene.FreeFlight` holder.

    Attributes:
        points: ``(K, 3)`` body-frame contact points relative to the centre of mass,
            principal frame (e.g. :func:`box_corners`); the body's convex hull.
        height: ``()`` floor height.
        restitution: ``()`` coefficient of restitution ``e`` in ``[0, 1]``.
        friction: ``()`` Coulomb coefficient ``μ ≥ 0``.

    Concrete bad values raise ``ValueError`` at construction.
    """

    points: jax.Array = eqx.field(converter=as_float)
    height: jax.Array = eqx.field(converter=as_float, default=0.0)
    restitution: jax.Array = eqx.field(converter=as_float, default=1.0)
    friction: jax.Array = eqx.field(converter=as_float, default=0.0)

    impulsive: ClassVar[bool] = True

    def __check_init__(self):
        if self.points.ndim != 2 or self.points.shape[1] != 3 or self.points.shape[0] < 1:
            raise ValueError(f"Floor points must have shape (K, 3), got {self.points.shape}")
        for name in ("height", "restitution", "friction"):
            if jnp.shape(getattr(self, name)) != ():
                raise ValueError(f"Floor {name} must be a scalar, got shape "
                                 f"{jnp.shape(getattr(self, name))} (one floor per scene; "
                                 "jax.vmap over scenes for several)")
        if is_traced(self.points, self.height, self.restitution, self.friction):
            return
        e, mu = float(self.restitution), float(self.friction)
        if not 0.0 <= e <= 1.0:
            raise ValueError(f"Floor restitution must be in [0, 1], got {e}")
        if not (np.isfinite(mu) and mu >= 0.0):
            raise ValueError(f"Floor friction must be finite and >= 0, got {mu}")
        if not (np.all(np.isfinite(self.points)) and np.isfinite(float(self.height))):
            raise ValueError("Floor points and height must be finite")

    def wrench(self, t, kin, scene):
        zero = jnp.zeros(3, dtype=kin.omega.dtype)
        return zero, zero


def _floor(scene: Scene) -> Floor:
    floors = [load for load in scene.loads if isinstance(load, Floor)]
    if len(floors) != 1 or not scene.translates:
        raise ValueError("simulate_bounces needs a FreeFlight scene with exactly one Floor load")
    return floors[0]


# --------------------------------------------------------------------------- compiled parts


def _lowest(scene, formulation, y):
    floor = _floor(scene)
    kin = formulation.kinematics(scene, y)
    return jnp.min(point_positions(kin.q, kin.x, floor.points)[:, 2]) - floor.height


#: The step counts of a segment's ``diffrax`` solve, summed over the segments.
_STEP_COUNTS = ("num_steps", "num_accepted_steps", "num_rejected_steps")


@eqx.filter_jit
def _segment(scene, formulation, solver, y0, t0, t1, rtol, atol, dt0, depth, max_steps):
    """Integrate from ``t0`` until ``t1`` or the next contact: the lowest point crossing
    ``depth`` below the floor downwards (``depth > 0`` keeps the start, on the floor,
    strictly above the event level).

    Returns ``(t_end, y_end, code, interpolation, counts)`` with ``counts (3,)`` the
    solve's :data:`_STEP_COUNTS` and ``code`` 0 (reached ``t1``), 1 (contact) or a
    :class:`~jrigid.trajectory.Result` failure code + 10.
    """
    eps = jnp.finfo(t0.dtype).eps
    # the bisection stops when the bracket is below root_atol + rtol |t| and
    # |height| < root_atol
    root_atol = jnp.maximum(0.5 * depth, 1000 * eps)
    event = diffrax.Event(
        lambda t, y, args, **kw: _lowest(args, formulation, y) + depth,
        optx.Bisection(rtol=100 * eps, atol=root_atol, flip="detect"),
        direction=False,
    )
    steps = controller(jnp.stack([t0, t1]), rtol, atol, formulation=formulation)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(formulation.vector_field), solver, t0, t1, dt0, y0, args=scene,
        saveat=diffrax.SaveAt(t1=True, dense=True, controller_state=True),
        stepsize_controller=steps, event=event, max_steps=max_steps, throw=False,
    )  # fmt: skip
    R = diffrax.RESULTS
    # a bisection out of iterations still brackets the contact time to a few ulps of t
    hit = (sol.result == R.event_occurred) | (sol.result == R.nonlinear_max_steps_reached)
    y1 = jax.tree_util.tree_map(lambda a: a[-1], sol.ys)
    failure = classify(sol.result, formulation, scene, y1, sol.ts[-1], sol.ys, t1 - t0,
                       nonfinite_trials=steps.nonfinite_trials(sol.controller_state))
    code = jnp.where(sol.result == R.successful, 0, jnp.where(hit, 1, 10 + failure))
    counts = jnp.stack([sol.stats[k] for k in _STEP_COUNTS])
    return sol.ts[-1], y1, code, sol.interpolation, counts


@eqx.filter_jit
def _sample(interpolation, ts, t_a, t_b):
    return jax.vmap(interpolation.evaluate)(jnp.clip(ts, t_a, t_b))


def _energies(scene, kin):
    m = scene.body.mass
    return jnp.stack([0.5 * m * jnp.dot(kin.v, kin.v),
                      0.5 * jnp.dot(kin.omega, scene.body.moments * kin.omega),
                      scene.potential_energy(kin)])  # fmt: skip


def _sequential(m, moments, q, floor, r_all, near, v, omega, max_iter):
    """One point at the floor: impulses at it until it no longer approaches (one impulse,
    :func:`jrigid.impacts.contact_impulse`, unless rounding leaves it approaching)."""
    n = jnp.zeros(3, dtype=v.dtype).at[2].set(1.0)

    def approaching(v, omega):
        un = point_velocities(q, omega, v, floor.points)[:, 2]
        return jnp.where(near, un, jnp.inf)

    def cond(c):
        return (jnp.min(approaching(c[0], c[1])) < 0) & (c[2] < max_iter)

    def body(c):
        v, omega, count, first, P_sum = c
        un = approaching(v, omega)
        k = jnp.argmin(un)
        r = r_all[k]
        P = contact_impulse(m, moments, q, v, omega, r, n, floor.restitution, floor.friction)
        v2, omega2 = apply_impulse(m, moments, q, v, omega, r, P)
        un2 = point_velocities(q, omega2, v2, floor.points)[k, 2]
        rec = jnp.concatenate([k[None].astype(v.dtype), un[k][None], un2[None], P])
        first = jnp.where(count == 0, rec, first)
        return v2, omega2, count + 1, first, P_sum + P

    first0 = jnp.full(6, jnp.nan, dtype=v.dtype)
    init = (v, omega, jnp.zeros((), jnp.int32), first0, jnp.zeros(3, v.dtype))
    return jax.lax.while_loop(cond, body, init)


def _simultaneous(m, moments, q, floor, r_all, near, v, omega, max_sweeps):
    """Several points at the floor: their impulses solved together (projected
    Gauss–Seidel on the accumulated impulses, Catto's sequential impulses, :func:`_pgs`).

    Each point's target is Newton's ``u_n⁺ = −e u_n⁻`` of its velocity *before* the
    contact (a near point that was not approaching: ``u_n⁺ ≥ 0``); sweeps over the points
    move each one's accumulated impulse toward its target, normal part ``≥ 0``,
    tangential part within the friction cone ``|P_t| ≤ μ P_n`` (Coulomb, from the point's
    own ``2 × 2`` block of the collision matrix), until no impulse changes by more than
    ``eps^¾`` of the largest ``M |u_n⁻|``. A body landing flat on four corners leaves
    the floor at ``e`` times its speed, without spin; impulses applied one point at a time,
    each from the velocity the previous ones left, gave an effective ``e`` of 0.26 for
    0.5 and a tumble.

    Newton's restitution with friction can raise the kinetic energy (Kane's paradox; a
    box landing on an edge at ``e = 1``, ``μ = 0.3`` gained 2.4 %). As
    :func:`jrigid.impacts.contact_impulse` does for one point, the impulses are then
    moved toward those without friction, and, if those gain too, toward the plastic
    ones (``e = 0``, no friction: the least kinetic energy that leaves no point
    approaching), to the first that does not gain (bisection on the straight line
    between the solutions: the velocities are linear in the impulses)."""
    dtype = v.dtype
    K = jax.vmap(lambda r: collision_matrix(m, moments, q, r))(r_all)
    un0 = point_velocities(q, omega, v, floor.points)[:, 2]
    zero = jnp.zeros((), dtype)
    mus = jnp.stack([jnp.asarray(floor.friction, dtype), zero, zero])
    es = jnp.stack([jnp.asarray(floor.restitution, dtype)] * 2 + [zero])
    lams = jax.vmap(lambda mu, e: _pgs(m, moments, q, K, r_all, near, un0, v, omega, mu, e,
                                       max_sweeps))(mus, es)

    def velocities(lam):
        dL = jnp.sum(jnp.cross(r_all, lam), axis=0)
        return v + jnp.sum(lam, axis=0) / m, omega + quat.rotate_inverse(q, dL) / moments

    def kinetic(lam):
        v2, w2 = velocities(lam)
        return 0.5 * (m * jnp.sum(v2 * v2) + jnp.sum(moments * w2 * w2))

    before = kinetic(jnp.zeros_like(lams[0]))
    gains = jax.vmap(kinetic)(lams) > before * (1.0 + 8 * jnp.finfo(dtype).eps)
    # the segment from a solution that gains to the next (the last one is the plastic
    # impulse, which cannot gain): full → frictionless, or frictionless → plastic
    i = jnp.where(gains[1], 1, 0)
    a, b = lams[i], lams[i + 1]

    def halve(_, bounds):
        lo, hi = bounds  # kinetic(lo) > before >= kinetic(hi), as fractions of b − a
        mid = 0.5 * (lo + hi)
        up = kinetic(a + mid * (b - a)) > before
        return jnp.where(up, mid, lo), jnp.where(up, hi, mid)

    _, alpha = jax.lax.fori_loop(0, 60, halve, (zero, jnp.ones((), dtype)))
    lam = jnp.where(gains[0], a + alpha * (b - a), lams[0])
    v, omega = velocities(lam)
    k = jnp.argmin(jnp.where(near, un0, jnp.inf))
    un = point_velocities(q, omega, v, floor.points)[k, 2]
    first = jnp.concatenate([k[None].astype(dtype), un0[k][None], un[None], lam[k]])
    count = jnp.sum(jnp.any(lam != 0, axis=-1)).astype(jnp.int32)
    return v, omega, count, first, jnp.sum(lam, axis=0)


def _pgs(m, moments, q, K, r_all, near, un0, v, omega, friction, restitution, max_sweeps):
    """``(P, 3)`` accumulated impulses of :func:`_simultaneous`'s projected Gauss–Seidel
    for one friction coefficient and restitution."""
    dtype = v.dtype
    target = jnp.where(near & (un0 < 0), -restitution * un0, 0.0)
    scale = m * jnp.max(jnp.where(near, jnp.abs(un0), 0.0))
    tol = jnp.finfo(dtype).eps ** 0.75 * scale

    def point(k, c):
        v, omega, lam, change = c
        r, Kk = r_all[k], K[k]
        u = v + jnp.cross(quat.rotate(q, omega), r)
        ln_old = lam[k, 2]
        ln = jnp.maximum(ln_old + (target[k] - u[2]) / Kk[2, 2], 0.0)
        u_t = u[:2] + Kk[:2, 2] * (ln - ln_old)
        a, b, d = Kk[0, 0], Kk[0, 1], Kk[1, 1]
        det = a * d - b * b
        lt = lam[k, :2] - jnp.stack([d * u_t[0] - b * u_t[1], a * u_t[1] - b * u_t[0]]) / det
        norm2 = jnp.sum(lt * lt)
        cap = friction * ln
        over = norm2 > cap * cap
        lt = jnp.where(over, lt * cap / jnp.sqrt(jnp.where(over, norm2, 1.0)), lt)
        dP = jnp.where(near[k], jnp.concatenate([lt, ln[None]]) - lam[k], 0.0)
        v, omega = apply_impulse(m, moments, q, v, omega, r, dP)
        return v, omega, lam.at[k].add(dP), jnp.maximum(change, jnp.max(jnp.abs(dP)))

    def cond(c):
        return (c[3] > tol) & (c[4] < max_sweeps)

    def sweep(c):
        v, omega, lam, _, count = c
        v, omega, lam, change = jax.lax.fori_loop(
            0, r_all.shape[0], point, (v, omega, lam, jnp.zeros((), dtype)))
        return v, omega, lam, change, count + 1

    lam0 = jnp.zeros(r_all.shape, dtype)
    _, _, lam, _, _ = jax.lax.while_loop(
        cond, sweep, (v, omega, lam0, jnp.asarray(jnp.inf, dtype), jnp.zeros((), jnp.int32)))
    return lam


def _near(scene, formulation, y, contact_tol):
    """``(r_all (P, 3), near (P,))``: the contact points relative to the centre of mass
    (space frame) and which of them are within ``contact_tol`` of the floor; a point
    listed twice (or within rounding of another) is one contact point."""
    floor = _floor(scene)
    kin = formulation.kinematics(scene, y)
    r_all = quat.rotate(kin.q[None, :], floor.points)
    near = (kin.x[2] + r_all[:, 2] - floor.height) <= contact_tol
    size = jnp.max(jnp.abs(r_all))
    same = jnp.all(jnp.abs(r_all[:, None, :] - r_all[None, :, :]) <= 1e-12 * size, axis=-1)
    earlier = jnp.tril(jnp.ones(same.shape, bool), -1)
    return r_all, near & ~jnp.any(same & earlier & near[None, :], axis=-1)


@eqx.filter_jit
def _points_at_floor(scene, formulation, y, contact_tol):
    """``()`` int: how many distinct points are within ``contact_tol`` of the floor."""
    return jnp.sum(_near(scene, formulation, y, contact_tol)[1])


@eqx.filter_jit
def _resolve(scene, formulation, y, contact_tol, max_iter, several: bool):
    """The impulses at the points within ``contact_tol`` of the floor: at one point,
    :func:`_sequential`; at several (``several``, static: compiled only when a contact
    needs it), :func:`_simultaneous`."""
    floor = _floor(scene)
    kin = formulation.kinematics(scene, y)
    q, x, m, moments = kin.q, kin.x, scene.body.mass, scene.body.moments
    r_all, near = _near(scene, formulation, y, contact_tol)
    if several:
        v, omega, count, first, P_sum = _simultaneous(
            m, moments, q, floor, r_all, near, kin.v, kin.omega, max(max_iter, 1000))
    else:
        v, omega, count, first, P_sum = _sequential(
            m, moments, q, floor, r_all, near, kin.v, kin.omega, max_iter)
    after = type(kin)(q, omega, x, v)
    lowest = jnp.min(x[2] + r_all[:, 2] - floor.height)
    # lift the body out of the floor by the event's tolerance depth (<= contact_tol)
    x_lift = x.at[2].add(jnp.maximum(-lowest, 0.0))
    y2 = formulation.from_state(scene, State(q, quat.derivative(q, omega), x_lift, v))
    # angular momentum about the first contact point, before and after (space frame)
    k = jnp.where(count > 0, first[0], 0).astype(jnp.int32)
    rc = r_all[k]

    def L_about(kk):
        Ls = quat.rotate(q, moments * kk.omega)
        return Ls - m * jnp.cross(rc, kk.v)

    return dict(
        y=y2, count=count, first=first, P_sum=P_sum,
        energy_before=_energies(scene, kin), energy_after=_energies(scene, after),
        L_point_before=L_about(kin), L_point_after=L_about(after),
        momentum_before=m * kin.v, momentum_after=m * v,
        lowest=lowest,
    )  # fmt: skip


# --------------------------------------------------------------------------- driver


class BounceRun(NamedTuple):
    """Result of :func:`simulate_bounces`.

    Attributes:
        trajectory: :class:`~jrigid.trajectory.Trajectory` at the output times (after
            a ``"resting"`` stop the body is held still; after ``"max_bounces"`` or
            ``"failed"`` the samples are ``NaN``).
        bounces: dict of numpy arrays, one row per contact: ``t``; ``point`` (index of the
            first point hit, the one approaching fastest); ``un_before``, ``un_after``
            (its normal velocity before and after its impulse: at one point its own, at
            several all of them); ``impulse`` ``(B, 3)`` (the first point's) and
            ``impulse_total`` ``(B, 3)``; ``impulses`` (at one point, how many impulses
            it took, one unless rounding left it approaching; at several, how many of
            them carry an impulse);
            ``energy_before``, ``energy_after`` ``(B, 3)`` = (translational kinetic,
            rotational kinetic, potential); ``momentum_before/after`` ``(B, 3)``;
            ``L_point_before/after`` ``(B, 3)`` angular momentum about the first contact
            point; ``depth`` (how far the lowest point was below the floor).
        status: ``"t_end"``, ``"resting"``, ``"max_bounces"`` or ``"failed"``.
        t_stop: the final time for ``"t_end"``, else the time of the last contact.
        dropped_energy: kinetic energy removed when the body was put to rest (more than
            :data:`RESTING_ENERGY` of the largest at a contact: a :class:`RestingWarning`).
        num_steps: solver steps over all segments.
    """

    trajectory: Trajectory
    bounces: dict[str, np.ndarray]
    status: str
    t_stop: float
    dropped_energy: float
    num_steps: int


def simulate_bounces(
    scene: Scene,
    initial_state: State,
    ts: ArrayLike,
    *,
    formulation: Any = "quaternion_acceleration",
    solver: diffrax.AbstractSolver | None = None,
    rtol: ArrayLike | None = None,
    atol: ArrayLike | None = None,
    max_bounces: int = 200,
    min_gap: float = 1e-3,
    rapid_bounces: int = 8,
    contact_tol: float | None = None,
    max_steps: int = 100_000,
) -> BounceRun:
    """Integrate a body in free flight that bounces on a :class:`Floor`.

    Args:
        scene: a :class:`~jrigid.scene.Scene` with a :class:`~jrigid.scene.FreeFlight`
            holder and one :class:`Floor` load (plus :class:`~jrigid.scene.Gravity`).
        initial_state: :class:`~jrigid.state.State` with ``x, v`` at ``ts[0]``; every
            contact point must start above the floor.
        ts: ``(T,)`` increasing output times.
        formulation: as :func:`jrigid.simulate` (a quaternion formulation).
        solver: diffrax solver, default :data:`jrigid.solve.DEFAULT_SOLVER`, wrapped in
            :class:`~jrigid.solve.ProjectedSolver`.
        rtol, atol: step-size tolerances (defaults as :func:`jrigid.simulate`).
        max_bounces: stop after this many contacts, at least 1 (status ``"max_bounces"``).
        min_gap, rapid_bounces: resting criterion: ``rapid_bounces`` consecutive contacts
            each within ``min_gap`` (time) of the previous one.
        contact_tol: points within this distance of the floor take part in a contact;
            a contact is detected when the lowest point is ``contact_tol`` below the
            floor (so that a segment starting on the floor starts above the event
            level), and the body is then lifted back onto the floor (an energy change
            of at most ``M g contact_tol`` per contact). Default ``1e-10`` (float64),
            ``1e-5`` (float32).
        max_steps: step budget of each segment.

    Returns:
        :class:`BounceRun`; ``trajectory.result`` is ``Result.success`` for
        ``"t_end"`` and ``"resting"``, ``Result.max_steps`` for ``"max_bounces"`` and the
        segment's failure code (e.g. ``nonfinite``) for ``"failed"``.

    Raises:
        ValueError: a scene without a floor or free flight, a start below the floor,
            bad tolerances (see :func:`jrigid.simulate`).
        TypeError: traced inputs (inside ``jax.jit``, ``jax.grad`` or ``jax.vmap``).

    Example:
        A ball dropped from 1.5 m above the floor bounces once in the first second,
        leaving the floor at half the speed it arrived with:

        >>> import jax.numpy as jnp, jrigid
        >>> from jrigid import contact, inertia, initial
        >>> body = jrigid.RigidBody(inertia.sphere(1.0, 0.5), 1.0)
        >>> floor = contact.Floor(jnp.array([[0.0, 0.0, -0.5]]), restitution=0.5)
        >>> scene = jrigid.Scene(body, jrigid.FreeFlight(), (jrigid.Gravity(), floor))
        >>> state = initial.from_omega(None, (0.0, 0.0, 0.0), x=(0.0, 0.0, 2.0),
        ...                            v=(0.0, 0.0, 0.0))
        >>> run = contact.simulate_bounces(scene, state, jnp.linspace(0.0, 1.0, 5))
        >>> run.status, len(run.bounces["t"]), run.trajectory.x.shape
        ('t_end', 1, (5, 3))
        >>> after, before = run.bounces["un_after"], run.bounces["un_before"]
        >>> round(float(after[0] / before[0]), 3)
        -0.5
    """
    if is_traced(scene, initial_state, ts, rtol, atol):
        raise TypeError(
            "simulate_bounces runs its segments and contacts from Python, so it cannot be "
            "traced (jax.jit, jax.grad, jax.vmap): differentiate jrigid.impacts' functions "
            "(contact_impulse, apply_impulse), or jrigid.simulate over a segment")
    formulation = get_formulation(formulation)
    if not formulation.carries_quaternion:
        raise ValueError("simulate_bounces needs a quaternion formulation")
    floor = _floor(scene)
    dtype = jnp.result_type(float)
    state, ts, rtol, atol = prepare(scene, initial_state, ts, rtol, atol, dtype)
    _check_count(max_bounces, "max_bounces", 1)
    _check_count(rapid_bounces, "rapid_bounces", 1)
    _check_positive(min_gap, "min_gap")
    if contact_tol is not None:
        _check_positive(contact_tol, "contact_tol")
    q0 = quat.normalize(state.q)
    if float(jnp.min(point_positions(q0, state.x, floor.points)[:, 2])) < float(floor.height):
        raise ValueError("the body starts below the floor: raise initial_state.x")
    check_scene(formulation, scene)
    validate(formulation, scene, state, ts, rtol, atol)
    solver = ProjectedSolver(DEFAULT_SOLVER() if solver is None else solver, formulation)
    y = formulation.from_state(scene, State(q0, state.qdot, state.x, state.v))
    t, t1 = ts[0], ts[-1]
    dt0 = jnp.asarray(min_gap / 4, dtype)
    if contact_tol is None:
        contact_tol = 1e-10 if jnp.dtype(dtype).itemsize >= 8 else 1e-5
    tol = jnp.asarray(contact_tol, dtype)
    ts_np = np.asarray(ts)
    ys = jax.tree_util.tree_map(lambda a: np.full((len(ts_np),) + a.shape, np.nan, a.dtype), y)
    rows, status, rapid, last, dropped, grazes = [], "t_end", 0, -np.inf, 0.0, 0
    counts = np.zeros(len(_STEP_COUNTS), np.int64)
    failure = Result.solver_failure
    while True:
        t_hit, y_hit, code, interp, n_counts = _segment(
            scene, formulation, solver, y, t, t1, rtol, atol, dt0, tol, max_steps
        )
        counts += np.asarray(n_counts)
        t_hit_f = float(t_hit)
        mask = (ts_np >= float(t)) & (ts_np <= t_hit_f)
        if mask.any():
            idx = np.nonzero(mask)[0]
            size = max(64, 1 << (len(idx) - 1).bit_length())  # few compiled sizes
            tt = np.full(size, t_hit_f, ts_np.dtype)
            tt[: len(idx)] = ts_np[idx]
            seg = jax.device_get(_sample(interp, jnp.asarray(tt), t, t_hit))
            ys = _put(ys, idx, seg)
        code = int(code)
        if code >= 10:
            status, failure = "failed", Result(code - 10)
            break
        if code == 0:
            break
        several = int(_points_at_floor(scene, formulation, y_hit, tol)) > 1
        res = jax.device_get(_resolve(scene, formulation, y_hit, tol, 20 * len(floor.points),
                                      several))
        if int(res["count"]) == 0:  # grazing: the lowest point was not approaching
            grazes += 1
            if grazes > 10:
                status, failure = "failed", Result.solver_failure
                break
            y, t = res["y"], t_hit
            continue
        grazes = 0
        row = dict(t=t_hit_f, point=int(res["first"][0]), un_before=res["first"][1],
                   un_after=res["first"][2], impulse=res["first"][3:],
                   impulse_total=res["P_sum"], impulses=int(res["count"]),
                   energy_before=res["energy_before"], energy_after=res["energy_after"],
                   momentum_before=res["momentum_before"], momentum_after=res["momentum_after"],
                   L_point_before=res["L_point_before"], L_point_after=res["L_point_after"],
                   depth=-float(res["lowest"]))  # fmt: skip
        rows.append(row)
        y, t = res["y"], t_hit
        rapid = rapid + 1 if t_hit_f - last < min_gap else 0
        last = t_hit_f
        if rapid >= rapid_bounces:
            status = "resting"
            dropped = float(np.sum(res["energy_after"][:2]))
            moving = max(float(np.sum(r["energy_before"][:2])) for r in rows)
            if dropped > RESTING_ENERGY * moving:
                warnings.warn(
                    f"contacts piled up at t={t_hit_f:.6g} while the body still had "
                    f"{dropped:.3g} of kinetic energy ({dropped / moving:.2g} of its largest "
                    "at a contact): it is held still there, but it was sliding, rolling or "
                    "tipping along the floor, which impulses alone do not model",
                    RestingWarning, stacklevel=2)
            rest = jax.device_get(_at_rest(scene, formulation, y))
            ys = _put(ys, np.nonzero(ts_np > t_hit_f)[0], rest)
            break
        if len(rows) >= max_bounces:
            status = "max_bounces"
            break
    t_stop = float(t1) if status == "t_end" else float(t)
    steps = int(counts[0])
    stats = {k: jnp.asarray(int(n)) for k, n in zip(_STEP_COUNTS, counts, strict=True)}
    ys = jax.tree_util.tree_map(jnp.asarray, ys)
    traj = Trajectory.build(
        scene, formulation, ts, ys, stats=stats,
        result=jnp.asarray(
            {"t_end": Result.success, "resting": Result.success,
             "max_bounces": Result.max_steps}.get(status, failure), jnp.int32),
        t_stop=jnp.asarray(t_stop, dtype),
    )  # fmt: skip
    return BounceRun(traj, _stack(rows), status, t_stop, dropped, steps)


def _check_count(value, name: str, least: int) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < least:
        raise ValueError(f"{name} must be an int >= {least}, got {value!r}")


def _check_positive(value, name: str) -> None:
    try:
        ok = isinstance(value, (int, float, np.number)) and not isinstance(value, bool) \
            and math.isfinite(float(value)) and float(value) > 0
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")


def _put(ys, idx, new):
    """Write ``new`` (its first rows, or one row broadcast) into rows ``idx`` of ``ys``."""

    def put(a, b):
        a[idx] = b[: len(idx)] if b.ndim == a.ndim else b
        return a

    return jax.tree_util.tree_map(put, ys, new)


def _at_rest(scene, formulation, y):
    kin = formulation.kinematics(scene, y)
    zero = jnp.zeros(3, dtype=kin.x.dtype)
    return formulation.from_state(scene, State(kin.q, jnp.zeros(4, kin.q.dtype), kin.x, zero))


def _stack(rows: list[dict]) -> dict[str, np.ndarray]:
    keys = ("t", "point", "un_before", "un_after", "impulse", "impulse_total", "impulses",
            "energy_before", "energy_after", "momentum_before", "momentum_after",
            "L_point_before", "L_point_after", "depth")  # fmt: skip
    shapes = {"impulse": (0, 3), "impulse_total": (0, 3), "energy_before": (0, 3),
              "energy_after": (0, 3), "momentum_before": (0, 3), "momentum_after": (0, 3),
              "L_point_before": (0, 3), "L_point_after": (0, 3)}  # fmt: skip
    if not rows:
        return {k: np.zeros(shapes.get(k, (0,))) for k in keys}
    return {k: np.asarray([np.asarray(r[k]) for r in rows]) for k in keys}
