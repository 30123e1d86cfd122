"""An executor for :func:`jrigid.ensemble.run` from two command-line style settings.

:func:`executor` opens a Dask ``distributed`` client — on a new ``LocalCluster`` of
``workers`` processes, or on the scheduler at ``scheduler`` (a workstation pool, or a
Slurm/PBS/SGE cluster started with ``dask-jobqueue``) — and yields its
:class:`concurrent.futures.Executor`; with neither setting it yields ``None`` (compute
in this process). It is what ``jrigid run NAME --workers N`` / ``--scheduler ADDRESS``
and the experiments use; in a script, making the client yourself is as short::

    from distributed import Client
    with Client("tcp://host:8786") as client:
        out = ensemble.simulate_many(..., executor=client.get_executor())

Needs the ``distributed`` extra (``pip install "jrigid[distributed]"``).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from concurrent.futures import Executor

__all__ = ["executor"]


@contextlib.contextmanager
def executor(workers: int = 0, scheduler: str = "") -> Iterator[Executor | None]:
    """Yield a Dask executor for ``workers`` local processes or an existing ``scheduler``.

    Args:
        workers: start a ``distributed.LocalCluster`` with this many worker processes
            (one thread each; every worker computes whole chunks on its own core). ``0``:
            none.
        scheduler: address of a running Dask scheduler (``"tcp://host:8786"``), e.g. of
            ``dask-jobqueue``'s ``SLURMCluster``. ``""``: none.

    Yields:
        the client's ``get_executor()``, or ``None`` when both settings are empty. The
        client (and a cluster it started) is closed on exit.

    Raises:
        ValueError: both settings given, a negative ``workers``, or ``distributed`` not
            installed.
    """
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 0:
        raise ValueError(f"workers must be a non-negative int, got {workers!r}")
    if workers and scheduler:
        raise ValueError("give workers (a new local cluster) or scheduler (an existing "
                         "one), not both")
    if not workers and not scheduler:
        yield None
        return
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise ValueError(
            "workers/scheduler need Dask's distributed package: pip install "
            '"jrigid[distributed]"'
        ) from None
    with contextlib.ExitStack() as stack:
        if workers:
            cluster = stack.enter_context(
                LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                             dashboard_address=":0")
            )
            client = stack.enter_context(Client(cluster))
        else:
            client = stack.enter_context(Client(scheduler))
        yield client.get_executor()
