"""The experiment's disk cache: hits, misses on every part of the key, damaged entries, killed writers."""

import io
import json
import os
import signal
import subprocess
import sys
import zipfile
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest
import shapes

from classify.experiment import samples
from classify.runtime import cache


class Counter:
    """A compute function that counts its calls."""

    def __init__(self, value=1.0):
        self.calls, self.value = 0, value

    def __call__(self):
        self.calls += 1
        return {"x": np.full(4, self.value), "ids": np.arange(3)}


# ---------------------------------------------------------------- cached(): hit and miss


def test_the_second_call_reads_the_entry_and_computes_nothing(tmp_path):
    compute = Counter()
    first = cache.cached(tmp_path, "k", compute)
    again = cache.cached(tmp_path, "k", Counter(value=9.0))  # would give other numbers if it ran
    assert compute.calls == 1
    for name in ("x", "ids"):
        np.testing.assert_array_equal(again[name], first[name])
        assert again[name].dtype == first[name].dtype
    assert [p.name for p in tmp_path.iterdir()] == ["k.npz"]


def test_another_key_computes_and_no_directory_always_computes(tmp_path):
    compute = Counter()
    cache.cached(tmp_path, "a", compute)
    cache.cached(tmp_path, "b", compute)
    assert compute.calls == 2
    cache.cached(None, "a", compute)
    cache.cached(None, "a", compute)
    assert compute.calls == 4


# ---------------------------------------------------------------- the parts of a key


def test_cache_key_changes_with_every_part_and_not_with_dict_order():
    parts = ("mesh-hash", "cow", "attention", {"n": 15, "size": 150.0}, [0, 1], "code", {"numpy": "2.0"})
    key = cache.cache_key("paper", *parts)
    assert key == cache.cache_key("paper", *parts[:3], {"size": 150.0, "n": 15}, *parts[4:])
    assert key.startswith("paper-") and cache.cache_key("instance", *parts) != key
    changed = ["other-hash", "cup", "uniform", {"n": 16, "size": 150.0}, [0, 2], "code2", {"numpy": "2.1"}]
    for i, value in enumerate(changed):
        assert cache.cache_key("paper", *parts[:i], value, *parts[i + 1 :]) != key, f"part {i} is not in the key"


def test_hash_arrays_changes_with_one_vertex_the_dtype_or_a_missing_array():
    V = np.random.default_rng(0).random((30, 3))
    moved = V.copy()
    moved[7, 2] += 1e-12
    h = cache.hash_arrays(V, None)
    assert h == cache.hash_arrays(V.copy(), None)
    assert (
        len(
            {
                h,
                cache.hash_arrays(moved, None),
                cache.hash_arrays(V.astype(np.float32), None),
                cache.hash_arrays(V, np.zeros(0)),
                cache.hash_arrays(V.reshape(45, 2), None),
            }
        )
        == 5
    )


def test_code_fingerprint_changes_when_a_source_file_changes(tmp_path, monkeypatch):
    package = tmp_path / "fingerprinted_pkg"
    (package / "sub").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "sub" / "rule.py").write_text("THRESHOLD = 0.5\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    before = cache.code_fingerprint("fingerprinted_pkg")
    (package / "notes.txt").write_text("not code")
    assert cache.code_fingerprint("fingerprinted_pkg") == before
    (package / "sub" / "rule.py").write_text("THRESHOLD = 0.6\n")
    edited = cache.code_fingerprint("fingerprinted_pkg")
    assert edited != before
    (package / "sub" / "extra.py").write_text("")
    assert cache.code_fingerprint("fingerprinted_pkg") not in (before, edited)


def test_library_versions_report_an_upgrade(monkeypatch):
    before = cache.library_versions()
    real = metadata.version
    monkeypatch.setattr(metadata, "version", lambda name: "999.0" if name == "scipy" else real(name))
    assert cache.library_versions() == before  # read once per process
    # The next process reads them again.
    cache._installed_versions.cache_clear()
    try:
        after = cache.library_versions()
    finally:
        cache._installed_versions.cache_clear()
    assert after["scipy"] == "999.0" != before["scipy"]
    assert {k: v for k, v in after.items() if k != "scipy"} == {k: v for k, v in before.items() if k != "scipy"}


@pytest.fixture
def paper(tmp_path, monkeypatch):
    """The experiment's per-object stage on a small ball, counting how often it computes points."""
    import meshsal.points

    calls = []
    real = meshsal.points.interest_points

    def counting(*args, **kwargs):
        calls.append(kwargs.get("method"))
        return real(*args, **kwargs)

    monkeypatch.setattr(meshsal.points, "interest_points", counting)
    settings = samples.Settings(n_points=3)
    ball = samples.nominal_mesh(shapes.icosphere(40.0, 2), settings)

    def run(mesh=ball, settings=settings, method="uniform"):
        before = len(calls)
        task = samples.PaperSampleTask(mesh, "ball", method, settings, cache_dir=tmp_path / "cache")
        return samples.paper_sample(task).to_arrays(), len(calls) - before

    return run, ball, settings


def test_the_experiment_reads_its_own_entry_back(paper):
    run, _, _ = paper
    first, computed = run()
    again, recomputed = run()
    assert (computed, recomputed) == (1, 0)
    for name in first:
        np.testing.assert_array_equal(again[name], first[name])


def test_the_experiment_misses_when_a_setting_the_mesh_the_code_or_a_library_changes(paper, monkeypatch):
    import dataclasses

    run, ball, settings = paper
    assert run()[1] == 1 and run()[1] == 0
    assert run(settings=dataclasses.replace(settings, n_points=4))[1] == 1
    assert run(settings=dataclasses.replace(settings, seed=1))[1] == 1
    assert run(method="random")[1] == 1
    vertices = ball.vertices.copy()
    vertices[0] *= 1.001
    assert run(mesh=dataclasses.replace(ball, vertices=vertices))[1] == 1
    real_code = cache.code_fingerprint
    monkeypatch.setattr(cache, "code_fingerprint", lambda *packages: real_code(*packages) + "-edited")
    assert run()[1] == 1 and run()[1] == 0
    # An upgrade between runs: the next process reads the new version.
    real_versions = cache._installed_versions
    monkeypatch.setattr(cache, "_installed_versions", lambda: {**real_versions(), "numpy": "999.0"})
    assert run()[1] == 1 and run()[1] == 0
    monkeypatch.undo()
    assert run()[1] == 0  # the original entry is still there


# ---------------------------------------------------------------- damaged entries


def _npy_header(shape, descr="<f8") -> bytes:
    text = repr({"descr": descr, "fortran_order": False, "shape": tuple(shape)})
    text += " " * (63 - (len(text) + 10) % 64) + "\n"
    return b"\x93NUMPY\x01\x00" + len(text).to_bytes(2, "little") + text.encode("latin1")


def _truncated(path):
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _corrupt_deflate(path):
    rng = np.random.default_rng(1)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("x.npy", _npy_header((4000,)) + rng.random(4000).tobytes())
    data = bytearray(path.read_bytes())
    for i in range(400, 440):
        data[i] ^= 0xA5
    path.write_bytes(bytes(data))


def _huge_header(path):
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("x.npy", _npy_header((10**12,)))  # 8 TB of float64, declared in 128 bytes


def _foreign(path):
    path.write_text("a note someone saved under the cache's name\n")


def _pickled(path):
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("x.npy", _npy_header((1,), "|O") + b"\x80\x04N.")


@pytest.mark.parametrize("damage", [_truncated, _corrupt_deflate, _huge_header, _foreign, _pickled])
def test_a_damaged_entry_is_recomputed_and_overwritten(tmp_path, damage):
    compute = Counter()
    cache.cached(tmp_path, "k", compute)
    damage(tmp_path / "k.npz")
    assert cache.load(tmp_path, "k") is None
    again = cache.cached(tmp_path, "k", compute)
    assert compute.calls == 2
    np.testing.assert_array_equal(again["x"], np.ones(4))
    healed = cache.load(tmp_path, "k")  # the damaged file was replaced
    np.testing.assert_array_equal(healed["x"], np.ones(4))
    assert cache.cached(tmp_path, "k", compute) and compute.calls == 2


def test_a_damaged_entry_costs_no_memory(tmp_path):
    import tracemalloc

    _huge_header(tmp_path / "k.npz")
    tracemalloc.start()
    try:
        assert cache.load(tmp_path, "k") is None
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 1 << 20


_KILLED_WRITER = """
import os, signal, sys
import numpy as np
from classify.runtime import cache

real_savez = np.savez

def savez_then_die(file, **arrays):
    real_savez(file, **arrays)             # a whole archive, under the temporary name
    os.kill(os.getpid(), signal.SIGKILL)   # killed before the rename: no finally, no clean-up

np.savez = savez_then_die
cache.store(sys.argv[1], "k", {"x": np.full(4, -1.0)})
"""


def test_a_killed_writers_temporary_file_is_never_read(tmp_path):
    done = subprocess.run(
        [sys.executable, "-c", _KILLED_WRITER, str(tmp_path)], cwd=Path(__file__).parents[1], capture_output=True
    )
    assert done.returncode == -signal.SIGKILL, done.stderr.decode()
    leftovers = [p for p in tmp_path.iterdir()]
    assert len(leftovers) == 1 and leftovers[0].name.startswith(".k.") and leftovers[0].suffix == ".npz"
    np.testing.assert_array_equal(np.load(leftovers[0])["x"], np.full(4, -1.0))  # whole, and poisoned
    assert cache.load(tmp_path, "k") is None
    compute = Counter()
    np.testing.assert_array_equal(cache.cached(tmp_path, "k", compute)["x"], np.ones(4))
    np.testing.assert_array_equal(cache.cached(tmp_path, "k", compute)["x"], np.ones(4))
    assert compute.calls == 1


def test_an_entry_reads_back_exactly(tmp_path):
    arrays = {
        "f": np.asfortranarray(np.arange(12.0).reshape(3, 4)),
        "i": np.arange(5, dtype=np.int16),
        "text": np.array(json.dumps({"a": 1})),
        "empty": np.zeros((0, 16, 16), np.float32),
        "scalar": np.float64(2.5),
        "rec": np.zeros(2, dtype=[("a", "<f4"), ("b", "<i8")]),
    }
    cache.store(tmp_path, "k", arrays)
    back = cache.load(tmp_path, "k")
    reference = dict(np.load(io.BytesIO((tmp_path / "k.npz").read_bytes())))
    assert list(back) == list(arrays)
    for name, value in reference.items():
        assert back[name].dtype == value.dtype and back[name].shape == value.shape
        np.testing.assert_array_equal(back[name], value)
        assert back[name].flags.writeable
    assert back["f"].flags.f_contiguous
    assert os.listdir(tmp_path) == ["k.npz"]
