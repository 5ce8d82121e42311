"""SIGTERM (a batch scheduler's time limit), Ctrl-C and a worker killed (out of memory) end `visuotactile
experiment` with its temporary folders removed."""

import contextlib
import os
import signal
import subprocess
import sys
import time

import pytest


@contextlib.contextmanager
def _experiment_at_work(tmp_path, *options):
    """A ``visuotactile experiment`` on three toys with local workers, once it holds a temporary folder of its
    own (the workers' task files), and that folder (its ``TMPDIR``); killed on the way out if still running."""
    temp = tmp_path / "tmp"
    temp.mkdir()
    command = [sys.executable, "-m", "classify.cli", "experiment", "--objects", "cow,cup,hand", "--methods"]
    command += ["uniform", "--classifiers", "knn", "--protocols", "instance", "--n-points", "4", "--view-size"]
    command += ["64", "--replicates", "4", "--jobs", "2", "--out", str(tmp_path / "out"), "--quiet", *options]
    # A child inherits an ignored SIGINT (CI's, any background job's): it gets Ctrl-C's default, as in a terminal.
    run = subprocess.Popen(
        command,
        env={**os.environ, "TMPDIR": str(temp)},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        deadline = time.monotonic() + 240
        while not list(temp.glob("visuotactile-*")) and run.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert run.poll() is None, "the run ended before it made a temporary folder"
        assert list(temp.glob("visuotactile-*"))
        yield run, temp
    finally:
        if run.poll() is None:
            run.kill()


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
@pytest.mark.parametrize(
    ("signum", "status", "said"), [(signal.SIGTERM, 143, "terminated"), (signal.SIGINT, 130, "interrupted")]
)
def test_a_signal_during_an_experiment_removes_its_temporary_folders_and_exits_with_its_status(
    tmp_path, signum, status, said
):
    with _experiment_at_work(tmp_path) as (run, temp):
        time.sleep(0.5)  # into the work
        run.send_signal(signum)
        _, err = run.communicate(timeout=120)
    assert run.returncode == status, err
    assert f"visuotactile experiment: {said}" in err
    assert not list(temp.glob("visuotactile-*"))


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_a_worker_killed_mid_experiment_ends_it_with_a_message_and_no_temporary_folder(tmp_path):
    import psutil

    with _experiment_at_work(tmp_path, "--cache-dir", str(tmp_path / "cache")) as (run, temp):
        time.sleep(1.0)  # the workers at work
        children = psutil.Process(run.pid).children()
        workers = [c for c in children if "spawn_main" in " ".join(c.cmdline())]  # not the resource tracker
        assert run.poll() is None and workers, "the run ended before its workers started"
        workers[0].kill()  # as the system's out-of-memory killer would
        _, err = run.communicate(timeout=120)
    assert run.returncode == 1, err
    assert "visuotactile experiment: error: a worker process ended abruptly" in err and "to resume" in err
    assert "Traceback" not in err
    assert not list(temp.glob("visuotactile-*"))
