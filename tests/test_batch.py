"""Batches of meshes: the same entries in process, on a LocalCluster and on a tcp:// Dask cluster of real
``dask scheduler`` / ``dask worker`` processes; resumable; broken meshes recorded; a killed worker or a
killed run loses nothing."""

import json
import signal
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
from classify.runtime.cluster import open_executor

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


def test_entries_are_the_same_in_process_on_a_local_cluster_and_on_a_tcp_cluster(corpus, serial_store, tmp_path,
                                                                                  dask_cluster):
    local = tmp_path / "local"
    with open_executor(workers=2) as executor:
        summary = batch.run_batch(corpus, local, SETTINGS, executor, quiet=True)
    assert summary.done == 8
    remote = tmp_path / "remote"
    with open_executor(scheduler=dask_cluster.address) as executor:
        assert batch.run_batch(corpus, remote, SETTINGS, executor, quiet=True).done == 8
    reference = _entries(serial_store)
    assert len(reference) == 8 and "meshes/sub/m03.npz" in reference
    _assert_same(reference, _entries(local))
    _assert_same(reference, _entries(remote))


def test_a_killed_worker_loses_nothing_and_every_mesh_is_stored_once(tmp_path, dask_cluster):
    corpus = _corpus(tmp_path / "corpus", 12)
    store = tmp_path / "store"
    settings = batch.BatchSettings(methods=("attention",), n_points=6, view_size=48)
    killer_done = []

    def kill_one_worker_when_work_has_started():
        end = time.monotonic() + 120
        while time.monotonic() < end and not _finished(store):
            time.sleep(0.05)
        dask_cluster.workers[0].send_signal(signal.SIGKILL)
        killer_done.append(dask_cluster.workers[0].wait(timeout=30))

    killer = threading.Thread(target=kill_one_worker_when_work_has_started)
    killer.start()
    with open_executor(scheduler=dask_cluster.address) as executor:
        summary = batch.run_batch(corpus, store, settings, executor, quiet=True)
    killer.join()
    assert killer_done and killer_done[0] != 0                      # the worker really died mid-batch
    assert (summary.done, summary.failed) == (12, 0)
    files = sorted(p.relative_to(store).as_posix() for p in (store / "meshes").rglob("*") if p.is_file())
    assert len(files) == 12 and len(set(files)) == 12 and not any(Path(f).name.startswith(".") for f in files)
    reference = tmp_path / "reference"
    batch.run_batch(corpus, reference, settings, quiet=True)
    _assert_same(_entries(reference), _entries(store))


def test_a_killed_run_resumes_where_it_stopped(corpus, serial_store, tmp_path):
    store = tmp_path / "store"
    command = [sys.executable, "-m", "classify.cli", "batch", str(corpus), "--out", str(store), "--workers", "1",
               "--methods", "attention,uniform", "--n-points", "6", "--view-size", "32", "--quiet"]
    run = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    end = time.monotonic() + 120
    while time.monotonic() < end and len(_finished(store)) < 2:
        time.sleep(0.05)
    run.send_signal(signal.SIGKILL)
    run.wait(timeout=30)
    first = _finished(store)
    assert 2 <= len(first) < 8                                      # killed with work left to do
    summary = batch.run_batch(corpus, store, SETTINGS, quiet=True)
    assert summary.skipped == len(first) and summary.done == 8 - len(first)
    assert not list((store / "meshes").rglob(".*"))                 # a write cut short by the kill is gone
    _assert_same(_entries(serial_store), _entries(store))
    again = batch.run_batch(corpus, store, SETTINGS, quiet=True)
    assert (again.done, again.skipped) == (0, 8)


def test_a_broken_mesh_is_recorded_and_does_not_stop_the_batch(tmp_path, capsys):
    corpus = _corpus(tmp_path / "corpus", 3)
    (corpus / "broken.obj").write_text("v 0 0 0\nv 1 0 0\nf 1 2 9\n")
    store = tmp_path / "store"
    assert main(["batch", str(corpus), "--out", str(store), "--workers", "1", "--methods", "uniform",
                 "--n-points", "4", "--quiet"]) == 0
    out, err = capsys.readouterr()
    assert "| 3 | 0 | 1 |" in out and "failures.jsonl" in err
    failures = [json.loads(line) for line in (store / "failures.jsonl").read_text().splitlines()]
    assert [f["name"] for f in failures] == ["broken"] and "broken.obj" in failures[0]["error"]
    entries = batch.load_store(store)
    assert sorted(entries) == ["m00", "m01", "m02"]
    entry = entries["m01"]
    assert len(entry.points["uniform"]) == 4 and entry.imprints["uniform"].imprints.shape == (4, 16, 16)
    source = entry.transform.to_source(entry.points["uniform"].positions)
    assert np.abs(source).max() < 10.0                               # back in the file's own units


def test_a_store_refuses_other_settings(corpus, serial_store):
    with pytest.raises(ValueError, match="other settings"):
        batch.run_batch(corpus, serial_store, batch.BatchSettings(methods=("uniform",)), quiet=True)
