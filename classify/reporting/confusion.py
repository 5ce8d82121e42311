"""Confusion counts kept by their non-zero cells, so that they grow with the touches recognized, not the objects squared.

A 1,000-object experiment's confusion matrix has a million cells, almost
all of them zero: in ``results.json`` each took a line (13 MB a matrix),
and each replicate's job carried one per method.  Here a confusion is its
*pairs*: a (k, 3) int64 array of rows ``(true, predicted, count)``, count
above zero, sorted by true then predicted class.  At most one row per
touch recognized, whatever the number of classes.

Examples
--------
>>> pairs = confusion_pairs([0, 0, 1, 2, 2], [0, 1, 1, 2, 1])
>>> pairs.tolist()
[[0, 0, 1], [0, 1, 1], [1, 1, 1], [2, 1, 1], [2, 2, 1]]
>>> dense_counts(pairs, 3).tolist()
[[1, 1, 0], [0, 1, 0], [0, 1, 1]]
>>> top_pairs(pairs, ["a", "b", "c"], k=1)
[('a', 'b', 1, 0.5)]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "ConfusionMatrix",
    "confusion_pairs",
    "counts_pairs",
    "summed_pairs",
    "reordered_pairs",
    "dense_counts",
    "top_pairs",
]

_EMPTY = np.zeros((0, 3), np.int64)


def _checked(pairs) -> np.ndarray:
    pairs = np.asarray(pairs, dtype=np.int64)
    if pairs.size == 0:
        return _EMPTY.copy()
    if pairs.ndim != 2 or pairs.shape[1] != 3:
        raise ValueError(f"confusion pairs must be a (k, 3) array of (true, predicted, count), got shape {pairs.shape}")
    if (pairs[:, :2] < 0).any() or (pairs[:, 2] < 0).any():
        raise ValueError("confusion pairs must hold non-negative classes and counts")
    return pairs


def _grouped(true, predicted, weights) -> np.ndarray:
    """The pairs of these (true, predicted) cells, each cell's weights summed; cells of zero weight dropped."""
    if true.size == 0:
        return _EMPTY.copy()
    width = int(predicted.max()) + 1
    cells, where = np.unique(true * width + predicted, return_inverse=True)
    counts = np.bincount(where.ravel(), weights=weights, minlength=len(cells)).astype(np.int64)
    keep = counts > 0
    return np.column_stack([cells[keep] // width, cells[keep] % width, counts[keep]])


def confusion_pairs(truth, guess) -> np.ndarray:
    """The pairs of single-touch decisions: how often each true class was recognized as each class.

    Parameters
    ----------
    truth, guess : (t,) int
        Each touch's true class and the class it was recognized as (non-negative).

    Returns
    -------
    (k, 3) int64
        ``(true, predicted, count)``, sorted; empty when nothing was recognized.
    """
    truth, guess = np.asarray(truth, np.int64).ravel(), np.asarray(guess, np.int64).ravel()
    if truth.shape != guess.shape:
        raise ValueError(f"truth and guess differ in length: {truth.size} and {guess.size}")
    if truth.size and (truth.min() < 0 or guess.min() < 0):
        raise ValueError("classes must be non-negative (a touch not recognized has no pair)")
    return _grouped(truth, guess, np.ones(truth.size))


def counts_pairs(counts) -> np.ndarray:
    """The pairs of a dense (n, n) count matrix (rows true class), its zero cells left out."""
    counts = np.asarray(counts)
    if counts.ndim != 2 or counts.shape[0] != counts.shape[1]:
        raise ValueError(f"a confusion matrix must be square, got shape {counts.shape}")
    i, j = np.nonzero(counts)
    return _checked(np.column_stack([i, j, counts[i, j]]))


def summed_pairs(many) -> np.ndarray:
    """The pairs of the sum of several confusions (each given by its pairs)."""
    many = [_checked(p) for p in many]
    every = np.concatenate([_EMPTY, *many])
    return _grouped(every[:, 0], every[:, 1], every[:, 2].astype(np.float64))


def reordered_pairs(pairs, back) -> np.ndarray:
    """The pairs of ``counts[np.ix_(back, back)]``: class ``back[i]`` becomes class ``i``.

    Parameters
    ----------
    pairs : (k, 3) int
    back : (n,) int, a permutation of the classes
    """
    pairs, back = _checked(pairs), np.asarray(back, np.int64)
    if sorted(back.tolist()) != list(range(len(back))):
        raise ValueError("back must be a permutation of 0..n-1")
    new = np.empty_like(back)
    new[back] = np.arange(len(back))
    if pairs.size and pairs[:, :2].max() >= len(back):
        raise ValueError(f"confusion pairs name a class beyond the {len(back)} reordered")
    moved = np.column_stack([new[pairs[:, 0]], new[pairs[:, 1]], pairs[:, 2]])
    return moved[np.lexsort((moved[:, 1], moved[:, 0]))]


def dense_counts(pairs, n: int) -> np.ndarray:
    """(n, n) int64 counts of the pairs, rows true class (for drawing a few classes; n squared cells)."""
    pairs = _checked(pairs)
    if pairs.size and pairs[:, :2].max() >= n:
        raise ValueError(f"confusion pairs name a class beyond the {n} given")
    counts = np.zeros((n, n), np.int64)
    np.add.at(counts, (pairs[:, 0], pairs[:, 1]), pairs[:, 2])
    return counts


def top_pairs(pairs, names, k: int = 20) -> list[tuple[str, str, int, float]]:
    """The ``k`` largest confusions: (true, predicted, count, share of the true class's touches).

    Ties go to the lower true class, then the lower predicted class.
    """
    pairs = _checked(pairs)
    pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
    totals = np.bincount(pairs[:, 0], weights=pairs[:, 2], minlength=len(names))
    off = pairs[pairs[:, 0] != pairs[:, 1]]
    largest = off[np.argsort(-off[:, 2], kind="stable")[:k]]
    return [(names[t], names[p], int(c), float(c / totals[t])) for t, p, c in largest.tolist()]


@dataclass(frozen=True)
class ConfusionMatrix:
    """Single-touch counts summed over all folds and replicates, kept by their non-zero cells.

    ``pairs`` (k, 3) int64: rows ``(true, predicted, count)`` indexing
    ``object_names`` (:func:`confusion_pairs`); :attr:`counts` gives the
    dense matrix, rows true object, columns predicted.
    """

    method: str
    protocol: str
    classifier: str
    n_objects: int
    selection: bool
    object_names: tuple
    pairs: np.ndarray

    @property
    def counts(self) -> np.ndarray:
        """(n, n) int64, rows true object, columns predicted (n squared cells: for a few objects)."""
        return dense_counts(self.pairs, len(self.object_names))

    def top(self, k: int = 20) -> list[tuple[str, str, int, float]]:
        """The ``k`` largest confusions (:func:`top_pairs`)."""
        return top_pairs(self.pairs, list(self.object_names), k)
