"""The README's recipes for a cluster ("Running a cluster safely"), run as written on 127.0.0.1: the SSH-tunnel
recipe listens on loopback only; the TLS recipe listens elsewhere only on ports that speak nothing but mutual TLS,
and its plain-HTTP endpoints stay on loopback."""

import os
import re
import shlex
import shutil
import socket
import ssl
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest
from conftest import missing

from classify.runtime.cluster import LOOPBACK, tls_security

ROOT = Path(__file__).resolve().parents[1]
SECTION = "## Running a cluster safely"
LOOPBACKS = {LOOPBACK, "::1"}


def _recipes() -> dict:
    """``{"tunnel" | "tls": (set-up lines, [scheduler argv, worker argv])}`` from the section's bash blocks."""
    text = (ROOT / "README.md").read_text()
    start = text.index(SECTION)
    section = text[start : text.index("\n## ", start)]
    recipes = {}
    for block in re.findall(r"```bash\n(.*?)```", section, re.S):
        lines = [line.strip() for line in re.sub(r"\\\n\s*", " ", block).splitlines()]
        lines = [line for line in lines if line and not line.startswith("#")]
        first = next(i for i, line in enumerate(lines) if "dask scheduler" in line)
        dask = [
            shlex.split(line.removesuffix("&"))
            for line in lines[first:]
            if re.search(r"\bdask (scheduler|worker)", line)
        ]
        recipes["tls" if "--protocol" in dask[0] else "tunnel"] = (lines[:first], dask)
    return recipes


def _as_run_here(argv: list[str], port: int) -> list[str]:
    """A recipe's command on this machine: HOST is 127.0.0.1, 8786 a free port, two workers, this venv's tools."""
    bin_dir = Path(sys.executable).parent
    out = [t.replace("HOST", LOOPBACK).replace("8786", str(port)) for t in argv]
    out = [str(bin_dir / "dask") if t == "dask" else sys.executable if t == "python" else t for t in out]
    if "--nworkers" in out:
        out[out.index("--nworkers") + 1] = "2"
    if "scheduler" in out and "--port" not in out:
        out += ["--port", str(port)]  # the default, 8786, may be another cluster's
    return out


def _free_port() -> int:
    with socket.socket() as s:
        s.bind((LOOPBACK, 0))
        return s.getsockname()[1]


def _listening(processes) -> set:
    """(ip, port) of every listening TCP socket of these processes and their children."""
    tree = [q for p in processes for q in [psutil.Process(p.pid), *psutil.Process(p.pid).children(recursive=True)]]
    return {
        (c.laddr.ip, c.laddr.port)
        for q in tree
        for c in q.net_connections(kind="inet")
        if c.status == psutil.CONN_LISTEN
    }


def _plain_http_answers(port: int) -> bool:
    with socket.create_connection((LOOPBACK, port), timeout=10) as s:
        s.sendall(b"GET /health HTTP/1.0\r\nHost: localhost\r\n\r\n")
        try:
            return s.recv(16).startswith(b"HTTP/")
        except (ConnectionError, TimeoutError):
            return False


def _tls_handshake(port: int, cwd: Path, cert: str | None) -> bool:
    """Whether the port lets a TLS client signed by the recipe's CA in, showing ``cert`` (None: no certificate)."""
    context = ssl.create_default_context(cafile=str(cwd / "ca.pem"))
    context.check_hostname = False
    if cert:
        context.load_cert_chain(cwd / f"{cert}.pem", cwd / f"{cert}-key.pem")
    with socket.create_connection((LOOPBACK, port), timeout=10) as raw:
        try:
            tls = context.wrap_socket(raw)
        except (ssl.SSLError, ConnectionError, TimeoutError):
            return False
        with tls:
            # TLS 1.3 servers judge the client's certificate after the handshake: a refusal arrives as an alert.
            tls.settimeout(1.0)
            try:
                tls.sendall(b"\0")
                tls.recv(1)
            except (ssl.SSLError, ConnectionError):
                return False
            except TimeoutError:
                pass  # let in: the server waits for the rest of a message
        return True


def _start(recipe: str, cwd: Path):
    setup, (scheduler, worker) = _recipes()[recipe]
    if setup:
        subprocess.run(["bash", "-ec", "\n".join(setup)], cwd=cwd, check=True, capture_output=True)
    port = _free_port()
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    quiet = {"cwd": cwd, "env": env, "stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    started = [subprocess.Popen(_as_run_here(scheduler, port), **quiet)]
    end = time.monotonic() + 60
    while not any(port == p for _, p in _listening(started)):
        assert started[0].poll() is None and time.monotonic() < end, "the scheduler did not start"
        time.sleep(0.2)
    started.append(subprocess.Popen(_as_run_here(worker, port), **quiet))
    return started, port


def _stop(processes):
    for p in reversed(processes):
        p.terminate()
    for p in processes:
        try:
            p.wait(timeout=30)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(timeout=30)


def _wait_for_two_workers(address: str, security=None):
    from distributed import Client

    with Client(address, timeout="30s", security=security) as client:
        client.wait_for_workers(2, timeout=90)


@pytest.fixture
def tools():
    if shutil.which("openssl") is None:
        missing("the openssl command, which the TLS recipe uses, is not installed")


def test_the_tunnel_recipe_listens_on_loopback_only(tmp_path):
    processes, port = _start("tunnel", tmp_path)
    try:
        _wait_for_two_workers(f"tcp://{LOOPBACK}:{port}")
        opened = _listening(processes)
    finally:
        _stop(processes)
    # The scheduler, the nanny of each worker, the two workers, the HTTP endpoints of the scheduler and workers.
    assert len(opened) >= 6 and (LOOPBACK, port) in opened
    assert {ip for ip, _ in opened} == {LOOPBACK}, opened


def test_the_tls_recipe_speaks_only_tls_beyond_loopback_and_serves_no_dashboard(tmp_path, tools):
    processes, port = _start("tls", tmp_path)
    try:
        client = tls_security(tmp_path / "ca.pem", tmp_path / "client.pem", tmp_path / "client-key.pem")
        _wait_for_two_workers(f"tls://{LOOPBACK}:{port}", client)
        opened = _listening(processes)
        http = {p for _, p in opened if _plain_http_answers(p)}
        beyond = {p for ip, p in opened if ip not in LOOPBACKS}
        with_certificate = {p for p in beyond - http if _tls_handshake(p, tmp_path, "client")}
        without_certificate = {p for p in beyond - http if _tls_handshake(p, tmp_path, None)}
    finally:
        _stop(processes)
    # Plain HTTP (health, metrics) on loopback only: the scheduler's and each worker's.
    assert len(http) >= 3 and {ip for ip, p in opened if p in http} <= LOOPBACKS, opened
    # Other machines reach the scheduler and the workers on every interface (the nannies bind the one that
    # leads to the scheduler, here loopback), over mutual TLS.
    assert port in beyond and len(beyond) >= 3, opened
    assert with_certificate == beyond and without_certificate == set()
