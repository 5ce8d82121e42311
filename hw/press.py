"""Baseline estimation and press detection on a stream of tactile frames.

A pure streaming object, independent of any port: feed it frames, it answers
with each completed press.  Force-resistive arrays read a per-taxel offset at
rest, so the baseline is the per-taxel median of the first quiet frames (a
window with no contact) and is subtracted from every later frame.  A press
starts when the summed pressure above the baseline rises over ``on`` and ends
when it falls back under ``off < on`` (hysteresis, so noise around one
threshold does not split a press); the frame of highest summed pressure is the
press's imprint.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hw.protocol import Frame

__all__ = ["Baseline", "Press", "PressDetector"]


@dataclass(frozen=True, eq=False)
class Baseline:
    """The sensor at rest.

    Attributes
    ----------
    values : (rows, cols) float32
        Per-taxel rest reading, subtracted from every frame.
    noise : float
        Standard deviation of the summed pressure at rest (ADC counts).
    on, off : float
        Summed-pressure thresholds that start and end a press.
    frames : int
        Frames it was estimated from.
    """

    values: np.ndarray
    noise: float
    on: float
    off: float
    frames: int


@dataclass(frozen=True, eq=False)
class Press:
    """One completed press.

    Attributes
    ----------
    imprint : (rows, cols) float32
        Peak frame minus the baseline, negatives clipped to 0 (ADC counts).
    raw : (rows, cols) uint16
        The peak frame as received.
    peak_sum : float
        Summed pressure of the peak frame above the baseline.
    seq_start, seq_peak, seq_end : int
        Sequence numbers of the first, peak and last frame of the press.
    t_start_us, t_peak_us, t_end_us : int
        Device times of the same frames.
    frames : int
        Frames above the ``off`` threshold.
    """

    imprint: np.ndarray
    raw: np.ndarray
    peak_sum: float
    seq_start: int
    seq_peak: int
    seq_end: int
    t_start_us: int
    t_peak_us: int
    t_end_us: int
    frames: int


class PressDetector:
    """Estimate the baseline, then turn a frame stream into presses.

    Parameters
    ----------
    baseline_frames : int
        Size of the quiet window the baseline is estimated from.
    on_sigma, off_sigma : float
        Thresholds in standard deviations of the summed pressure at rest.
    min_rise : float
        Floor of the ``on`` threshold in summed ADC counts, for sensors whose
        rest noise is nearly zero (``off`` is at least half of it).
    threshold : float, optional
        Fixed ``on`` threshold in summed counts, replacing the noise rule
        (``off`` is then half of it).
    min_frames : int
        Presses shorter than this are discarded as glitches.

    Attributes
    ----------
    baseline : Baseline or None
        None until a quiet window has been seen.
    waiting : bool
        True when the baseline window holds frames with contact, so the
        detector waits for the sensor to be left alone.

    Examples
    --------
    >>> rest = np.full((4, 4), 100, np.uint16)
    >>> touch = rest.copy(); touch[1, 1] = 900
    >>> det = PressDetector(baseline_frames=5)
    >>> stream = [rest] * 5 + [touch] * 3 + [rest] * 2
    >>> presses = [p for i, v in enumerate(stream) if (p := det.update(Frame(i, 0, v)))]
    >>> len(presses), float(presses[0].imprint[1, 1]), presses[0].frames
    (1, 800.0, 3)
    """

    def __init__(
        self,
        baseline_frames: int = 20,
        on_sigma: float = 8.0,
        off_sigma: float = 4.0,
        min_rise: float = 64.0,
        threshold: float | None = None,
        min_frames: int = 2,
    ):
        if baseline_frames < 2:
            raise ValueError(f"baseline_frames must be at least 2, got {baseline_frames}")
        if not 0 < off_sigma <= on_sigma:
            raise ValueError(f"need 0 < off_sigma <= on_sigma, got {off_sigma} and {on_sigma}")
        if threshold is not None and not threshold > 0:
            raise ValueError(f"threshold must be positive, got {threshold}")
        if min_frames < 1:
            raise ValueError(f"min_frames must be at least 1, got {min_frames}")
        self.baseline_frames = baseline_frames
        self.on_sigma = on_sigma
        self.off_sigma = off_sigma
        self.min_rise = min_rise
        self.threshold = threshold
        self.min_frames = min_frames
        self.baseline: Baseline | None = None
        self.waiting = False
        self._window: list[np.ndarray] = []
        self._press: dict | None = None

    @property
    def pressing(self) -> bool:
        """True while a press is under way."""
        return self._press is not None

    def pressure(self, values: np.ndarray) -> float:
        """Summed pressure of a frame above the baseline (signed, so rest noise averages out)."""
        return float(np.sum(values, dtype=np.float64) - np.sum(self.baseline.values, dtype=np.float64))

    def update(self, frame: Frame) -> Press | None:
        """Take the next frame; return the press it completes, if any."""
        values = frame.values
        if self.baseline is None:
            self._learn(values)
            return None
        if values.shape != self.baseline.values.shape:
            raise ValueError(
                f"frame of {values.shape[0]} x {values.shape[1]} taxels after a baseline of "
                f"{self.baseline.values.shape[0]} x {self.baseline.values.shape[1]}"
            )
        s = self.pressure(values)
        p = self._press
        if p is None:
            if s > self.baseline.on:
                self._press = {"start": frame, "peak": frame, "peak_sum": s, "last": frame, "n": 1}
            return None
        if s >= self.baseline.off:
            p["n"] += 1
            p["last"] = frame
            if s > p["peak_sum"]:
                p["peak"], p["peak_sum"] = frame, s
            return None
        self._press = None
        if p["n"] < self.min_frames:
            return None
        peak = p["peak"]
        imprint = np.clip(peak.values.astype(np.float32) - self.baseline.values, 0.0, None)
        return Press(
            imprint=imprint,
            raw=peak.values.copy(),
            peak_sum=p["peak_sum"],
            seq_start=p["start"].seq,
            seq_peak=peak.seq,
            seq_end=p["last"].seq,
            t_start_us=p["start"].t_us,
            t_peak_us=peak.t_us,
            t_end_us=p["last"].t_us,
            frames=p["n"],
        )

    def _learn(self, values: np.ndarray) -> None:
        if self._window and values.shape != self._window[0].shape:
            self._window.clear()
        self._window.append(values.astype(np.float32))
        if len(self._window) < self.baseline_frames:
            return
        stack = np.stack(self._window)
        rest = np.median(stack, axis=0)
        # With contact in the window some frames stand far from the median;
        # pure noise keeps every frame's deviation near the typical one.
        deviation = np.abs(stack - rest).reshape(len(stack), -1).sum(axis=1)
        floor = 2.0 * rest.size
        if deviation.max() > 2.0 * np.median(deviation) + floor:
            self.waiting = True
            self._window.pop(0)
            return
        sums = stack.reshape(len(stack), -1).sum(axis=1, dtype=np.float64) - rest.sum(dtype=np.float64)
        noise = float(sums.std())
        level = float(sums.mean())
        if self.threshold is not None:
            on, off = self.threshold, self.threshold / 2.0
        else:
            on = level + max(self.on_sigma * noise, self.min_rise)
            off = level + max(self.off_sigma * noise, self.min_rise / 2.0)
        self.baseline = Baseline(values=rest.astype(np.float32), noise=noise, on=on, off=off, frames=len(stack))
        self.waiting = False
        self._window = []
