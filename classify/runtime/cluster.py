"""Where the work runs: this process, local worker processes, or a Dask cluster.

:func:`open_executor` yields a ``concurrent.futures``-style executor whose
``map`` returns results in order:

* ``scheduler="tls://host:port"`` (or ``tcp://``): an existing Dask cluster
  (``dask scheduler`` and ``dask worker`` processes), through a
  ``distributed.Client``; a ``tls://`` address needs certificates
  (``security``, see :func:`tls_security`, or dask's own
  ``distributed.comm.tls`` settings) and is refused without them;
* ``workers=N``: a ``distributed.LocalCluster`` of N worker processes, one
  thread each, started for the call and closed after it, with Dask's
  housekeeping slowed (:data:`QUIET`) unless it serves a dashboard.  Everything it
  opens listens on 127.0.0.1 only (the scheduler, the workers, their nannies
  and the scheduler's HTTP endpoints); the dashboard is off unless
  ``dashboard`` gives an address; ``security`` puts it on TLS too, which
  matters on a machine shared with other users, who can all reach its
  loopback ports;
* neither: ``n_jobs`` spawned worker processes (one runs in this process),
  which read their tasks from files in a private temporary folder
  (:class:`FilePool`), send results back over pipes and open no port.

A Dask worker runs whatever the scheduler sends it, and results come back
pickled: whoever reaches a plain ``tcp://`` scheduler can run code on every
worker and on the client.  Reach a remote cluster over TLS, an SSH tunnel or
a private network only.

A worker is one thread: BLAS, OpenMP and OpenCV's own thread pool (which
the attention's filters and matching use) run on the task's thread only.
Two workers on two cores then share them without a third thread fighting
for either, and the batch's tasks cap the three inside their worker
(:func:`one_thread`), whatever started the worker.  A LocalCluster's
workers also start with the thread caps and the pinned kernels of
``meshsal.util.reproducible`` in their environment.  Workers of an external
cluster pick their kernels by CPU unless started pinned, e.g.
``python -m meshsal.util.reproducible dask worker ADDRESS``, for the same
numbers as everywhere else.  Every Dask worker that :func:`open_executor` reaches loads PyMeshLab and
the thread pools on its main thread as it starts (a worker plugin): loaded first inside a task, PyMeshLab
aborts the worker as it exits.  The plugin also gives glibc's malloc back the thresholds that Dask's nanny
takes from it (:data:`MALLOC_THRESHOLDS`).
"""

from __future__ import annotations

import functools
import itertools
import logging
import multiprocessing
import os
import pickle
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from pathlib import Path

__all__ = [
    "FilePool",
    "Inline",
    "QUIET",
    "one_thread",
    "worker_pool",
    "OnThisMachine",
    "open_executor",
    "runs_pinned_here",
    "shares_disk",
    "tls_security",
    "worker_env",
    "LOOPBACK",
]

LOOPBACK = "127.0.0.1"
#: Dask's housekeeping in a LocalCluster without a dashboard: the statistical profiler (the dashboard's)
#: off, the event loops' tick and the system monitor slowed.  At Dask's defaults (10 ms, 20 ms, 500 ms)
#: they take about a tenth of a core between them with 2 workers, idle or busy: CPU the workers lose on
#: a machine they fill.
QUIET = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
}


class Inline:
    """The executor interface, run in the calling thread (one task at a time)."""

    def map(self, fn, *iterables):
        return map(fn, *iterables)


class OnThisMachine:
    """A Dask executor whose workers run on this machine (a LocalCluster's): they read the files this process
    writes.  ``client`` is the cluster's ``distributed.Client``, e.g. to ask every worker something with
    ``client.run``."""

    def __init__(self, client):
        self.client = client
        self.executor = client.get_executor()

    def map(self, fn, *iterables):
        return self.executor.map(fn, *iterables)


def runs_pinned_here(executor) -> bool:
    """Whether ``executor``'s workers are processes this one spawns with its own environment, so with its kernel
    pin (:func:`meshsal.util.reproducible.pin_kernels`): local worker processes (``None``, a
    ``ProcessPoolExecutor``, :class:`FilePool`).  A cluster's workers, even a LocalCluster's, start elsewhere.

    Examples
    --------
    >>> runs_pinned_here(None), runs_pinned_here(Inline())
    (True, False)
    """
    return executor is None or isinstance(executor, ProcessPoolExecutor | FilePool)


def shares_disk(executor) -> bool:
    """Whether ``executor``'s workers read the files this process writes: local worker processes, this process
    (``None``, :class:`Inline`) or a LocalCluster's (:class:`OnThisMachine`); never a cluster by address, whose
    workers may run elsewhere.

    Examples
    --------
    >>> shares_disk(Inline()), shares_disk(None)
    (True, True)
    """
    return executor is None or isinstance(executor, ProcessPoolExecutor | Inline | FilePool | OnThisMachine)


@contextmanager
def one_thread():
    """BLAS, OpenMP and OpenCV on the calling thread only, for the block; the caps before it come back after.

    OpenCV's pool is process-wide, so a block in one thread caps it for the
    process's other threads too; a worker runs one task at a time.

    Examples
    --------
    >>> import cv2
    >>> with one_thread():
    ...     cv2.getNumThreads()
    1
    """
    from threadpoolctl import threadpool_limits

    from meshsal.util.threads import opencv_threads

    _load_thread_pools()
    with opencv_threads(1), threadpool_limits(1):
        yield


def _load_thread_pools() -> None:
    """Load the thread pools a task would otherwise load later: ``threadpool_limits`` reaches only those already
    loaded (SciPy's BLAS, scikit-learn's and PyMeshLab's OpenMP)."""
    import pymeshlab  # noqa: F401
    import scipy.linalg  # noqa: F401
    import sklearn.utils._openmp_helpers  # noqa: F401


def _die_with_parent() -> None:
    """Have the kernel end this process when its parent ends (Linux), so that a run stopped by a signal
    leaves no worker computing for nobody; elsewhere, nothing."""
    import ctypes
    import signal

    if sys.platform.startswith("linux"):
        PR_SET_PDEATHSIG = 1
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
        parent = multiprocessing.parent_process()
        if parent is not None and os.getppid() != parent.pid:  # the parent ended before the request
            os._exit(1)


#: glibc's malloc thresholds for a Dask worker (bytes): arrays up to 32 MB come from the heap and are reused, and
#: the heap's free top goes back to the system past 64 MB.  Dask's nanny starts its workers with
#: ``MALLOC_TRIM_THRESHOLD_=65536``, which hands memory back at once and turns off glibc's sliding thresholds:
#: every array above 128 KB is mapped anew and its pages zeroed, and a corpus mesh's attention, hundreds of
#: temporary maps of 64 KB to a few MB, takes 40 % more CPU (0.65 against 0.46 s).  These are the values
#: glibc's sliding thresholds reach by themselves.
MALLOC_THRESHOLDS = {"mmap": 32 << 20, "trim": 64 << 20}


@functools.cache
def _glibc():
    """The C library, when it is glibc on Linux (whose malloc the functions below tune); else None.

    Looked up once, though a stack of a thousand banks hands its pages back
    many times: each lookup loads the library, and off glibc
    ``platform.libc_ver`` scans the interpreter's binary to say so.
    """
    import ctypes
    import platform

    if sys.platform != "linux" or platform.libc_ver()[0] != "glibc":
        return None
    return ctypes.CDLL("libc.so.6")


def _set_malloc_thresholds() -> None:
    """Set :data:`MALLOC_THRESHOLDS` in this process with ``mallopt`` (glibc on Linux; elsewhere nothing)."""
    libc = _glibc()
    if libc is not None:
        # glibc's M_MMAP_THRESHOLD and M_TRIM_THRESHOLD.
        libc.mallopt(-3, MALLOC_THRESHOLDS["mmap"])
        libc.mallopt(-1, MALLOC_THRESHOLDS["trim"])


def release_free_memory() -> None:
    """Hand the freed pages inside glibc's heaps back to the system (``malloc_trim``; glibc on Linux, elsewhere
    nothing).

    Arrays below the mmap threshold (:data:`MALLOC_THRESHOLDS`: 32 MB in a
    Dask worker) come from the heap, and once freed their pages stay the
    process's until the heap's top is free.  Copying a thousand objects'
    banks into one stack, each bank's own arrays let go as they are copied,
    would hold both copies at once otherwise.
    """
    libc = _glibc()
    if libc is not None:
        libc.malloc_trim(0)


def _worker_setup():
    """A Dask worker plugin run as each worker starts, on its main thread (a plugin's ``setup`` runs on the
    worker's event loop): loads the thread pools (:func:`_load_thread_pools`) and sets glibc's malloc
    thresholds (:data:`MALLOC_THRESHOLDS`), whatever started the worker.

    With PyMeshLab first loaded in a task's thread, the worker aborts as the
    process exits, after every result is in ("malloc_consolidate(): unaligned
    fastbin chunk detected": a free of the task thread's heap arena in the
    destructor of PyMeshLab's bundled GnuTLS), in about half of the batches
    on a LocalCluster; loaded on the main thread first, in none of a dozen.
    """
    from distributed.diagnostics.plugin import WorkerPlugin

    class WorkerSetup(WorkerPlugin):
        name = "visuotactile-worker-setup"

        def setup(self, worker):
            _set_malloc_thresholds()
            _load_thread_pools()

    return WorkerSetup()


def _start_worker(preload=()):
    """Worker initializer: one BLAS, OpenMP and OpenCV thread per worker process, for its whole life; ``preload``
    imported; ended with its parent."""
    import importlib

    import cv2
    from threadpoolctl import threadpool_limits

    _die_with_parent()
    _load_thread_pools()
    threadpool_limits(1)
    cv2.setNumThreads(1)
    for name in preload:
        importlib.import_module(name)


def worker_env() -> dict:
    """Environment of a LocalCluster's workers: one BLAS, OpenMP and OpenCV thread, the pinned kernels."""
    from meshsal.util.reproducible import kernel_environment

    names = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OPENCV_FOR_THREADS_NUM")
    return {**{name: "1" for name in names}, **kernel_environment()}


@contextmanager
def worker_pool(n_jobs: int, preload: tuple = ()):
    """``n_jobs`` spawned worker processes with capped BLAS, OpenMP and OpenCV threads (:class:`Inline` for one).

    Workers are spawned, not forked: the parent may hold Embree and BLAS threads.
    They start at once and import the modules named in ``preload`` (the
    toolkit's take seconds) while the caller goes on, e.g. loading its meshes.
    They take their tasks from files (:class:`FilePool`).
    """
    if int(n_jobs) <= 1:
        yield Inline()
        return
    with (
        tempfile.TemporaryDirectory(prefix="visuotactile-tasks-") as folder,
        ProcessPoolExecutor(
            int(n_jobs),
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_start_worker,
            initargs=(tuple(preload),),
        ) as pool,
    ):
        # A process is spawned per submitted task, up to n_jobs: these start them all now.
        for _ in range(int(n_jobs)):
            pool.submit(int)
        yield FilePool(pool, Path(folder))


class FilePool:
    """A process pool that hands each task to its worker through a file, not through the pool's pipe.

    A task piped to a worker is pickled whole in this process, and the
    pipe's feeder thread keeps the last one it sent until the next: a
    recognition job of a thousand objects is hundreds of megabytes, held for
    the whole stage, with the heap the pickling fragmented.  Here each task is
    pickled straight into a file (protocol 5: arrays written from where they
    lie), and the worker reads it and deletes it.  Results come back through
    the pipe.  A run killed outright (SIGKILL) leaves its unread tasks'
    files in the folder, under the system's temporary directory.

    Parameters
    ----------
    pool : concurrent.futures.ProcessPoolExecutor
    folder : Path, a private folder for the tasks' files (the caller removes it)
    """

    def __init__(self, pool, folder: Path):
        self.pool, self.folder = pool, Path(folder)
        self._written = itertools.count()

    def map(self, fn, *iterables):
        """``fn(*args)`` for each tuple of ``iterables``' items, results in order (as ``Executor.map``)."""
        return self.pool.map(_run_task_file, (self._write(fn, args) for args in zip(*iterables)))

    def submit(self, fn, *args):
        return self.pool.submit(_run_task_file, self._write(fn, args))

    def _write(self, fn, args) -> str:
        path = self.folder / f"{next(self._written)}.pkl"
        try:
            with open(path, "wb") as f:
                pickle.dump((fn, args), f, protocol=5)
        except BaseException:
            path.unlink(missing_ok=True)  # no half-written task left for a worker
            raise
        return str(path)


def _run_task_file(path: str):
    """Run the task :class:`FilePool` wrote to ``path``, deleting the file once read."""
    try:
        with open(path, "rb") as f:
            fn, args = pickle.load(f)
    finally:
        os.unlink(path)
    return fn(*args)


def tls_security(ca_file, cert, key=None):
    """A ``distributed.Security`` for mutual TLS, one certificate for every role.

    The client, the scheduler and the workers of a LocalCluster all present
    ``cert``; towards an existing cluster only the client role is used.  Each
    side accepts only peers whose certificate ``ca_file`` signed.

    Parameters
    ----------
    ca_file : path
        PEM file of the certificate authority that signed the cluster's certificates.
    cert : path
        PEM certificate of this side (it may hold the key too).
    key : path, optional
        PEM private key of ``cert`` when it is a separate file.

    Raises
    ------
    ValueError
        A file is missing, unreadable, or the certificate and key do not load,
        naming the file.
    """
    import ssl

    from distributed import Security

    files = {"CA file": ca_file, "certificate": cert, "key": key}
    for what, path in files.items():
        if path is not None and not Path(path).is_file():
            raise ValueError(f"{path}: no such TLS {what}")
    ca, cert, key = (None if p is None else str(Path(p).resolve()) for p in (ca_file, cert, key))
    try:
        ssl.create_default_context(cafile=ca)
    except (ssl.SSLError, OSError) as exc:
        raise ValueError(f"{ca}: not a PEM certificate authority ({exc})") from None
    try:
        ssl.create_default_context().load_cert_chain(cert, key)
    except (ssl.SSLError, OSError) as exc:
        raise ValueError(
            f"{cert}{' with ' + key if key else ''}: not a PEM certificate and its private key ({exc})"
        ) from None
    roles = {
        f"tls_{role}_{part}": value
        for role in ("client", "scheduler", "worker")
        for part, value in (("cert", cert), ("key", key))
        if value is not None
    }
    return Security(require_encryption=True, tls_ca_file=ca, **roles)


def _has_client_certificate(security) -> bool:
    return bool(security.tls_ca_file and security.tls_client_cert)


def _client_security(scheduler: str, security):
    """The Security a client of ``scheduler`` uses; refuses a tls:// address without certificates."""
    from distributed import Security

    security = Security() if security is None else security  # None: dask's distributed.comm.tls config
    if scheduler.startswith("tls://") and not _has_client_certificate(security):
        raise ValueError(
            f"{scheduler}: a tls:// scheduler needs a CA file and a client certificate "
            f"(--tls-ca-file, --tls-cert, --tls-key; security=tls_security(...) in Python)"
        )
    if security.require_encryption and not scheduler.startswith("tls://"):
        raise ValueError(
            f"{scheduler}: certificates were given but the address is not tls://; write it as tls://host:port"
        )
    return security


@contextmanager
def open_executor(
    workers: int | None = None,
    scheduler: str | None = None,
    n_jobs: int = 1,
    security=None,
    dashboard: str | None = None,
    preload: tuple = (),
):
    """An executor on a Dask cluster (``scheduler``), a new LocalCluster (``workers``) or local processes.

    Parameters
    ----------
    workers : int, optional
        Start a ``distributed.LocalCluster`` of this many single-threaded
        worker processes, listening on 127.0.0.1 only.
    scheduler : str, optional
        Address of a running Dask scheduler: ``tls://host:8786`` with
        ``security``, or ``tcp://127.0.0.1:8786`` through an SSH tunnel or on
        a private network.
    n_jobs : int
        Without either: local worker processes (:func:`worker_pool`).
    security : distributed.Security, optional
        Certificates (:func:`tls_security`): the client's towards
        ``scheduler``; every role's for a LocalCluster, which then runs on
        TLS.  Without it a client takes dask's ``distributed.comm.tls``
        configuration, and a ``tls://`` address without certificates is a
        ``ValueError``.
    dashboard : str, optional
        LocalCluster only: serve the dashboard at this address, e.g.
        ``127.0.0.1:8787`` (``:8787`` would serve every interface); its link
        is printed on stderr.  Off by default.
    preload : tuple of str
        Local processes only: modules each imports as it starts (:func:`worker_pool`).

    Yields
    ------
    An object with ``map(fn, iterable)`` returning results in order.
    """
    if workers is not None and scheduler is not None:
        raise ValueError("give workers or a scheduler address, not both")
    if dashboard is not None and workers is None:
        raise ValueError(
            "a dashboard address is for a new LocalCluster (workers); an existing cluster's scheduler serves its own"
        )
    if scheduler is None and workers is None:
        if security is not None:
            raise ValueError("certificates are for a Dask cluster: give workers or a scheduler address")
        with worker_pool(n_jobs, preload) as pool:
            yield pool
        return
    from distributed import Client, LocalCluster

    if scheduler is not None:
        security = _client_security(scheduler, security)
        try:
            client = Client(scheduler, timeout="20s", security=security)
        except OSError as exc:
            raise OSError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from None
        with client:
            client.register_plugin(_worker_setup())
            yield client.get_executor()
        return
    if int(workers) < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    # The scheduler always serves health and metrics over HTTP: on a free loopback port, never 8787
    # (another cluster's), and with the dashboard only when asked.
    http = (
        {"dashboard_address": dashboard}
        if dashboard is not None
        else {"dashboard_address": None, "scheduler_kwargs": {"dashboard_address": f"{LOOPBACK}:0"}}
    )
    import dask

    with (
        dask.config.set(QUIET if dashboard is None else {}),
        LocalCluster(
            n_workers=int(workers),
            threads_per_worker=1,
            processes=True,
            host=LOOPBACK,
            security=security,
            env=worker_env(),
            silence_logs=logging.ERROR,
            **http,
        ) as cluster,
        Client(cluster, security=security) as client,
    ):
        client.register_plugin(_worker_setup())
        if dashboard is not None:
            print(f"dashboard: {client.dashboard_link}", file=sys.stderr)
        yield OnThisMachine(client)
