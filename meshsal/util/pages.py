"""Measurement pages in ``docs/``: written by the command that measured them, with where and when in a header.

A figure people quote carries the command that produced it, the commit it
ran at, the machine and the date.  :func:`write_page` writes a Markdown page
whose header says all four, read from the running process, never typed by
hand; the body is the command's own tables.

Examples
--------
>>> import tempfile, pathlib
>>> path = pathlib.Path(tempfile.mkdtemp()) / "bench.md"
>>> write_page(path, "Rendering", "| a |\\n|---|\\n| 1 |\\n", command=["bench_render.py"])
>>> text = path.read_text()
>>> text.splitlines()[0], "bench_render.py" in text, "| 1 |" in text
('# Rendering', True, True)
"""

from __future__ import annotations

import datetime
import os
import platform
import shlex
import subprocess
import sys
from pathlib import Path

from meshsal.util.atomic import write_text

__all__ = ["commit", "cpu_model", "machine", "provenance", "write_page"]


def cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo (the platform's processor string elsewhere)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown CPU"


def _instruction_set() -> str:
    try:
        flags = next(
            (line for line in Path("/proc/cpuinfo").read_text().splitlines() if line.startswith("flags")), ""
        ).split()
    except OSError:
        return ""
    for name, flag in (("AVX-512", "avx512f"), ("AVX2", "avx2")):
        if flag in flags:
            return name
    return ""


def machine() -> str:
    """One line: CPU model and its widest vector set, cores, load average over 1 / 5 / 15 minutes."""
    load = " / ".join(f"{x:.2f}" for x in os.getloadavg()) if hasattr(os, "getloadavg") else "n/a"
    isa = _instruction_set()
    return f"{cpu_model()}{f' ({isa})' if isa else ''}, {os.cpu_count()} cores, load average {load} (1 / 5 / 15 min)"


def commit(where=None) -> str:
    """The checkout's commit (short hash, ``+changes`` when the code differs from it), or ``unknown``.

    Changes under ``docs/`` do not count: they are what the commands write
    (a benchmark's picture is written before its page), not what they measure.
    """
    where = Path(__file__).resolve().parents[2] if where is None else Path(where)

    def git(*args):
        return subprocess.run(["git", "-C", str(where), *args], capture_output=True, text=True, timeout=10)

    try:
        head = git("rev-parse", "--short=10", "HEAD")
        if head.returncode != 0:
            return "unknown"
        dirty = git("status", "--porcelain", "--untracked-files=no", "--", ":/", ":(top,exclude)docs").stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return head.stdout.strip() + (" +changes" if dirty else "")


def provenance(command=None) -> str:
    """The header lines of a page: command, commit, machine, date (UTC)."""
    command = sys.argv if command is None else command
    now = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    return "\n".join(
        [
            f"- command: `{shlex.join(str(c) for c in command)}`",
            f"- commit: {commit()}",
            f"- machine: {machine()}",
            f"- date: {now}",
        ]
    )


def write_page(path, title: str, body: str, command=None) -> None:
    """Write ``docs``' page ``path`` atomically: ``# title``, the :func:`provenance` header, then ``body``.

    Parameters
    ----------
    path : path of the Markdown page
    title : str
    body : str, Markdown (the command's tables and what they mean)
    command : sequence of str, optional
        The command line to name (default ``sys.argv``).
    """
    header = (
        f"# {title}\n\n*Written by the command below; do not edit by hand: run it again.*\n\n{provenance(command)}\n"
    )
    write_text(path, f"{header}\n{body.rstrip()}\n")
