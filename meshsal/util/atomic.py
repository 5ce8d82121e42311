"""Write files so that a reader never sees a half-written one."""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    The temporary name keeps ``path``'s suffix, so writers that choose the
    format by extension (``cv2.imwrite``, ``np.savez``) still work.  On an
    exception the temporary file is removed and ``path`` is left untouched.
    The file is flushed to disk before the rename and the directory after
    it, so a power loss leaves the old file or the new one, never an empty
    one under the final name.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> target = pathlib.Path(tempfile.mkdtemp()) / "a.txt"
    >>> with atomic_path(target) as tmp:
    ...     _ = tmp.write_text("hello")
    >>> target.read_text()
    'hello'
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    tmp = Path(tmp)
    try:
        yield tmp
        # mkstemp creates the file private (0600); results are for sharing.
        os.chmod(tmp, 0o644)
        _fsync(tmp, os.O_RDONLY)
        os.replace(tmp, path)
        _fsync(path.parent, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    finally:
        if tmp.exists():
            tmp.unlink()


def check_writable(path, folder: bool) -> Path:
    """Refuse, before any work, an output that cannot be written: ``path`` itself, or on its way, a file where a
    folder goes (or a folder where the file goes), or a folder that is not writable.  Nothing is created.

    Parameters
    ----------
    path : path of the output
    folder : bool, whether the output is a folder (else a file, in its parent folder)

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        Naming ``path`` and what is in the way.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> root = pathlib.Path(tempfile.mkdtemp())
    >>> _ = (root / "notes.txt").write_text("")
    >>> check_writable(root / "new" / "results", folder=True) == root / "new" / "results"
    True
    >>> check_writable(root / "notes.txt" / "results", folder=True)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: .../notes.txt/results: cannot be written: .../notes.txt is a file, not a folder
    """
    path = Path(path)
    if path.exists():
        if path.is_dir() != folder:
            raise ValueError(f"{path}: exists and is {'a file, not a folder' if folder else 'a folder, not a file'}")
        target = path if folder else path.parent
    else:
        target = next(above for above in path.parents if above.exists())
        if not target.is_dir():
            raise ValueError(f"{path}: cannot be written: {target} is a file, not a folder")
    if not os.access(target, os.W_OK | os.X_OK):
        raise ValueError(f"{path}: cannot be written: the folder {target} is not writable")
    return path


def _fsync(path, flags) -> None:
    fd = os.open(path, flags)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_text(path, text: str) -> None:
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def write_png(path, image) -> None:
    """Write an (H,W) or (H,W,3) uint8 RGB image as PNG, atomically."""
    import cv2
    import numpy as np

    image = np.asarray(image)
    if image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
    with atomic_path(path) as tmp:
        if not cv2.imwrite(str(tmp), image):
            raise OSError(f"{path}: could not write PNG")
