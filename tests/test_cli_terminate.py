"""SIGTERM (a batch scheduler's time limit) and Ctrl-C end `visuotactile experiment` with its temporary folders
removed."""

import os
import signal
import subprocess
import sys
import time

import pytest


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
@pytest.mark.parametrize(
    ("signum", "status", "said"), [(signal.SIGTERM, 143, "terminated"), (signal.SIGINT, 130, "interrupted")]
)
def test_a_signal_during_an_experiment_removes_its_temporary_folders_and_exits_with_its_status(
    tmp_path, signum, status, said
):
    temp = tmp_path / "tmp"
    temp.mkdir()
    env = {**os.environ, "TMPDIR": str(temp)}
    command = [sys.executable, "-m", "classify.cli", "experiment", "--objects", "cow,cup,hand", "--methods"]
    command += ["uniform", "--classifiers", "knn", "--protocols", "instance", "--n-points", "4", "--view-size"]
    command += ["64", "--replicates", "4", "--jobs", "2", "--out", str(tmp_path / "out"), "--quiet"]
    # A child inherits an ignored SIGINT (CI's, any background job's): it gets Ctrl-C's default, as in a terminal.
    run = subprocess.Popen(
        command,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        deadline = time.monotonic() + 240
        # Wait until the run holds a temporary folder of its own (the local workers' task files).
        while not list(temp.glob("visuotactile-*")) and run.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert run.poll() is None, "the run ended before it made a temporary folder"
        assert list(temp.glob("visuotactile-*"))
        time.sleep(0.5)  # into the work
        run.send_signal(signum)
        _, err = run.communicate(timeout=120)
    finally:
        if run.poll() is None:
            run.kill()
    assert run.returncode == status, err
    assert f"visuotactile experiment: {said}" in err
    assert not list(temp.glob("visuotactile-*"))
