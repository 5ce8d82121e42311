"""Capture presses from a tactile sensor on a serial port into a session.

``python -m hw.capture --port /dev/ttyACM0 --session s.sqlite --object cup``
(the same as ``visuotactile capture``).  Frames are parsed as they arrive, the
first quiet frames give the baseline, each press's peak frame is committed to
the session in its own transaction under the next point id, and running again
on the same session resumes it.  Status lines go to stderr.
"""

from __future__ import annotations

import argparse
import dataclasses
import errno
import signal
import sqlite3
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from hw.press import PressDetector
from hw.protocol import FRAME_PROTOCOLS, FrameParser
from hw.session import Session
from meshsal.util.arguments import HelpFormatter, add_renamed

__all__ = [
    "PortError",
    "NoFramesError",
    "CaptureResult",
    "CaptureOptions",
    "open_port",
    "capture",
    "add_arguments",
    "run",
    "main",
]


class PortError(OSError):
    """The serial port is missing, busy, unreadable or was disconnected."""


class NoFramesError(OSError):
    """Bytes arrive but none of them form a valid frame (wrong baud rate or protocol)."""


@dataclass(frozen=True)
class CaptureResult:
    """What one capture run did.

    Attributes
    ----------
    point_ids : tuple of int
        Point ids of the presses stored by this run, in order.
    stopped : str
        Why it stopped: "presses" (``presses`` reached), "plan" (every
        planned point recorded) or "interrupted" (Ctrl-C).
    frames, crc_errors, bad_lines, gaps, bytes_skipped : int
        The frame parser's counters at the end.
    """

    point_ids: tuple[int, ...]
    stopped: str
    frames: int
    crc_errors: int
    bad_lines: int
    gaps: int
    bytes_skipped: int


def open_port(port: str, baud: int = 115200, timeout: float = 0.05):
    """Open a device path or pyserial URL exclusively, with clear errors.

    Raises
    ------
    PortError
        The port does not exist, is busy (another program holds it) or
        cannot be opened.
    """
    import serial

    try:
        return serial.serial_for_url(port, baudrate=baud, timeout=timeout, exclusive=True)
    except serial.SerialException as exc:
        code = getattr(exc, "errno", None)
        if code == errno.ENOENT:
            raise PortError(f"{port}: no such serial port (is the sensor plugged in? check the device path)") from None
        if code in (errno.EBUSY, errno.EAGAIN):
            raise PortError(f"{port}: the serial port is busy (another program has it open)") from None
        if code == errno.EACCES:
            raise PortError(
                f"{port}: permission denied opening the serial port (on Linux, join the 'dialout' group)"
            ) from None
        raise PortError(f"{port}: cannot open the serial port: {exc}") from None
    except ValueError as exc:
        raise PortError(f"{port}: not a usable port or pyserial URL: {exc}") from None


@dataclass(frozen=True)
class CaptureOptions:
    """How a capture reads its port and when it stops (:func:`capture`).

    Attributes
    ----------
    baud : int
    protocol : {"binary", "text"}
    plan : hw.plan.Plan, optional
        Presses take the ids of the plan's points in order, skipping points
        already recorded for this object; capture stops when all are done.
        Each press stores its point's position in the planning frame (mm)
        and approach direction.
    first_point : int
        Without a plan: id of the first press; ids count up from it, or from
        one past the largest id recorded for this object when that is larger.
        Either way the id is chosen as the press is committed, so captures
        running into one session and object at once never share an id.
    presses : int, optional
        Stop after this many presses; otherwise run until Ctrl-C.
    garbage_timeout : float
        Seconds of received bytes without any valid frame before giving up
        with ``NoFramesError``.  Silence is not an error.
    detector : PressDetector, optional
        Baseline and press thresholds; the defaults otherwise.

    quiet : bool
        No status lines.
    stream : file, optional
        Where status lines go (default stderr).
    """

    baud: int = 115200
    protocol: str = "binary"
    plan: object = None
    first_point: int = 0
    presses: int | None = None
    garbage_timeout: float = 5.0
    detector: PressDetector | None = None
    quiet: bool = False
    stream: object = None


def capture(
    port: str, session: Session, object_name: str, options: CaptureOptions | None = None, **changes
) -> CaptureResult:
    """Record presses from ``port`` into ``session`` until done.

    Parameters
    ----------
    port : str
        Device path or pyserial URL.
    session : Session
    object_name : str
        The object being pressed.
    options : CaptureOptions, optional
        Changed by any ``**changes`` named as its fields (``presses=15``, ``plan=``...).

    Raises
    ------
    PortError, NoFramesError, ValueError
        Port missing, busy or disconnected; only garbage arriving; frames
        whose size differs from the session's sensor.  Presses committed
        before the error stay in the session.
    """
    o = dataclasses.replace(options or CaptureOptions(), **changes)
    FRAME_PROTOCOLS.get(o.protocol)  # ValueError naming the protocols
    if o.presses is not None and o.presses < 1:
        raise ValueError(f"presses must be at least 1, got {o.presses}")
    stream = sys.stderr if o.stream is None else o.stream

    def say(text: str) -> None:
        if not o.quiet:
            print(f"capture: {text}", file=stream, flush=True)

    recorded = session.point_ids(object_name)
    planned = None
    if o.plan is not None:
        planned = [(p.id, position, p.approach) for p, position in zip(o.plan.points, o.plan.positions_mm())]
        if session.next_point(object_name, planned=planned) is None:
            say(f"all {len(o.plan.points)} planned points of {object_name!r} are already in {session.path}")
            return CaptureResult((), "plan", 0, 0, 0, 0, 0)

    def upcoming():
        return session.next_point(object_name, o.first_point, planned)

    if recorded:
        say(f"resuming {session.path}: {len(recorded)} presses of {object_name!r} already stored")

    detector = PressDetector() if o.detector is None else o.detector
    parser = FrameParser(protocol=o.protocol)
    ser = open_port(port, o.baud)
    say(f"reading {port} at {o.baud} baud ({o.protocol}); keep the sensor untouched for the baseline")
    stored: list[int] = []
    run_id = None
    told_waiting = False
    sensor = session.sensor
    last_valid = time.monotonic()
    garbage = 0
    # Ctrl-C sets a flag that the loop reads between reads, so it never lands inside a commit; a run in another
    # thread (no signal handler there) stops on the KeyboardInterrupt instead.
    interrupted: list[int] = []
    handles = threading.current_thread() is threading.main_thread()
    if handles:
        # None: a handler not set from Python, which cannot be set back; Python's own then.
        previous = signal.getsignal(signal.SIGINT) or signal.default_int_handler
        signal.signal(signal.SIGINT, lambda signum, frame: interrupted.append(signum))
    try:
        while not interrupted:
            try:
                data = ser.read(ser.in_waiting or 1)
            except Exception as exc:  # pyserial raises SerialException or OSError subclasses
                raise PortError(
                    f"{port}: the port stopped answering ({exc}); {len(stored)} presses of this run "
                    f"are stored in {session.path}; run again to resume"
                ) from None
            frames = parser.feed(data)
            now = time.monotonic()
            if frames:
                last_valid, garbage = now, 0
            else:
                garbage += len(data)
                if garbage and now - last_valid > o.garbage_timeout:
                    raise NoFramesError(
                        f"{port}: {garbage} bytes in {now - last_valid:.1f} s but no valid {o.protocol} frame; "
                        f"check the baud rate (--baud {o.baud}) and the protocol (--protocol {o.protocol})"
                    )
            for frame in frames:
                if frame.shape != sensor:
                    session.ensure_sensor(*frame.shape)
                    sensor = frame.shape
                press = detector.update(frame)
                if detector.waiting and not told_waiting:
                    say("contact while estimating the baseline: release the sensor")
                    told_waiting = True
                if run_id is None and detector.baseline is not None:
                    b = detector.baseline
                    run_id = session.start_run(port, o.baud, o.protocol, object_name, b)
                    say(
                        f"baseline from {b.frames} frames (summed noise {b.noise:.1f}, press above {b.on:.0f}); "
                        f"ready for point {upcoming()}"
                    )
                if press is None:
                    continue
                counters = {
                    "frames": parser.frames,
                    "crc_errors": parser.crc_errors + parser.bad_lines,
                    "gaps": parser.gaps,
                    "bytes_skipped": parser.bytes_skipped,
                }
                # The id is chosen as the press is committed: another capture into this session may have
                # taken the one announced.
                added = session.add_next_press(
                    run_id, object_name, press, counters, first_point=o.first_point, planned=planned
                )
                if added is None:
                    say(f"press not stored: another capture recorded the last planned points of {object_name!r}")
                    return _result(stored, "plan", parser)
                point_id = added[1]
                stored.append(point_id)
                following = upcoming()
                say(
                    f"press {len(stored)}: point {point_id} stored (peak {press.peak_sum:.0f}, "
                    f"{press.frames} frames; {parser.frames} frames received, {parser.crc_errors} CRC errors, "
                    f"{parser.gaps} missing)" + ("" if following is None else f"; next point {following}")
                )
                if following is None:
                    return _result(stored, "plan", parser)
                if o.presses is not None and len(stored) >= o.presses:
                    return _result(stored, "presses", parser)
    except KeyboardInterrupt:
        pass
    finally:
        if handles:
            signal.signal(signal.SIGINT, previous)
        ser.close()
    say(f"interrupted; {len(stored)} presses of this run are stored in {session.path}")
    return _result(stored, "interrupted", parser)


def _result(stored, stopped, parser) -> CaptureResult:
    return CaptureResult(
        tuple(stored), stopped, parser.frames, parser.crc_errors, parser.bad_lines, parser.gaps, parser.bytes_skipped
    )


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The capture options, shared by ``visuotactile capture`` and ``python -m hw.capture``."""
    p.add_argument("--port", required=True, help="device path (/dev/ttyACM0, COM3) or pyserial URL")
    p.add_argument("--baud", type=int, default=115200, help="baud rate (default 115200)")
    p.add_argument("--protocol", choices=FRAME_PROTOCOLS.names(), default="binary", help=FRAME_PROTOCOLS.help_text())
    p.add_argument("--session", required=True, help="session file (.sqlite); created or resumed")
    p.add_argument("--object", required=True, help="name of the object being pressed")
    ids = p.add_mutually_exclusive_group()
    ids.add_argument("--points", metavar="PLAN_JSON", help="probe plan: presses take its point ids in order")
    ids.add_argument(
        "--first-point",
        type=int,
        default=0,
        metavar="ID",
        help="id of the first press without a plan; counts up (default 0, or resume)",
    )
    p.add_argument("--presses", type=int, metavar="N", help="stop after N presses (default: until Ctrl-C)")
    p.add_argument(
        "--garbage-timeout",
        type=float,
        default=5.0,
        metavar="SECONDS",
        help="give up after this long with bytes but no valid frame (default 5)",
    )
    p.add_argument("--baseline-frames", type=int, default=20, help="quiet frames for the baseline (default 20)")
    add_renamed(
        p,
        "--threshold",
        p.add_argument(
            "--press-threshold",
            type=float,
            help="summed counts above the baseline that start a press (default: from the rest noise)",
        ),
    )
    p.add_argument("--quiet", action="store_true", help="no status lines on stderr (errors are still printed)")


def _discard_if_empty(path: Path) -> None:
    """Delete the session file ``path`` (and SQLite's files beside it) if it exists and holds no press.

    A file that cannot be read as a session stays: this runs on the way out of another error.
    """
    if not path.exists():
        return
    try:
        with Session(path, create=False) as session:
            empty = not session.presses()
    except (ValueError, OSError, sqlite3.Error):
        return
    if empty:
        for leftover in (path, path.with_name(path.name + "-wal"), path.with_name(path.name + "-shm")):
            leftover.unlink(missing_ok=True)


def run(args) -> int:
    """Handler of the capture subcommand."""
    from hw.plan import load_plan

    plan = load_plan(args.points) if args.points else None
    detector = PressDetector(baseline_frames=args.baseline_frames, threshold=args.press_threshold)
    new = not Path(args.session).exists()
    try:
        with Session(args.session) as session:
            result = capture(
                args.port,
                session,
                args.object,
                baud=args.baud,
                protocol=args.protocol,
                plan=plan,
                first_point=args.first_point,
                presses=args.presses,
                garbage_timeout=args.garbage_timeout,
                detector=detector,
                quiet=args.quiet,
            )
    finally:
        # A run that stored no press (a wrong port, an option refused, Ctrl-C at once) leaves no session it made.
        if new:
            _discard_if_empty(Path(args.session))
    if not args.quiet:
        kept = Path(args.session).exists()
        print(
            f"capture: {len(result.point_ids)} presses stored in {args.session}{'' if kept else ' (not kept)'} "
            f"({result.stopped}); {result.frames} frames, {result.crc_errors + result.bad_lines} corrupt, "
            f"{result.gaps} missing",
            file=sys.stderr,
        )
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m hw.capture``: the same as ``visuotactile capture``."""
    parser = argparse.ArgumentParser(
        prog="python -m hw.capture", description=__doc__.splitlines()[0], formatter_class=HelpFormatter
    )
    add_arguments(parser)
    args = parser.parse_args(argv)
    try:
        return run(args)
    except (ValueError, OSError) as exc:
        print(f"capture: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
