"""The batch store on disk: its header, its lock, its entries and the records of a run (format: :mod:`classify.batch`)."""

from __future__ import annotations

import json
import os
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = [
    "FORMAT",
    "ENTRY_FORMAT",
    "VERSION",
    "LOCK",
    "BatchSettings",
    "MeshEntry",
    "StoreInUseError",
    "entry_path",
    "entry_meta",
    "write_entry",
    "open_store",
    "write_records",
    "lock_store",
    "load_entry",
    "load_store",
]

FORMAT = "visuotactile.BatchStore"
ENTRY_FORMAT = "visuotactile.BatchEntry"
VERSION = 1
LOCK = "batch.lock"


@dataclass(frozen=True)
class BatchSettings:
    """What every entry of a store is computed with."""

    methods: tuple = ("attention", "uniform")
    n_points: int = 15
    size_mm: float = 150.0
    view_size: int = 128
    seed: int = 0

    def __post_init__(self):
        from meshsal.points import MODEL_METHODS, POINT_METHODS

        methods = POINT_METHODS.check(self.methods)
        needs_model = [m for m in methods if m in MODEL_METHODS]
        if needs_model:
            raise ValueError(
                f"{', '.join(needs_model)}: a learned method needs a touch model fitted on training "
                f"instances ('visuotactile experiment'), which a batch of single meshes has not"
            )
        if int(self.n_points) != self.n_points or self.n_points < 1:
            raise ValueError(f"n_points must be a positive integer, got {self.n_points!r}")
        if int(self.seed) != self.seed or self.seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {self.seed!r}")
        from meshsal.points.rules import MIN_VIEW_SIZE

        if not self.size_mm > 0 or self.view_size < MIN_VIEW_SIZE:
            raise ValueError(
                f"size_mm must be positive and view_size at least {MIN_VIEW_SIZE}, got {self.size_mm}, {self.view_size}"
            )
        object.__setattr__(self, "methods", methods)

    def to_json(self) -> dict:
        return {
            "methods": list(self.methods),
            "n_points": int(self.n_points),
            "size_mm": float(self.size_mm),
            "view_size": int(self.view_size),
            "seed": int(self.seed),
        }


@dataclass(frozen=True, eq=False)
class MeshEntry:
    """One mesh of a store: its points and imprints per method, in the nominal frame (mm)."""

    name: str
    source: str
    points: dict
    imprints: dict
    transform: object
    timings: dict = field(default_factory=dict)


class StoreInUseError(OSError):
    """Another batch holds the store; the message names the store and the holder."""


def entry_path(store: Path, name: str) -> Path:
    """Where the entry of mesh ``name`` lives in ``store``."""
    return Path(store) / "meshes" / f"{name}.npz"


def entry_meta(path: Path) -> dict:
    """The ``meta`` of an entry; FileNotFoundError when absent, ValueError naming the file when unreadable.

    Read within the caps of :func:`meshsal.util.npzfile.read_npz`.
    """
    from meshsal.util.jsonfile import parse_json
    from meshsal.util.npzfile import read_npz

    arrays = read_npz(path, "batch entry")
    if "meta" not in arrays:
        raise ValueError(f"{path}: not a batch entry (no 'meta' array)")
    meta = parse_json(str(arrays["meta"]), path, "batch entry")
    if not isinstance(meta, dict) or meta.get("format") != ENTRY_FORMAT or meta.get("version") != VERSION:
        raise ValueError(f"{path}: not a version {VERSION} batch entry")
    return meta


def write_entry(store: Path, name: str, meta: dict, arrays: dict) -> None:
    """Write one entry atomically: a reader, or a run killed meanwhile, sees the old file or the new one."""
    from meshsal.util.atomic import atomic_path

    meta = {"format": ENTRY_FORMAT, "version": VERSION, **meta}
    with atomic_path(entry_path(store, name)) as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, meta=np.array(json.dumps(meta)), **arrays)


def open_store(store: Path, settings: BatchSettings) -> None:
    """Write the header of a new store; refuse a store computed with other settings."""
    from meshsal.util.atomic import write_text
    from meshsal.util.jsonfile import read_json

    header = store / "store.json"
    wanted = {"format": FORMAT, "version": VERSION, "settings": settings.to_json()}
    if header.exists():
        have = read_json(header, "batch store header")
        if not isinstance(have, dict):
            raise ValueError(f"{header}: not a batch store header (not a JSON object)")
        if have.get("format") != FORMAT or have.get("settings") != wanted["settings"]:
            raise ValueError(
                f"{store}: this store holds other settings ({have.get('settings')}); "
                f"write to another --out or use the same settings"
            )
        return
    write_text(header, json.dumps(wanted, indent=2) + "\n")


def write_records(store: Path, file: str, rows) -> None:
    """``STORE/file`` as JSON lines, one per row, atomically (an empty file for no rows)."""
    from meshsal.util.atomic import write_text

    write_text(store / file, "".join(json.dumps(row) + "\n" for row in rows))


@contextmanager
def lock_store(store):
    """Hold ``store`` for one batch: while held, another :func:`lock_store` on it fails at once.

    An exclusive ``flock`` on ``STORE/batch.lock``.  The kernel drops it when
    the holding process ends, however it ends, so a killed run never leaves
    the store locked.  The file names the holder (process id, host, start
    time) for the error.  ``flock`` is advisory and binds every process on a
    local filesystem; on NFS, Linux turns it into an NFS byte-range lock (NFS
    v4, or v3 with a lock daemon), which other machines see too.  Some
    network filesystems (SMB and FUSE mounts such as sshfs, NFS mounted with
    ``nolock``) grant it locally only or to everyone: there two batches from
    different machines are not kept apart.

    Raises
    ------
    StoreInUseError
        Another batch holds the store.
    OSError
        The filesystem refuses file locks.
    """
    import fcntl
    import socket

    store = Path(store)
    store.mkdir(parents=True, exist_ok=True)
    path = store / LOCK
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise StoreInUseError(
                f"{store}: in use by another batch ({_holder(fd)}); wait for it to end or write to another --out"
            ) from None
        except OSError as exc:
            raise OSError(
                f"{path}: cannot lock the store ({exc.strerror}); put the store on a filesystem with file locks"
            ) from None
        holder = {"pid": os.getpid(), "host": socket.gethostname(), "started": time.strftime("%Y-%m-%d %H:%M:%S %z")}
        os.ftruncate(fd, 0)
        os.pwrite(fd, (json.dumps(holder) + "\n").encode(), 0)
        yield
    finally:
        os.close(fd)


def _holder(fd: int) -> str:
    """Who holds a store's lock, as its lock file says."""
    try:
        info = json.loads(os.pread(fd, 4096, 0))
        return f"process {int(info['pid'])} on {info['host']}, since {info['started']}"
    except (ValueError, TypeError, KeyError, OSError):
        return "holder unknown: it is starting"


def load_entry(store, name: str) -> MeshEntry:
    """One mesh's points and imprints per method, from a store written by :func:`classify.batch.run_batch`.

    A damaged, truncated or foreign entry, or one declaring arrays beyond
    the caps of :func:`meshsal.util.npzfile.read_npz`, raises a ValueError
    naming its file.
    """
    import tactile
    from meshsal.mesh import Similarity
    from meshsal.points import InterestPoints
    from meshsal.util.jsonfile import parse_json
    from meshsal.util.npzfile import read_npz

    path = entry_path(Path(store), name)
    try:
        arrays = read_npz(path, "batch entry")
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: no such entry in the store") from None
    if "meta" not in arrays:
        raise ValueError(f"{path}: not a batch entry (no 'meta' array)")
    meta = parse_json(str(arrays.pop("meta")), path, "batch entry")
    if not isinstance(meta, dict) or meta.get("format") != ENTRY_FORMAT or meta.get("version") != VERSION:
        found = meta if isinstance(meta, dict) else {}
        raise ValueError(
            f"{path}: not a version {VERSION} batch entry (format {found.get('format')!r}, "
            f"version {found.get('version')!r})"
        )
    try:
        source, frame = str(meta["source"]), meta["to_source"]
        transform = Similarity(frame["scale"], frame["offset"], frame["rotation"])
        points, imprints = {}, {}
        for method, info in meta["methods"].items():
            mine = {key.split("/", 1)[1]: value for key, value in arrays.items() if key.startswith(f"{method}/")}
            points[method] = InterestPoints.from_arrays(mine, info, arrays["vertex_saliency"], method)
            k = len(mine["positions"])
            imprints[method] = tactile.ImprintSet(
                imprints=mine["imprints"],
                labels=np.zeros(k, np.int64),
                object_names=(name,),
                point_ids=np.arange(k),
                positions=mine["positions"],
                normals=mine["normals"],
                sensor=tactile.Sensor(),
                source=f"{source} ({method} points)",
            )
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise ValueError(f"{path}: damaged batch entry ({type(exc).__name__}: {exc})") from None
    return MeshEntry(name, source, points, imprints, transform, meta.get("timings_s", {}))


def load_store(store) -> dict:
    """Every entry of a store, ``{name: MeshEntry}``, sorted by name."""
    root = Path(store) / "meshes"
    if not (Path(store) / "store.json").exists():
        raise ValueError(f"{store}: not a batch store (no store.json)")
    names = sorted(
        p.relative_to(root).with_suffix("").as_posix() for p in root.rglob("*.npz") if not p.name.startswith(".")
    )
    return {name: load_entry(store, name) for name in names}
