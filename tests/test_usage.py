"""The cost of a stage: CPU time and resident memory of this process and the processes below it."""

import subprocess
import sys
import time

import numpy as np
import pytest

from classify.runtime.usage import StageUsage, cpu_seconds, measured, resident_mb


def _child(code: str) -> subprocess.Popen:
    """A Python child that runs ``code``, prints ``ready`` and waits, alive, until its stdin closes."""
    return subprocess.Popen(
        [sys.executable, "-c", code + "\nprint('ready', flush=True)\nsys.stdin.read()"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )


def test_the_cpu_time_counts_the_workers_still_running():
    before = cpu_seconds()
    # A child that works for a while and then waits, alive, as a run's local workers do when it ends.
    child = _child("import sys, time\nt = time.process_time()\nwhile time.process_time() - t < 0.5: pass")
    try:
        assert child.stdout.readline().strip() == "ready"
        assert cpu_seconds() - before >= 0.5
    finally:
        child.communicate("")


def test_the_resident_memory_counts_a_child_holding_memory():
    before = resident_mb()
    # 256 MB written, so resident, held while the child waits.
    child = _child("import sys\nheld = bytearray(256 * 2**20)\nheld[::4096] = b'x' * len(held[::4096])")
    try:
        assert child.stdout.readline().strip() == "ready"
        assert resident_mb() - before > 250
    finally:
        child.communicate("")
    assert resident_mb() - before < 100


def test_a_measured_stage_catches_a_peak_it_frees_before_it_ends():
    def work():
        held = np.ones(160 * 2**20 // 8)  # 160 MB, written
        time.sleep(0.5)
        return float(held[-1])

    before = resident_mb()
    out, usage = measured(work, interval=0.05)
    assert out == 1.0
    assert usage.peak_mb - before > 150
    assert resident_mb() < usage.peak_mb - 100
    assert usage.wall_s >= 0.5


def test_a_measured_stage_counts_its_cpu_time():
    def spin():
        t = time.process_time()
        while time.process_time() - t < 0.3:
            pass

    _, usage = measured(spin)
    # One thread spun 0.3 s of CPU, so at least 0.3 s passed too.
    assert usage.cpu_s >= 0.3 and usage.wall_s >= 0.3


def test_a_measured_stage_counts_a_worker_it_starts_after_the_sampler_looked():
    def work():
        time.sleep(0.2)  # the sampler has looked for processes by now, and found none below this one
        child = _child("import sys\nheld = bytearray(256 * 2**20)\nheld[::4096] = b'x' * len(held[::4096])")
        try:
            assert child.stdout.readline().strip() == "ready"
            time.sleep(0.5)  # a few refreshes
        finally:
            child.communicate("")

    before = resident_mb()
    _, usage = measured(work, interval=0.02, refresh=0.1)
    assert usage.peak_mb - before > 250


def test_the_sampler_looks_for_processes_once_a_refresh_whatever_its_interval(monkeypatch):
    import threading

    import psutil

    searches, samples = [], []
    children, memory_info = psutil.Process.children, psutil.Process.memory_info

    def counted(calls, method):
        def call(self, *args, **kwargs):
            if threading.current_thread().name == "stage-memory":
                calls.append(1)
            return method(self, *args, **kwargs)

        return call

    monkeypatch.setattr(psutil.Process, "children", counted(searches, children))
    monkeypatch.setattr(psutil.Process, "memory_info", counted(samples, memory_info))
    # A search reads every process of the machine; a sample only the few it found.
    measured(lambda: time.sleep(0.5), interval=0.01, refresh=60.0)
    assert len(samples) >= 10
    assert len(searches) == 1


def test_the_costs_of_stages_in_turn_add_their_times_and_keep_the_larger_peak():
    assert StageUsage(1.0, 2.0, 300.0) + StageUsage(0.5, 0.25, 200.0) == StageUsage(1.5, 2.25, 300.0)


def test_a_stage_is_measured_only_with_a_positive_interval_and_a_refresh_not_below_zero():
    with pytest.raises(ValueError, match="interval must be positive"):
        measured(lambda: None, interval=0)
    with pytest.raises(ValueError, match="refresh must be >= 0"):
        measured(lambda: None, refresh=-1.0)


def test_a_failing_stage_stops_its_sampler_and_raises():
    import threading

    with pytest.raises(RuntimeError, match="boom"):
        measured(lambda: (_ for _ in ()).throw(RuntimeError("boom")))
    assert not any(t.name == "stage-memory" for t in threading.enumerate())


def test_the_libraries_that_every_process_maps_count_once():
    import psutil

    children = [_child("import sys\nimport numpy") for _ in range(2)]
    try:
        assert all(c.stdout.readline().strip() == "ready" for c in children)
        tree = [psutil.Process(), *(psutil.Process(c.pid) for c in children)]
        memory = [p.memory_info() for p in tree]
        every_rss = sum(m.rss for m in memory) / 2**20
        private = sum(m.rss - m.shared for m in memory) / 2**20
        # Each child maps Python's and NumPy's libraries: counted in every resident set, once here.
        assert min(m.shared for m in memory[1:]) / 2**20 > 5
        assert private < resident_mb() < every_rss - 5
    finally:
        for c in children:
            c.communicate("")
