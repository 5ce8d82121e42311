"""hw.press: baseline estimation and press detection on synthetic frame streams."""

import numpy as np
import pytest

from hw.press import PressDetector
from hw.protocol import Frame


def _frames(rest, loads, shape, rng, noise=3.0, seq=0):
    """Frames of ``rest + load * shape`` plus noise, one per load."""
    out = []
    for i, load in enumerate(loads):
        v = rest + load * shape + rng.normal(0, noise, size=rest.shape)
        out.append(Frame(seq + i, 1000 * (seq + i), np.clip(np.rint(v), 0, 4095).astype(np.uint16)))
    return out


def _rest(rng, size=16):
    return 300 + rng.uniform(-50, 50, size=(size, size))


def _blob(cy, cx, size=16):
    yy, xx = np.mgrid[:size, :size]
    return np.exp(-((yy - cy) ** 2 + (xx - cx) ** 2) / 4.0)


def test_one_press_peak_is_the_imprint():
    rng = np.random.default_rng(0)
    shape = 2000 * _blob(5, 9)
    profile = np.sin(np.pi * np.arange(1, 10) / 10)  # peak 1 at index 4
    loads = [0] * 30 + list(profile) + [0] * 10
    rest = _rest(rng)
    det = PressDetector(baseline_frames=20)
    presses = [p for f in _frames(rest, loads, shape, rng) if (p := det.update(f)) is not None]
    assert len(presses) == 1
    press = presses[0]
    assert press.seq_peak == 34 and press.t_peak_us == 34000
    assert press.seq_start <= 31 and press.seq_end >= 37
    # The baseline median is within noise of the rest pattern, so the imprint is the shape.
    assert np.abs(det.baseline.values - rest).max() < 6
    assert np.abs(press.imprint - shape).max() < 20
    assert press.imprint.min() >= 0 and press.raw.dtype == np.uint16


def test_hysteresis_keeps_a_wobbling_press_whole():
    rng = np.random.default_rng(1)
    shape = 1000 * _blob(8, 8)
    rest = _rest(rng)
    det = PressDetector(baseline_frames=20)
    for frame in _frames(rest, [0] * 25, shape, rng):
        det.update(frame)
    on, off = det.baseline.on, det.baseline.off
    mid = (on + off) / 2 / shape.sum()
    high = 3 * on / shape.sum()
    # Dips between the thresholds must not split the press.
    loads = [high, mid, high, mid, high, 0, 0]
    presses = [p for frame in _frames(rest, loads, shape, rng, noise=0.0, seq=25) if (p := det.update(frame))]
    assert len(presses) == 1 and presses[0].frames == 5


def test_separate_presses_and_glitch_rejected():
    rng = np.random.default_rng(3)
    rest = _rest(rng)
    a, b = 1500 * _blob(4, 4), 1500 * _blob(11, 12)
    frames = _frames(rest, [0] * 20, a, rng)
    # press A (4 frames), a one-frame glitch, press B (4 frames)
    for shape, loads in ((a, [0.5, 1, 1, 0.5, 0, 0]), (b, [1, 0, 0]), (b, [0.5, 1, 1, 0.5, 0])):
        frames += _frames(rest, loads, shape, rng, seq=len(frames))
    det = PressDetector(baseline_frames=20, min_frames=2)
    presses = [p for f in frames if (p := det.update(f))]
    assert len(presses) == 2
    assert np.unravel_index(np.argmax(presses[0].imprint), (16, 16)) == (4, 4)
    assert np.unravel_index(np.argmax(presses[1].imprint), (16, 16)) == (11, 12)


def test_baseline_waits_for_a_quiet_window():
    rng = np.random.default_rng(4)
    shape = 2000 * _blob(8, 8)
    # The sensor is touched while the capture starts: the baseline must not absorb the touch.
    loads = [1.0] * 8 + [0] * 40
    det = PressDetector(baseline_frames=20)
    seen_waiting = False
    rest = _rest(rng)
    for frame in _frames(rest, loads, shape, rng):
        det.update(frame)
        seen_waiting |= det.waiting
    assert seen_waiting and det.baseline is not None
    assert np.abs(det.baseline.values - rest).max() < 6


def test_fixed_threshold_and_validation():
    det = PressDetector(baseline_frames=3, threshold=500)
    rest = np.full((2, 2), 100, np.uint16)
    for i in range(3):
        det.update(Frame(i, 0, rest))
    assert det.baseline.on == 500 and det.baseline.off == 250
    det.update(Frame(3, 0, rest + 200))  # summed 800 > 500
    assert det.pressing
    with pytest.raises(ValueError, match="baseline of 2 x 2"):
        det.update(Frame(4, 0, np.zeros((3, 3), np.uint16)))
    with pytest.raises(ValueError, match="off_sigma"):
        PressDetector(on_sigma=2, off_sigma=3)
