"""Ensembles: one function over thousands of members, chunked, sharded, saved, resumable.

- :func:`run` — ``fn(member) -> dict`` over a pytree of inputs with a leading member
  axis, as ``jax.jit(jax.vmap(fn))`` in chunks of ``chunk_size`` members: in this process
  (each chunk split over every device, :mod:`jrigid.ensemble.sharding`; several chunks at
  once on a CPU) or one task per chunk on any ``concurrent.futures`` ``executor`` (a
  Dask cluster, a process pool); each finished chunk written to ``out_dir``
  (:mod:`jrigid.ensemble.storage`) so an interrupted run resumes. Its steps: plan
  (:mod:`~jrigid.ensemble.plan`), resume (:mod:`~jrigid.ensemble.runner`), dispatch
  (:mod:`~jrigid.ensemble.dispatch`, :mod:`~jrigid.ensemble.worker`);
- :func:`simulate_many` — the common case, :func:`jrigid.simulate` for every member, by
  default in shared-step groups (:data:`SWEEP_DEFAULTS`); invalid or failed members are
  counted and named (:class:`SweepWarning`);
- :func:`simulate_lockstep` — a batch integrated as one system with a shared adaptive
  step (the fast route on a CPU; see :mod:`jrigid.ensemble.lockstep`);
- :func:`executor` — a Dask executor for ``N`` local worker processes or an existing
  scheduler (what ``jrigid run NAME --workers N`` uses);
- :func:`default_summary` — what :func:`simulate_many` keeps by default;
- :func:`difficulty_order`, :func:`lockstep_efficiency` — grouping members of similar
  cost for ``run(..., order=...)``, and the useful fraction of a chunking's steps
  (:mod:`jrigid.ensemble.schedule`).

Several processes with one global mesh (``jax.distributed``): call
``jax.distributed.initialize()`` on every process before anything else touches JAX, then
call :func:`run` with the same ``fn``, inputs and arguments on every process.
``devices=None`` is then the global list ``jax.devices()``: each chunk is split over the
devices of all processes and its outputs are gathered to every process, so every
process returns the full results. Process 0 alone writes ``out_dir``, which must then be
on a file system every process can read (process 0 decides which chunks are finished
and tells the others). Tested with two local processes on CPU (gloo collectives:
``jax.config.update("jax_cpu_collectives_implementation", "gloo")``). Every process
computes every chunk together, so one lost process stops the run: an executor
(``executor=``) is the sturdier way across hosts.
"""

from jrigid.ensemble import executors, lockstep, many, runner, schedule  # noqa: I001
from jrigid.ensemble.executors import *  # noqa: F403
from jrigid.ensemble.lockstep import *  # noqa: F403
from jrigid.ensemble.many import *  # noqa: F403
from jrigid.ensemble.runner import *  # noqa: F403
from jrigid.ensemble.schedule import *  # noqa: F403

# The package's names: each listed once, in the ``__all__`` of the module defining it.
__all__: list[str] = []
__all__ += executors.__all__
__all__ += lockstep.__all__
__all__ += many.__all__
__all__ += runner.__all__
__all__ += schedule.__all__
