"""A dependency-free progress bar on stderr."""

from __future__ import annotations

import sys
import time
from collections.abc import Iterable, Iterator
from typing import TypeVar

T = TypeVar("T")


def progress(
    items: Iterable[T], total: int | None = None, desc: str = "", quiet: bool = False, stream=None, unit: str = ""
) -> Iterator[T]:
    """Yield ``items`` while drawing ``desc [#####.....] k/total elapsed, left`` on stderr.

    ``left`` estimates the time still to go from the mean time per item so
    far.  Nothing is drawn when ``quiet`` is true.  On a terminal the bar redraws in
    place; elsewhere (logs, CI) it prints a line at most every 10 % so logs
    stay short.  With a ``unit`` (``"meshes"``) the rate follows: ``2.4 meshes/s``.

    Examples
    --------
    >>> sum(progress(range(3), quiet=True))
    3
    """
    if quiet:
        yield from items
        return
    stream = sys.stderr if stream is None else stream
    if total is None:
        total = len(items) if hasattr(items, "__len__") else 0
    tty = hasattr(stream, "isatty") and stream.isatty()
    start = time.perf_counter()
    last_decile = -1

    def draw(k: int) -> None:
        nonlocal last_decile
        elapsed = time.perf_counter() - start
        if total:
            frac = min(k / total, 1.0)
            decile = int(frac * 10)
            if not tty and decile == last_decile and k != total:
                return
            last_decile = decile
            bar = "#" * int(frac * 30) + "." * (30 - int(frac * 30))
            text = f"{desc} [{bar}] {k}/{total} {elapsed:5.1f}s"
            if 0 < k < total:
                text += f", about {duration(elapsed / k * (total - k))} left"
        else:
            text = f"{desc} {k} {elapsed:5.1f}s"
        if unit:
            text += f" {k / elapsed if elapsed > 0 else 0.0:.2f} {unit}/s"
        stream.write(("\r" + text) if tty else text + "\n")
        stream.flush()

    draw(0)
    k = 0
    for item in items:
        yield item
        k += 1
        draw(k)
    if tty:
        stream.write("\n")
        stream.flush()


def duration(seconds: float) -> str:
    """``42 s``, ``7 min``, ``2 h 05 min``: as precise as an estimate deserves."""
    if seconds < 60:
        return f"{seconds:.0f} s"
    if seconds < 3600:
        return f"{seconds / 60:.0f} min"
    hours, minutes = divmod(round(seconds / 60), 60)
    return f"{hours} h {minutes:02d} min"
