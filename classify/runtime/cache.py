"""A content-keyed disk cache for the deterministic stages of the experiment.

Interest points and imprints depend only on the mesh, the settings and the
code that computes them, so each result is stored under a key hashing all
of it: the mesh's arrays (vertices, faces, colors, texture), the settings (as
canonical JSON), the source files of the packages that compute it and the
versions of the libraries they call and the kernels those run
(:func:`library_versions`).  Editing the mesh, a setting or that code,
upgrading a library or unpinning its kernels gives a new key; stale
entries are never read.  Entries are ``.npz`` files written atomically, so an
interrupted run leaves no half-written entry (only a temporary file, which is
never read); an entry that :func:`meshsal.util.npzfile.read_npz` refuses
(truncated, corrupt, foreign, or declaring arrays beyond its caps) is
recomputed and overwritten.

The default directory is ``$XDG_CACHE_HOME/visuotactile`` when that variable
is set, else ``.cache/visuotactile`` in the working directory.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from meshsal.util.atomic import atomic_path
from meshsal.util.npzfile import NpzError, read_npz

__all__ = [
    "default_dir",
    "hash_arrays",
    "hash_array_stream",
    "code_fingerprint",
    "file_fingerprint",
    "library_versions",
    "cache_key",
    "cached",
    "load",
    "store",
]

#: The distributions whose numbers reach a cached result.
LIBRARIES = ("numpy", "scipy", "scikit-learn", "opencv-contrib-python-headless", "embreex", "libigl", "pymeshlab")


def default_dir() -> Path:
    """``$XDG_CACHE_HOME/visuotactile`` if set, else ``./.cache/visuotactile``."""
    base = os.environ.get("XDG_CACHE_HOME")
    return Path(base) / "visuotactile" if base else Path(".cache") / "visuotactile"


def hash_arrays(*arrays) -> str:
    """SHA-256 over the dtype, shape and bytes of each array (None allowed).

    Examples
    --------
    >>> hash_arrays(np.zeros(3)) == hash_arrays(np.zeros(3))
    True
    >>> hash_arrays(np.zeros(3)) == hash_arrays(np.zeros(3, np.float32))
    False
    """
    return hash_array_stream(arrays)


def hash_array_stream(arrays) -> str:
    """:func:`hash_arrays` of the arrays an iterable yields, read one at a time: a generator that makes each
    array when asked never holds them all.

    Examples
    --------
    >>> hash_array_stream(np.full(2, k) for k in range(3)) == hash_arrays(*(np.full(2, k) for k in range(3)))
    True
    """
    h = hashlib.sha256()
    for a in arrays:
        if a is None:
            h.update(b"none;")
            continue
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape};".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def code_fingerprint(*packages: str) -> str:
    """SHA-256 over the ``.py`` sources of the named packages (sorted by path)."""
    import importlib

    h = hashlib.sha256()
    for name in packages:
        root = Path(importlib.import_module(name).__file__).parent
        for path in sorted(root.rglob("*.py")):
            h.update(str(path.relative_to(root)).encode())
            h.update(path.read_bytes())
    return h.hexdigest()


def file_fingerprint(*paths) -> str:
    """SHA-256 over the named files' bytes."""
    h = hashlib.sha256()
    for path in paths:
        h.update(Path(path).read_bytes())
    return h.hexdigest()


def library_versions() -> dict:
    """``{distribution: version}`` of :data:`LIBRARIES` ("absent" when not installed), and their ``kernels``.

    ``kernels`` says which kernels those libraries run in this process
    (:func:`meshsal.util.reproducible.kernels`): a result computed with
    unpinned kernels is never read back by a pinned run, nor one from
    another CPU by an unpinned run.

    Examples
    --------
    >>> sorted(library_versions()) == sorted(LIBRARIES + ("kernels",))
    True
    """
    from meshsal.util.reproducible import kernels

    return {**_installed_versions(), "kernels": kernels()}


@functools.cache
def _installed_versions() -> dict:
    # Read once per process: each metadata lookup scans sys.path (6 ms for the seven), and every cache key asks.
    from importlib import metadata

    versions = {}
    for name in LIBRARIES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "absent"
    return versions


def cache_key(kind: str, *parts) -> str:
    """A file-name-safe key: ``kind`` then a hash of the JSON-serializable ``parts``."""
    text = json.dumps(parts, sort_keys=True, default=repr)
    return f"{kind}-{hashlib.sha256(text.encode()).hexdigest()[:32]}"


def cached(directory, key: str, compute: Callable[[], dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Load the arrays stored under ``key``, or compute, store and return them.

    Parameters
    ----------
    directory : path or None
        Cache directory; None disables caching.
    key : str
        From :func:`cache_key`.
    compute : callable returning a dict of arrays

    Examples
    --------
    >>> import tempfile
    >>> d = tempfile.mkdtemp()
    >>> cached(d, "demo", lambda: {"x": np.arange(3)})["x"]
    array([0, 1, 2])
    >>> cached(d, "demo", lambda: {"x": np.zeros(3)})["x"]   # second call reads the entry
    array([0, 1, 2])
    """
    if directory is None:
        return compute()
    found = load(directory, key)
    if found is not None:
        return found
    arrays = compute()
    store(directory, key, arrays)
    return arrays


def load(directory, key: str) -> dict[str, np.ndarray] | None:
    """The arrays stored under ``key``, or None when absent, damaged or ``directory`` is None.

    Damaged means anything :func:`meshsal.util.npzfile.read_npz` refuses: a
    truncated or foreign file, a corrupt deflate stream or CRC, Python
    objects, or arrays declaring more than its caps (512 MiB in all, 256 MiB
    each; nothing is allocated first).  The caller then recomputes the entry
    and :func:`store` overwrites it.
    """
    if directory is None:
        return None
    path = Path(directory) / f"{key}.npz"
    try:
        return read_npz(path, "cache entry")
    except (NpzError, OSError):
        return None  # absent, damaged or unreadable: the caller recomputes and overwrites it


def store(directory, key: str, arrays: dict[str, np.ndarray]) -> None:
    """Write ``arrays`` under ``key`` atomically (nothing when ``directory`` is None)."""
    if directory is None:
        return
    path = Path(directory) / f"{key}.npz"
    with atomic_path(path) as tmp:
        np.savez(tmp, **arrays)
