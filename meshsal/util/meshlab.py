"""pymeshlab, first imported by a thread that lives as long as the process.

pymeshlab loads its plugins, which are Qt objects, when it is imported. Each
plugin belongs to the thread that imported it. When that thread ends before
the process does, Qt frees the thread's data while the plugins still refer
to it. Typical such threads are a Dask worker's task thread and a
``ThreadPoolExecutor`` thread. The plugins' destructors, run at exit, then
write into the freed memory, and glibc may abort the finished process with
``malloc_consolidate(): unaligned fastbin chunk detected``.

Measured here:

* It happens in 3 of 8 runs of the batch's work on 10 corpus meshes in a
  ``ThreadPoolExecutor``, and in 3 of 4 ``visuotactile batch`` runs on a
  LocalCluster (after their results are written).
* valgrind shows ``QThreadData::deref`` on a freed block in
  ``PluginManager::~PluginManager``.
* With pymeshlab imported in the main thread, 0 of 8 runs abort, and
  valgrind is clean.

So :func:`import_pymeshlab` imports it in the calling thread when that is
the main thread. Otherwise it imports it in a daemon thread that never ends.
A process's exit runs no other thread's clean-up, so that thread's data
outlives the plugins.
"""

from __future__ import annotations

import functools
import importlib
import sys
import threading

__all__ = ["import_pymeshlab"]

_lock = threading.Lock()
_forever = threading.Event()  # never set: the importing daemon thread waits on it until the process exits


def import_pymeshlab():
    """The ``pymeshlab`` module, imported by the main thread or by a thread that never ends.

    Examples
    --------
    >>> import_pymeshlab().MeshSet().mesh_number()
    0
    """
    with _lock:
        return _imported()


@functools.cache
def _imported():
    # Already imported, its plugins belong to whichever thread did it: nothing to choose any more.
    if threading.current_thread() is threading.main_thread() or "pymeshlab" in sys.modules:
        return importlib.import_module("pymeshlab")
    done, outcome = threading.Event(), []

    def hold():
        try:
            outcome.append(importlib.import_module("pymeshlab"))
        except BaseException as exc:  # noqa: BLE001 - handed to the caller, who raises it
            outcome.append(exc)
        done.set()
        _forever.wait()

    threading.Thread(target=hold, name="pymeshlab-import", daemon=True).start()
    done.wait()
    if isinstance(outcome[0], BaseException):
        raise outcome[0]
    return outcome[0]
