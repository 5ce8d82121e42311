"""classify.runtime.cluster: a LocalCluster listens on 127.0.0.1 only (dashboard off unless asked), on TLS when
given certificates; a tls:// address without certificates and mixed-up options are clear errors."""

import platform
import shutil
import sys

import numpy as np
import psutil
import pytest
from conftest import missing

from classify.cli import main
from classify.runtime.cluster import (
    LOOPBACK,
    QUIET,
    one_thread,
    open_executor,
    shares_disk,
    tls_security,
    worker_pool,
)


def _listening() -> set:
    """(pid, ip, port) of every listening TCP socket of this process and its children."""
    me = psutil.Process()
    return {
        (p.pid, c.laddr.ip, c.laddr.port)
        for p in [me, *me.children(recursive=True)]
        for c in p.net_connections(kind="inet")
        if c.status == psutil.CONN_LISTEN
    }


def _addresses(_):
    from distributed import get_worker

    worker = get_worker()
    return worker.address, worker.scheduler.address


@pytest.fixture(scope="module")
def certificates(tmp_path_factory):
    from dask_cluster import make_certificates

    if shutil.which("openssl") is None:
        missing("the openssl command, which makes the test certificates, is not installed")
    return make_certificates(tmp_path_factory.mktemp("certs"))


@pytest.mark.parametrize("tls", [False, True], ids=["tcp", "tls"])
def test_a_local_cluster_listens_on_loopback_only_with_no_dashboard(tls, request, capsys):
    security = None
    if tls:
        c = request.getfixturevalue("certificates")
        security = tls_security(c.ca_file, c.cert, c.key)
    before = _listening()
    with open_executor(workers=2, security=security) as executor:
        addresses = list(executor.map(_addresses, range(4)))
        opened = _listening() - before
    scheme = "tls://" if tls else "tcp://"
    assert {a for pair in addresses for a in pair} <= {a for a in _as_addresses(opened, scheme)}
    # The scheduler, its nannies and workers, and the HTTP endpoints (health, metrics) of the scheduler and
    # each worker: all on the loopback interface.
    assert len(opened) >= 5 and {ip for _, ip, _ in opened} == {LOOPBACK}
    assert "dashboard" not in capsys.readouterr().err


def _threads(_) -> tuple:
    """OpenCV's threads and the most threads any BLAS or OpenMP pool of this process may use."""
    import cv2
    from threadpoolctl import threadpool_info

    return cv2.getNumThreads(), max(pool["num_threads"] for pool in threadpool_info())


def _housekeeping(_) -> tuple:
    import dask

    return tuple(dask.config.get(key) for key in QUIET)


def _task_threads(_) -> tuple:
    with one_thread():
        return _threads(None)


def test_a_task_runs_on_one_thread_wherever_it_runs():
    import cv2

    default = cv2.getNumThreads()
    try:
        cv2.setNumThreads(3)
        assert _task_threads(None) == (1, 1)
        assert cv2.getNumThreads() == 3  # the caps end with the block
    finally:
        cv2.setNumThreads(default)
    # Workers of a LocalCluster and of the local process pool start on one thread; a worker started
    # elsewhere, as a plain 'dask worker', gets the caps from each task (tests/test_batch.py runs on one).
    with open_executor(workers=2) as executor:
        assert shares_disk(executor)  # its workers read the files this process writes
        assert list(executor.map(_threads, range(2))) == [(1, 1)] * 2
        # Without a dashboard, no profiler samples the task's thread and the loops tick slowly.
        assert list(executor.map(_housekeeping, range(2))) == [tuple(QUIET.values())] * 2
    with worker_pool(2) as pool:
        assert list(pool.map(_threads, range(2))) == [(1, 1)] * 2


def _mapped_blocks() -> tuple:
    """The nanny's MALLOC_TRIM_THRESHOLD_, and how many blocks glibc maps apart from its heap for a 1 MB and a
    64 MB allocation (``mallinfo2().hblks`` while each is held)."""
    import ctypes
    import os

    # glibc's struct mallinfo2, every field: it is returned by value.
    fields = "arena ordblks smblks hblks hblkhd usmblks fsmblks uordblks fordblks keepcost".split()

    class Info(ctypes.Structure):
        _fields_ = [(name, ctypes.c_size_t) for name in fields]

    libc = ctypes.CDLL("libc.so.6")
    libc.mallinfo2.restype, libc.malloc.restype = Info, ctypes.c_void_p
    mapped = []
    for size in (1 << 20, 64 << 20):
        before = libc.mallinfo2().hblks
        block = libc.malloc(size)
        mapped.append(libc.mallinfo2().hblks - before)
        libc.free(ctypes.c_void_p(block))
    return os.environ.get("MALLOC_TRIM_THRESHOLD_"), tuple(mapped)


@pytest.mark.skipif(sys.platform != "linux" or platform.libc_ver()[0] != "glibc", reason="glibc's malloc only")
def test_dask_workers_keep_arrays_up_to_32_mb_on_the_heap_whatever_the_nanny_sets():
    """Dask's nanny starts workers with MALLOC_TRIM_THRESHOLD_=65536, which maps every block above 128 KB anew;
    the worker plugin gives the worker glibc's own thresholds back."""
    with open_executor(workers=2) as executor:
        assert list(executor.client.run(_mapped_blocks).values()) == [("65536", (0, 1))] * 2


def test_dask_workers_load_pymeshlab_on_their_main_thread_before_any_task(dask_cluster):
    # Loaded first in a task's thread, PyMeshLab's GnuTLS aborts the worker process as it exits.
    from distributed import Client

    def _imported_at_start(dask_worker):  # local: sent by value to workers that cannot import the tests
        """Whether the worker holds the plugin that loads PyMeshLab on its main thread, and PyMeshLab is loaded."""
        import sys

        return "visuotactile-worker-setup" in dask_worker.plugins and "pymeshlab" in sys.modules

    with open_executor(workers=2) as executor:
        assert list(executor.client.run(_imported_at_start).values()) == [True, True]
    with Client(dask_cluster.address) as client:  # workers started elsewhere, before any client
        assert not any(client.run(_imported_at_start).values())
        with open_executor(scheduler=dask_cluster.address):
            assert list(client.run(_imported_at_start).values()) == [True, True]


def _nbytes(a):
    return a.nbytes


def _fail(x):
    raise ValueError(f"task {x} failed")


def test_the_local_pool_hands_tasks_over_in_files_it_deletes_and_keeps_none_of_them():
    import pickle

    big = np.ones(48 * 2**20 // 8)  # 48 MB
    me = psutil.Process()
    with worker_pool(2) as pool:
        folder = pool.folder
        assert list(pool.map(pow, [2, 3, 4], [3, 2, 1])) == [8, 9, 4]  # in order, several iterables
        before = me.memory_info().rss
        assert list(pool.map(_nbytes, [big, big])) == [big.nbytes] * 2
        # A piped task stays pickled in this process until the next is sent (the feeder's last object).
        assert me.memory_info().rss - before < 0.5 * big.nbytes
        assert pool.submit(_nbytes, big).result() == big.nbytes
        with pytest.raises(ValueError, match="task 1 failed"):
            list(pool.map(_fail, [1]))
        with pytest.raises((pickle.PicklingError, AttributeError)):
            pool.map(_nbytes, [lambda: big])  # a task that cannot be written leaves no half of it
        assert not any(folder.iterdir())  # each file deleted once read, a failing task's too
    assert not folder.exists()


def _as_addresses(opened, scheme):
    return {f"{scheme}{ip}:{port}" for _, ip, port in opened}


def test_a_dashboard_is_served_where_asked(capsys):
    import urllib.request

    before = _listening()
    with open_executor(workers=1, dashboard=f"{LOOPBACK}:0") as executor:
        assert list(executor.map(abs, [-1])) == [1]
        opened = _listening() - before
        link = capsys.readouterr().err.strip().removeprefix("dashboard: ")
        assert link.startswith(f"http://{LOOPBACK}:")
        with urllib.request.urlopen(link.rsplit("/", 1)[0] + "/health", timeout=10) as reply:
            assert reply.read() == b"ok"
    assert {ip for _, ip, _ in opened} == {LOOPBACK}


def test_mixed_up_cluster_options_are_clear_errors(certificates, tmp_path):
    security = tls_security(certificates.ca_file, certificates.cert, certificates.key)
    with pytest.raises(ValueError, match="tls://10.0.0.1:8786: a tls:// scheduler needs a CA file"):
        with open_executor(scheduler="tls://10.0.0.1:8786"):
            pass
    with pytest.raises(ValueError, match="tcp://10.0.0.1:8786: certificates were given but the address is not tls"):
        with open_executor(scheduler="tcp://10.0.0.1:8786", security=security):
            pass
    with pytest.raises(ValueError, match="certificates are for a Dask cluster"):
        with open_executor(n_jobs=2, security=security):
            pass
    with pytest.raises(ValueError, match="a dashboard address is for a new LocalCluster"):
        with open_executor(scheduler="tcp://127.0.0.1:8786", dashboard="127.0.0.1:8787"):
            pass
    with pytest.raises(ValueError, match="nowhere.pem: no such TLS certificate"):
        tls_security(certificates.ca_file, tmp_path / "nowhere.pem")
    with pytest.raises(ValueError, match="not a PEM certificate and its private key"):
        tls_security(certificates.ca_file, certificates.cert, certificates.ca_file)  # the wrong key


def test_the_command_line_refuses_tls_without_certificates(tmp_path, capsys, certificates):
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "tet.obj").write_text(
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
    )
    args = ["batch", str(tmp_path / "meshes"), "--out", str(tmp_path / "store")]
    assert main([*args, "--scheduler", "tls://127.0.0.1:8786"]) == 1
    assert (
        "tls://127.0.0.1:8786: a tls:// scheduler needs a CA file and a client certificate (--tls-ca-file, "
        "--tls-cert, --tls-key" in capsys.readouterr().err
    )
    assert main([*args, "--scheduler", "tls://127.0.0.1:8786", "--tls-cert", str(certificates.cert)]) == 1
    assert "TLS needs both --tls-ca-file and --tls-cert; only --tls-cert was given" in capsys.readouterr().err
    assert (
        main(
            [
                "experiment",
                "--tls-ca-file",
                str(certificates.ca_file),
                "--tls-cert",
                str(certificates.cert),
                "--tls-key",
                str(certificates.key),
                "--out",
                str(tmp_path / "results"),
            ]
        )
        == 1
    )
    assert "certificates are for a Dask cluster" in capsys.readouterr().err
    assert not (tmp_path / "store").exists()


_ORPHAN = """
import os, sys, time
from classify.runtime.cluster import worker_pool
if __name__ == "__main__":
    with worker_pool(2) as pool:
        pids = sorted(p.pid for p in pool.pool._processes.values())
        print(" ".join(map(str, pids)), flush=True)
        pool.submit(time.sleep, 600)
        time.sleep(600)
"""


def test_workers_end_with_a_run_that_is_killed(tmp_path):
    import os
    import signal
    import subprocess
    import sys
    import time

    script = tmp_path / "run.py"
    script.write_text(_ORPHAN)
    # The killed run's task folder, with its unread task, is left where TMPDIR says: here, not in /tmp.
    env = {**os.environ, "TMPDIR": str(tmp_path)}
    run = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True, env=env)
    pids = [int(p) for p in run.stdout.readline().split()]
    assert len(pids) == 2 and all(psutil.pid_exists(p) for p in pids)
    run.send_signal(signal.SIGKILL)  # no clean-up runs: only the kernel can end the workers now
    run.wait(timeout=30)
    deadline = time.monotonic() + 30
    while any(psutil.pid_exists(p) and psutil.Process(p).status() != psutil.STATUS_ZOMBIE for p in pids):
        assert time.monotonic() < deadline, f"workers {pids} outlive their killed parent"
        time.sleep(0.2)
    assert len(list(tmp_path.glob("visuotactile-tasks-*"))) == 1
