"""Points and imprints for every mesh of a folder, one task per mesh, into a resumable store.

The store is a folder:

``store.json``
    ``{"format": "visuotactile.BatchStore", "version": 1, "settings": {...}}``:
    what every entry was computed with.  A store is only ever extended with
    the same settings.
``batch.lock``
    Held (``flock``) by the one batch writing to the store; it names that
    batch's process, host and start time (:func:`lock_store`).
``meshes/<name>.npz``
    One entry per mesh, ``<name>`` its path under the input folder without
    the suffix.  A NumPy archive (no pickles) holding a ``meta`` JSON string
    (``format`` "visuotactile.BatchEntry", ``version`` 1, the source file's
    absolute path, ``source_sha256``: the hash of the mesh as loaded from it
    (vertices, faces, vertex colours, texture coordinates and texture image,
    so an edited texture counts too), ``mesh_sha256``: the hash of the
    nominal mesh, the transform from the nominal frame back to the file, per method the best view set, the spacing and the views that
    voted for each point, and the time each stage took) and the arrays
    ``vertex_saliency`` and, per method, ``<method>/vertex_ids``,
    ``positions``, ``normals``, ``scores``, ``votes`` and ``imprints``
    (k, 16, 16).  Positions and normals are in the nominal frame: the mesh
    scaled to ``size_mm`` (principal-frame box diagonal), centroid at the
    origin, in millimetres.
``failures.jsonl``
    One JSON line per mesh the last run could not process: its name, file
    and error.
``repairs.jsonl``
    One JSON line per mesh the last run repaired as it loaded it: its name,
    file and what was repaired (the loader's ``MeshRepairWarning``, which a
    worker on another machine would only have printed in its own log).

:func:`load_entry` reads one entry back as ``meshsal.InterestPoints`` and
``tactile.ImprintSet`` per method; :func:`load_store` reads them all.

Each mesh is a pure function of its file's content and the settings, and is
written atomically (temporary file, fsync, rename, fsync of the folder), so
a run killed at any point leaves whole entries only.  A rerun loads every
mesh again (in its task) and skips it when its entry was computed from the
same mesh; a mesh whose file changed is computed again, and a mesh that
fails loses its old entry, so every entry matches its file as it is now.
(Entries of meshes no longer in the folder are left alone.)  Tasks carry
absolute paths, so workers read and write the same files wherever they run,
provided the folder and the store are on a filesystem every worker sees at
the same path; an entry a task reports written that the client cannot read
counts as a failure.

Over 500 lines because the store's format, its lock and the run that fills
it are one contract: a change to one is checked against the others here.
"""

from __future__ import annotations

import json
import os
import time
import traceback
import warnings
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = [
    "FORMAT",
    "ENTRY_FORMAT",
    "VERSION",
    "SUFFIXES",
    "LOCK",
    "BatchSettings",
    "MeshEntry",
    "BatchSummary",
    "StoreInUseError",
    "find_meshes",
    "source_hash",
    "process_mesh",
    "lock_store",
    "run_batch",
    "load_entry",
    "load_store",
]

FORMAT = "visuotactile.BatchStore"
ENTRY_FORMAT = "visuotactile.BatchEntry"
VERSION = 1
SUFFIXES = (".obj", ".ply", ".off", ".stl")
STAGES = ("load", "mesh_saliency", "points", "imprints", "write")
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
        if not self.size_mm > 0 or self.view_size < 16:
            raise ValueError(
                f"size_mm must be positive and view_size at least 16, got {self.size_mm}, {self.view_size}"
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


@dataclass(frozen=True)
class BatchSummary:
    """What a run did: meshes done now (``redone`` of them because their file changed), skipped as already
    stored from the same mesh, failed; wall time; stage medians (s); meshes repaired as they loaded."""

    done: int
    skipped: int
    failed: int
    wall_s: float
    stage_median_s: dict
    redone: int = 0
    repaired: int = 0

    def markdown(self) -> str:
        rate = self.done / self.wall_s if self.wall_s > 0 else 0.0
        lines = [
            "| meshes done | skipped (stored, unchanged) | failed | redone (file changed) | wall | meshes/s |",
            "|---:|---:|---:|---:|---:|---:|",
            f"| {self.done} | {self.skipped} | {self.failed} | {self.redone} | {self.wall_s:.1f} s | {rate:.2f} |",
        ]
        if self.stage_median_s:
            lines += ["", "| stage | median per mesh |", "|---|---:|"]
            lines += [f"| {k} | {v * 1000:.1f} ms |" for k, v in self.stage_median_s.items()]
        return "\n".join(lines)


def find_meshes(directory) -> list[tuple[str, Path]]:
    """``(name, path)`` of every mesh file under ``directory``, sorted by name.

    The name is the path under ``directory`` without its suffix (``a/b`` for
    ``a/b.obj``); two files differing only by suffix are refused.
    """
    root = Path(directory)
    if not root.is_dir():
        raise ValueError(f"{root}: not a folder of meshes")
    found = {}
    for path in sorted(root.rglob("*")):
        if path.is_file() and path.suffix.lower() in SUFFIXES and not path.name.startswith("."):
            name = path.relative_to(root).with_suffix("").as_posix()
            if name in found:
                raise ValueError(f"{root}: {found[name].name} and {path.name} would share the entry {name!r}")
            found[name] = path
    return sorted(found.items())


class StoreInUseError(OSError):
    """Another batch holds the store; the message names the store and the holder."""


def _entry_path(store: Path, name: str) -> Path:
    return store / "meshes" / f"{name}.npz"


def source_hash(mesh) -> str:
    """SHA-256 of a mesh as loaded from its file: vertices, faces, vertex colours, texture coordinates, texture.

    Every input of an entry but the settings: a mesh whose hash is unchanged
    gives the same entry.
    """
    from classify.runtime.cache import hash_arrays

    return hash_arrays(mesh.vertices, mesh.faces, mesh.vertex_colors, mesh.uv, mesh.texture)


def _entry_meta(path: Path) -> dict:
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


def process_mesh(path, name: str, store, settings: BatchSettings) -> dict:
    """Write one mesh's entry unless the store holds one computed from the same mesh.

    Returns ``{"name", "status", "error", "timings", "source_sha256", "redone", "repairs"}``;
    ``repairs`` says what the loader repaired ("" for nothing), which the
    loader's warning would have said only on the worker's own stderr.
    ``status`` is ``"skipped"`` (the stored entry has this mesh's
    :func:`source_hash` and these settings), ``"done"`` (written now;
    ``redone`` when it replaced the entry of another version of the file) or
    ``"failed"`` (``error`` says why).  A failed mesh loses its old entry,
    which its file no longer gives.  A failure never raises, so one broken
    mesh cannot stop a batch.
    """
    from threadpoolctl import threadpool_limits

    from meshsal.mesh.io import MeshRepairWarning, load_mesh

    timings = {}
    path, store = Path(path), Path(store)
    target = _entry_path(store, name)
    result = {
        "name": name,
        "status": "done",
        "error": "",
        "timings": timings,
        "source_sha256": "",
        "redone": False,
        "repairs": "",
    }
    try:
        with threadpool_limits(1):
            t = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", MeshRepairWarning)
                source, found = load_mesh(path, report=True)
            if found.noteworthy:
                result["repairs"] = found.message()
            timings["load"] = time.perf_counter() - t
            result["source_sha256"] = digest = source_hash(source)
            try:
                old = _entry_meta(target)
            except FileNotFoundError:
                old = None
            except ValueError:
                old = {}
            if old and old.get("source_sha256") == digest and old.get("settings") == settings.to_json():
                return {**result, "status": "skipped"}
            result["redone"] = old is not None
            _compute(source, path, name, store, settings, timings, digest)
        return result
    except Exception as exc:  # noqa: BLE001 - a broken mesh is recorded, whatever broke it
        last = traceback.extract_tb(exc.__traceback__)[-1] if exc.__traceback__ else None
        where = f" ({Path(last.filename).name}:{last.lineno})" if last else ""
        error = f"{type(exc).__name__}: {exc}{where}"
        if target.exists():
            target.unlink(missing_ok=True)
            error += "; its entry from an earlier run was removed"
        return {**result, "status": "failed", "error": error}


def _compute(source, path: Path, name: str, store: Path, settings: BatchSettings, timings: dict, digest: str) -> None:
    import tactile
    from classify.experiment.samples import method_points
    from classify.runtime.cache import hash_arrays
    from meshsal.mesh.curvature import mesh_saliency
    from meshsal.mesh.embree import embree_scene
    from meshsal.mesh.transform import scale_to_principal
    from meshsal.points import PointOptions
    from meshsal.util.atomic import atomic_path

    t = time.perf_counter()
    mesh = scale_to_principal(source, settings.size_mm)
    timings["load"] += time.perf_counter() - t
    t = time.perf_counter()
    saliency = mesh_saliency(mesh)
    timings["mesh_saliency"] = time.perf_counter() - t
    arrays = {"vertex_saliency": saliency}
    methods = {}
    timings["imprints"] = 0.0
    scene = embree_scene(mesh)
    sensor = tactile.Sensor()
    t = time.perf_counter()
    options = PointOptions(
        n=settings.n_points, seed=settings.seed, size=settings.view_size, threads=1, pad_width=sensor.width_mm
    )
    picked = method_points(mesh, settings.methods, options, vertex_saliency=saliency)
    timings["points"] = time.perf_counter() - t
    for method in settings.methods:
        pts = picked[method]
        t = time.perf_counter()
        images = tactile.imprints(mesh, pts.positions, pts.normals, sensor, workers=1, scene=scene)
        timings["imprints"] += time.perf_counter() - t
        point_arrays, methods[method] = pts.to_arrays()
        arrays.update({f"{method}/{key}": value for key, value in point_arrays.items()})
        arrays[f"{method}/imprints"] = np.asarray(images, np.float32)
    t = time.perf_counter()
    frame = mesh.transform
    meta = {
        "format": ENTRY_FORMAT,
        "version": VERSION,
        "name": name,
        "source": str(path),
        "source_sha256": digest,
        "mesh_sha256": hash_arrays(mesh.vertices, mesh.faces),
        "settings": settings.to_json(),
        "to_source": {
            "scale": frame.scale,
            "offset": frame.offset.tolist(),
            "rotation": frame.rotation.tolist(),
            "meaning": "nominal = scale * rotation @ source + offset",
        },
        "methods": methods,
        "timings_s": timings,
    }
    target = _entry_path(store, name)
    with atomic_path(target) as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, meta=np.array(json.dumps(meta)), **arrays)
    timings["write"] = time.perf_counter() - t


def _task(args):
    return process_mesh(*args)


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


def _open_store(store: Path, settings: BatchSettings) -> None:
    from meshsal.util.atomic import write_text

    header = store / "store.json"
    wanted = {"format": FORMAT, "version": VERSION, "settings": settings.to_json()}
    if header.exists():
        from meshsal.util.jsonfile import read_json

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


def _check_entry(store: Path, result: dict) -> dict:
    """A task's result once the client has read the entry it reports; a failure when it cannot."""
    if result["status"] == "failed":
        return result
    path = _entry_path(store, result["name"])
    try:
        meta = _entry_meta(path)
    except FileNotFoundError:
        problem = (
            f"{path}: the task reported the entry {'written' if result['status'] == 'done' else 'stored'} "
            f"but it is not there; the workers must write to the client's store (a filesystem every "
            f"worker mounts at the same path)"
        )
        return {**result, "status": "failed", "error": problem}
    except ValueError as exc:
        problem = f"{exc}, after the task reported it {'written' if result['status'] == 'done' else 'stored'}"
    else:
        if meta.get("source_sha256") == result["source_sha256"]:
            return result
        problem = f"{path}: holds another version of the mesh than its task computed"
    path.unlink(missing_ok=True)  # no entry rather than one its file does not give
    return {**result, "status": "failed", "error": problem + "; the entry was removed"}


def run_batch(
    directory, store, settings: BatchSettings | None = None, executor=None, quiet: bool = False
) -> BatchSummary:
    """Write the entry of every mesh under ``directory`` that ``store`` does not hold for the same mesh.

    Parameters
    ----------
    directory : folder searched recursively for .obj, .ply, .off, .stl
    store : folder of the store (created if needed); one batch at a time (:func:`lock_store`)
    settings : BatchSettings
    executor : optional
        Anything with an ordered ``map`` (``classify.runtime.cluster.open_executor``);
        None runs in this process.
    quiet : no progress bar on stderr

    Returns
    -------
    BatchSummary

    Raises
    ------
    StoreInUseError
        Another batch is writing to ``store``.
    """
    from classify.runtime.cluster import Inline
    from meshsal.util.atomic import write_text
    from meshsal.util.progress import progress

    settings = BatchSettings() if settings is None else settings
    store = Path(store).resolve()
    meshes = find_meshes(Path(directory).resolve())
    with lock_store(store):
        _open_store(store, settings)
        started = time.perf_counter()
        executor = Inline() if executor is None else executor
        tasks = [(str(path), name, str(store), settings) for name, path in meshes]
        results = [
            _check_entry(store, r)
            for r in progress(executor.map(_task, tasks), total=len(tasks), desc="batch", quiet=quiet, unit="meshes")
        ]
        wall = time.perf_counter() - started
        failed = [r for r in results if r["status"] == "failed"]
        repaired = [r for r in results if r["repairs"]]
        sources = {name: str(path) for name, path in meshes}
        for file, rows, key in (("failures.jsonl", failed, "error"), ("repairs.jsonl", repaired, "repairs")):
            write_text(
                store / file,
                "".join(
                    json.dumps({"name": r["name"], "source": sources[r["name"]], key: r[key]}) + "\n" for r in rows
                ),
            )
        for stale in (store / "meshes").rglob(".*.npz"):
            stale.unlink(missing_ok=True)  # left by a worker killed while writing; its mesh was redone
    done = [r for r in results if r["status"] == "done"]
    skipped = sum(r["status"] == "skipped" for r in results)
    medians = {
        k: float(np.median([r["timings"][k] for r in done]))
        for k in STAGES
        if done and all(k in r["timings"] for r in done)
    }
    return BatchSummary(
        len(done), skipped, len(failed), wall, medians, redone=sum(r["redone"] for r in done), repaired=len(repaired)
    )


def load_entry(store, name: str) -> MeshEntry:
    """One mesh's points and imprints per method, from a store written by :func:`run_batch`.

    A damaged, truncated or foreign entry, or one declaring arrays beyond
    the caps of :func:`meshsal.util.npzfile.read_npz`, raises a ValueError
    naming its file.
    """
    import tactile
    from meshsal.mesh import Similarity
    from meshsal.points import InterestPoints
    from meshsal.util.jsonfile import parse_json
    from meshsal.util.npzfile import read_npz

    path = _entry_path(Path(store), name)
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
