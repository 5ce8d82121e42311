"""What a stage of work costs the machine: its wall time, its CPU time and its peak memory, workers included.

A run's local workers are child processes, so the CPU time and the
resident memory of this process and every process below it are the run's.
Workers of a Dask cluster started elsewhere are not below it: their cost is
the cluster's, not counted here.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass

__all__ = ["StageUsage", "cpu_seconds", "measured", "resident_mb"]


def cpu_seconds() -> float:
    """User and system CPU seconds of this process and of every process below it, running or ended.

    Local workers still run when a run ends, so the kernel's count of ended
    children alone would miss all their work.
    """
    import resource

    import psutil

    own, ended = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    total = own.ru_utime + own.ru_stime + ended.ru_utime + ended.ru_stime
    for child in psutil.Process().children(recursive=True):
        try:
            times = child.cpu_times()
        except psutil.Error:  # ended meanwhile: counted with the ended ones once reaped
            continue
        total += times.user + times.system
    return total


def resident_mb() -> float:
    """Memory this process and every process below it hold together, in MB (2**20 bytes).

    Each process's private resident memory (its resident set less the
    pages it maps from files: the heap, the arrays), summed, plus the
    largest process's file-backed resident pages (the libraries, which
    every worker maps and which count once).  Read from ``/proc/<pid>/statm``
    on Linux: counters, so sampling never walks a worker's page tables nor
    holds its memory map's lock.  Elsewhere the shared pages are not
    reported, and each process's whole resident set is summed.
    """
    return _ProcessTree(refresh=0.0).resident_mb()


class _ProcessTree:
    """This process and the processes below it, looked for anew at most every ``refresh`` seconds.

    Finding the processes below this one reads every process of the machine
    (psutil walks ``/proc``), so its cost grows with the machine's process
    count, not the run's, and each of its reads makes the threads doing the
    work give up Python's lock.  Between two searches a sample reads only
    the processes already found: a few counters each.
    """

    def __init__(self, refresh: float):
        import psutil

        self._me, self._refresh, self._found, self._below = psutil.Process(), refresh, -math.inf, []

    def resident_mb(self) -> float:
        import psutil

        now = time.monotonic()
        if now - self._found >= self._refresh:
            self._below, self._found = self._me.children(recursive=True), now
        private, shared = 0, 0
        for process in [self._me, *self._below]:
            try:
                memory = process.memory_info()
            except psutil.Error:  # ended meanwhile: it holds nothing now
                continue
            mapped = getattr(memory, "shared", 0)
            private += memory.rss - mapped
            shared = max(shared, mapped)
        return (private + shared) / 2**20


@dataclass(frozen=True)
class StageUsage:
    """The cost of one piece of work: ``wall_s`` and ``cpu_s`` seconds, ``peak_mb`` its largest :func:`resident_mb`.

    ``+`` joins the costs of two pieces run one after the other: times add, the peak is the larger one.

    Examples
    --------
    >>> StageUsage(2.0, 3.5, 100.0) + StageUsage(1.0, 1.5, 250.0)
    StageUsage(wall_s=3.0, cpu_s=5.0, peak_mb=250.0)
    """

    wall_s: float
    cpu_s: float
    peak_mb: float

    def __add__(self, other: StageUsage) -> StageUsage:
        return StageUsage(self.wall_s + other.wall_s, self.cpu_s + other.cpu_s, max(self.peak_mb, other.peak_mb))


def measured(work, interval: float = 0.1, refresh: float = 1.0):
    """``work()`` and its :class:`StageUsage`: ``(result, usage)``.

    The memory is sampled every ``interval`` seconds by a thread that
    only reads ``/proc``, and once before and once after the work, so a
    peak shorter than ``interval`` between two samples can be missed.  The
    sampler looks for the processes below this one every ``refresh``
    seconds, so a worker started meanwhile counts from then on.

    Examples
    --------
    >>> out, usage = measured(lambda: sum(range(10**6)))
    >>> out, usage.peak_mb > 0, usage.cpu_s >= 0
    (499999500000, True, True)
    """
    if not interval > 0:
        raise ValueError(f"interval must be positive, got {interval}")
    if not refresh >= 0:
        raise ValueError(f"refresh must be >= 0, got {refresh}")
    peak = [resident_mb()]
    done = threading.Event()

    def sample():
        tree = _ProcessTree(refresh)
        while not done.wait(interval):
            peak[0] = max(peak[0], tree.resident_mb())

    sampler = threading.Thread(target=sample, name="stage-memory", daemon=True)
    started, cpu_started = time.perf_counter(), cpu_seconds()
    sampler.start()
    try:
        out = work()
    finally:
        done.set()
        sampler.join()
    usage = StageUsage(time.perf_counter() - started, cpu_seconds() - cpu_started, max(peak[0], resident_mb()))
    return out, usage
