"""Atomic writes: all or nothing under the final name, flushed to disk before and after the rename."""

import os
import re

import pytest

from meshsal.util import atomic


def test_the_file_is_flushed_before_the_rename_and_the_directory_after(tmp_path, monkeypatch):
    events = []
    real_fsync, real_replace = os.fsync, os.replace

    def fsync(fd):
        events.append(("fsync", os.path.realpath(f"/proc/self/fd/{fd}")))
        real_fsync(fd)

    def replace(a, b):
        events.append(("replace", str(b)))
        real_replace(a, b)

    monkeypatch.setattr(atomic.os, "fsync", fsync)
    monkeypatch.setattr(atomic.os, "replace", replace)
    target = tmp_path / "out.txt"
    atomic.write_text(target, "done")
    assert target.read_text() == "done"
    kinds = [kind for kind, _ in events]
    assert kinds == ["fsync", "replace", "fsync"]
    assert events[0][1].startswith(str(tmp_path / ".out.")) and events[2][1] == str(tmp_path)


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "keep.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic.atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("disk full")
    assert target.read_text() == "old" and sorted(p.name for p in tmp_path.iterdir()) == ["keep.txt"]


def test_an_output_with_a_file_or_a_folder_in_its_way_is_refused_and_nothing_is_made(tmp_path):
    (tmp_path / "notes.txt").write_text("")
    (tmp_path / "results").mkdir()
    assert atomic.check_writable(tmp_path / "results", folder=True) == tmp_path / "results"
    assert atomic.check_writable(tmp_path / "a" / "b", folder=True) == tmp_path / "a" / "b"
    assert atomic.check_writable(tmp_path / "notes.txt", folder=False) == tmp_path / "notes.txt"  # replaced
    refused = {
        (tmp_path / "notes.txt", True): "exists and is a file, not a folder",
        (tmp_path / "results", False): "exists and is a folder, not a file",
        (tmp_path / "notes.txt" / "deep" / "results", True): f"cannot be written: {tmp_path / 'notes.txt'} is a file",
        (tmp_path / "notes.txt" / "set.npz", False): f"cannot be written: {tmp_path / 'notes.txt'} is a file",
    }
    for (path, folder), problem in refused.items():
        with pytest.raises(ValueError, match=f"^{re.escape(str(path))}: {re.escape(problem)}"):
            atomic.check_writable(path, folder=folder)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt", "results"]  # nothing made


def test_an_output_in_a_folder_that_cannot_be_written_is_refused(tmp_path, monkeypatch):
    locked = tmp_path / "locked"
    locked.mkdir()
    # As a user without write permission sees it (root, who runs CI, may write anywhere).
    monkeypatch.setattr(atomic.os, "access", lambda path, mode: os.fspath(path) != os.fspath(locked))
    with pytest.raises(ValueError, match=f"the folder {re.escape(str(locked))} is not writable"):
        atomic.check_writable(locked / "deep" / "results", folder=True)
    with pytest.raises(ValueError, match=f"the folder {re.escape(str(locked))} is not writable"):
        atomic.check_writable(locked / "set.npz", folder=False)
    assert atomic.check_writable(tmp_path / "results", folder=True) == tmp_path / "results"
