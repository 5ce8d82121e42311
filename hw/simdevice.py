"""A simulated tactile sensor on a pseudo-terminal, for trying capture without hardware.

``python -m hw.simdevice --object cow`` prints the pty's path on stdout, then
streams frames there at ``--rate`` Hz: baseline noise at rest and, one after
the other, presses whose peak frame is the simulated imprint
(``tactile.imprint``) of the object at its interest points (or at the points
of a ``--points plan.json``).  Like a USB sensor that streams once the host
opens the port, it sends only while a program has the pty open, and each time
one does it starts with quiet frames (the capture's baseline) and restarts a
press it was in the middle of.  Faults can be injected: garbage bytes, bit
flips, dropped frames and a disconnect.

Then, in another terminal: ``visuotactile capture --port <path> --session s.sqlite --object cow``.
"""

from __future__ import annotations

import argparse
import os
import select
import signal
import sys
import time
import tty

import numpy as np

from hw.protocol import FRAME_PROTOCOLS, HEADER_SIZE, SYNC, VERSION, encode

__all__ = ["SimulatedSensor", "open_pty", "serve", "press_targets", "main"]


class SimulatedSensor:
    """The frame source of a simulated force-resistive array.

    Each call of :meth:`next_bytes` is one frame period.  The sensor rests
    (per-taxel offset plus Gaussian noise), then presses each imprint in
    turn: the load rises and falls as a half sine over ``press_frames``
    frames, peaking at ``rest + full_scale * imprint``.

    Parameters
    ----------
    imprints : (k, rows, cols) array in [0, 1]
        Peak shapes, pressed in order (cycled when ``presses`` > k).
    rng : numpy.random.Generator
    protocol : {"binary", "text"}
    presses : int, optional
        Number of presses (default k); afterwards the sensor rests.
    press_frames, idle_frames, lead_frames : int
        Frames per press, rest frames between presses, and rest frames
        after each (re)connection before the first press.
    rest_level, rest_spread, noise, full_scale, adc_max : float
        Mean rest reading, spread of the fixed per-taxel offsets, noise
        standard deviation, load at imprint 1, and ADC ceiling (counts).
    garbage, bitflips, drop : float
        Per-frame probabilities of a burst of random bytes before the frame
        (sometimes holding a fake header), of one flipped bit, and of the
        frame not being sent (its sequence number is still used).
    rate : float
        Frames per second, for the device clock.

    Attributes
    ----------
    pressed : int
        Presses completed so far.

    Examples
    --------
    >>> from hw.protocol import FrameParser
    >>> sim = SimulatedSensor(np.ones((1, 4, 4)), np.random.default_rng(0), lead_frames=3, press_frames=3)
    >>> frames = FrameParser().feed(b"".join(sim.next_bytes() for _ in range(6)))
    >>> [int(f.values.mean() > 1000) for f in frames]
    [0, 0, 0, 1, 1, 1]
    """

    def __init__(
        self,
        imprints,
        rng,
        protocol: str = "binary",
        presses: int | None = None,
        press_frames: int = 15,
        idle_frames: int = 20,
        lead_frames: int = 40,
        rest_level: float = 200.0,
        rest_spread: float = 40.0,
        noise: float = 3.0,
        full_scale: float = 3000.0,
        adc_max: float = 4095.0,
        garbage: float = 0.0,
        bitflips: float = 0.0,
        drop: float = 0.0,
        rate: float = 100.0,
    ):
        imprints = np.asarray(imprints, dtype=np.float64)
        if imprints.ndim != 3 or imprints.shape[0] == 0:
            raise ValueError(f"imprints must have shape (k, rows, cols) with k >= 1, got {imprints.shape}")
        FRAME_PROTOCOLS.get(protocol)  # ValueError naming the protocols
        for name, p in (("garbage", garbage), ("bitflips", bitflips), ("drop", drop)):
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"{name} must be a probability in [0, 1], got {p}")
        if min(press_frames, lead_frames) < 1 or idle_frames < 0:
            raise ValueError("press_frames and lead_frames must be >= 1 and idle_frames >= 0")
        self.imprints = imprints
        self.rng = rng
        self.protocol = protocol
        self.presses = imprints.shape[0] if presses is None else int(presses)
        self.press_frames = press_frames
        self.idle_frames = idle_frames
        self.lead_frames = lead_frames
        self.noise = noise
        self.full_scale = full_scale
        self.adc_max = adc_max
        self.garbage = garbage
        self.bitflips = bitflips
        self.drop = drop
        self.period_us = 1e6 / rate
        shape = imprints.shape[1:]
        self.rest = rest_level + rng.uniform(-rest_spread, rest_spread, size=shape)
        # Half sine: load 0 before and after, exactly 1 at the middle frame when press_frames is odd.
        self.profile = np.sin(np.pi * np.arange(1, press_frames + 1) / (press_frames + 1))
        self.seq = 0
        self.pressed = 0
        self._wait = lead_frames
        self._step = 0

    @property
    def done(self) -> bool:
        """True once every press has been made."""
        return self.pressed >= self.presses

    def restart(self) -> None:
        """A host (re)opened the port: rest first, and redo an interrupted press."""
        self._wait = self.lead_frames
        self._step = 0

    def load(self) -> np.ndarray:
        """The next frame's taxel values (uint16), advancing the press schedule."""
        if self._wait > 0 or self.done:
            self._wait -= 1
            pressed = 0.0
        else:
            imprint = self.imprints[self.pressed % len(self.imprints)]
            pressed = self.profile[self._step] * self.full_scale * imprint
            self._step += 1
            if self._step == self.press_frames:
                self._step = 0
                self.pressed += 1
                self._wait = self.idle_frames
        values = self.rest + pressed + self.rng.normal(0.0, self.noise, size=self.rest.shape)
        return np.clip(np.rint(values), 0, self.adc_max).astype(np.uint16)

    def next_bytes(self) -> bytes:
        """The bytes sent during the next frame period (possibly none, or with faults)."""
        values = self.load()
        seq, self.seq = self.seq, (self.seq + 1) % 2**32
        rng = self.rng
        out = b""
        if self.garbage and rng.random() < self.garbage:
            out += self._garbage_burst(values.shape)
        if self.drop and rng.random() < self.drop:
            return out
        frame = bytearray(encode(seq, int(seq * self.period_us) % 2**32, values, self.protocol))
        if self.bitflips and rng.random() < self.bitflips:
            bit = int(rng.integers(8 * len(frame)))
            frame[bit // 8] ^= 1 << (bit % 8)
        return out + bytes(frame)

    def _garbage_burst(self, shape) -> bytes:
        rng = self.rng
        burst = rng.integers(0, 256, size=int(rng.integers(1, 65)), dtype=np.uint8).tobytes()
        if rng.random() < 0.25:
            # A plausible header of the right size: the parser must wait, fail the CRC and rescan.
            fake = SYNC + bytes([VERSION, shape[0], shape[1], 0])
            burst = fake + rng.integers(0, 256, size=HEADER_SIZE - len(fake), dtype=np.uint8).tobytes() + burst
        return burst


def open_pty() -> tuple[int, str]:
    """Open a raw pseudo-terminal; returns (master fd, slave path).

    The slave end is closed again, so the master reports a hang-up until a
    program opens the path.
    """
    master, slave = os.openpty()
    tty.setraw(slave)
    path = os.ttyname(slave)
    os.close(slave)
    os.set_blocking(master, False)
    return master, path


def serve(
    master: int,
    sensor: SimulatedSensor,
    rate: float,
    disconnect_after: int | None = None,
    wait_for_reader: bool = True,
    stop=None,
    log=None,
) -> None:
    """Stream ``sensor`` into a pty master at ``rate`` frames per second.

    Returns after ``disconnect_after`` frames (closing ``master``, which the
    reader sees as an unplugged device) or when the ``stop`` event is set.
    With ``wait_for_reader`` nothing is sent while no program has the pty
    open.  A reader that falls behind holds the device back (flow control,
    as a USB device waits for the host), so no byte is lost on the link:
    frames go missing only through the ``drop`` fault.
    """
    poller = select.poll()
    poller.register(master, select.POLLOUT)
    period = 1.0 / rate
    connected = False
    sent = 0
    due = time.monotonic()

    def stopped() -> bool:
        return stop is not None and stop.is_set()

    try:
        while not stopped():
            if wait_for_reader and _hung_up(poller, 0):
                if connected and log:
                    log("reader closed the port; pausing")
                connected = False
                time.sleep(0.01)
                continue
            if not connected:
                connected = True
                sensor.restart()
                due = time.monotonic()
                if log:
                    log(f"reader connected; streaming at {rate:g} Hz")
            data = sensor.next_bytes()
            while data and not stopped():
                try:
                    data = data[os.write(master, data) :]
                except BlockingIOError:
                    if _hung_up(poller, 50) and wait_for_reader:
                        break
                except OSError:
                    break
            sent += 1
            if disconnect_after is not None and sent >= disconnect_after:
                if log:
                    log(f"disconnecting after {sent} frames")
                return
            due += period
            delay = due - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            elif delay < -0.25:
                due = time.monotonic()
    finally:
        os.close(master)


def _hung_up(poller, timeout_ms: int) -> bool:
    """Wait up to ``timeout_ms`` for the pty to be writable; True if no reader has it open."""
    return any(ev & select.POLLHUP for _, ev in poller.poll(timeout_ms))


def press_targets(mesh, plan=None, n: int = 15, method: str = "random", seed: int = 0):
    """Points to press on ``mesh`` (scaled as planned): from a probe plan or ``meshsal.interest_points``.

    Returns
    -------
    ids : (k,) int64
    positions, normals : (k, 3) float64
        In ``mesh``'s current frame; normals point outward.
    """
    if plan is not None:
        ids = np.array([p.id for p in plan.points], dtype=np.int64)
        positions = plan.positions_mm()
        normals = -np.array([p.approach for p in plan.points], dtype=np.float64)
        return ids, positions, normals
    import meshsal

    pts = meshsal.interest_points(mesh, n=n, method=method, seed=seed, quiet=True)
    return np.arange(len(pts.positions), dtype=np.int64), pts.positions, pts.normals


def _parser() -> argparse.ArgumentParser:
    from meshsal.points import POINT_METHODS
    from meshsal.util.arguments import HelpFormatter, add_renamed
    from tactile.sensor import SENSOR_MODES

    p = argparse.ArgumentParser(
        prog="python -m hw.simdevice", description=__doc__.split("\n\n")[0], formatter_class=HelpFormatter
    )
    p.add_argument("--object", required=True, help="a toy name (meshsal.objects.toys.NAMES) or a mesh file")
    p.add_argument(
        "--size-mm", type=float, default=150.0, help="principal-frame box diagonal of the object in mm (default 150)"
    )
    p.add_argument("--points", metavar="PLAN_JSON", help="press the points of this probe plan")
    add_renamed(p, "--n", p.add_argument("--n-points", type=int, default=15, help="interest points without a plan"))
    p.add_argument(
        "--method",
        default="random",
        choices=POINT_METHODS.names(),
        help="interest point method without a plan (default random: starts at once)",
    )
    p.add_argument("--presses", type=int, help="number of presses (default: one per point)")
    p.add_argument("--rate", type=float, default=100.0, help="frames per second (default 100)")
    p.add_argument("--press-frames", type=int, default=31, help="frames per press (default 31)")
    p.add_argument("--idle-frames", type=int, default=50, help="rest frames between presses (default 50)")
    p.add_argument("--lead-frames", type=int, default=100, help="rest frames after the port opens (default 100)")
    p.add_argument("--noise", type=float, default=3.0, help="taxel noise, ADC counts (default 3)")
    p.add_argument("--full-scale", type=float, default=3000.0, help="counts at imprint value 1 (default 3000)")
    p.add_argument("--rows", type=int, default=16, help="sensor rows (default 16)")
    p.add_argument("--cols", type=int, default=16, help="sensor columns (default 16)")
    p.add_argument(
        "--mode",
        choices=SENSOR_MODES.names(),
        default="contour",
        help="imprint mode of the simulated pad (default contour, the paper's image)",
    )
    p.add_argument("--protocol", choices=FRAME_PROTOCOLS.names(), default="binary", help=FRAME_PROTOCOLS.help_text())
    p.add_argument("--garbage", type=float, default=0.0, help="probability of a garbage burst per frame")
    p.add_argument("--bitflips", type=float, default=0.0, help="probability of a flipped bit per frame")
    p.add_argument("--drop", type=float, default=0.0, help="probability of dropping a frame")
    p.add_argument("--disconnect-after", type=int, metavar="FRAMES", help="close the pty after this many frames")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--dump", metavar="NPZ", help="write what is pressed (imprints, point ids, points) here")
    p.add_argument("--no-wait", action="store_true", help="stream even while no program has the port open")
    return p


def main(argv: list[str] | None = None) -> int:
    """``python -m hw.simdevice``: run a simulated sensor until interrupted."""
    args = _parser().parse_args(argv)

    def log(text: str) -> None:
        print(f"simdevice: {text}", file=sys.stderr, flush=True)

    try:
        import tactile
        from hw.plan import load_plan
        from meshsal.mesh.transform import scale_to_principal
        from meshsal.objects import load_object

        plan = load_plan(args.points) if args.points else None
        mesh = scale_to_principal(load_object(args.object), plan.size_mm if plan is not None else args.size_mm)
        ids, positions, normals = press_targets(mesh, plan, n=args.n_points, method=args.method, seed=args.seed)
        sensor = tactile.Sensor(rows=args.rows, cols=args.cols, mode=args.mode)
        imprints = tactile.imprints(mesh, positions, normals, sensor)
        empty = np.flatnonzero(imprints.reshape(len(imprints), -1).max(axis=1) <= 0)
        if empty.size:
            raise ValueError(f"{args.object}: the sensor touches nothing at point(s) {ids[empty].tolist()}")
        sim = SimulatedSensor(
            imprints,
            np.random.default_rng(args.seed),
            protocol=args.protocol,
            presses=args.presses,
            press_frames=args.press_frames,
            idle_frames=args.idle_frames,
            lead_frames=args.lead_frames,
            noise=args.noise,
            full_scale=args.full_scale,
            garbage=args.garbage,
            bitflips=args.bitflips,
            drop=args.drop,
            rate=args.rate,
        )
        if args.dump:
            from meshsal.util.atomic import atomic_path

            with atomic_path(args.dump) as tmp:
                np.savez(
                    tmp,
                    imprints=imprints.astype(np.float32),
                    point_ids=ids,
                    positions=positions,
                    normals=normals,
                    full_scale=args.full_scale,
                )
    except (ValueError, OSError) as exc:
        print(f"simdevice: error: {exc}", file=sys.stderr)
        return 1
    master, path = open_pty()
    print(path, flush=True)
    log(f"{args.object}: {sim.presses} presses of {len(ids)} points on {path}")
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    try:
        serve(master, sim, args.rate, disconnect_after=args.disconnect_after, wait_for_reader=not args.no_wait, log=log)
    except KeyboardInterrupt:
        pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
