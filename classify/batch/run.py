"""A batch run: read every mesh of a folder, then compute the entries the store lacks, one task per mesh."""

from __future__ import annotations

import time
import traceback
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from classify.batch.store import (
    BatchSettings,
    entry_meta,
    entry_path,
    lock_store,
    open_store,
    write_entry,
    write_records,
)

__all__ = [
    "STAGES",
    "BatchSummary",
    "BadMeshesError",
    "find_meshes",
    "source_hash",
    "read_meshes",
    "process_mesh",
    "run_batch",
]

STAGES = ("load", "mesh_saliency", "points", "imprints", "write")
#: Meshes one reading task loads: enough that a task's own cost (a few ms) is small beside theirs.
READ_CHUNK = 16


@dataclass(frozen=True)
class BatchSummary:
    """What a run did.

    Meshes done now (``redone`` of them because their file changed), skipped
    as already stored from the same mesh, failed (unreadable ones skipped with
    ``skip_bad`` among them), left out as ``duplicates`` of another mesh of
    the folder, repaired as they loaded; wall time, the CPU time of every task
    (s, summed over the workers) and the stage medians (s).
    """

    done: int
    skipped: int
    failed: int
    wall_s: float
    stage_median_s: dict
    redone: int = 0
    repaired: int = 0
    duplicates: int = 0
    cpu_s: float = 0.0

    def markdown(self) -> str:
        rate = self.done / self.wall_s if self.wall_s > 0 else 0.0
        lines = [
            "| meshes done | skipped (stored, unchanged) | failed | redone (file changed) | duplicates "
            "| wall | CPU of the tasks | meshes/s |",
            "|---:|---:|---:|---:|---:|---:|---:|---:|",
            f"| {self.done} | {self.skipped} | {self.failed} | {self.redone} | {self.duplicates} "
            f"| {self.wall_s:.1f} s | {self.cpu_s:.1f} s | {rate:.2f} |",
        ]
        if self.stage_median_s:
            lines += ["", "| stage | median per mesh |", "|---|---:|"]
            lines += [f"| {k} | {v * 1000:.1f} ms |" for k, v in self.stage_median_s.items()]
        return "\n".join(lines)


class BadMeshesError(ValueError):
    """Meshes of the folder that cannot be read, found before any work; ``bad`` holds their reading records."""

    def __init__(self, root: Path, bad: list, total: int):
        self.bad = bad
        # The loader's errors name their file; others get it in front.
        lines = "".join(
            f"\n  {row['error']}" if row["source"] in row["error"] else f"\n  {row['source']}: {row['error']}"
            for row in bad
        )
        super().__init__(
            f"{root}: {len(bad)} of {total} meshes cannot be read, so nothing was computed; repair or remove "
            f"them, or skip them (--skip-bad) to run on the other {total - len(bad)}:{lines}"
        )


def find_meshes(directory) -> list[tuple[str, Path]]:
    """``(name, path)`` of every mesh file under ``directory``, sorted by name.

    The name is the path under ``directory`` without its suffix (``a/b`` for
    ``a/b.obj``); two files differing only by suffix are refused, and so is
    a folder that holds no mesh file (a mistyped path, most likely).
    """
    root = Path(directory)
    if not root.is_dir():
        raise ValueError(f"{root}: not a folder of meshes")
    from meshsal.mesh.io import SUPPORTED_EXTENSIONS, mesh_files

    files = mesh_files(root)
    if not files:
        raise ValueError(f"{root}: no mesh file ({', '.join(SUPPORTED_EXTENSIONS)}) under this folder")
    found = {}
    for path in files:
        name = path.relative_to(root).with_suffix("").as_posix()
        if name in found:
            raise ValueError(f"{root}: {found[name].name} and {path.name} would share the entry {name!r}")
        found[name] = path
    return sorted(found.items())


def source_hash(mesh) -> str:
    """SHA-256 of a mesh as loaded from its file: vertices, faces, vertex colours, texture coordinates, texture.

    Every input of an entry but the settings: a mesh whose hash is unchanged
    gives the same entry.
    """
    from classify.runtime.cache import hash_arrays

    return hash_arrays(mesh.vertices, mesh.faces, mesh.vertex_colors, mesh.uv, mesh.texture)


def _load(path: Path):
    """The mesh as loaded (repairs reported, not printed) and the loader's report."""
    from meshsal.mesh.io import MeshRepairWarning, load_mesh

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MeshRepairWarning)
        return load_mesh(path, report=True)


def _describe(exc: Exception) -> str:
    """An exception as a failure record says it: its type, message and the line of ours it came from."""
    last = traceback.extract_tb(exc.__traceback__)[-1] if exc.__traceback__ else None
    where = f" ({Path(last.filename).name}:{last.lineno})" if last else ""
    return f"{type(exc).__name__}: {exc}{where}"


def _read_task(items) -> list[dict]:
    """``{"name", "source", "source_sha256", "error", "cpu_s"}`` of each ``(name, path)``: loaded, or why not."""
    from classify.runtime.cluster import one_thread

    rows = []
    with one_thread():
        for name, path in items:
            cpu = time.process_time()
            row = {"name": name, "source": str(path), "source_sha256": "", "error": ""}
            try:
                row["source_sha256"] = source_hash(_load(Path(path))[0])
            except Exception as exc:  # noqa: BLE001 - an unreadable mesh is listed, whatever broke it
                row["error"] = _describe(exc)
            rows.append({**row, "cpu_s": time.process_time() - cpu})
    return rows


def read_meshes(meshes, executor=None, quiet: bool = True) -> list[dict]:
    """Load every ``(name, path)`` of :func:`find_meshes` once, in tasks of :data:`READ_CHUNK` meshes.

    Returns
    -------
    list of dict, in the order of ``meshes``
        ``name``, ``source`` (the path), ``source_sha256`` (:func:`source_hash`;
        "" when unreadable), ``error`` ("" when it loads: else why not) and
        ``cpu_s`` (the CPU time its reading took).
    """
    from classify.runtime.cluster import Inline
    from meshsal.util.progress import progress

    executor = Inline() if executor is None else executor
    items = [(name, str(path)) for name, path in meshes]
    chunks = [items[i : i + READ_CHUNK] for i in range(0, len(items), READ_CHUNK)]
    rows = (row for rows in executor.map(_read_task, chunks) for row in rows)
    return list(progress(rows, total=len(items), desc="reading", quiet=quiet, unit="meshes"))


def process_mesh(path, name: str, store, settings: BatchSettings) -> dict:
    """Write one mesh's entry unless the store holds one computed from the same mesh.

    Runs with one BLAS, OpenMP and OpenCV thread (``classify.runtime.cluster.one_thread``).

    Returns ``{"name", "status", "error", "timings", "source_sha256", "redone", "repairs", "cpu_s"}``;
    ``repairs`` says what the loader repaired ("" for nothing), which the
    loader's warning would have said only on the worker's own stderr, and
    ``cpu_s`` the CPU time of the task's process while it ran.
    ``status`` is ``"skipped"`` (the stored entry has this mesh's
    :func:`source_hash` and these settings), ``"done"`` (written now;
    ``redone`` when it replaced the entry of another version of the file) or
    ``"failed"`` (``error`` says why).  A failed mesh loses its old entry,
    which its file no longer gives.  A failure never raises, so one broken
    mesh cannot stop a batch.
    """
    from classify.runtime.cluster import one_thread

    cpu = time.process_time()
    timings = {}
    path, store = Path(path), Path(store)
    target = entry_path(store, name)
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
        with one_thread():
            t = time.perf_counter()
            source, found = _load(path)
            if found.noteworthy:
                result["repairs"] = found.message()
            timings["load"] = time.perf_counter() - t
            result["source_sha256"] = digest = source_hash(source)
            try:
                old = entry_meta(target)
            except FileNotFoundError:
                old = None
            except ValueError:
                old = {}
            if old and old.get("source_sha256") == digest and old.get("settings") == settings.to_json():
                result["status"] = "skipped"
            else:
                result["redone"] = old is not None
                _compute(source, path, name, store, settings, timings, digest)
    except Exception as exc:  # noqa: BLE001 - a broken mesh is recorded, whatever broke it
        error = _describe(exc)
        if target.exists():
            target.unlink(missing_ok=True)
            error += "; its entry from an earlier run was removed"
        result.update(status="failed", error=error)
    return {**result, "cpu_s": time.process_time() - cpu}


def _compute(source, path: Path, name: str, store: Path, settings: BatchSettings, timings: dict, digest: str) -> None:
    import tactile
    from classify.runtime.cache import hash_arrays
    from meshsal.mesh.transform import scale_to_principal
    from meshsal.points import PointOptions, Workpiece, method_points

    t = time.perf_counter()
    mesh = scale_to_principal(source, settings.size_mm)
    timings["load"] += time.perf_counter() - t
    piece = Workpiece(mesh, settings.view_size, threads=1)
    t = time.perf_counter()
    arrays = {"vertex_saliency": piece.vertex_saliency}
    timings["mesh_saliency"] = time.perf_counter() - t
    sensor = tactile.Sensor()
    t = time.perf_counter()
    options = PointOptions(
        n=settings.n_points, seed=settings.seed, size=settings.view_size, threads=1, pad_width=sensor.width_mm
    )
    picked = method_points(piece, settings.methods, options)
    timings["points"] = time.perf_counter() - t
    t = time.perf_counter()
    # Every method's pads in one cast: a pad's imprint does not depend on the others.
    P = np.concatenate([picked[m].positions for m in settings.methods]).reshape(-1, 3)
    N = np.concatenate([picked[m].normals for m in settings.methods]).reshape(-1, 3)
    images = np.split(
        np.asarray(tactile.imprints(mesh, P, N, sensor, workers=1, scene=piece.scene), np.float32),
        np.cumsum([len(picked[m]) for m in settings.methods])[:-1],
    )
    timings["imprints"] = time.perf_counter() - t
    methods = {}
    for method, imprints in zip(settings.methods, images):
        point_arrays, methods[method] = picked[method].to_arrays()
        arrays.update({f"{method}/{key}": value for key, value in point_arrays.items()})
        arrays[f"{method}/imprints"] = imprints
    t = time.perf_counter()
    frame = mesh.transform
    meta = {
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
    write_entry(store, name, meta, arrays)
    timings["write"] = time.perf_counter() - t


def _task(args):
    return process_mesh(*args)


def _check_entry(store: Path, result: dict) -> dict:
    """A task's result once the client has read the entry it reports; a failure when it cannot."""
    if result["status"] == "failed":
        return result
    path = entry_path(store, result["name"])
    said = "written" if result["status"] == "done" else "stored"
    try:
        meta = entry_meta(path)
    except FileNotFoundError:
        problem = (
            f"{path}: the task reported the entry {said} but it is not there; the workers must write to the "
            f"client's store (a filesystem every worker mounts at the same path)"
        )
        return {**result, "status": "failed", "error": problem}
    except ValueError as exc:
        problem = f"{exc}, after the task reported it {said}"
    else:
        if meta.get("source_sha256") == result["source_sha256"]:
            return result
        problem = f"{path}: holds another version of the mesh than its task computed"
    path.unlink(missing_ok=True)  # no entry rather than one its file does not give
    return {**result, "status": "failed", "error": problem + "; the entry was removed"}


def _same_meshes(read: list[dict]) -> dict:
    """``{name: name of the first mesh with the same source hash}`` for every readable mesh after the first."""
    first, same = {}, {}
    for row in read:
        if not row["error"]:
            kept = first.setdefault(row["source_sha256"], row["name"])
            if kept != row["name"]:
                same[row["name"]] = kept
    return same


def run_batch(
    directory, store, settings: BatchSettings | None = None, executor=None, quiet: bool = False, skip_bad: bool = False
) -> BatchSummary:
    """Write the entry of every mesh under ``directory`` that ``store`` does not hold for the same mesh.

    First every mesh is loaded once (:func:`read_meshes`, on the executor):
    unreadable ones stop the run before any work, and the store is left as
    it was, unless ``skip_bad``; meshes identical as loaded (byte-identical
    files among them) are one object, stored under the first name.

    Parameters
    ----------
    directory : folder searched recursively for .obj, .ply, .off, .stl
    store : folder of the store (created if needed); one batch at a time (:func:`lock_store`)
    settings : BatchSettings
    executor : optional
        Anything with an ordered ``map`` (``classify.runtime.cluster.open_executor``);
        None runs in this process.
    quiet : no progress bar on stderr
    skip_bad : run on the readable meshes when some are not; the others go to ``failures.jsonl``

    Returns
    -------
    BatchSummary

    Raises
    ------
    BadMeshesError
        Some meshes cannot be read and ``skip_bad`` is false; the message lists them.
    StoreInUseError
        Another batch is writing to ``store``.
    """
    from classify.runtime.cluster import Inline
    from meshsal.util.atomic import check_writable
    from meshsal.util.progress import progress

    settings = BatchSettings() if settings is None else settings
    store = check_writable(store, folder=True).resolve()
    root = Path(directory).resolve()
    meshes = find_meshes(root)
    executor = Inline() if executor is None else executor
    started = time.perf_counter()
    read = read_meshes(meshes, executor, quiet)
    bad = [row for row in read if row["error"]]
    if bad and not skip_bad:
        raise BadMeshesError(root, bad, len(meshes))
    same = _same_meshes(read)
    sources = {name: str(path) for name, path in meshes}
    left_out = {row["name"] for row in bad} | same.keys()
    with lock_store(store):
        open_store(store, settings)
        tasks = [(str(path), name, str(store), settings) for name, path in meshes if name not in left_out]
        results = [
            _check_entry(store, r)
            for r in progress(executor.map(_task, tasks), total=len(tasks), desc="batch", quiet=quiet, unit="meshes")
        ]
        failed = []
        for row in bad:
            error, old = row["error"], entry_path(store, row["name"])
            if old.exists():
                old.unlink()
                error += "; its entry from an earlier run was removed"
            failed.append({"name": row["name"], "error": error})
        failed += [r for r in results if r["status"] == "failed"]
        for name in same:
            entry_path(store, name).unlink(missing_ok=True)  # one entry per object, under its first name
        repaired = [r for r in results if r["repairs"]]
        write_records(
            store,
            "failures.jsonl",
            ({"name": r["name"], "source": sources[r["name"]], "error": r["error"]} for r in failed),
        )
        write_records(
            store,
            "repairs.jsonl",
            ({"name": r["name"], "source": sources[r["name"]], "repairs": r["repairs"]} for r in repaired),
        )
        write_records(
            store,
            "duplicates.jsonl",
            (
                {"name": n, "source": sources[n], "same_as": kept, "same_as_source": sources[kept]}
                for n, kept in same.items()
            ),
        )
        for stale in (store / "meshes").rglob(".*.npz"):
            stale.unlink(missing_ok=True)  # left by a worker killed while writing; its mesh was redone
    wall = time.perf_counter() - started
    done = [r for r in results if r["status"] == "done"]
    medians = {
        k: float(np.median([r["timings"][k] for r in done]))
        for k in STAGES
        if done and all(k in r["timings"] for r in done)
    }
    return BatchSummary(
        done=len(done),
        skipped=sum(r["status"] == "skipped" for r in results),
        failed=len(failed),
        wall_s=wall,
        stage_median_s=medians,
        redone=sum(r["redone"] for r in done),
        repaired=len(repaired),
        duplicates=len(same),
        cpu_s=sum(r["cpu_s"] for r in read) + sum(r["cpu_s"] for r in results),
    )
