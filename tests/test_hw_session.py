"""hw.session: the SQLite session store, resume, size checks and resampling."""

import sqlite3

import numpy as np
import pytest

from hw.press import Baseline, Press
from hw.session import Session, resample


def _press(value: float, shape=(16, 16)) -> Press:
    imprint = np.zeros(shape, np.float32)
    imprint[2, 3] = value
    return Press(imprint=imprint, raw=(imprint + 100).astype(np.uint16), peak_sum=value, seq_start=1, seq_peak=2,
                 seq_end=3, t_start_us=10, t_peak_us=20, t_end_us=30, frames=3)


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
    from tactile import ImprintSet

    from classify.cli import main
    from hw.session import export_imprints

    path = tmp_path / "s.sqlite"
    with Session(path) as s:
        s.ensure_sensor(32, 32)
        run = s.start_run("p", 1, "binary", "cup", _baseline((32, 32)))
        for obj, pid, value in (("mug", 0, 400.0), ("cup", 3, 800.0), ("mug", 1, 200.0)):
            press = _press(value, (32, 32))
            press.imprint[20:22, 10:12] = value
            s.add_press(run, obj, pid, press, COUNTERS, position=[pid, 0, 0] if obj == "cup" else None,
                        approach=[0, -1, 0] if obj == "cup" else None)
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
