"""Capture sessions in SQLite, and their export to a ``tactile.ImprintSet``.

One session file holds the presses of any number of objects made with one
sensor, at most one press per object and point id (a UNIQUE index).  The
database runs in WAL mode with full sync and every press is its own
transaction, so a killed process or a pulled cable loses nothing already
pressed; opening the same file again resumes the session.  Several captures
may write to one session at once, from any number of processes: the point id
of a press is chosen inside its own insert transaction (``BEGIN IMMEDIATE``).
The file itself (its schema, creation and migration, and the write-ahead log
that network filesystems may refuse) is :mod:`hw.session_file`.
"""

from __future__ import annotations

import sqlite3
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hw import session_file
from hw.press import Baseline, Press
from hw.session_file import FORMAT, SCHEMA_VERSION

__all__ = ["FORMAT", "SCHEMA_VERSION", "Session", "PressRecord", "export_imprints", "resample"]


@dataclass(frozen=True, eq=False)
class PressRecord:
    """One stored press, as read back from a session.

    ``imprint`` is float32 ADC counts above the baseline, ``raw`` the uint16
    peak frame; ``position`` (planning frame, mm, as in simulated imprint
    sets) and ``approach`` come from the probe plan and are None when the
    press was not planned.  ``frames_received``, ``crc_errors`` and ``gaps``
    are the parser's counts when the press was stored; ``crc_errors`` counts
    every frame lost to corruption: failed CRCs (binary) and unreadable
    lines (text).
    """

    id: int
    run_id: int
    object: str
    point_id: int
    imprint: np.ndarray
    raw: np.ndarray
    peak_sum: float
    seq_peak: int
    t_peak_us: int
    host_time: float
    frames_received: int
    crc_errors: int
    gaps: int
    position: np.ndarray | None
    approach: np.ndarray | None


class Session:
    """An open capture session (a SQLite file), created on first use.

    Parameters
    ----------
    path : str or Path
        The ``.sqlite`` file.
    create : bool
        Create the file when it does not exist; otherwise a missing file is
        a ``FileNotFoundError``.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "s.sqlite"
    >>> with Session(path) as s:
    ...     s.ensure_sensor(16, 16)
    ...     s.sensor
    (16, 16)
    """

    def __init__(self, path, create: bool = True):
        self.path = Path(path)
        self._con = session_file.connect(self.path, create)

    def _meta(self) -> dict[str, str]:
        return session_file.meta(self._con)

    def close(self) -> None:
        self._con.close()

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def sensor(self) -> tuple[int, int] | None:
        """(rows, cols) of the session's sensor, or None before the first frame."""
        meta = self._meta()
        if "rows" not in meta:
            return None
        return int(meta["rows"]), int(meta["cols"])

    def ensure_sensor(self, rows: int, cols: int) -> None:
        """Record the sensor size on first use; afterwards insist on the same size."""
        with self._transaction():
            known = self.sensor
            if known is None:
                self._con.executemany(
                    "INSERT INTO meta VALUES (?, ?)", [("rows", str(int(rows))), ("cols", str(int(cols)))]
                )
        if known is not None and known != (rows, cols):
            raise ValueError(
                f"{self.path}: the session was recorded with a {known[0]} x {known[1]} sensor "
                f"but the port sends {rows} x {cols} frames; use another --session for this sensor"
            )

    def start_run(self, port: str, baud: int, protocol: str, object_name: str, baseline: Baseline) -> int:
        """Record the start of a capture run with its baseline; returns the run id."""
        with self._transaction():
            cur = self._con.execute(
                "INSERT INTO runs (started, port, baud, protocol, object, baseline, baseline_noise,"
                " threshold_on, threshold_off) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (
                    time.time(),
                    port,
                    int(baud),
                    protocol,
                    object_name,
                    np.ascontiguousarray(baseline.values, np.float32).tobytes(),
                    baseline.noise,
                    baseline.on,
                    baseline.off,
                ),
            )
            return int(cur.lastrowid)

    def add_press(
        self, run_id: int, object_name: str, point_id: int, press: Press, counters: dict, position=None, approach=None
    ) -> int:
        """Commit one press under ``point_id`` in its own transaction; returns its row id.

        ``counters`` holds the parser's ``frames``, ``crc_errors`` (failed
        CRCs and unreadable text lines), ``gaps`` and ``bytes_skipped`` at the
        time of the press.  A point id already recorded for the object is a
        ``ValueError``; :meth:`add_next_press` chooses a free one.
        """
        self._check_size(press)
        with self._transaction():
            return self._insert(run_id, object_name, int(point_id), press, counters, position, approach)

    def add_next_press(
        self, run_id: int, object_name: str, press: Press, counters: dict, *, first_point: int = 0, planned=None
    ) -> tuple[int, int] | None:
        """Commit one press under the next free point id, chosen inside the insert's own transaction.

        Two captures into one session and object, in one process or several,
        never take the same id: each sees the other's committed presses.

        Parameters
        ----------
        run_id, object_name, press, counters
            As for :meth:`add_press`.
        first_point : int
            Without ``planned``: the id is one past the largest recorded for
            the object, and at least this.
        planned : sequence of (point_id, position, approach), optional
            A probe plan in order: the press takes its first point not yet
            recorded for the object, with that point's position and approach.

        Returns
        -------
        (row id, point id), or None when every planned point is recorded
        (nothing is stored then).
        """
        self._check_size(press)
        with self._transaction():
            choice = self._next_point(object_name, first_point, planned)
            if choice is None:
                return None
            point_id, position, approach = choice
            return self._insert(run_id, object_name, point_id, press, counters, position, approach), point_id

    def next_point(self, object_name: str, first_point: int = 0, planned=None) -> int | None:
        """The point id :meth:`add_next_press` would take now (None: the plan is done).

        Only a forecast while other captures write to the session too.
        """
        choice = self._next_point(object_name, first_point, planned)
        return None if choice is None else choice[0]

    def _next_point(self, object_name: str, first_point: int, planned):
        if planned is None:
            (largest,) = self._con.execute(
                "SELECT max(point_id) FROM presses WHERE object = ?", (object_name,)
            ).fetchone()
            return int(first_point) if largest is None else max(int(first_point), largest + 1), None, None
        done = set(self.point_ids(object_name))
        return next(((int(i), p, a) for i, p, a in planned if int(i) not in done), None)

    def _check_size(self, press: Press) -> None:
        rows, cols = press.raw.shape
        if self.sensor != (rows, cols):
            raise ValueError(f"{self.path}: a {rows} x {cols} press does not fit the session's sensor {self.sensor}")

    def _insert(self, run_id, object_name, point_id, press, counters, position, approach) -> int:
        p = [None] * 3 if position is None else [float(x) for x in position]
        a = [None] * 3 if approach is None else [float(x) for x in approach]
        try:
            cur = self._con.execute(
                "INSERT INTO presses (run_id, object, point_id, imprint, raw, peak_sum, seq_start, seq_peak,"
                " seq_end, t_start_us, t_peak_us, t_end_us, frames, host_time, frames_received, crc_errors,"
                " gaps, bytes_skipped, px, py, pz, ax, ay, az)"
                " VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (
                    run_id,
                    object_name,
                    point_id,
                    np.ascontiguousarray(press.imprint, np.float32).tobytes(),
                    np.ascontiguousarray(press.raw, "<u2").tobytes(),
                    float(press.peak_sum),
                    press.seq_start,
                    press.seq_peak,
                    press.seq_end,
                    press.t_start_us,
                    press.t_peak_us,
                    press.t_end_us,
                    press.frames,
                    time.time(),
                    int(counters["frames"]),
                    int(counters["crc_errors"]),
                    int(counters["gaps"]),
                    int(counters["bytes_skipped"]),
                    *p,
                    *a,
                ),
            )
        except sqlite3.IntegrityError:
            raise ValueError(f"{self.path}: point {point_id} of {object_name!r} is already recorded") from None
        return int(cur.lastrowid)

    def _transaction(self):
        return session_file.transaction(self._con)

    def point_ids(self, object_name: str) -> list[int]:
        """Point ids already recorded for ``object_name``, in recording order."""
        return [
            r[0] for r in self._con.execute("SELECT point_id FROM presses WHERE object = ? ORDER BY id", (object_name,))
        ]

    def presses(self, object_name: str | None = None) -> list[PressRecord]:
        """All stored presses (of one object when given), in recording order."""
        sensor = self.sensor
        query = (
            "SELECT id, run_id, object, point_id, imprint, raw, peak_sum, seq_peak, t_peak_us, host_time,"
            " frames_received, crc_errors, gaps, px, py, pz, ax, ay, az FROM presses"
        )
        args: tuple = ()
        if object_name is not None:
            query += " WHERE object = ?"
            args = (object_name,)
        out = []
        for r in self._con.execute(query + " ORDER BY id", args):
            position = None if r[13] is None else np.array(r[13:16], dtype=np.float64)
            approach = None if r[16] is None else np.array(r[16:19], dtype=np.float64)
            out.append(
                PressRecord(
                    id=r[0],
                    run_id=r[1],
                    object=r[2],
                    point_id=r[3],
                    imprint=np.frombuffer(r[4], np.float32).reshape(sensor).copy(),
                    raw=np.frombuffer(r[5], "<u2").reshape(sensor).astype(np.uint16),
                    peak_sum=r[6],
                    seq_peak=r[7],
                    t_peak_us=r[8],
                    host_time=r[9],
                    frames_received=r[10],
                    crc_errors=r[11],
                    gaps=r[12],
                    position=position,
                    approach=approach,
                )
            )
        return out


def resample(imprint: np.ndarray, rows: int = 16, cols: int = 16) -> np.ndarray:
    """Resample an imprint to ``rows`` x ``cols`` by area averaging (float32).

    Examples
    --------
    >>> resample(np.ones((32, 32), np.float32)).shape
    (16, 16)
    """
    import cv2

    imprint = np.asarray(imprint, dtype=np.float32)
    if imprint.shape == (rows, cols):
        return imprint
    return cv2.resize(imprint, (cols, rows), interpolation=cv2.INTER_AREA)


def export_imprints(path, rows: int = 16, cols: int = 16, full_scale="session", sensor=None):
    """Read a session as a ``tactile.ImprintSet``.

    Parameters
    ----------
    path : str or Path
        The session file.
    rows, cols : int
        Size of the exported imprints; other sensor sizes are resampled by
        area averaging.
    full_scale : "session", "imprint" or float
        What maps to 1: "session" divides every imprint by the largest
        baseline-subtracted reading of the whole session (the relative
        force between presses is kept); "imprint" divides each imprint by
        its own maximum (shape only, as when every press is pushed to the
        same depth); a number gives the count for 1 directly (the ADC
        maximum, e.g. 4095 for 12 bits).  Values are clipped to [0, 1].
    sensor : tactile.Sensor, optional
        Stored with the set; defaults to ``tactile.Sensor(rows=rows, cols=cols)``.

    Returns
    -------
    tactile.ImprintSet
        Labels index the sorted object names; positions and normals come
        from the probe plan (planning frame in mm, normal = -approach) and
        are NaN for unplanned presses.
    """
    import tactile

    path = Path(path)
    with Session(path, create=False) as session:
        records = session.presses()
    if not records:
        raise ValueError(f"{path}: the session holds no presses")
    imprints = np.stack([resample(r.imprint, rows, cols) for r in records])
    if full_scale == "session":
        scale = np.full(len(records), max(float(imprints.max()), 1e-12))
    elif full_scale == "imprint":
        scale = np.maximum(imprints.reshape(len(records), -1).max(axis=1), 1e-12)
    else:
        try:
            value = float(full_scale)
        except (TypeError, ValueError):
            raise ValueError(
                f"full_scale must be 'session', 'imprint' or a positive number, got {full_scale!r}"
            ) from None
        if not value > 0:
            raise ValueError(f"full_scale must be positive, got {value}")
        scale = np.full(len(records), value)
    imprints = np.clip(imprints / scale[:, None, None], 0.0, 1.0).astype(np.float32)
    names = tuple(sorted({r.object for r in records}))
    nan3 = np.full(3, np.nan)
    return tactile.ImprintSet(
        imprints=imprints,
        labels=np.array([names.index(r.object) for r in records], dtype=np.int64),
        object_names=names,
        point_ids=np.array([r.point_id for r in records], dtype=np.int64),
        positions=np.stack([nan3 if r.position is None else r.position for r in records]),
        normals=np.stack([nan3 if r.approach is None else -r.approach for r in records]),
        sensor=sensor if sensor is not None else tactile.Sensor(rows=rows, cols=cols),
        perturbation=None,
        seed=None,
        source=str(path),
    )
