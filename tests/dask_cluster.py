"""A real Dask cluster for the tests: ``dask scheduler`` and ``dask worker`` processes on 127.0.0.1, over tcp://
or over TLS with certificates made for the test (the ``openssl`` command line, which ships with the system)."""

import json
import os
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from meshsal.util.reproducible import kernel_environment


@dataclass(frozen=True)
class Certificates:
    """PEM files: a certificate authority and one certificate (with its key) it signed."""

    ca_file: Path
    cert: Path
    key: Path

    def dask_options(self) -> list[str]:
        return ["--tls-ca-file", str(self.ca_file), "--tls-cert", str(self.cert), "--tls-key", str(self.key)]


def make_certificates(folder: Path, name: str = "dask") -> Certificates:
    """A new certificate authority and a certificate it signed, under ``folder`` (EC P-256, valid 2 days)."""
    openssl = shutil.which("openssl")
    if openssl is None:
        raise RuntimeError("the openssl command is needed to make test certificates")
    folder.mkdir(parents=True, exist_ok=True)
    ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]

    def run(*args):
        subprocess.run([openssl, *args], cwd=folder, check=True, capture_output=True)

    run(
        "req",
        "-x509",
        *ec,
        "-keyout",
        f"{name}-ca-key.pem",
        "-out",
        f"{name}-ca.pem",
        "-days",
        "2",
        "-subj",
        f"/CN={name} test CA",
    )
    run("req", *ec, "-keyout", f"{name}-key.pem", "-out", f"{name}.csr", "-subj", f"/CN={name}")
    run(
        "x509",
        "-req",
        "-in",
        f"{name}.csr",
        "-CA",
        f"{name}-ca.pem",
        "-CAkey",
        f"{name}-ca-key.pem",
        "-CAcreateserial",
        "-out",
        f"{name}.pem",
        "-days",
        "2",
    )
    return Certificates(folder / f"{name}-ca.pem", folder / f"{name}.pem", folder / f"{name}-key.pem")


class DaskCluster:
    """A ``dask scheduler`` and two ``dask worker`` processes (no nanny: a kill is a kill) on 127.0.0.1.

    With ``certificates`` everything speaks TLS (``tls://`` address) and accepts only peers whose
    certificate the same authority signed; ``cwd`` is the working folder of the scheduler and workers.
    """

    def __init__(self, folder: Path, certificates: Certificates | None = None, cwd: Path | None = None):
        self.file = folder / "scheduler.json"
        self.certificates = certificates
        self.cwd = cwd
        self.tls = [] if certificates is None else certificates.dask_options()
        env = {**os.environ, **kernel_environment(), "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
        # The workers import the project from its folder, wherever they run.
        env["PYTHONPATH"] = os.pathsep.join([str(Path(__file__).resolve().parents[1]), env.get("PYTHONPATH", "")])
        self.env = env
        host = "127.0.0.1" if certificates is None else "tls://127.0.0.1"
        self.scheduler = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "distributed.cli.dask_scheduler",
                "--host",
                host,
                "--port",
                "0",
                "--no-dashboard",
                "--dashboard-address",  # health and metrics: on loopback, never 0.0.0.0:8787
                "127.0.0.1:0",
                "--scheduler-file",
                str(self.file),
                *self.tls,
            ],
            env=env,
            cwd=cwd,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        self._wait(lambda: self.file.exists() and "address" in self.file.read_text(), "the scheduler")
        self.address = json.loads(self.file.read_text())["address"]
        self.workers = [self._worker() for _ in range(2)]
        self.wait_for_workers(2)

    def _worker(self):
        return subprocess.Popen(
            [
                sys.executable,
                "-m",
                "distributed.cli.dask_worker",
                "--scheduler-file",
                str(self.file),
                "--nthreads",
                "1",
                "--no-nanny",
                "--no-dashboard",
                "--dashboard-address",
                "127.0.0.1:0",
                "--host",
                "127.0.0.1",
                *self.tls,
            ],
            env=self.env,
            cwd=self.cwd,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )

    def security(self):
        """The client's ``distributed.Security`` (None on tcp://)."""
        from classify.runtime.cluster import tls_security

        c = self.certificates
        return None if c is None else tls_security(c.ca_file, c.cert, c.key)

    @staticmethod
    def _wait(ready, what, timeout=60.0):
        end = time.monotonic() + timeout
        while not ready():
            if time.monotonic() > end:
                raise TimeoutError(f"{what} did not start within {timeout} s")
            time.sleep(0.2)

    def wait_for_workers(self, n):
        from distributed import Client

        with Client(self.address, timeout="30s", security=self.security()) as client:
            client.wait_for_workers(n, timeout=60)

    def close(self):
        for p in self.workers + [self.scheduler]:
            if p.poll() is None:
                p.kill()
            p.wait(timeout=30)
