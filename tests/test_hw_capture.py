"""hw.capture through real pseudo-terminals, with hw.simdevice streaming synthetic presses.

The simulated sensor runs in a thread on a pty; the capture runs as the
function or as ``python -m hw.capture`` in a subprocess (so it can be killed).
Imprints here are Gaussian blobs, so these tests do not depend on tactile.
"""

import contextlib
import os
import signal
import sqlite3
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from hw.capture import NoFramesError, PortError, capture, main, open_port
from hw.protocol import FrameParser, encode_frame
from hw.session import Session
from hw.simdevice import SimulatedSensor, open_pty, serve

# 1 kHz and short presses keep the tests fast; the lead-in leaves room for the
# frames lost while a port opens (opening flushes its input).
FAST = dict(press_frames=7, idle_frames=8, lead_frames=60, rate=1000.0)


def blobs(k, size=16, seed=0):
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[:size, :size]
    out = np.empty((k, size, size))
    for i in range(k):
        cy, cx = rng.uniform(2, size - 3, 2)
        out[i] = np.exp(-((yy - cy) ** 2 + (xx - cx) ** 2) / (2 * rng.uniform(1.0, 3.0) ** 2))
    return out


def ncc(a, b):
    a = np.ravel(a) - np.mean(a)
    b = np.ravel(b) - np.mean(b)
    return float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)))


@contextlib.contextmanager
def sim_thread(imprints, seed=0, disconnect_after=None, **kw):
    """A simulated sensor streaming on a fresh pty in a thread; yields (path, sensor)."""
    options = {**FAST, **kw}
    sim = SimulatedSensor(imprints, np.random.default_rng(seed), **options)
    master, path = open_pty()
    stop = threading.Event()
    thread = threading.Thread(
        target=serve,
        args=(master, sim, options["rate"]),
        kwargs={"stop": stop, "disconnect_after": disconnect_after},
        daemon=True,
    )
    thread.start()
    # Should a capture wait for a press that never comes, pulling the cable makes it fail instead of hang.
    watchdog = threading.Timer(60.0, stop.set)
    watchdog.start()
    try:
        yield path, sim
    finally:
        watchdog.cancel()
        stop.set()
        thread.join(5)


def stored(session_path):
    """(point_id, imprint) rows committed so far, read without the capture's help."""
    if not session_path.exists():
        return []
    con = sqlite3.connect(f"file:{session_path}?mode=ro", uri=True)
    try:
        return [
            (pid, np.frombuffer(blob, np.float32))
            for pid, blob in con.execute("SELECT point_id, imprint FROM presses ORDER BY id")
        ]
    except sqlite3.OperationalError:
        return []
    finally:
        con.close()


def test_fifteen_presses_with_faults_match_what_was_sent(tmp_path):
    imprints = blobs(15)
    with sim_thread(imprints, garbage=0.05, bitflips=0.05, drop=0.05) as (path, _):
        with Session(tmp_path / "s.sqlite") as session:
            result = capture(path, session, "blobs", presses=15, first_point=100, quiet=True)
            records = session.presses()
    assert result.point_ids == tuple(range(100, 115)) and result.stopped == "presses"
    assert result.crc_errors > 0 and result.gaps > 0 and result.bytes_skipped > 0
    assert len(records) == 15
    for rec, sent in zip(records, imprints):
        assert ncc(rec.imprint, sent) >= 0.99
        assert rec.object == "blobs"


def test_text_protocol_end_to_end(tmp_path):
    imprints = blobs(4, seed=5)
    with sim_thread(imprints, protocol="text") as (path, _):
        with Session(tmp_path / "s.sqlite") as session:
            capture(path, session, "t", protocol="text", presses=4, quiet=True)
            records = session.presses()
    assert [ncc(r.imprint, s) >= 0.99 for r, s in zip(records, imprints)] == [True] * 4


def test_bit_flips_through_a_pty_no_corrupt_frame_accepted():
    rng = np.random.default_rng(7)
    sent = {seq: rng.integers(0, 4096, size=(16, 16)).astype(np.uint16) for seq in range(300)}
    chunks, intact = [], set()
    for seq, values in sent.items():
        good = encode_frame(seq, seq, values)
        frame = bytearray(good)
        if rng.random() < 0.3:
            for bit in rng.choice(8 * len(frame), size=int(rng.integers(1, 3)), replace=False):
                frame[bit // 8] ^= 1 << (bit % 8)
        if frame == good:
            intact.add(seq)
        if rng.random() < 0.1:
            chunks.append(rng.integers(0, 256, size=int(rng.integers(1, 40)), dtype=np.uint8).tobytes())
        chunks.append(bytes(frame))
    master, path = open_pty()
    port = open_port(path)
    parser = FrameParser()
    got = []
    try:
        writer = threading.Thread(target=_write_all, args=(master, b"".join(chunks)), daemon=True)
        writer.start()
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            data = port.read(4096)
            if not data and not writer.is_alive():
                break
            got += parser.feed(data)
    finally:
        port.close()
        os.close(master)
    # CRC-16 catches every 1- and 2-bit error: exactly the intact frames come through, unchanged.
    assert {f.seq for f in got} == intact and len(intact) < 300
    for frame in got:
        assert np.array_equal(frame.values, sent[frame.seq]) and frame.t_us == frame.seq
    assert parser.crc_errors >= 300 - len(intact)
    assert parser.gaps == 300 - len(intact) - (299 - max(intact)) - min(intact)


def _write_all(fd, data):
    while data:
        try:
            data = data[os.write(fd, data[:4096]) :]
        except BlockingIOError:
            time.sleep(0.001)


def test_session_size_mismatch_is_a_clear_error(tmp_path):
    path = tmp_path / "s.sqlite"
    with Session(path) as session:
        session.ensure_sensor(16, 16)
    with sim_thread(blobs(2, size=8)) as (port, _):
        with Session(path) as session, pytest.raises(ValueError, match=r"16 x 16 sensor.*8 x 8 frames"):
            capture(port, session, "small", presses=1, quiet=True)


def test_missing_and_busy_ports(tmp_path, capsys):
    session = str(tmp_path / "s.sqlite")
    assert main(["--port", str(tmp_path / "ttyNOPE"), "--session", session, "--object", "x"]) == 1
    assert "no such serial port" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []  # no empty session left behind for export to trip on
    master, path = open_pty()
    holder = open_port(path)
    try:
        with pytest.raises(PortError, match="busy"):
            open_port(path)
    finally:
        holder.close()
        os.close(master)


def test_a_capture_that_stores_no_press_leaves_only_the_sessions_that_were_there(tmp_path, capsys):
    kept = tmp_path / "kept.sqlite"
    with Session(kept) as session:
        session.ensure_sensor(16, 16)  # an existing session, even an empty one, is the user's: it stays
    for path in (tmp_path / "new.sqlite", kept):
        argv = ["--port", str(tmp_path / "ttyNOPE"), "--session", str(path), "--object", "x"]
        assert main(argv) == 1 and main([*argv, "--presses", "0"]) == 1
    assert "presses must be at least 1, got 0" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.sqlite"]
    with sim_thread(blobs(1)) as (port, _):
        assert main(["--port", port, "--session", str(tmp_path / "one.sqlite"), "--object", "x", "--presses", "1"]) == 0
    with Session(tmp_path / "one.sqlite", create=False) as session:
        assert len(session.presses("x")) == 1


def test_only_garbage_times_out_suggesting_the_baud_rate(tmp_path):
    master, path = open_pty()
    stop = threading.Event()

    def noise():
        rng = np.random.default_rng(0)
        while not stop.is_set():
            with contextlib.suppress(OSError):
                os.write(master, rng.integers(0, 256, size=64, dtype=np.uint8).tobytes())
            time.sleep(0.005)

    thread = threading.Thread(target=noise, daemon=True)
    thread.start()
    try:
        with Session(tmp_path / "s.sqlite") as session, pytest.raises(NoFramesError, match="baud"):
            capture(path, session, "x", garbage_timeout=0.4, quiet=True)
    finally:
        stop.set()
        thread.join(5)
        os.close(master)


def test_disconnect_keeps_the_presses_made_before(tmp_path):
    imprints = blobs(10, seed=3)
    # lead-in + 3 presses of (7 + 8) frames, then the cable is pulled mid-way through the 4th press.
    with sim_thread(imprints, disconnect_after=FAST["lead_frames"] + 3 * 15 + 3) as (path, _):
        with Session(tmp_path / "s.sqlite") as session:
            with pytest.raises(PortError, match="run again to resume"):
                capture(path, session, "x", quiet=True)
            assert session.point_ids("x") == [0, 1, 2]


def _capture_cmd(port, session, *extra):
    return [sys.executable, "-m", "hw.capture", "--port", port, "--session", str(session), "--object", "blobs", *extra]


def _wait_for(predicate, timeout=30.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.02)
    return False


def test_ctrl_c_stops_between_presses_keeps_them_and_gives_the_handler_back(tmp_path):
    if threading.current_thread() is not threading.main_thread():
        pytest.skip("signals reach the main thread only")
    before = signal.getsignal(signal.SIGINT)
    path = tmp_path / "s.sqlite"

    done = threading.Event()

    def interrupt_after_two_presses():
        # Never after the capture ended on its own: the signal would stop the test run instead.
        if _wait_for(lambda: len(stored(path)) >= 2 or done.is_set()) and not done.is_set():
            os.kill(os.getpid(), signal.SIGINT)

    with sim_thread(blobs(40, seed=3), idle_frames=30) as (port, _):
        with Session(path) as session:
            interrupter = threading.Thread(target=interrupt_after_two_presses)
            interrupter.start()
            try:
                result = capture(port, session, "blobs", quiet=True)
            finally:
                done.set()
                interrupter.join()
            kept = session.presses()
    assert result.stopped == "interrupted" and len(result.point_ids) >= 2
    assert [p.point_id for p in kept] == list(result.point_ids)
    assert signal.getsignal(signal.SIGINT) is before


def test_killed_capture_keeps_every_completed_press_and_resumes(tmp_path):
    session = tmp_path / "s.sqlite"
    imprints = blobs(40, seed=11)
    with sim_thread(imprints, idle_frames=30) as (port, sim):
        proc = subprocess.Popen(_capture_cmd(port, session), stderr=subprocess.PIPE, text=True)
        try:
            assert _wait_for(lambda: len(stored(session)) >= 3), "no presses stored"
            proc.send_signal(signal.SIGKILL)
            err = proc.communicate(timeout=30)[1]
        finally:
            proc.kill()
        before = stored(session)
        # Each "stored" line is printed after its commit: all of them survived the kill.
        assert 3 <= err.count(" stored (peak") <= len(before)
        # Every press committed before the kill is whole: it is one of the imprints sent.
        assert [p for p, _ in before] == list(range(len(before)))
        for _, imprint in before:
            assert max(ncc(imprint, sent) for sent in imprints) >= 0.99
        # Resume: point ids continue; Ctrl-C ends the run cleanly with its presses kept.
        proc = subprocess.Popen(_capture_cmd(port, session), stderr=subprocess.PIPE, text=True)
        try:
            assert _wait_for(lambda: len(stored(session)) >= len(before) + 2), "no presses after resuming"
            proc.send_signal(signal.SIGINT)
            err = proc.communicate(timeout=30)[1]
        finally:
            proc.kill()
        assert proc.returncode == 0, err
        assert "resuming" in err and "interrupted" in err
    after = stored(session)
    assert [p for p, _ in after] == list(range(len(after)))
    for _, imprint in after[len(before) :]:
        assert max(ncc(imprint, sent) for sent in imprints) >= 0.99


def test_plan_ids_in_order_and_resume_skips_recorded_points(tmp_path):
    from hw.plan import Plan, ProbePoint
    from meshsal.mesh import Similarity

    points = tuple(
        ProbePoint(pid, np.array([pid, 0.0, 0.0]), np.array([0.0, 0.0, -1.0]), np.array([1.0, 0.0, 0.0, 0.0]))
        for pid in (7, 3, 9)
    )
    plan = Plan(
        points=points,
        sensor={},
        mesh="m",
        size_mm=150.0,
        method="random",
        frame=Similarity(2.0, np.array([1.0, 0.0, 0.0])),
    )
    imprints = blobs(3, seed=9)
    # Captures follow each other faster than the device notices, so it does not restart its
    # lead-in: rest between presses must be long enough for a new baseline.
    with sim_thread(imprints, idle_frames=30, presses=12) as (port, _), Session(tmp_path / "s.sqlite") as session:
        first = capture(port, session, "obj", plan=plan, presses=1, quiet=True)
        second = capture(port, session, "obj", plan=plan, quiet=True)
        third = capture(port, session, "obj", plan=plan, quiet=True)
        records = session.presses()
    assert first.point_ids == (7,) and first.stopped == "presses"
    assert second.point_ids == (3, 9) and second.stopped == "plan"
    assert third.point_ids == () and third.stopped == "plan"
    assert [r.point_id for r in records] == [7, 3, 9]
    # Positions are stored in the planning frame (mm): 2 * x + 1.
    assert [r.position[0] for r in records] == [15.0, 7.0, 19.0]
    assert all(np.array_equal(r.approach, [0, 0, -1]) for r in records)


def test_visuotactile_capture_reports_errors(tmp_path, capsys):
    from classify.cli import main as cli_main

    assert (
        cli_main(
            ["capture", "--port", str(tmp_path / "ttyNONE"), "--session", str(tmp_path / "s.sqlite"), "--object", "x"]
        )
        == 1
    )
    assert "visuotactile capture: error:" in capsys.readouterr().err
