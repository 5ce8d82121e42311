"""The SQLite file under a capture session: its schema, its creation and migration, its transactions.

:func:`connect` opens a session file, creating it or migrating it to
:data:`SCHEMA_VERSION` where needed, in write-ahead-log mode with full sync.
It reads before it writes, so a foreign or read-only file is never written,
and creates or migrates inside one ``BEGIN IMMEDIATE`` (:func:`transaction`),
looking again there: several processes opening the same new file together
get one schema.  SQLite's write-ahead log needs shared memory and working
file locks, which network filesystems may not give: a file the log cannot be
switched on for is refused (keep sessions on a local disk).
"""

from __future__ import annotations

import sqlite3
import time
from pathlib import Path

__all__ = ["FORMAT", "SCHEMA_VERSION", "connect", "transaction", "meta"]

FORMAT = "visuotactile-capture-session"
# 2: a UNIQUE (object, point_id) index; version 1 files, with a plain index, are migrated on opening.
SCHEMA_VERSION = 2
# How long an opening waits for another process to release the file.
BUSY_SECONDS = 10.0

SCHEMA = """
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE runs (
    id INTEGER PRIMARY KEY,
    started REAL NOT NULL,
    port TEXT NOT NULL,
    baud INTEGER NOT NULL,
    protocol TEXT NOT NULL,
    object TEXT NOT NULL,
    baseline BLOB NOT NULL,
    baseline_noise REAL NOT NULL,
    threshold_on REAL NOT NULL,
    threshold_off REAL NOT NULL
);
CREATE TABLE presses (
    id INTEGER PRIMARY KEY,
    run_id INTEGER NOT NULL REFERENCES runs(id),
    object TEXT NOT NULL,
    point_id INTEGER NOT NULL,
    imprint BLOB NOT NULL,
    raw BLOB NOT NULL,
    peak_sum REAL NOT NULL,
    seq_start INTEGER NOT NULL, seq_peak INTEGER NOT NULL, seq_end INTEGER NOT NULL,
    t_start_us INTEGER NOT NULL, t_peak_us INTEGER NOT NULL, t_end_us INTEGER NOT NULL,
    frames INTEGER NOT NULL,
    host_time REAL NOT NULL,
    frames_received INTEGER NOT NULL,
    crc_errors INTEGER NOT NULL,
    gaps INTEGER NOT NULL,
    bytes_skipped INTEGER NOT NULL,
    px REAL, py REAL, pz REAL,
    ax REAL, ay REAL, az REAL
);
CREATE UNIQUE INDEX presses_point ON presses(object, point_id);
"""


def connect(path: Path, create: bool = True) -> sqlite3.Connection:
    """An open connection to the session file ``path``, created or migrated as needed.

    Parameters
    ----------
    path : Path
        The ``.sqlite`` file; its folder is made when the file is created.
    create : bool
        Create the file when it does not exist; otherwise a missing file is
        a ``FileNotFoundError``.

    Returns
    -------
    sqlite3.Connection
        In autocommit mode (``isolation_level=None``): writes go through
        :func:`transaction`.

    Raises
    ------
    OSError
        The file cannot be opened now (locked, read-only, I/O) or cannot keep
        a write-ahead log.
    ValueError
        The file is not a capture session, is of another version, or is a
        version 1 session whose presses share a point id (named).

    Examples
    --------
    >>> import tempfile
    >>> con = connect(Path(tempfile.mkdtemp()) / "s.sqlite")
    >>> meta(con)["version"], con.execute("PRAGMA journal_mode").fetchone()[0]
    ('2', 'wal')
    >>> con.close()
    """
    path = Path(path)
    if not path.exists():
        if not create:
            raise FileNotFoundError(f"{path}: no such capture session")
        path.parent.mkdir(parents=True, exist_ok=True)
    try:
        con = sqlite3.connect(path, isolation_level=None, timeout=BUSY_SECONDS)
    except sqlite3.Error as exc:
        raise OSError(f"{path}: cannot open the session ({exc})") from None
    try:
        _prepare(con, path)
    except BaseException as exc:
        con.close()
        if isinstance(exc, sqlite3.OperationalError):  # locked, read-only, I/O: unusable now
            raise OSError(f"{path}: cannot open the session ({exc})") from None
        if isinstance(exc, sqlite3.DatabaseError):
            raise ValueError(f"{path}: not a capture session ({exc})") from None
        raise
    return con


def meta(con: sqlite3.Connection) -> dict[str, str]:
    """The session's ``meta`` table: format, version, creation time, sensor size."""
    return dict(con.execute("SELECT key, value FROM meta"))


def transaction(con: sqlite3.Connection) -> Transaction:
    """``with transaction(con):`` runs the block in one ``BEGIN IMMEDIATE`` ... ``COMMIT``."""
    return Transaction(con)


class Transaction:
    """``BEGIN IMMEDIATE`` ... ``COMMIT``, rolled back on an exception."""

    def __init__(self, con: sqlite3.Connection):
        self._con = con

    def __enter__(self):
        self._con.execute("BEGIN IMMEDIATE")

    def __exit__(self, exc_type, *rest):
        self._con.execute("ROLLBACK" if exc_type else "COMMIT")


def _prepare(con: sqlite3.Connection, path: Path) -> None:
    """Create or migrate the schema where needed, check it, and switch to the log with full sync."""
    # Read first, so a foreign or read-only file is never written; create or migrate inside one
    # BEGIN IMMEDIATE, looking again there: another process may have done it meanwhile.
    if not _tables(con) or meta(con).get("version") == "1":
        with transaction(con):
            if not _tables(con):
                for statement in SCHEMA.split(";"):
                    if statement.strip():
                        con.execute(statement)
                con.executemany(
                    "INSERT INTO meta VALUES (?, ?)",
                    [("format", FORMAT), ("version", str(SCHEMA_VERSION)), ("created", repr(time.time()))],
                )
            elif meta(con).get("format") == FORMAT and meta(con).get("version") == "1":
                _migrate_from_1(con, path)
    found = meta(con)
    if found.get("format") != FORMAT:
        raise sqlite3.DatabaseError("it holds no visuotactile capture session")
    if found.get("version") != str(SCHEMA_VERSION):
        raise sqlite3.DatabaseError(f"session version {found.get('version')} is not the supported {SCHEMA_VERSION}")
    mode = _write_ahead_log(con)
    if mode.lower() != "wal":
        raise OSError(
            f"{path}: SQLite cannot keep a write-ahead log here (journal mode stays {mode!r}): "
            f"the filesystem lacks the shared memory or file locks it needs, as network "
            f"filesystems may; keep the session on a local disk"
        )
    # FULL: a press is on disk before the next one starts.
    con.execute("PRAGMA synchronous=FULL")


def _write_ahead_log(con: sqlite3.Connection) -> str:
    """``PRAGMA journal_mode=WAL``, the mode it leaves; asked again while the file is locked.

    Switching a new file to the log needs it alone, and SQLite answers "locked" at once, without
    the busy wait, while another process opens it beside this one (4 times in 240 openings of 4
    processes on 2 busy cores).
    """
    deadline = time.monotonic() + BUSY_SECONDS
    while True:
        try:
            return con.execute("PRAGMA journal_mode=WAL").fetchone()[0]
        except sqlite3.OperationalError as exc:
            if "locked" not in str(exc) or time.monotonic() > deadline:
                raise
        time.sleep(0.01)


def _tables(con: sqlite3.Connection) -> set[str]:
    tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")}
    if tables and "meta" not in tables:
        raise sqlite3.DatabaseError("it holds no visuotactile capture session")
    return tables


def _migrate_from_1(con: sqlite3.Connection, path: Path) -> None:
    """Version 1 to 2, inside the caller's transaction: the UNIQUE (object, point_id) index."""
    shared = con.execute(
        "SELECT object, point_id, group_concat(id, ', ') FROM presses"
        " GROUP BY object, point_id HAVING count(*) > 1 ORDER BY min(id)"
    ).fetchall()
    if shared:
        listed = "; ".join(f"{obj!r} point {pid} (presses {ids})" for obj, pid, ids in shared[:10])
        more = f" and {len(shared) - 10} more" if len(shared) > 10 else ""
        raise ValueError(
            f"{path}: presses share a point id: {listed}{more}.  A version 1 session "
            f"cannot take the index that keeps point ids unique until each (object, point) "
            f"has one press: delete the extra presses or give them free point ids (sqlite3 "
            f'{path} "UPDATE presses SET point_id = ... WHERE id = ..."), then open it '
            f"again"
        )
    con.execute("DROP INDEX IF EXISTS presses_object")
    con.execute("CREATE UNIQUE INDEX presses_point ON presses(object, point_id)")
    con.execute("UPDATE meta SET value = ? WHERE key = 'version'", (str(SCHEMA_VERSION),))
