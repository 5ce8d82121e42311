"""Where the work runs: this process, local worker processes, or a Dask cluster.

:func:`open_executor` yields a ``concurrent.futures``-style executor whose
``map`` returns results in order:

* ``scheduler="tcp://host:port"``: an existing Dask cluster (``dask
  scheduler`` and ``dask worker`` processes), through a
  ``distributed.Client``;
* ``workers=N``: a ``distributed.LocalCluster`` of N worker processes, one
  thread each, started for the call and closed after it;
* neither: ``n_jobs`` spawned worker processes (one runs in this process).

Every task caps BLAS and OpenMP at one thread inside its worker
(``threadpoolctl``), whatever started the worker, and a LocalCluster's
workers also start with the thread caps and the pinned kernels of
``meshsal.util.reproducible`` in their environment.  Workers of an external
cluster pick their kernels by CPU unless started pinned, e.g.
``python -m meshsal.util.reproducible dask worker ADDRESS``, for the same
numbers as everywhere else.
"""

from __future__ import annotations

import logging
import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager

__all__ = ["Inline", "worker_pool", "open_executor", "worker_env"]


class Inline:
    """The executor interface, run in the calling thread (one task at a time)."""

    def map(self, fn, *iterables):
        return map(fn, *iterables)


def _limit_threads():
    """Worker initializer: one BLAS/OpenMP thread per worker process, for its whole life."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)


def worker_env() -> dict:
    """Environment of a LocalCluster's workers: one BLAS/OpenMP thread, the pinned kernels."""
    from meshsal.util.reproducible import kernel_environment

    env = {name: "1" for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
    return {**env, **kernel_environment()}


@contextmanager
def worker_pool(n_jobs: int):
    """``n_jobs`` spawned worker processes with capped BLAS/OpenMP threads (:class:`Inline` for one).

    Workers are spawned, not forked: the parent may hold Embree and BLAS threads.
    """
    if int(n_jobs) <= 1:
        yield Inline()
        return
    with ProcessPoolExecutor(int(n_jobs), mp_context=multiprocessing.get_context("spawn"),
                             initializer=_limit_threads) as pool:
        yield pool


@contextmanager
def open_executor(workers: int | None = None, scheduler: str | None = None, n_jobs: int = 1):
    """An executor on a Dask cluster (``scheduler``), a new LocalCluster (``workers``) or local processes.

    Parameters
    ----------
    workers : int, optional
        Start a ``distributed.LocalCluster`` of this many single-threaded worker processes.
    scheduler : str, optional
        Address of a running Dask scheduler, e.g. ``tcp://127.0.0.1:8786``.
    n_jobs : int
        Without either: local worker processes (:func:`worker_pool`).

    Yields
    ------
    An object with ``map(fn, iterable)`` returning results in order.
    """
    if workers is not None and scheduler is not None:
        raise ValueError("give workers or a scheduler address, not both")
    if scheduler is None and workers is None:
        with worker_pool(n_jobs) as pool:
            yield pool
        return
    from distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            client = Client(scheduler, timeout="20s")
        except OSError as exc:
            raise OSError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from None
        with client:
            yield client.get_executor()
        return
    if int(workers) < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    # A free port for its status page: never the 8787 another cluster may hold.
    with LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True, dashboard_address=":0",
                      env=worker_env(), silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
        yield client.get_executor()
