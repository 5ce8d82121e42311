"""OpenCV's thread pool, capped for a block and restored after it."""

from __future__ import annotations

from contextlib import contextmanager

__all__ = ["opencv_threads"]


@contextmanager
def opencv_threads(n: int):
    """OpenCV's own pool at ``n`` threads for the block; the count before it comes back after.

    The pool is process-wide: the cap holds for the process's other threads too.

    Examples
    --------
    >>> import cv2
    >>> before = cv2.getNumThreads()
    >>> with opencv_threads(1):
    ...     cv2.getNumThreads()
    1
    >>> cv2.getNumThreads() == before
    True
    """
    import cv2

    before = cv2.getNumThreads()
    cv2.setNumThreads(int(n))
    try:
        yield
    finally:
        cv2.setNumThreads(before)
