"""Stratified folds of whole groups: scikit-learn's assignment, in memory linear in the groups.

:class:`StratifiedGroupKFold` places each group (an instance's point, its
re-touches) in the fold that keeps the class proportions most even.
scikit-learn holds a dense groups x classes table of counts and scores each
group against every class, one candidate fold at a time in Python: a third
of the recognition time on the demo, and at 1,000 objects (200,000 groups)
gigabytes of memory and time that grows with the square of the objects.
:class:`GroupFolds` keeps each group's counts of its own classes only and
rescores only those classes' columns; the mean over the classes of each
candidate fold is the kept pairwise sum of the others with the group's
column changed (a few dozen additions, not C).  Every spread, sum and mean
is the one scikit-learn computes, in the same order, so the folds are the
same, split for split (``tests/test_folds.py`` checks it against
scikit-learn's, up to 1,000 classes).
"""

from __future__ import annotations

import math
import warnings

import numpy as np
from sklearn.model_selection import StratifiedGroupKFold
from sklearn.utils import check_random_state
from sklearn.utils.multiclass import type_of_target

__all__ = ["GroupFolds"]

# np.isclose's defaults, which scikit-learn's tie rule uses.
_RTOL, _ATOL = 1e-5, 1e-8
# Values of the dense groups x classes table the spread of the groups is computed on at once.
_CELLS = 1 << 22
# NumPy's pairwise summation: the longest run it sums with 8 accumulators (PW_BLOCKSIZE).
_BLOCK = 128


class GroupFolds(StratifiedGroupKFold):
    """:class:`sklearn.model_selection.StratifiedGroupKFold`, the same splits, faster and without the dense table.

    Parameters
    ----------
    n_splits, shuffle, random_state : as in scikit-learn's class

    Examples
    --------
    >>> y = np.repeat([0, 1], 6); groups = np.repeat(np.arange(6), 2)
    >>> [sorted(test.tolist()) for _, test in GroupFolds(3, shuffle=True, random_state=0).split(y, y, groups)]
    [[0, 1, 10, 11], [4, 5, 6, 7], [2, 3, 8, 9]]
    """

    def _iter_test_indices(self, X, y, groups):
        y = np.asarray(y)
        kind = type_of_target(y)
        if kind not in ("binary", "multiclass"):
            raise ValueError(f"Supported target types are: ('binary', 'multiclass'). Got {kind!r} instead.")
        _, y_inv, y_cnt = np.unique(y.ravel(), return_inverse=True, return_counts=True)
        k = self.n_splits
        if np.all(k > y_cnt):
            raise ValueError(f"n_splits={k} cannot be greater than the number of members in each class.")
        if k > y_cnt.min():
            warnings.warn(
                f"The least populated class in y has only {y_cnt.min()} members, which is less than n_splits={k}.",
                UserWarning,
                stacklevel=3,
            )
        C = len(y_cnt)
        _, groups_inv, groups_cnt = np.unique(groups, return_inverse=True, return_counts=True)
        groups_inv = groups_inv.ravel()
        G = len(groups_cnt)
        if k > G:
            raise ValueError(f"Cannot have number of splits n_splits={k} greater than the number of groups: {G}.")
        if self.shuffle:
            # scikit-learn's draw: a shuffled order of the groups.
            perm = np.arange(G)
            check_random_state(self.random_state).shuffle(perm)
            inv = np.empty_like(perm)
            inv[perm] = np.arange(G)
            groups_inv = inv[groups_inv]
        # Each group's classes and counts, group by group: (group, class) pairs sorted.
        pairs, counts = np.unique(groups_inv.astype(np.int64) * C + y_inv, return_counts=True)
        owner, cls = np.divmod(pairs, C)
        start = np.searchsorted(owner, np.arange(G + 1))
        counts = counts.astype(np.float64)
        # The spread of each group's row of the dense table, rows a block at a time.
        spread = np.empty(G)
        step = max(1, _CELLS // C)
        for a in range(0, G, step):
            b = min(a + step, G)
            dense = np.zeros((b - a, C))
            lo, hi = start[a], start[b]
            dense[owner[lo:hi] - a, cls[lo:hi]] = counts[lo:hi]
            spread[a:b] = np.std(dense, axis=1)
        per_fold = np.zeros((k, C))
        # Each class's spread over the folds, as scikit-learn's table has it for a fold the group leaves alone.
        base = np.zeros(C)
        mean = _ChangedMean(base)
        fold_of = np.empty(G, np.int64)
        sizes = [0.0] * k
        diagonal = np.arange(k)
        for g in np.argsort(-spread, kind="stable").tolist():
            lo, hi = start[g], start[g + 1]
            if hi - lo == 1:
                # One class, as an instance's point is: scikit-learn's arithmetic on Python floats.
                c, n = int(cls[lo]), float(counts[lo])
                spreads = _fold_spreads(per_fold[:, c].tolist(), n, float(y_cnt[c]))
                best = _best_fold([mean.with_value(c, v) for v in spreads], sizes)
                per_fold[best, c] += n
                sizes[best] += n
                chosen = {c: spreads[best]}
            else:
                c, n = cls[lo:hi], counts[lo:hi]
                # Contiguous columns: numpy then sums each spread over the folds in the order it takes in the
                # k x k x C table, first to last.
                trial = np.repeat(np.ascontiguousarray(per_fold[:, c])[None], k, axis=0)
                trial[diagonal, diagonal] += n
                spreads = np.std(trial / y_cnt[c], axis=1)
                scores = np.tile(base, (k, 1))
                scores[:, c] = spreads
                best = _best_fold(np.mean(scores, axis=1).tolist(), sizes)
                per_fold[best, c] += n
                sizes[best] += float(n.sum())
                chosen = dict(zip(c.tolist(), spreads[best].tolist()))
            fold_of[g] = best
            # The group's fold now holds what that fold's trial held.
            for column, value in chosen.items():
                base[column] = value
                mean.set(column, value)
        row_fold = fold_of[groups_inv]
        for i in range(k):
            yield np.flatnonzero(row_fold == i)


def _fold_spreads(column: list, n: float, total: float) -> list:
    """``np.std`` over the folds of one class's counts (its ``column``, one per fold) with ``n`` more in each fold
    in turn, divided by the class's ``total``: the k spreads, as NumPy computes them on the k x k table (sums
    first to last, each operation rounded as its own), as Python floats."""
    k = len(column)
    out = []
    for i in range(k):
        x = [(v + n if f == i else v) / total for f, v in enumerate(column)]
        s = x[0]
        for v in x[1:]:
            s += v
        mean = s / k
        d = [v - mean for v in x]
        ss = d[0] * d[0]
        for v in d[1:]:
            ss += v * v
        out.append(math.sqrt(ss / k))
    return out


class _Block:
    """A run of at most 128 values that NumPy sums with 8 interleaved accumulators (fewer than 8: in turn)."""

    __slots__ = ("lo", "stop", "body", "accumulators", "sum")

    def __init__(self, lo: int, n: int):
        self.lo, self.stop = lo, lo + n
        # The values the accumulators take; the rest, the tail, is added after them.
        self.body = lo + n - n % 8 if n >= 8 else lo


class _Halves:
    """A run NumPy sums as two halves, the first a multiple of 8 long."""

    __slots__ = ("split", "left", "right", "sum")

    def __init__(self, split: int, left, right):
        self.split, self.left, self.right = split, left, right


class _ChangedMean:
    """``np.mean`` of a float64 row with one value changed (:meth:`with_value`), bit for bit, without a copy.

    NumPy sums a contiguous row pairwise: halves (their lengths multiples
    of 8) down to blocks of at most 128, summed with 8 interleaved
    accumulators, then their tail.  The sums of that tree are kept, so a
    changed value costs its block's accumulator and the sums above it: a
    few dozen additions for a row of thousands.
    """

    def __init__(self, row: np.ndarray):
        self.values = np.asarray(row, np.float64).tolist()
        self.root = self._build(0, len(self.values))

    def _build(self, lo: int, n: int):
        if n > _BLOCK:
            half = n // 2
            half -= half % 8
            node = _Halves(lo + half, self._build(lo, half), self._build(lo + half, n - half))
            node.sum = node.left.sum + node.right.sum
            return node
        node = _Block(lo, n)
        node.accumulators = [self._chain(node, q, None, 0.0) for q in range(8)] if node.body > lo else None
        node.sum = self._block_sum(node, node.accumulators, None, 0.0)
        return node

    def _chain(self, block: _Block, q: int, j, v) -> float:
        """Accumulator ``q`` of a block: its values q, q + 8, ... summed in turn (value j read as v)."""
        a = self.values
        first = block.lo + q
        r = v if first == j else a[first]
        for i in range(first + 8, block.body, 8):
            r += v if i == j else a[i]
        return r

    def _block_sum(self, block: _Block, accumulators, j, v) -> float:
        a = self.values
        if accumulators is None:
            res = -0.0
        else:
            r = accumulators
            res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
        for i in range(block.body, block.stop):
            res += v if i == j else a[i]
        return res

    def _sum(self, node, j: int, v: float, keep: bool) -> float:
        """The sum of ``node``'s values with value ``j`` read as ``v``; with ``keep``, kept as its sums."""
        if isinstance(node, _Halves):
            if j < node.split:
                total = self._sum(node.left, j, v, keep) + node.right.sum
            else:
                total = node.left.sum + self._sum(node.right, j, v, keep)
        else:
            accumulators = node.accumulators
            if j < node.body:
                q = (j - node.lo) % 8
                accumulators = accumulators if keep else list(accumulators)
                accumulators[q] = self._chain(node, q, j, v)
            total = self._block_sum(node, accumulators, j, v)
        if keep:
            node.sum = total
        return total

    def with_value(self, j: int, v: float) -> float:
        """The row's mean with value ``j`` read as ``v``."""
        return (0.0 + self._sum(self.root, j, v, False)) / len(self.values)

    def set(self, j: int, v: float) -> None:
        """Change value ``j`` to ``v`` for good."""
        self._sum(self.root, j, v, True)
        self.values[j] = v


def _best_fold(evals: list, samples: list) -> int:
    """scikit-learn's choice: the most even fold; near-equal ones (np.isclose) go to the fold with fewer samples."""
    best, min_eval, min_samples = None, np.inf, np.inf
    for i, e in enumerate(evals):
        tie = min_eval != np.inf and abs(e - min_eval) <= _ATOL + _RTOL * abs(min_eval)
        if e < min_eval or (tie and samples[i] < min_samples):
            best, min_eval, min_samples = i, e, samples[i]
    return best
