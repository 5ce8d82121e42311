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
    nominal mesh, the transform from the nominal frame back to the file, per
    method the best view set, the spacing and the views that voted for each
    point, and the time each stage took) and the arrays ``vertex_saliency``
    and, per method, ``<method>/vertex_ids``, ``positions``, ``normals``,
    ``scores``, ``votes`` and ``imprints`` (k, 16, 16).  Positions and
    normals are in the nominal frame: the mesh scaled to ``size_mm``
    (principal-frame box diagonal), centroid at the origin, in millimetres.
``failures.jsonl``
    One JSON line per mesh the last run could not process: its name, file
    and error.
``repairs.jsonl``
    One JSON line per mesh the last run repaired as it loaded it: its name,
    file and what was repaired (the loader's ``MeshRepairWarning``, which a
    worker on another machine would only have printed in its own log).
``duplicates.jsonl``
    One JSON line per mesh of the last run that is the same mesh as another
    of the folder (the same :func:`source_hash`, as byte-identical files
    have): its name and file, and the name and file of the mesh stored for
    both.  Such a mesh has no entry: two classes no touch can tell apart
    are one object.

:func:`load_entry` reads one entry back as ``meshsal.InterestPoints`` and
``tactile.ImprintSet`` per method; :func:`load_store` reads them all.

A run (:func:`run_batch`) first loads every mesh once, in tasks of a few
meshes (:func:`read_meshes`): meshes that cannot be read are listed before
any work and stop the run, the store untouched, unless it is asked to skip
them (``skip_bad``, ``--skip-bad``); meshes identical as loaded are one
object, stored under the first name in sorted order.  Then each mesh to
store is one task, a pure function of its file's content and the settings,
written atomically (temporary file, fsync, rename, fsync of the folder), so
a run killed at any point leaves whole entries only.  A task loads its mesh
again and skips it when its entry was computed from the same mesh; a mesh
whose file changed is computed again, and a mesh that fails, or stops
loading, loses its old entry, so every entry matches its file as it is now.
(Entries of meshes no longer in the folder are left alone.)  Tasks carry
absolute paths, so workers read and write the same files wherever they run,
provided the folder and the store are on a filesystem every worker sees at
the same path; an entry a task reports written that the client cannot read
counts as a failure.  Every task runs on one thread (BLAS, OpenMP and
OpenCV's pool), so N workers on N cores do not fight over them.

``store`` holds the format, the lock and the readers; ``run`` the run.
"""

from classify.batch.run import (
    READ_CHUNK,
    STAGES,
    BadMeshesError,
    BatchSummary,
    find_meshes,
    process_mesh,
    read_meshes,
    run_batch,
    source_hash,
)
from classify.batch.store import (
    ENTRY_FORMAT,
    FORMAT,
    LOCK,
    VERSION,
    BatchSettings,
    MeshEntry,
    StoreInUseError,
    load_entry,
    load_store,
    lock_store,
)

__all__ = [
    "FORMAT",
    "ENTRY_FORMAT",
    "VERSION",
    "STAGES",
    "READ_CHUNK",
    "LOCK",
    "BatchSettings",
    "MeshEntry",
    "BatchSummary",
    "BadMeshesError",
    "StoreInUseError",
    "find_meshes",
    "source_hash",
    "read_meshes",
    "process_mesh",
    "lock_store",
    "run_batch",
    "load_entry",
    "load_store",
]
