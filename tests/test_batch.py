"""Batches of meshes: the same entries in process, on a LocalCluster and on a TLS Dask cluster of real
``dask scheduler`` / ``dask worker`` processes started elsewhere; resumable; broken meshes recorded; a killed
worker or a killed run loses nothing; an edited mesh is computed again; an entry the client cannot read is a
failure; one batch per store."""

import json
import os
import signal
import socket
import ssl
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import shapes

from classify import batch
from classify.cli import main
from classify.runtime.cluster import open_executor, tls_security

SETTINGS = batch.BatchSettings(methods=("attention", "uniform"), n_points=6, view_size=32)


def _corpus(folder: Path, count: int) -> Path:
    """Small closed meshes of several shapes and sizes, some in a subfolder."""
    folder.mkdir(parents=True, exist_ok=True)
    for i in range(count):
        if i % 3 == 0:
            mesh = shapes.icosphere(radius=1.0 + 0.1 * i, subdivisions=2)
            mesh = mesh.replace(vertices=mesh.vertices * [1.0, 0.6 + 0.05 * i, 1.3])
        elif i % 3 == 1:
            mesh = shapes.box(half=2.0 + i, n=6)
        else:
            mesh = shapes.icosphere(radius=2.0, subdivisions=2)
            mesh = mesh.replace(vertices=mesh.vertices + 0.3 * np.sin(3 * mesh.vertices[:, [1, 2, 0]] + i))
        target = folder / ("sub" if i % 4 == 3 else ".") / f"m{i:02d}.obj"
        target.parent.mkdir(exist_ok=True)
        shapes.write_obj(target, mesh)
    return folder


def _finished(store: Path) -> list[Path]:
    """The store's entries written to the end (a write in flight has a hidden temporary name)."""
    return sorted(p for p in (store / "meshes").rglob("*.npz") if not p.name.startswith("."))


def _entries(store: Path) -> dict:
    """Every entry's arrays and meta, timings and file paths left out."""
    out = {}
    for path in _finished(store):
        with np.load(path) as archive:
            meta = json.loads(str(archive["meta"]))
            meta.pop("timings_s")
            meta.pop("source")
            out[path.relative_to(store).as_posix()] = (meta, {k: archive[k] for k in archive.files if k != "meta"})
    return out


def _assert_same(a: dict, b: dict):
    assert a.keys() == b.keys()
    for key in a:
        assert a[key][0] == b[key][0], key
        assert a[key][1].keys() == b[key][1].keys()
        for name in a[key][1]:
            np.testing.assert_array_equal(a[key][1][name], b[key][1][name], err_msg=f"{key} {name}")


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    return _corpus(tmp_path_factory.mktemp("corpus"), 8)


@pytest.fixture(scope="module")
def serial_store(corpus, tmp_path_factory):
    store = tmp_path_factory.mktemp("serial")
    summary = batch.run_batch(corpus, store, SETTINGS, quiet=True)
    assert (summary.done, summary.skipped, summary.failed) == (8, 0, 0)
    return store


# Runs 'visuotactile batch' in a process of its own and stops it at the rename of entry number AFTER + 1 (tasks
# run in order in that process): 'kill' SIGKILLs the process there, a run killed mid-write (AFTER entries whole,
# the next one's temporary file written but never renamed); 'pause' prints 'paused' and waits for stdin to
# close, holding the store meanwhile, then finishes the batch.
DRIVER = """
import os, signal, sys
from classify.cli import main

after, action, argv = int(sys.argv[1]), sys.argv[2], sys.argv[3:]
rename, renamed = os.replace, []


def replace(src, dst):
    if str(dst).endswith(".npz") and f"{os.sep}meshes{os.sep}" in str(dst):
        if len(renamed) == after:
            if action == "kill":
                os.kill(os.getpid(), signal.SIGKILL)
            print("paused", flush=True)
            sys.stdin.read()
        renamed.append(dst)
    return rename(src, dst)


os.replace = replace
sys.exit(main(argv))
"""


def _batch_argv(corpus: Path, store: Path, *options: str) -> list[str]:
    """``visuotactile batch`` of ``corpus`` into ``store`` on one worker, quiet."""
    return ["batch", str(corpus), "--out", str(store), "--workers", "1", "--quiet", *options]


def _driver(after: int, action: str, corpus: Path, store: Path, *options: str) -> subprocess.Popen:
    options = options or ("--methods", "attention,uniform", "--n-points", "6", "--view-size", "32")
    return subprocess.Popen(
        [sys.executable, "-c", DRIVER, str(after), action, *_batch_argv(corpus, store, *options)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _in_flight(store: Path) -> list[Path]:
    """Temporary files of entries being written (hidden names)."""
    return sorted(p for p in (store / "meshes").rglob(".*") if p.is_file())


def test_entries_are_the_same_in_process_on_a_local_cluster_and_on_a_tls_cluster_started_elsewhere(
    corpus, serial_store, tmp_path, tls_dask_cluster, monkeypatch
):
    local = tmp_path / "local"
    with open_executor(workers=2) as executor:
        summary = batch.run_batch(corpus, local, SETTINGS, executor, quiet=True)
    assert summary.done == 8
    # The workers run in a folder of their own; the client gives paths relative to its own.
    client_cwd = tmp_path / "client"
    client_cwd.mkdir()
    monkeypatch.chdir(client_cwd)
    assert tls_dask_cluster.address.startswith("tls://")
    with open_executor(scheduler=tls_dask_cluster.address, security=tls_dask_cluster.security()) as executor:
        summary = batch.run_batch(os.path.relpath(corpus), "remote", SETTINGS, executor, quiet=True)
    assert (summary.done, summary.failed) == (8, 0)
    remote = client_cwd / "remote"
    assert not list(tls_dask_cluster.cwd.rglob("*"))  # nothing written beside the workers
    reference = _entries(serial_store)
    assert len(reference) == 8 and "meshes/sub/m03.npz" in reference
    _assert_same(reference, _entries(local))
    _assert_same(reference, _entries(remote))
    entry = batch.load_entry(remote, "sub/m03")
    assert entry.source == str(corpus.resolve() / "sub" / "m03.obj")


def test_a_tls_cluster_refuses_clients_without_its_certificates(tls_dask_cluster, tmp_path):
    from dask_cluster import make_certificates

    address = tls_dask_cluster.address
    with pytest.raises(ValueError, match=f"{address}: a tls:// scheduler needs a CA file and a client certificate"):
        with open_executor(scheduler=address):
            pass
    with pytest.raises(OSError, match="cannot reach the Dask scheduler"):
        with open_executor(scheduler=address.replace("tls://", "tcp://")):
            pass
    intruder = make_certificates(tmp_path, "intruder")  # a certificate another authority signed
    with pytest.raises(OSError, match="cannot reach the Dask scheduler"):
        with open_executor(scheduler=address, security=tls_security(intruder.ca_file, intruder.cert, intruder.key)):
            pass
    # Trusting the cluster's authority without a certificate of one's own: the scheduler ends the handshake.
    host, port = address.removeprefix("tls://").rsplit(":", 1)
    context = ssl.create_default_context(cafile=str(tls_dask_cluster.certificates.ca_file))
    context.check_hostname = False
    with socket.create_connection((host, int(port)), timeout=10) as raw:
        with pytest.raises(ssl.SSLError, match="CERTIFICATE_REQUIRED"):
            with context.wrap_socket(raw) as tls:
                tls.recv(1)


def test_a_killed_worker_loses_nothing_and_every_mesh_is_stored_once(corpus, serial_store, tmp_path, dask_cluster):
    store = tmp_path / "store"
    victim = dask_cluster.workers[0]
    at_kill = {}

    def kill_one_worker_once_an_entry_is_finished():
        end = time.monotonic() + 120
        while not _finished(store):
            if time.monotonic() > end:
                return  # nothing finished: no kill, the test fails
            time.sleep(0.05)
        victim.send_signal(signal.SIGKILL)
        victim.wait(timeout=30)
        # Read after the kill: whatever is not here yet was finished after it.
        at_kill.update({p: p.stat().st_mtime_ns for p in _finished(store)})

    killer = threading.Thread(target=kill_one_worker_once_an_entry_is_finished)
    killer.start()
    with open_executor(scheduler=dask_cluster.address) as executor:
        summary = batch.run_batch(corpus, store, SETTINGS, executor, quiet=True)
    killer.join()
    assert victim.returncode == -signal.SIGKILL  # alive until our kill, killed by it
    # A task whose worker died after writing its entry finds it complete when it runs again elsewhere.
    assert summary.done + summary.skipped == 8 and summary.skipped <= 1 and summary.failed == 0
    finished = _finished(store)
    assert at_kill and len(at_kill) < len(finished) == 8  # entries finished before and after the kill
    assert {p: p.stat().st_mtime_ns for p in at_kill} == at_kill  # none of them written again
    assert not _in_flight(store)
    _assert_same(_entries(serial_store), _entries(store))


def test_a_run_killed_mid_write_resumes_where_it_stopped(corpus, serial_store, tmp_path):
    store = tmp_path / "store"
    run = _driver(3, "kill", corpus, store)
    run.communicate(timeout=300)
    assert run.returncode == -signal.SIGKILL
    assert [p.relative_to(store / "meshes").as_posix() for p in _finished(store)] == ["m00.npz", "m01.npz", "m02.npz"]
    cut_short = _in_flight(store)
    assert len(cut_short) == 1 and cut_short[0].name.startswith(".m04.")
    summary = batch.run_batch(corpus, store, SETTINGS, quiet=True)  # the killed run's lock died with it
    assert (summary.skipped, summary.done, summary.redone, summary.failed) == (3, 5, 0, 0)
    assert not _in_flight(store)
    _assert_same(_entries(serial_store), _entries(store))
    again = batch.run_batch(corpus, store, SETTINGS, quiet=True)
    assert (again.done, again.skipped) == (0, 8)


def test_one_batch_per_store_a_second_fails_at_once_naming_the_holder(tmp_path, capsys):
    corpus = _corpus(tmp_path / "corpus", 4)
    store = tmp_path / "store"
    options = ("--methods", "uniform", "--n-points", "4")
    holder = _driver(2, "pause", corpus, store, *options)
    assert holder.stdout.readline() == "paused\n", holder.stderr.read()
    header = (store / "store.json").read_bytes()
    in_flight = _in_flight(store)
    assert len(_finished(store)) == 2 and len(in_flight) == 1
    assert main(_batch_argv(corpus, store, *options)) == 1
    err = capsys.readouterr().err
    assert (
        f"visuotactile batch: error: {store}: in use by another batch (process {holder.pid} on "
        f"{socket.gethostname()}, since "
    ) in err
    with pytest.raises(batch.StoreInUseError, match="in use by another batch"):
        batch.run_batch(corpus, store, batch.BatchSettings(methods=("random",)), quiet=True)
    # Neither touched the holder's header or its write in flight.
    assert (store / "store.json").read_bytes() == header and _in_flight(store) == in_flight
    holder.stdin.close()
    assert holder.wait(timeout=300) == 0, holder.stderr.read()
    assert len(_finished(store)) == 4 and not _in_flight(store)
    summary = batch.run_batch(corpus, store, batch.BatchSettings(methods=("uniform",), n_points=4), quiet=True)
    assert (summary.done, summary.skipped) == (0, 4)


def _write_colored_obj(path: Path, mesh, rgb) -> None:
    lines = [f"v {x!r} {y!r} {z!r} {rgb[0]} {rgb[1]} {rgb[2]}" for x, y, z in mesh.vertices.tolist()]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in mesh.faces.tolist()]
    path.write_text("\n".join(lines) + "\n")


def test_an_edited_mesh_is_computed_again_and_an_unchanged_one_is_not(tmp_path):
    import meshsal

    settings = batch.BatchSettings(methods=("uniform",), n_points=4)
    corpus = _corpus(tmp_path / "corpus", 3)
    grey = meshsal.load_mesh(corpus / "m02.obj")
    _write_colored_obj(corpus / "m02.obj", grey, (0.5, 0.5, 0.5))
    store = tmp_path / "store"
    assert batch.run_batch(corpus, store, settings, quiet=True).done == 3
    written = {p.name: p.stat().st_mtime_ns for p in _finished(store)}
    scale = batch.load_entry(store, "m01").transform.scale
    # Twice the size in the file: the same nominal mesh, another transform back to the file.
    m01 = meshsal.load_mesh(corpus / "m01.obj")
    shapes.write_obj(corpus / "m01.obj", m01.replace(vertices=m01.vertices * 2.0))
    # The same vertices and faces in another colour: only the colours changed.
    _write_colored_obj(corpus / "m02.obj", grey, (0.9, 0.1, 0.1))
    summary = batch.run_batch(corpus, store, settings, quiet=True)
    assert (summary.done, summary.redone, summary.skipped, summary.failed) == (2, 2, 1, 0)
    now = {p.name: p.stat().st_mtime_ns for p in _finished(store)}
    assert now["m00.npz"] == written["m00.npz"] and now["m01.npz"] != written["m01.npz"]
    assert now["m02.npz"] != written["m02.npz"]
    assert batch.load_entry(store, "m01").transform.scale == pytest.approx(scale / 2.0)
    fresh = tmp_path / "fresh"
    batch.run_batch(corpus, fresh, settings, quiet=True)
    _assert_same(_entries(fresh), _entries(store))
    # A file that no longer loads loses its entry: the store never holds one its file would not give.
    (corpus / "m01.obj").write_text("v 0 0 0\nv 1 0 0\nf 1 2 9\n")
    summary = batch.run_batch(corpus, store, settings, quiet=True, skip_bad=True)
    assert (summary.done, summary.skipped, summary.failed) == (0, 2, 1)
    assert sorted(batch.load_store(store)) == ["m00", "m02"]
    (failure,) = [json.loads(line) for line in (store / "failures.jsonl").read_text().splitlines()]
    assert failure["name"] == "m01" and failure["error"].endswith("its entry from an earlier run was removed")


class _LosingExecutor:
    """Runs each task in this process, then loses one entry and damages another, as workers writing to a disk
    of their own, or to a broken one, would leave them."""

    def map(self, fn, tasks):
        if fn is not batch.run._task:  # the reading of the meshes, before any entry
            yield from map(fn, tasks)
            return
        for task in tasks:
            result = fn(task)
            entry = Path(task[2]) / "meshes" / f"{task[1]}.npz"
            if task[1] == "m01":
                entry.unlink()
            elif task[1] == "m02":
                entry.write_bytes(entry.read_bytes()[:200])
            yield result


def test_an_entry_the_client_cannot_read_is_a_failure(tmp_path):
    settings = batch.BatchSettings(methods=("uniform",), n_points=4)
    corpus = _corpus(tmp_path / "corpus", 4)
    store = tmp_path / "store"
    summary = batch.run_batch(corpus, store, settings, _LosingExecutor(), quiet=True)
    assert (summary.done, summary.failed) == (2, 2)
    failures = {f["name"]: f["error"] for f in map(json.loads, (store / "failures.jsonl").read_text().splitlines())}
    assert failures.keys() == {"m01", "m02"}
    assert failures["m01"].startswith(
        f"{store / 'meshes' / 'm01.npz'}: the task reported the entry written but it is not there"
    )
    assert failures["m02"].startswith(f"{store / 'meshes' / 'm02.npz'}: damaged or truncated batch entry")
    assert sorted(batch.load_store(store)) == ["m00", "sub/m03"]  # the damaged entry is gone
    again = batch.run_batch(corpus, store, settings, quiet=True)
    assert (again.done, again.skipped, again.failed) == (2, 2, 0)


class _SpyExecutor:
    """Runs in this process and keeps the name of every function it maps."""

    def __init__(self):
        self.mapped = []

    def map(self, fn, tasks):
        self.mapped.append(fn.__name__)
        return map(fn, tasks)


def _tree(folder: Path) -> dict:
    """Every file under ``folder``: its bytes and modification time."""
    return {p: (p.read_bytes(), p.stat().st_mtime_ns) for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("folder", ["missing", "no_meshes"])
def test_a_folder_without_meshes_stops_the_batch_before_a_cluster_or_a_store(tmp_path, capsys, monkeypatch, folder):
    (tmp_path / "no_meshes").mkdir()
    (tmp_path / "no_meshes" / "notes.txt").write_text("a mistyped folder")
    opened = []
    monkeypatch.setattr("classify.runtime.cluster.open_executor", lambda **kwargs: opened.append(kwargs))
    store = tmp_path / "store"
    assert main(["batch", str(tmp_path / folder), "--out", str(store), "--workers", "2", "--quiet"]) == 1
    problem = "not a folder of meshes" if folder == "missing" else "no mesh file (.obj, .off, .ply, .stl) under"
    assert f"visuotactile batch: error: {tmp_path / folder}: {problem}" in capsys.readouterr().err
    assert opened == [] and not store.exists()
    with pytest.raises(ValueError, match=problem.replace("(", r"\(").replace(")", r"\)")):
        batch.run_batch(tmp_path / folder, store, quiet=True)
    assert not store.exists()


def test_a_negative_seed_is_refused_before_the_store_is_made(tmp_path, capsys):
    corpus = _corpus(tmp_path / "corpus", 1)
    assert main(_batch_argv(corpus, tmp_path / "store", "--seed", "-1")) == 1
    assert "visuotactile batch: error: seed must be a non-negative integer, got -1" in capsys.readouterr().err
    assert not (tmp_path / "store").exists()


def test_unreadable_meshes_are_listed_before_any_work_and_skipped_only_when_asked(tmp_path, capsys):
    corpus = _corpus(tmp_path / "corpus", 4)
    store = tmp_path / "store"
    options = ("--methods", "uniform", "--n-points", "4")
    settings = batch.BatchSettings(methods=("uniform",), n_points=4)
    assert main(_batch_argv(corpus, store, *options)) == 0
    before = _tree(store)
    (corpus / "broken.obj").write_text("v 0 0 0\nv 1 0 0\nf 1 2 9\n")  # a face beyond the vertices
    (corpus / "sub" / "empty.stl").write_bytes(b"")
    capsys.readouterr()
    # Refused, naming both files and what is wrong with each; the store as it was, and no mesh computed.
    assert main(_batch_argv(corpus, store, *options)) == 1
    err = capsys.readouterr().err
    assert f"{corpus}: 2 of 6 meshes cannot be read, so nothing was computed" in err and "--skip-bad" in err
    assert f"{corpus / 'broken.obj'}: line 3: face vertex index 9 out of range (2 vertices defined)" in err
    assert f"{corpus / 'sub' / 'empty.stl'}" in err
    assert _tree(store) == before
    spy = _SpyExecutor()
    with pytest.raises(batch.BadMeshesError) as caught:
        batch.run_batch(corpus, tmp_path / "new", settings, spy, quiet=True)
    assert spy.mapped == ["_read_task"] and not (tmp_path / "new").exists()
    assert [row["name"] for row in caught.value.bad] == ["broken", "sub/empty"]
    # Asked to skip them: the others are computed, the two recorded as failures.
    assert main(_batch_argv(corpus, store, *options, "--skip-bad")) == 0
    out, err = capsys.readouterr()
    assert "| 0 | 4 | 2 | 0 | 0 |" in out and "2 mesh(es) failed" in err
    failures = [json.loads(line) for line in (store / "failures.jsonl").read_text().splitlines()]
    assert [(f["name"], f["source"]) for f in failures] == [
        ("broken", str(corpus / "broken.obj")),
        ("sub/empty", str(corpus / "sub" / "empty.stl")),
    ]
    assert "out of range" in failures[0]["error"]
    entries = batch.load_store(store)
    assert sorted(entries) == ["m00", "m01", "m02", "sub/m03"]
    entry = entries["m01"]
    assert len(entry.points["uniform"]) == 4 and entry.imprints["uniform"].imprints.shape == (4, 16, 16)
    source = entry.transform.to_source(entry.points["uniform"].positions)
    assert np.abs(source).max() < 10.0  # back in the file's own units


def test_identical_meshes_are_one_object_stored_under_the_first_name(tmp_path, capsys):
    settings = batch.BatchSettings(methods=("uniform",), n_points=4)
    corpus = _corpus(tmp_path / "corpus", 3)
    store = tmp_path / "store"
    # A copy stored first, under a name that sorts after the original's.
    (corpus / "sub").mkdir()
    (corpus / "sub" / "m01.obj").write_bytes((corpus / "m01.obj").read_bytes())
    (corpus / "m01.obj").rename(tmp_path / "m01.obj")
    assert batch.run_batch(corpus, store, settings, quiet=True).done == 3
    (tmp_path / "m01.obj").rename(corpus / "m01.obj")
    # The same mesh, byte for byte, twice more; and one whose file differs but loads the same.
    (corpus / "sub" / "m01-again.obj").write_bytes((corpus / "m01.obj").read_bytes())
    (corpus / "z.obj").write_text((corpus / "m02.obj").read_text().replace("\n", "\r\n"))
    summary = batch.run_batch(corpus, store, settings, quiet=True)
    assert (summary.done, summary.skipped, summary.duplicates, summary.failed) == (1, 2, 3, 0)
    assert sorted(batch.load_store(store)) == ["m00", "m01", "m02"]
    rows = [json.loads(line) for line in (store / "duplicates.jsonl").read_text().splitlines()]
    assert [(r["name"], r["same_as"]) for r in rows] == [("sub/m01", "m01"), ("sub/m01-again", "m01"), ("z", "m02")]
    assert rows[0]["source"] == str(corpus / "sub" / "m01.obj")
    assert rows[0]["same_as_source"] == str(corpus / "m01.obj")
    fresh = tmp_path / "fresh"
    assert batch.run_batch(corpus, fresh, settings, quiet=True).duplicates == 3
    _assert_same(_entries(fresh), _entries(store))  # whatever the store held before
    capsys.readouterr()
    assert main(_batch_argv(corpus, store, "--methods", "uniform", "--n-points", "4")) == 0
    out, err = capsys.readouterr()
    assert "| 0 | 3 | 0 | 0 | 3 |" in out
    assert f"3 mesh(es) are the same mesh as another and are stored once: see {store}/duplicates.jsonl" in err


def test_what_loading_repaired_reaches_the_store_from_workers_elsewhere(tmp_path, dask_cluster, capsys):
    corpus = _corpus(tmp_path / "corpus", 2)
    ball = shapes.icosphere(radius=2.0, subdivisions=2)
    stray = corpus / "stray.obj"
    shapes.write_obj(stray, ball.replace(vertices=np.vstack([ball.vertices, [9.0, 9, 9]])))
    store = tmp_path / "store"
    options = ("--methods", "uniform", "--n-points", "4")
    with open_executor(scheduler=dask_cluster.address) as executor:
        summary = batch.run_batch(corpus, store, batch.BatchSettings(methods=("uniform",), n_points=4), executor)
    assert (summary.done, summary.repaired) == (3, 1)
    (row,) = [json.loads(line) for line in (store / "repairs.jsonl").read_text().splitlines()]
    assert row["name"] == "stray" and row["source"] == str(stray.resolve())
    assert row["repairs"] == f"{stray.resolve()}: removed 1 unreferenced vertices", row
    # A rerun skips every mesh and still says what loading repaired, once, in the client's words.
    capsys.readouterr()
    assert main(_batch_argv(corpus, store, *options)) == 0
    out, err = capsys.readouterr()
    assert "| 0 | 3 | 0 | 0 |" in out
    assert err.strip() == f"1 mesh(es) were repaired as they loaded: see {store}/repairs.jsonl", err
    assert [json.loads(line) for line in (store / "repairs.jsonl").read_text().splitlines()] == [row]


def test_a_store_refuses_other_settings(corpus, serial_store):
    with pytest.raises(ValueError, match="other settings"):
        batch.run_batch(corpus, serial_store, batch.BatchSettings(methods=("uniform",)), quiet=True)


def test_a_batch_task_computes_on_one_thread_and_gives_the_threads_back(tmp_path, monkeypatch):
    import cv2
    from threadpoolctl import threadpool_info

    corpus = _corpus(tmp_path / "corpus", 1)
    seen, compute = [], batch.run._compute

    def spying(*args):
        seen.append((cv2.getNumThreads(), max(pool["num_threads"] for pool in threadpool_info())))
        compute(*args)

    monkeypatch.setattr(batch.run, "_compute", spying)
    default = cv2.getNumThreads()
    try:
        cv2.setNumThreads(3)
        result = batch.process_mesh(corpus / "m00.obj", "m00", tmp_path / "store", SETTINGS)
        assert cv2.getNumThreads() == 3
    finally:
        cv2.setNumThreads(default)
    assert result["status"] == "done" and seen == [(1, 1)] and result["cpu_s"] > 0
