"""Nearest-neighbour distances that do not depend on the CPU, the thread count or the block size.

Imprints on an ADC's grid (multiples of ``1 / LEVELS``) are compared through
their integer codes, where float64 sums are exact in any order; other rows
have their squared distances rounded to 1e-9.  Training rows are prepared
once (:class:`Rows`), queries are read a block at a time whose distances stay
under :data:`CELLS` values, and neighbours at equal distance are ranked by a
key, never by position (:func:`ranked`).  ``classify.recognizers.classifiers.KNN``
and ``classify.recognizers.shortlist.knn_shortlist`` share them.

Examples
--------
>>> A = np.array([[0.0, 0.0], [3 / 255, 4 / 255]])
>>> (sq_distances(A, A) * 255**2).round(6).tolist()
[[0.0, 25.0], [25.0, 0.0]]
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "LEVELS",
    "BLOCK",
    "CELLS",
    "block_rows",
    "on_grid",
    "Rows",
    "sq_distances",
    "distances_to",
    "ranked",
    "class_distances",
]

#: An 8-bit ADC's grid: imprints on it are multiples of ``1 / LEVELS``.
LEVELS = 255.0
#: Queries per block of distances.
BLOCK = 512
#: Distances a block of queries holds at most (128 MB of float64): past ``CELLS / BLOCK`` training rows a
#: block holds fewer queries, so memory does not grow with the training set.
CELLS = 1 << 24
#: Shortest run of columns, and fewest runs per neighbour, that :func:`ranked` screens by runs.
_MIN_RUN = 8


def block_rows(n: int) -> int:
    """Queries per block against ``n`` training rows: :data:`BLOCK`, fewer past ``CELLS / BLOCK`` rows.

    Examples
    --------
    >>> block_rows(1000), block_rows(200_000)
    (512, 83)
    """
    return max(1, min(BLOCK, CELLS // max(int(n), 1)))


def on_grid(X) -> bool:
    """Whether every value of ``X`` is a multiple of ``1 / LEVELS`` (to 1e-3 of a level)."""
    codes = X * LEVELS
    return bool(np.all(np.abs(codes - np.round(codes)) < 1e-3))


@dataclass(frozen=True, eq=False)
class Rows:
    """Training rows ready for distances: ``values`` the integer codes of rows on the ADC's grid (``exact``),
    else the rows as given; ``sq`` (n,) their squared norms.  Prepared once, read by every block of queries."""

    values: np.ndarray
    sq: np.ndarray
    exact: bool

    @staticmethod
    def of(B, exact: bool) -> Rows:
        values = np.round(B * LEVELS) if exact else B
        return Rows(values, np.einsum("ij,ij->i", values, values), exact)


def sq_distances(A, B, exact: bool | None = None) -> np.ndarray:
    """(len(A), len(B)) squared Euclidean distances, the same on every CPU (see ``classify.recognizers.classifiers.KNN``'s Notes).

    ``exact`` says whether both are on the ADC's grid (default: checked here).
    """
    if exact is None:
        exact = on_grid(A) and on_grid(B)
    return distances_to(A, Rows.of(B, exact))


def distances_to(A, rows: Rows) -> np.ndarray:
    """(len(A), len(rows.values)) squared distances from ``A`` to prepared rows (as :func:`sq_distances`)."""
    if rows.exact:
        A = np.round(A * LEVELS)
    out = np.empty((len(A), len(rows.values)))
    step = block_rows(len(rows.values))
    for start in range(0, len(A), step):
        a, d2 = A[start : start + step], out[start : start + step]
        # (|a|^2 + |b|^2) - 2 a.b, written into the output: one temporary block, the same sums in the same order.
        np.add(np.einsum("ij,ij->i", a, a)[:, None], rows.sq[None, :], out=d2)
        cross = a @ rows.values.T
        cross *= 2.0
        d2 -= cross
        np.maximum(d2, 0.0, out=d2)
    # Integer codes: every sum is an integer below 2**53, exact in any order.
    if rows.exact:
        out /= LEVELS**2
        return out
    return np.round(out, 9, out=out)


def ranked(d2, tiebreak, k: int) -> np.ndarray:
    """The ``k`` nearest training indices by increasing distance, equal distances in ``tiebreak`` order, (n, k).

    ``tiebreak`` is (m,), one key per column, or (n, m), each row's own.

    Only the candidates no farther than each row's k-th distance are sorted
    (all of them, ties at that distance included), so the result is the first
    ``k`` columns of the full sort.  Past a few hundred columns per neighbour,
    the columns are first dealt into runs: a row's k nearest lie in the runs
    whose nearest column is no farther than its k-th nearest run's (k runs
    hold k columns that near), so only those runs, and the few columns left
    over, are selected from (5 to 10 times faster at 10,000 to 54,000 columns).
    """
    d2 = np.asarray(d2)
    tiebreak = np.asarray(tiebreak)
    n, m = d2.shape
    k = min(int(k), m)
    out = np.empty((n, k), np.int64)
    # Runs of about sqrt(m / k) columns: as many runs' nearest columns to select from as the k runs hold.
    run = math.isqrt(m // max(k, 1))
    runs = m // max(run, 1)
    screen = run >= _MIN_RUN and runs >= _MIN_RUN * k
    step = block_rows(m)
    for start in range(0, n, step):
        d = d2[start : start + step]
        tb = np.broadcast_to(tiebreak, d.shape) if tiebreak.ndim == 1 else tiebreak[start : start + step]
        if not screen:
            out[start : start + step] = _first_k(d, tb, k)
            continue
        # Run j holds columns j, j + runs, j + 2 runs...: their minima are elementwise ones over rows of runs.
        lows = d[:, : runs * run].reshape(len(d), run, runs).min(axis=1)
        chosen, bound = _within_kth(lows, k)
        if not np.isfinite(bound).all():  # fewer than k runs within reach: nothing to screen by
            out[start : start + step] = _first_k(d, tb, k)
            continue
        cols = (np.sort(chosen, axis=1)[:, :, None] + runs * np.arange(run)).reshape(len(d), -1)
        cols = np.concatenate([cols, np.broadcast_to(np.arange(runs * run, m), (len(d), m - runs * run))], axis=1)
        picked = _first_k(np.take_along_axis(d, cols, axis=1), np.take_along_axis(tb, cols, axis=1), k)
        out[start : start + step] = np.take_along_axis(cols, picked, axis=1)
    return out


def _within_kth(d: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Columns of each row of ``d`` (b, m) holding its ``k`` least values and every value tied with its k-th, as
    many per row as the row with most ties needs (b, w); and the k-th least values (b, 1)."""
    m = d.shape[1]
    near = np.argpartition(d, k - 1, axis=1)
    kth = np.take_along_axis(d, near[:, k - 1 : k], axis=1)
    wide = int((d <= kth).sum(axis=1).max())
    if wide >= m:
        return np.broadcast_to(np.arange(m), d.shape), kth
    if wide > k:  # ties at the k-th value: take them all
        return np.argpartition(d, wide - 1, axis=1)[:, :wide], kth
    return near[:, :k], kth


def _first_k(d: np.ndarray, tb: np.ndarray, k: int) -> np.ndarray:
    """(b, k) columns of the first ``k`` of each row of ``d`` (b, m) sorted by distance, then ``tb`` (b, m)."""
    near, _ = _within_kth(d, k)
    rows = np.arange(len(d))[:, None]
    order = np.lexsort((tb[rows, near], d[rows, near]), axis=1)[:, :k]
    return near[rows, order]


def class_distances(d2, codes, n_classes) -> np.ndarray:
    """(n, n_classes) distance from each row to the nearest training sample of each class (inf: none).

    One pass over ``d2``: its columns are read by class, in blocks (``codes`` sorted, as a fitted KNN keeps them).
    """
    codes = np.asarray(codes)
    if np.any(codes[1:] < codes[:-1]):
        order = np.argsort(codes, kind="stable")
        d2, codes = d2[:, order], codes[order]
    out = np.full((len(d2), n_classes), np.inf)
    present, starts = np.unique(codes, return_index=True)
    if present.size:
        out[:, present] = np.minimum.reduceat(d2, starts, axis=1)
    return np.sqrt(out)
