"""Outputs at given times, saved without ``diffrax.SaveAt(ts=...)``.

diffrax saves at output times with ``SaveAt(ts=ts)``, and checks ``ts`` with two runtime
errors (``equinox.error_if``). A runtime error is a custom call, which XLA:CPU cannot put
inside a kernel, so a solve saving at ``ts`` cannot run as one kernel
(``jrigid._dispatch``). Here the same outputs are saved by the step-size controller,
which is where diffrax's loop learns whether a step is accepted
(the checks of ``ts`` are jrigid's own input checks,
:func:`jrigid.solve.inputs.input_checks`):

- :class:`SavingSolver` hands each step's dense output to the controller along with its
  error estimate;
- :class:`SavingController` (:class:`~jrigid.solve.stepping.VectorPIDController` otherwise)
  writes, for an accepted step, the states at the output times in ``(t0, t1]``,
  interpolated as diffrax interpolates them, into a buffer in its own state, in place.
  ``diffrax.SaveAt(t1=True, controller_state=True)`` returns the buffer; :func:`saved`
  lays it out as ``SaveAt(ts=ts, t1=True)`` would.

The buffer is not in the solver's state because diffrax selects the whole solver state
between its old and new value after every step: a copy of all the outputs per step
(measured: 1001 outputs made a 290-step solve 3.4× slower).
"""

from __future__ import annotations

import diffrax
import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp

from jrigid.solve.stepping import VectorPIDController, WrappedSolver, traced_once

__all__ = ["SavingController", "SavingSolver", "saved"]


class SavingSolver(WrappedSolver):
    """Wrap a diffrax solver; pass each step's dense output to a :class:`SavingController`.

    ``step`` returns the error estimate as ``(error, dense_info)``; everything else is
    the inner solver's. Only for use with a :class:`SavingController`.
    """

    @traced_once
    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        y1, y_error, dense_info, solver_state, result = self.solver.step(
            terms, t0, t1, y0, args, solver_state, made_jump
        )
        return y1, (y_error, dense_info), dense_info, solver_state, result


class SavingController(VectorPIDController):
    """:class:`~jrigid.solve.stepping.VectorPIDController` that also saves the state at
    the times ``ts`` from the dense output of a :class:`SavingSolver`.

    The state is one array (:class:`~jrigid.solve.flat.Flat`). The controller state is
    ``(PID state, ys (T, n), i)``; ``ys[0]`` is the initial state, ``ys[i]`` is written
    by the accepted step whose ``(t0, t1]`` holds ``output_ts[i]``, and rows not reached
    (a solve that stopped early) stay NaN. ``i`` is the index of the first output time
    after the current time, carried from step to step: a binary search of ``output_ts``
    in every step cost 70–90 ns for 301–1001 output times (about a tenth of a step).

    Attributes:
        output_ts: ``(T,)`` increasing output times, ``output_ts[0]`` the start of the
            solve.
        interpolation_cls: the solver's ``interpolation_cls``.
        loop_kind: the ``equinox.internal.while_loop`` kind of the loop over a step's outputs:
            ``"checkpointed"`` (reverse mode, as diffrax's own saving loop under
            ``RecursiveCheckpointAdjoint``) or ``"lax"`` (forward mode).
    """

    output_ts: jax.Array | None = None
    interpolation_cls: type | None = eqx.field(static=True, default=None)
    loop_kind: str = eqx.field(static=True, default="checkpointed")

    def __check_init__(self):
        if self.output_ts is None or jnp.ndim(self.output_ts) != 1 or not jnp.shape(
                self.output_ts)[0]:
            raise ValueError("SavingController needs output_ts, a (T,) array of output "
                             f"times with T >= 1, got {self.output_ts!r}")
        if self.interpolation_cls is None:
            raise ValueError("SavingController needs the solver's interpolation_cls")
        if self.loop_kind not in ("checkpointed", "lax"):
            raise ValueError(
                f"loop_kind must be 'checkpointed' or 'lax', got {self.loop_kind!r}"
            )

    def init(self, terms, t0, t1, y0, dt0, args, func, error_order):
        t_next, state = super().init(terms, t0, t1, y0, dt0, args, func, error_order)
        ys = jnp.full((self.output_ts.shape[0],) + jnp.shape(y0), jnp.nan, jnp.result_type(y0))
        first = jnp.searchsorted(self.output_ts, t0, side="right").astype(jnp.int32)
        return t_next, (state, ys.at[0].set(y0), first)

    @traced_once
    def adapt_step_size(self, t0, t1, y0, y1_candidate, args, y_error, error_order,
                        controller_state):
        y_error, dense_info = y_error
        state, ys, first = controller_state
        keep, t_prev, t_next, jump, state, result = super().adapt_step_size(
            t0, t1, y0, y1_candidate, args, y_error, error_order, state
        )
        interpolation = self.interpolation_cls(t0=t0, t1=t1, **dense_info)
        ts, n = self.output_ts, self.output_ts.shape[0]

        def due(carry):
            i, _ = carry
            return keep & (i < n) & (ts[jnp.minimum(i, n - 1)] <= t1)

        def save(carry):
            i, ys = carry
            return i + 1, ys.at[i].set(interpolation.evaluate(ts[i]))

        # a rejected step saves nothing: the first output time after t0 stays where it is
        after, ys = eqxi.while_loop(due, save, (first, ys), max_steps=n,
                                    buffers=lambda c: c[1], kind=self.loop_kind, checkpoints=n)
        return keep, t_prev, t_next, jump, (state, ys, after), result

    def nonfinite_trials(self, controller_state) -> jax.Array:
        """:meth:`VectorPIDController.nonfinite_trials` of this controller's state."""
        return super().nonfinite_trials(self._parts(controller_state, 3)[0])


def saved(sol: diffrax.Solution, ts):
    """``(saved_ts (T + 1,), saved_ys (T + 1, n))`` of a :class:`SavingController` solve
    with ``SaveAt(t1=True, controller_state=True)``, laid out as diffrax's
    ``SaveAt(ts=ts, t1=True)`` lays them out: the output times reached (``inf`` beyond),
    then the final time; the states at them (NaN beyond), then the final state."""
    if sol.controller_state is None:
        raise ValueError("saved() needs the solve's controller state: solve with "
                         "SaveAt(t1=True, controller_state=True) and a SavingController")
    ys = sol.controller_state[1]
    t_end = sol.ts[-1]
    saved_ts = jnp.concatenate([jnp.where(ts <= t_end, ts, jnp.inf), sol.ts[-1:]])
    return saved_ts, jnp.concatenate([ys, sol.ys[-1:]])
