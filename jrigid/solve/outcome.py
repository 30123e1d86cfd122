"""A solve's outcome: diffrax's result as a :class:`~jrigid.trajectory.Result` and a trajectory.

:func:`classify` turns diffrax's outcome into a :class:`~jrigid.trajectory.Result` code,
:func:`finish` (a diffrax solution) and :func:`finish_sampled` (states computed directly
at the output times) build the :class:`~jrigid.trajectory.Trajectory`, and
:func:`raise_on_failure` raises or not.
"""

from __future__ import annotations

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jrigid._checks import all_finite
from jrigid._folds import first_true, largest
from jrigid.solve.inputs import message
from jrigid.trajectory import CAUSES, Result, SimulationError, Trajectory

__all__ = ["classify", "finish", "finish_sampled", "raise_on_failure"]


def classify(sol_result, formulation, scene, y_end, t_end, ys, span, user_event=False,
             nonfinite_trials=None):
    """Map diffrax's result to a :class:`~jrigid.trajectory.Result` code (``()`` int32).

    A collapsed step size, or an exhausted step budget, is blamed on non-finite values
    if the last accepted state is not finite, or if ``nonfinite_trials`` (``()`` bool:
    jrigid's controller records whether the trial steps since the last accepted one had
    non-finite values,
    :meth:`~jrigid.solve.stepping.VectorPIDController.nonfinite_trials`) says so. Without
    that record (a user's controller, or members of one shared solve), the vector field
    is probed at the last accepted state and a little beyond it (rejected trial steps
    are not kept, so their NaNs are not otherwise visible); the probe costs a copy of
    the vector field in the compiled program (about 0.2 s of a heavy top's
    compilation). An event is :attr:`~jrigid.trajectory.Result.gimbal_lock` for a
    formulation's own event and :attr:`~jrigid.trajectory.Result.event` when the user
    passed one (``user_event``).
    """
    R = diffrax.RESULTS
    if nonfinite_trials is None:
        finite = _probe(formulation, scene, y_end, t_end, span)
    else:
        finite = all_finite(y_end) & ~nonfinite_trials
    # steps exhausted on non-finite values (with a starting step that was itself NaN,
    # every step is rejected without reaching dtmin) are non-finite values
    code = jnp.where(sol_result == R.max_steps_reached,
                     jnp.where(finite, Result.max_steps, Result.nonfinite), Result.solver_failure)
    code = jnp.where(
        sol_result == R.dt_min_reached,
        jnp.where(finite, Result.step_size_collapse, Result.nonfinite),
        code,
    )
    event_code = Result.event if user_event else Result.gimbal_lock
    code = jnp.where(sol_result == R.event_occurred, event_code, code)
    ok = jnp.where(all_finite(ys), Result.success, Result.nonfinite)
    return jnp.where(sol_result == R.successful, ok, code).astype(jnp.int32)


def _probe(formulation, scene, y_end, t_end, span) -> jax.Array:
    """``()`` bool: ``y_end`` and the vector field at it and a little beyond are finite."""
    steps = jnp.asarray([0.0, 1e-12, 1e-8, 1e-4], jnp.result_type(t_end)) * span

    def probe(i, carry):
        # The field at y_end (i = 0), then along it a little beyond. One field in a
        # loop body: four inline evaluations took ~0.2-0.3 s of compile time each.
        f_end, finite = carry
        d = steps[i]
        y = jax.tree_util.tree_map(lambda a, f: a + d * f, y_end, f_end)
        f = formulation.vector_field(t_end + d, y, scene)
        f_end = jax.tree_util.tree_map(lambda a, b: jnp.where(i == 0, b, a), f_end, f)
        return f_end, finite & all_finite(f)

    zeros = jax.tree_util.tree_map(jnp.zeros_like, y_end)
    _, finite = jax.lax.fori_loop(0, 4, probe, (zeros, all_finite(y_end)))
    return finite


def finish(scene, formulation, ts, saved_ts, saved_ys, sol_result, sol_stats,
           interpolation=None, invalid=None, user_event=False, nonfinite_trials=None):
    """One member's :class:`~jrigid.trajectory.Trajectory` from a diffrax solution.

    Args:
        scene, formulation: as solved.
        ts: ``(T,)`` the requested output times.
        saved_ts: ``(T + 1,)`` ``sol.ts`` of ``SaveAt(ts=ts, t1=True)``.
        saved_ys: ``sol.ys``, leading axis ``T + 1``.
        sol_result, sol_stats: ``sol.result`` and ``sol.stats`` (the step counts are kept).
        interpolation: ``sol.interpolation`` or ``None``.
        invalid: ``()`` bool from :func:`~jrigid.solve.inputs.screen`, or ``None``: an
            invalid member's outputs are NaN and its code
            :attr:`~jrigid.trajectory.Result.invalid_input`.
        user_event: whether an event of the user's may have stopped the solve.
        nonfinite_trials: ``()`` bool or ``None``: see :func:`classify`.
    """
    stats = {k: sol_stats[k] for k in ("num_steps", "num_accepted_steps", "num_rejected_steps")}
    # diffrax writes the final state into the first unfilled slot: on failure that is
    # not the last one. Keep only slots saved at their requested time; NaN elsewhere.
    valid = saved_ts[:-1] == ts
    if invalid is not None:
        valid = valid & ~invalid
    t_end = largest(jnp.where(jnp.isfinite(saved_ts), saved_ts, -jnp.inf))
    i_end = first_true(saved_ts == t_end)
    y_end = jax.tree_util.tree_map(lambda a: a[i_end], saved_ys)

    def _mask(a):
        keep = valid.reshape(valid.shape + (1,) * (a.ndim - 1))
        return jnp.where(keep, a[:-1], jnp.nan)

    ys = jax.tree_util.tree_map(_mask, saved_ys)
    result = classify(sol_result, formulation, scene, y_end, t_end, ys, ts[-1] - ts[0],
                      user_event, nonfinite_trials)
    if invalid is not None:
        result = jnp.where(invalid, jnp.int32(Result.invalid_input), result)
        t_end = jnp.where(invalid, ts[0], t_end)
    return Trajectory.build(
        scene,
        formulation,
        ts,
        ys,
        stats=stats,
        result=result,
        t_stop=t_end,
        interpolation=interpolation,
    )


def finish_sampled(scene, formulation, ts, ys, invalid=None, interpolation=None, steps=None):
    """A :class:`~jrigid.trajectory.Trajectory` of states computed directly at ``ts``.

    For solvers without diffrax's loop (the closed forms, fixed-step integrators):
    the result is ``success`` if every output is finite, else ``nonfinite``; an
    ``invalid`` member (:func:`~jrigid.solve.inputs.screen`) gets NaN outputs and ``invalid_input``.

    Args:
        ys: the formulation's states at ``ts`` (leading axis ``T``).
        invalid: ``()`` bool or ``None``.
        interpolation: a dense output (``evaluate(t)``) or ``None``.
        steps: ``()`` int32 step count (zero for a closed form).
    """
    if invalid is not None:
        ys = jax.tree_util.tree_map(lambda a: jnp.where(invalid, jnp.nan, a), ys)
    result = jnp.where(all_finite(ys), Result.success, Result.nonfinite).astype(jnp.int32)
    t_stop = ts[-1]
    if invalid is not None:
        result = jnp.where(invalid, jnp.int32(Result.invalid_input), result)
        t_stop = jnp.where(invalid, ts[0], t_stop)
    steps = jnp.zeros((), jnp.int32) if steps is None else steps
    stats = dict(num_steps=steps, num_accepted_steps=steps,
                 num_rejected_steps=jnp.zeros((), jnp.int32))
    return Trajectory.build(scene, formulation, ts, ys, stats=stats, result=result,
                            t_stop=t_stop, interpolation=interpolation)


_FINE = frozenset({int(Result.success), int(Result.event)})


def raise_on_failure(traj: Trajectory, throw: bool, ts, rtol, atol, max_steps: int,
                     messages=None, cause=None, causes=None, tolerances: bool = True):
    """Apply ``throw`` (see :func:`jrigid.simulate`) to a solved trajectory.

    Concrete results: ``ValueError`` for an invalid input (``messages[cause]``),
    :class:`~jrigid.trajectory.SimulationError` for a failed integration (for a batch:
    its first failed member, with the count). Traced results: one
    ``equinox.branched_error_if`` whose message is the cause first, then the remedy.
    ``throw=False`` returns ``traj`` as it is. ``causes``: ``Result -> (cause, remedy)``
    texts that replace those of :data:`~jrigid.trajectory.CAUSES` (a fixed-step solver's
    step bound is not the adaptive solver's); ``tolerances``: quote ``rtol``/``atol`` in
    the message (not for a solver that has none).
    """
    if not throw:
        return traj
    causes = {**CAUSES, **(causes or {})}
    if isinstance(traj.result, jax.core.Tracer):
        texts = [""] * len(Result)
        for k, cause_text, remedy in ((k, *causes[k]) for k in Result if k.failed):
            texts[k] = (
                f"jrigid.simulate failed: {cause_text.format(max_steps=max_steps)}; "
                f"{remedy}. (Under vmap, pass throw=False for per-member result codes.)"
            )
        if messages is not None and cause is not None:
            # An invalid input names its check (the first invalid member's under vmap).
            codes = traj.result.reshape(-1)
            bad_input = jnp.any(codes == Result.invalid_input)
            first_cause = jnp.reshape(cause, (-1,))[jnp.argmax(codes == Result.invalid_input)]
            traj = eqx.branched_error_if(
                traj, bad_input, first_cause, [f"jrigid.simulate: {m}" for m in messages]
            )
        codes = traj.result.reshape(-1)
        is_failure = (codes != Result.success) & (codes != Result.event)
        first = codes[jnp.argmax(is_failure)]
        return eqx.branched_error_if(traj, jnp.any(is_failure), first, texts)
    codes = np.asarray(traj.result)
    if codes.ndim == 0 and int(codes) in _FINE:  # one member (comparing Result members
        return traj  # with an array takes 13 µs of a plain call)
    failed = (codes != Result.success) & (codes != Result.event)
    if not failed.any():
        return traj
    flat = failed.reshape(-1)
    k = int(flat.argmax())
    which = f"member {k} of {flat.size} ({int(flat.sum())} failed) " if codes.ndim else ""
    code = Result(int(codes.reshape(-1)[k]))
    if code == Result.invalid_input and messages is not None:
        index = int(np.asarray(cause).reshape(-1)[k])
        where = f" (member {k} of {flat.size})" if codes.ndim else ""
        raise ValueError(message(messages, index, rtol, atol) + where)
    member = traj
    if codes.ndim:
        member = jax.tree_util.tree_map(lambda a: a.reshape(-1, *a.shape[codes.ndim:])[k], traj)
    cause_text, remedy = causes[code]
    steps = int(member.stats["num_accepted_steps"])
    rejected = int(member.stats["num_rejected_steps"])
    setting = f", rtol={float(rtol):.3g}, atol={float(atol):.3g}" if tolerances else ""
    raise SimulationError(
        f"jrigid.simulate failed {which}at t={float(member.t_stop):.6g} "
        f"(integrating {float(ts[0]):.6g} → {float(ts[-1]):.6g}, "
        f"{steps} accepted and {rejected} rejected steps{setting}): "
        f"{cause_text.format(max_steps=max_steps)}; remedy: {remedy}."
    )
