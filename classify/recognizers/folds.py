"""Stratified folds of whole groups: scikit-learn's assignment, in memory linear in the groups.

:class:`StratifiedGroupKFold` places each group (an instance's point, its
re-touches) in the fold that keeps the class proportions most even.
scikit-learn holds a dense groups x classes table of counts and scores each
group against every class, one candidate fold at a time in Python: a third
of the recognition time on the demo, and at 1,000 objects (200,000 groups)
gigabytes of memory and time that grows with the square of the objects.
:class:`GroupFolds` keeps each group's counts of its own classes only and
rescores only those classes' columns (k x C values per group, one mean per
fold, instead of k x k x C); the other columns' spreads, and every sum and
mean, are the ones scikit-learn computes, in the same order, so the folds
are the same, split for split (``tests/test_folds.py`` checks it against
scikit-learn's).
"""

from __future__ import annotations

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
        fold_of = np.empty(G, np.int64)
        sizes = np.zeros(k)
        diagonal = np.arange(k)
        for g in np.argsort(-spread, kind="stable"):
            c, n = cls[start[g] : start[g + 1]], counts[start[g] : start[g + 1]]
            # At least two contiguous columns: numpy then sums each spread over the folds in the order it takes
            # in the k x k x C table (a lone column, or a column that is contiguous in memory, is summed pairwise).
            cc, nn = (np.r_[c, c], np.r_[n, n]) if c.size == 1 else (c, n)
            trial = np.repeat(np.ascontiguousarray(per_fold[:, cc])[None], k, axis=0)
            trial[diagonal, diagonal] += nn
            spreads = np.std(trial / y_cnt[cc], axis=1)
            scores = np.tile(base, (k, 1))
            scores[:, cc] = spreads
            best = _best_fold(np.mean(scores, axis=1).tolist(), sizes.tolist())
            per_fold[best, c] += n
            sizes[best] += n.sum()
            fold_of[g] = best
            # The group's fold now holds what that fold's trial held.
            base[cc] = spreads[best]
        row_fold = fold_of[groups_inv]
        for i in range(k):
            yield np.flatnonzero(row_fold == i)


def _best_fold(evals: list, samples: list) -> int:
    """scikit-learn's choice: the most even fold; near-equal ones (np.isclose) go to the fold with fewer samples."""
    best, min_eval, min_samples = None, np.inf, np.inf
    for i, e in enumerate(evals):
        tie = min_eval != np.inf and abs(e - min_eval) <= _ATOL + _RTOL * abs(min_eval)
        if e < min_eval or (tie and samples[i] < min_samples):
            best, min_eval, min_samples = i, e, samples[i]
    return best
