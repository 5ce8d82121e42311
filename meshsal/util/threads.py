"""Process-wide thread settings for a block, restored after it: OpenCV's pool, Python's switch interval."""

from __future__ import annotations

from contextlib import contextmanager

__all__ = ["opencv_threads", "switch_interval"]


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

    with _held(cv2.getNumThreads, cv2.setNumThreads, int(n)):
        yield


@contextmanager
def switch_interval(seconds: float):
    """Python's thread switch interval (``sys.setswitchinterval``) at ``seconds`` for the block; the interval
    before it comes back after.

    Threads that hand Python's lock back and forth between many short calls
    into C (OpenCV, NumPy) wait less for it at a short interval; the work
    and its results are the same.

    Examples
    --------
    >>> import sys
    >>> before = sys.getswitchinterval()
    >>> with switch_interval(0.0005):
    ...     sys.getswitchinterval()
    0.0005
    >>> sys.getswitchinterval() == before
    True
    """
    import sys

    with _held(sys.getswitchinterval, sys.setswitchinterval, float(seconds)):
        yield


@contextmanager
def _held(get, put, value):
    """``put(value)`` for the block, then ``put`` of what ``get()`` gave before it, whatever the block raised."""
    before = get()
    put(value)
    try:
        yield
    finally:
        put(before)
