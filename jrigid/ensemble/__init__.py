"""Ensembles: one function over thousands of members, chunked, sharded, saved, resumable.

- :func:`run` — ``fn(member) -> dict`` over a pytree of inputs with a leading member
  axis, as ``jax.jit(jax.vmap(fn))`` in chunks of ``chunk_size`` members, each chunk
  split over every device (:mod:`jrigid.ensemble.sharding`), each finished chunk written
  to ``out_dir`` (:mod:`jrigid.ensemble.storage`) so an interrupted run resumes;
- :func:`simulate_many` — the common case, :func:`jrigid.simulate` per member (or one
  shared-step solve per chunk, ``shared_step=True``);
- :func:`simulate_lockstep` — a batch integrated as one system with a shared adaptive
  step (the fast route on a CPU; see :mod:`jrigid.ensemble.lockstep`);
- :func:`default_summary` — what :func:`simulate_many` keeps by default.

Several processes (multi-host, ``jax.distributed``): call ``jax.distributed.initialize()``
on every process before anything else touches JAX, then call :func:`run` with the same
``fn``, inputs and arguments on every process. ``devices=None`` is then the global list
``jax.devices()``: each chunk is split over the devices of all processes and its outputs
are gathered to every process, so every process returns the full results. When the mesh
spans processes, process 0 alone writes ``out_dir``, which must then be on a file system
every process can read (process 0 decides which chunks are finished and tells the
others). Without a shared file system, run independent ensembles instead: each process
takes its own slice of the inputs, ``devices=jax.local_devices()`` and its own
``out_dir`` (a mesh of local devices involves no other process; each process writes its
own folder). The multi-process path follows JAX's documented APIs
(:func:`jax.make_array_from_callback`, ``multihost_utils``) but is tested here only with
forced host devices in one process.
"""

from jrigid.ensemble.lockstep import simulate_lockstep
from jrigid.ensemble.many import default_summary, simulate_many
from jrigid.ensemble.runner import run

__all__ = ["default_summary", "run", "simulate_lockstep", "simulate_many"]
