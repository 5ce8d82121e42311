"""hw.session: the SQLite session store, resume, size checks and resampling; one press per (object, point),
also with several processes writing at once; the version 1 migration; WAL checked."""

import multiprocessing
import shutil
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from hw import session_file
from hw.press import Baseline, Press
from hw.session import Session, resample


def _press(value: float, shape=(16, 16)) -> Press:
    imprint = np.zeros(shape, np.float32)
    imprint[2, 3] = value
    return Press(
        imprint=imprint,
        raw=(imprint + 100).astype(np.uint16),
        peak_sum=value,
        seq_start=1,
        seq_peak=2,
        seq_end=3,
        t_start_us=10,
        t_peak_us=20,
        t_end_us=30,
        frames=3,
    )


def _baseline(shape=(16, 16)) -> Baseline:
    return Baseline(values=np.full(shape, 100, np.float32), noise=1.0, on=50.0, off=25.0, frames=20)


COUNTERS = {"frames": 5, "crc_errors": 1, "gaps": 2, "bytes_skipped": 7}


def test_presses_round_trip_and_survive_reopening(tmp_path):
    path = tmp_path / "s.sqlite"
    with Session(path) as s:
        assert s.sensor is None
        s.ensure_sensor(16, 16)
        run = s.start_run("/dev/x", 9600, "binary", "cup", _baseline())
        s.add_press(run, "cup", 4, _press(500.0), COUNTERS, position=[1, 2, 3], approach=[0, 0, -1])
        s.add_press(run, "mug", 0, _press(700.0), COUNTERS)
    with Session(path, create=False) as s:
        assert s.sensor == (16, 16)
        assert s.point_ids("cup") == [4] and s.point_ids("mug") == [0] and s.point_ids("bowl") == []
        cup, mug = s.presses()
        assert cup.object == "cup" and cup.imprint[2, 3] == 500.0 and cup.raw.dtype == np.uint16
        assert cup.raw[2, 3] == 600 and cup.t_peak_us == 20 and cup.crc_errors == 1 and cup.gaps == 2
        assert np.array_equal(cup.position, [1, 2, 3]) and np.array_equal(cup.approach, [0, 0, -1])
        assert mug.position is None and mug.approach is None
    con = sqlite3.connect(path)
    assert con.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    con.close()


def test_sensor_size_mismatch_is_a_clear_error(tmp_path):
    path = tmp_path / "s.sqlite"
    with Session(path) as s:
        s.ensure_sensor(16, 16)
    with Session(path) as s:
        s.ensure_sensor(16, 16)
        with pytest.raises(ValueError, match=r"s\.sqlite.*16 x 16 sensor.*8 x 8"):
            s.ensure_sensor(8, 8)


def test_foreign_or_missing_files_are_rejected(tmp_path):
    junk = tmp_path / "junk.sqlite"
    junk.write_bytes(b"this is not sqlite at all" * 10)
    with pytest.raises(ValueError, match="junk.sqlite: not a capture session"):
        Session(junk)
    other = tmp_path / "other.sqlite"
    con = sqlite3.connect(other)
    con.execute("CREATE TABLE t (x)")
    con.commit()
    con.close()
    with pytest.raises(ValueError, match="other.sqlite: not a capture session"):
        Session(other)
    with pytest.raises(FileNotFoundError, match="missing.sqlite"):
        Session(tmp_path / "missing.sqlite", create=False)


def test_failed_press_rolls_back(tmp_path):
    with Session(tmp_path / "s.sqlite") as s:
        s.ensure_sensor(16, 16)
        run = s.start_run("p", 1, "binary", "cup", _baseline())
        with pytest.raises(KeyError):
            s.add_press(run, "cup", 0, _press(1.0), {"frames": 1})
        with pytest.raises(ValueError, match="8 x 8 press"):
            s.add_press(run, "cup", 0, _press(1.0, (8, 8)), COUNTERS)
        assert s.presses() == []


def test_resample_area_average():
    img = np.zeros((32, 32), np.float32)
    img[:2, :2] = 4.0
    small = resample(img, 16, 16)
    assert small.shape == (16, 16) and small[0, 0] == pytest.approx(4.0) and small.sum() == pytest.approx(4.0)
    assert resample(small, 16, 16) is small
    assert resample(np.ones((8, 8)), 16, 16).shape == (16, 16)


def test_export_resamples_normalizes_and_labels(tmp_path):
    from classify.cli import main
    from hw.session import export_imprints
    from tactile import ImprintSet

    path = tmp_path / "s.sqlite"
    with Session(path) as s:
        s.ensure_sensor(32, 32)
        run = s.start_run("p", 1, "binary", "cup", _baseline((32, 32)))
        for obj, pid, value in (("mug", 0, 400.0), ("cup", 3, 800.0), ("mug", 1, 200.0)):
            press = _press(value, (32, 32))
            press.imprint[20:22, 10:12] = value
            s.add_press(
                run,
                obj,
                pid,
                press,
                COUNTERS,
                position=[pid, 0, 0] if obj == "cup" else None,
                approach=[0, -1, 0] if obj == "cup" else None,
            )
    exported = export_imprints(path)
    assert exported.object_names == ("cup", "mug") and exported.labels.tolist() == [1, 0, 1]
    assert exported.point_ids.tolist() == [0, 3, 1] and exported.imprints.shape == (3, 16, 16)
    # 2x2 blocks of the 32x32 array average into one taxel; the largest reading of the session is 1.
    assert exported.imprints[1, 10, 5] == pytest.approx(1.0) and exported.imprints[0, 10, 5] == pytest.approx(0.5)
    assert exported.imprints[0, 1, 1] == pytest.approx(0.125)
    assert np.allclose(exported.positions[1], [3, 0, 0]) and np.allclose(exported.normals[1], [0, 1, 0])
    assert np.isnan(exported.positions[0]).all()
    per_imprint = export_imprints(path, full_scale="imprint")
    assert np.allclose(per_imprint.imprints.reshape(3, -1).max(axis=1), 1.0)
    adc = export_imprints(path, full_scale=4095)
    assert adc.imprints.max() == pytest.approx(800 / 4095)
    with pytest.raises(ValueError, match="full_scale"):
        export_imprints(path, full_scale="loud")
    out = tmp_path / "real.npz"
    assert main(["export", str(path), "--out", str(out), "--full-scale", "4095"]) == 0
    assert ImprintSet.load(out).source == str(path)
    empty = tmp_path / "empty.sqlite"
    Session(empty).close()
    assert main(["export", str(empty), "--out", str(out)]) == 1
    assert main(["export", str(tmp_path / "missing.sqlite"), "--out", str(out)]) == 1


DATA = Path(__file__).parent / "data"


def _copy(name: str, tmp_path: Path) -> Path:
    """A session file made by the version 1 code (hw/session.py at 224f8ab), copied: opening migrates it."""
    target = tmp_path / name
    shutil.copyfile(DATA / name, target)
    return target


def _indexes(path: Path) -> dict:
    con = sqlite3.connect(path)
    try:
        return {
            name: sql
            for name, sql in con.execute("SELECT name, sql FROM sqlite_master WHERE type = 'index' AND sql IS NOT NULL")
        }
    finally:
        con.close()


def test_a_version_1_session_is_migrated_to_one_press_per_point(tmp_path):
    path = _copy("session_v1.sqlite", tmp_path)
    assert list(_indexes(path)) == ["presses_object"]
    with Session(path) as s:
        assert s._meta()["version"] == "2"
        assert [(p.object, p.point_id, p.imprint[2, 3]) for p in s.presses()] == [
            ("cup", 0, 500.0),
            ("cup", 1, 600.0),
            ("mug", 5, 700.0),
        ]
        with pytest.raises(ValueError, match=r"session_v1.sqlite: point 1 of 'cup' is already recorded"):
            s.add_press(1, "cup", 1, _press(1.0), COUNTERS)
        assert s.add_next_press(1, "cup", _press(2.0), COUNTERS) == (4, 2)
    assert _indexes(path) == {"presses_point": "CREATE UNIQUE INDEX presses_point ON presses(object, point_id)"}
    with Session(path) as s:  # already version 2
        assert s.point_ids("cup") == [0, 1, 2]


def test_a_version_1_session_whose_presses_share_a_point_is_refused_naming_them(tmp_path):
    path = _copy("session_v1_duplicates.sqlite", tmp_path)
    before = path.read_bytes()
    with pytest.raises(
        ValueError,
        match=r"session_v1_duplicates.sqlite: presses share a point id: 'cup' point 3 "
        r"\(presses 1, 3\)\.",
    ):
        Session(path)
    con = sqlite3.connect(path)
    assert con.execute("SELECT value FROM meta WHERE key = 'version'").fetchone() == ("1",)  # rolled back
    con.execute("UPDATE presses SET point_id = 4 WHERE id = 3")
    con.commit()
    con.close()
    assert path.read_bytes() != before
    with Session(path) as s:
        assert s.point_ids("cup") == [3, 4]


def test_next_point_ids_count_up_or_follow_the_plan(tmp_path):
    with Session(tmp_path / "s.sqlite") as s:
        s.ensure_sensor(16, 16)
        run = s.start_run("p", 1, "binary", "cup", _baseline())
        assert [s.add_next_press(run, "cup", _press(1.0), COUNTERS, first_point=10)[1] for _ in range(2)] == [10, 11]
        assert s.add_next_press(run, "cup", _press(1.0), COUNTERS, first_point=20)[1] == 20
        assert s.add_next_press(run, "mug", _press(1.0), COUNTERS)[1] == 0
        plan = [(7, [1, 2, 3], [0, 0, -1]), (11, [4, 5, 6], [0, -1, 0]), (3, [7, 8, 9], [-1, 0, 0])]
        assert s.next_point("cup", planned=plan) == 7
        assert s.add_next_press(run, "cup", _press(1.0), COUNTERS, planned=plan)[1] == 7
        assert s.add_next_press(run, "cup", _press(1.0), COUNTERS, planned=plan)[1] == 3  # 11 is recorded
        assert s.next_point("cup", planned=plan) is None
        assert s.add_next_press(run, "cup", _press(1.0), COUNTERS, planned=plan) is None
        three = s.presses("cup")[-1]
        assert three.point_id == 3 and three.position.tolist() == [7, 8, 9] and three.approach.tolist() == [-1, 0, 0]
        assert len(s.presses()) == 6


def _hammer(path, start, results, presses, planned):
    """One capturing process: open (maybe create) the session when all start, then store presses; puts the
    (row id, point id) pairs stored, or the error that stopped it."""
    start.wait()
    stored = []
    try:
        with Session(path) as s:
            s.ensure_sensor(16, 16)
            run = s.start_run("p", 1, "binary", "cup", _baseline())
            for k in range(presses):
                added = s.add_next_press(run, "cup", _press(float(k + 1)), COUNTERS, planned=planned)
                if added is None:
                    break
                stored.append(added)
    except Exception as exc:  # noqa: BLE001 - reported to the test, whatever it is
        results.put(f"{type(exc).__name__}: {exc}")
        return
    results.put(stored)


@pytest.mark.parametrize("planned", [False, True], ids=["counting", "plan"])
def test_processes_creating_and_filling_one_session_at_once_never_share_a_point_id(tmp_path, planned):
    ctx = multiprocessing.get_context("spawn")
    path = tmp_path / "new" / "s.sqlite"
    n, presses = 4, 30
    plan = [(int(i), [float(i), 0.0, 1.0], [0.0, 0.0, -1.0]) for i in np.random.default_rng(0).permutation(80)]
    start, results = ctx.Barrier(n), ctx.Queue()
    workers = [
        ctx.Process(target=_hammer, args=(path, start, results, presses, plan if planned else None)) for _ in range(n)
    ]
    for w in workers:
        w.start()
    stored = [results.get(timeout=120) for _ in workers]
    for w in workers:
        w.join(timeout=60)
    assert not [each for each in stored if isinstance(each, str)]
    rows = sorted(row for each in stored for row, _ in each)
    ids = [pid for each in stored for _, pid in each]
    assert len(set(rows)) == len(rows) and len(set(ids)) == len(ids)
    with Session(path) as s:
        records = s.presses("cup")
        assert len(s._con.execute("SELECT * FROM meta WHERE key = 'format'").fetchall()) == 1  # one schema
        assert len(s._con.execute("SELECT * FROM runs").fetchall()) == n
    assert sorted(r.id for r in records) == rows
    if planned:
        assert sorted(ids) == list(range(80))  # every planned point once, then no more
        assert all(r.position.tolist() == [r.point_id, 0.0, 1.0] for r in records)
    else:
        assert sorted(ids) == list(range(n * presses))


class _LockedOnce:
    """A connection whose first switch to the write-ahead log finds the file locked, as SQLite answers,
    without waiting, while another process opens the new file beside it."""

    def __init__(self, con):
        self._con, self.refused = con, 0

    def execute(self, sql, *args):
        if "journal_mode" in sql and not self.refused:
            self.refused += 1
            raise sqlite3.OperationalError("database is locked")
        return self._con.execute(sql, *args)

    def __getattr__(self, name):
        return getattr(self._con, name)


def test_a_new_file_locked_while_it_turns_to_the_log_is_asked_again(tmp_path, monkeypatch):
    connect, made = sqlite3.connect, []
    monkeypatch.setattr(sqlite3, "connect", lambda *a, **kw: made.append(_LockedOnce(connect(*a, **kw))) or made[-1])
    with Session(tmp_path / "s.sqlite") as s:
        s.ensure_sensor(16, 16)
    assert [c.refused for c in made] == [1]
    monkeypatch.setattr(sqlite3, "connect", connect)
    with Session(tmp_path / "s.sqlite", create=False) as s:
        assert s.sensor == (16, 16)


def test_a_filesystem_without_a_write_ahead_log_is_refused(tmp_path, monkeypatch):
    connect = sqlite3.connect
    # SQLite's VFS for filesystems without POSIX locks has no shared memory, so WAL mode is refused there.
    monkeypatch.setattr(sqlite3, "connect", lambda path, **kw: connect(f"file:{path}?vfs=unix-dotfile", uri=True, **kw))
    with pytest.raises(
        OSError,
        match=r"s.sqlite: SQLite cannot keep a write-ahead log here \(journal mode "
        r"stays 'delete'\).*keep the session on a local disk",
    ):
        Session(tmp_path / "s.sqlite")


def test_a_file_created_by_another_opener_between_look_and_lock_is_taken_as_it_is(tmp_path, monkeypatch):
    path = tmp_path / "s.sqlite"
    transaction, first = session_file.transaction, []

    def another_opener_first(con):
        if not first:  # once: this opener has seen no tables
            first.append(con)
            with Session(path) as other:
                other.ensure_sensor(16, 16)
        return transaction(con)

    monkeypatch.setattr(session_file, "transaction", another_opener_first)
    with Session(path) as s:
        assert first == [s._con] and s.sensor == (16, 16)
        assert len(s._con.execute("SELECT * FROM meta WHERE key = 'format'").fetchall()) == 1


def test_a_press_committed_by_another_capture_between_look_and_lock_takes_the_next_id(tmp_path, monkeypatch):
    path = tmp_path / "s.sqlite"
    with Session(path) as a, Session(path) as b:
        a.ensure_sensor(16, 16)
        run = a.start_run("p", 1, "binary", "cup", _baseline())
        transaction, interleaved = Session._transaction, []

        def the_other_capture_first(self):
            if self is a and not interleaved:
                interleaved.append(b.add_next_press(run, "cup", _press(1.0), COUNTERS))
            return transaction(self)

        monkeypatch.setattr(Session, "_transaction", the_other_capture_first)
        assert a.add_next_press(run, "cup", _press(2.0), COUNTERS) == (2, 1)
        assert interleaved == [(1, 0)]
