"""hw.simdevice: the simulated sensor's frames, and the whole chain with tactile imprints:
``visuotactile plan`` -> ``python -m hw.simdevice`` on a pty -> ``python -m hw.capture`` -> ``visuotactile export``."""

import subprocess
import sys

import numpy as np
import pytest

from hw.protocol import FrameParser
from hw.simdevice import SimulatedSensor


def _frames(sim, n):
    return FrameParser().feed(b"".join(sim.next_bytes() for _ in range(n)))


def test_peak_frame_is_rest_plus_full_scale_imprint():
    imprints = np.random.default_rng(0).random((2, 4, 5))
    sim = SimulatedSensor(
        imprints, np.random.default_rng(1), noise=0.0, lead_frames=3, press_frames=5, idle_frames=2, full_scale=1000.0
    )
    frames = _frames(sim, 3 + 2 * (5 + 2))
    rest = frames[0].values.astype(float)
    assert all(np.array_equal(f.values, frames[0].values) for f in frames[:3])
    for k, first in enumerate((3, 10)):
        peak = frames[first + 2].values.astype(float)  # the middle of 5 frames has load 1
        assert np.abs(peak - rest - 1000.0 * imprints[k]).max() <= 1.0
        assert np.array_equal(frames[first + 5].values, frames[0].values)  # rest again
    assert sim.done and sim.pressed == 2
    assert [f.seq for f in frames] == list(range(len(frames)))


def test_restart_redoes_an_interrupted_press_after_a_lead_in():
    sim = SimulatedSensor(np.ones((1, 2, 2)), np.random.default_rng(0), noise=0.0, lead_frames=2, press_frames=5)
    loads = [f.values.mean() for f in _frames(sim, 4)]  # 2 rest, 2 frames of the press
    sim.restart()
    loads += [f.values.mean() for f in _frames(sim, 8)]
    rest = loads[0]
    pressed = [load > rest + 100 for load in loads]
    assert pressed == [False, False, True, True, False, False, True, True, True, True, True, False]
    assert sim.pressed == 1


def test_faults_drop_flip_and_garbage():
    imprints = np.ones((3, 4, 4))
    sim = SimulatedSensor(
        imprints,
        np.random.default_rng(2),
        drop=0.2,
        bitflips=0.2,
        garbage=0.2,
        lead_frames=5,
        press_frames=5,
        idle_frames=5,
    )
    parser = FrameParser()
    frames = parser.feed(b"".join(sim.next_bytes() for _ in range(400)))
    assert 200 < len(frames) < 330
    assert parser.gaps == 400 - len(frames) - (399 - frames[-1].seq) - frames[0].seq
    assert parser.crc_errors > 40 and parser.bytes_skipped > 0
    with pytest.raises(ValueError, match="drop must be a probability"):
        SimulatedSensor(imprints, np.random.default_rng(0), drop=1.5)


def test_bad_object_is_a_clear_error():
    proc = subprocess.run(
        [sys.executable, "-m", "hw.simdevice", "--object", "/nonexistent/thing.obj"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 1 and "simdevice: error:" in proc.stderr and "thing.obj" in proc.stderr


def ncc(a, b):
    a = np.ravel(a) - np.mean(a)
    b = np.ravel(b) - np.mean(b)
    return float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)))


def test_plan_simdevice_capture_export_chain(tmp_path):
    """15 tactile imprints of a toy pressed through a pty come back as an ImprintSet matching what was sent."""
    from classify.cli import main
    from hw.plan import load_plan
    from tactile import ImprintSet

    plan_path, truth, session, out = (tmp_path / n for n in ("plan.json", "truth.npz", "s.sqlite", "real.npz"))
    assert main(["plan", "cup", "--method", "random", "--n-points", "15", "--out", str(plan_path)]) == 0
    sim = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "hw.simdevice",
            "--object",
            "cup",
            "--points",
            str(plan_path),
            "--rate",
            "1000",
            "--press-frames",
            "7",
            "--idle-frames",
            "8",
            "--lead-frames",
            "60",
            "--dump",
            str(truth),
            "--garbage",
            "0.02",
            "--bitflips",
            "0.02",
            "--drop",
            "0.02",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        port = sim.stdout.readline().strip()
        assert port.startswith("/dev/"), sim.stderr.read()
        cap = subprocess.run(
            [
                sys.executable,
                "-m",
                "hw.capture",
                "--port",
                port,
                "--session",
                str(session),
                "--object",
                "cup",
                "--points",
                str(plan_path),
            ],
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert cap.returncode == 0, cap.stderr
        assert "15 presses stored" in cap.stderr
    finally:
        sim.terminate()
        sim.communicate(timeout=10)  # reaps it and closes its pipes
    assert main(["export", str(session), "--out", str(out)]) == 0
    real = ImprintSet.load(out)
    with np.load(truth) as data:
        sent = {name: data[name] for name in data.files}
    plan = load_plan(plan_path)
    assert real.object_names == ("cup",) and real.imprints.shape == (15, 16, 16)
    assert real.point_ids.tolist() == [p.id for p in plan.points] == sent["point_ids"].tolist()
    assert 0.0 <= real.imprints.min() and real.imprints.max() == pytest.approx(1.0)
    assert min(ncc(a, b) for a, b in zip(real.imprints, sent["imprints"])) >= 0.99
    assert np.allclose(real.positions, plan.positions_mm()) and np.allclose(real.positions, sent["positions"])
    assert np.allclose(real.normals, sent["normals"])
    assert real.source == str(session)
