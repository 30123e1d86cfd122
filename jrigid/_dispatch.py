"""How a small solve reaches XLA:CPU's fast path: one kernel, run on the calling thread.

XLA:CPU runs a compiled program in one of two ways, and a solve that takes a few hundred
steps costs more in the slow way than in its steps (measured on the free rotor of
``benchmarks/speed_vs_error.py``, 2 steps, Intel Xeon, 2 cores):

- **Where it runs.** JAX's CPU client runs a program on the calling thread only when XLA's
  cost model counts fewer than 1000 flops in it; anything larger (every ``simulate``) is
  handed to a worker thread, and the caller sleeps until it is done. Each hand-over costs
  tens of µs on a virtual machine. :func:`configure` turns JAX's
  ``jax_cpu_enable_async_dispatch`` off, so that every program runs on the calling thread
  (multi-device programs are not affected).
- **How it runs.** The top-level operations of a program (more than 8 of them, not one
  chain) are scheduled as a dataflow graph on XLA's thread pool, again with hand-overs
  between threads; the default solve has about 100. A ``while`` loop free of sorts,
  scatters and custom calls is compiled into a single kernel (with the threshold
  ``jrigid._xla`` raises). :func:`one_kernel` puts a whole function inside a loop that
  runs once, so that the program is that one kernel. (``simulate`` saves its outputs
  through its step-size controller, :mod:`jrigid.solve.saving`, because diffrax's
  ``SaveAt(ts=...)`` checks ``ts`` with runtime errors, which are custom calls.)

Neither alone helps: a solve of 2 steps took 126–135 µs with both off, 131 µs with
synchronous dispatch only, 125 µs in one kernel only, and 35 µs with both (a hand-written
``diffrax.diffeqsolve`` of the same steps: 11 µs, below the 1000-flop mark).

The dispatch option is a client option: it acts only if it is set before JAX's first
computation. ``import jrigid`` sets it when JAX is imported (at once if it already is),
so ``import jrigid`` still does not import JAX. To keep JAX's asynchronous dispatch, call
``jax.config.update("jax_cpu_enable_async_dispatch", True)`` after importing jrigid and
before the first computation.
"""

from __future__ import annotations

from jrigid._on_jax import after_jax_import

__all__ = ["OPTION", "configure", "one_kernel"]

#: JAX's configuration option for the CPU client's dispatch.
OPTION = "jax_cpu_enable_async_dispatch"


def _set_synchronous() -> None:
    import jax

    try:
        from jax._src import xla_bridge

        started = xla_bridge.backends_are_initialized()
    except (ImportError, AttributeError):  # pragma: no cover - JAX's layout changed
        started = False
    if not started:
        try:
            jax.config.update(OPTION, False)
        except AttributeError:  # pragma: no cover - an older JAX without the option
            pass


def configure() -> None:
    """Run JAX's CPU computations on the calling thread (see the module docstring):
    now if JAX is imported, else as soon as it is."""
    after_jax_import(_set_synchronous)


def one_kernel(fn, reverse: bool = False):
    """``fn`` (arrays in, arrays out) traced inside a ``while`` loop that runs once.

    XLA:CPU then compiles it into one kernel, if ``fn`` holds no sort, scatter or custom
    call (equinox's runtime errors are custom calls). Derivatives are those of ``fn``
    itself, which a ``while`` loop does not have in reverse mode: with ``reverse``, a
    ``custom_vjp`` (``jax.vjp`` of ``fn``: reverse mode only, as for a solve whose
    adjoint is diffrax's ``RecursiveCheckpointAdjoint``, itself a ``custom_vjp``);
    otherwise a ``custom_jvp`` (``jax.jvp`` of ``fn``: forward mode, and reverse mode
    where ``fn`` has it). (A ``custom_jvp`` over a ``custom_vjp`` could not be
    differentiated in reverse mode under ``vmap``: ``jax.grad`` of a loss summed over
    ``jax.vmap(simulate)`` failed.) Under ``vmap`` the loop stays one iteration.
    """
    import jax
    import jax.numpy as jnp

    traced = jax.jit(fn)  # traced once: the loop's body reuses the shapes' trace

    def looped(*args):
        shapes = jax.eval_shape(traced, *args)
        empty = jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), shapes)
        _, out = jax.lax.while_loop(
            lambda carry: ~carry[0],
            lambda carry: (jnp.array(True), traced(*args)),
            (jnp.array(False), empty),
        )
        return out

    if reverse:
        wrapped = jax.custom_vjp(looped)
        wrapped.defvjp(lambda *args: jax.vjp(fn, *args), lambda pullback, g: pullback(g))
        return wrapped
    wrapped = jax.custom_jvp(looped)
    wrapped.defjvp(lambda primals, tangents: jax.jvp(fn, primals, tangents))
    return wrapped
