"""The progress bar: what it draws on a log, and its estimate of the time left."""

import io

import pytest

import meshsal.util.progress as progress_mod
from meshsal.util.progress import progress


def test_a_log_gets_a_line_per_tenth_with_the_time_left(monkeypatch):
    clock = iter(float(t) for t in range(100))
    monkeypatch.setattr(progress_mod.time, "perf_counter", lambda: next(clock))
    out = io.StringIO()
    assert list(progress(range(20), desc="work", stream=out)) == list(range(20))
    lines = out.getvalue().splitlines()
    assert len(lines) == 11 and lines[0].startswith("work [") and "0/20" in lines[0]
    # The clock ticks one second per reading (the start, then each draw): after 10 of 20 items,
    # 11 s have passed, 1.1 s per item, so 11 s are left.
    half = next(line for line in lines if " 10/20 " in line)
    assert half.endswith("11.0s, about 11 s left")
    assert "left" not in lines[-1] and "20/20" in lines[-1]


@pytest.mark.parametrize(
    "seconds, text", [(42.4, "42 s"), (7 * 60 + 10, "7 min"), (2 * 3600 + 5 * 60, "2 h 05 min"), (3599.9, "60 min")]
)
def test_time_left_reads_as_an_estimate(seconds, text):
    assert progress_mod.duration(seconds) == text


def test_quiet_draws_nothing():
    out = io.StringIO()
    assert sum(progress(range(5), stream=out, quiet=True)) == 10 and out.getvalue() == ""
