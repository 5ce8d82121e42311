"""The five recognizers of the paper, and the place-aware one, as scikit-learn estimators.

``make(name, **params)`` builds one by name (``NAMES``).  The paper's five
(``PAPER_NAMES``) take imprints as 256-vectors (16x16 flattened row-major,
as in the paper) and also accept the (N, 16, 16) stack of an ``ImprintSet``
directly, flattening it; all of them have fit / predict / predict_proba /
get_params, so they can be cloned, grid-searched and cross-validated like
any scikit-learn classifier.

====================  ==========================================================
``knn``               k-nearest neighbours, k chosen by an inner stratified
                      cross-validation over ``ks`` on the training set, folds
                      grouped by instance and point when ``fit`` gets ``groups``
``naive_bayes``       Gaussian naive Bayes
``decision_tree``     CART (gini), seeded
``evolutionary_svm``  Mierswa's evolutionary SVM (see ``classify.recognizers.evolutionary_svm``)
``deep``              feed-forward network, two hidden layers (128, 64), ReLU,
                      Adam on mini-batches of 32, early stopping on a 10 %
                      validation split, seeded
``place``             the place-aware likelihood (``classify.recognizers.place``):
                      it also needs where each touch was taken, so it runs
                      in the instance protocol and the touch policies only
====================  ==========================================================
"""

from __future__ import annotations

import hashlib
import numbers
from dataclasses import dataclass

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin, clone
from sklearn.model_selection import StratifiedKFold
from sklearn.naive_bayes import GaussianNB
from sklearn.neural_network import MLPClassifier
from sklearn.tree import DecisionTreeClassifier
from sklearn.utils.validation import check_is_fitted

from classify.recognizers.distances import Rows, block_rows, class_distances, distances_to, on_grid, ranked
from classify.recognizers.evolutionary_svm import EvolutionarySVM, as_labels, as_matrix, check_n_features
from classify.recognizers.folds import GroupFolds
from classify.recognizers.place import PlaceAware
from meshsal.util.registry import Registry

__all__ = [
    "CLASSIFIERS",
    "NAMES",
    "PAPER_NAMES",
    "make",
    "as_matrix",
    "KNN",
    "NaiveBayes",
    "DecisionTree",
    "EvolutionarySVM",
    "DeepNet",
]


class _Flatten:
    """Mixin: flatten (N, rows, cols) inputs before the wrapped estimator sees them."""

    def __sklearn_tags__(self):
        # as_matrix refuses sparse input and NaN, which some wrapped estimators take.
        tags = super().__sklearn_tags__()
        tags.input_tags.sparse = False
        tags.input_tags.allow_nan = False
        return tags

    def fit(self, X, y, **kwargs):
        return super().fit(as_matrix(X), y, **kwargs)

    def predict(self, X):
        return super().predict(as_matrix(X))

    def predict_proba(self, X):
        return super().predict_proba(as_matrix(X))

    def predict_log_proba(self, X):
        return super().predict_log_proba(as_matrix(X))


class NaiveBayes(_Flatten, GaussianNB):
    """:class:`sklearn.naive_bayes.GaussianNB` taking imprints (N, d) or (N, rows, cols)."""


class DecisionTree(_Flatten, DecisionTreeClassifier):
    """:class:`sklearn.tree.DecisionTreeClassifier` (CART) taking imprints (N, d) or (N, rows, cols)."""


class DeepNet(_Flatten, MLPClassifier):
    """:class:`sklearn.neural_network.MLPClassifier` taking imprints (N, d) or (N, rows, cols).

    ``make("deep")`` sets two hidden layers (128, 64), mini-batches of 32,
    early stopping and a seed; the class itself keeps scikit-learn's
    defaults.  A training set smaller than the batch is one batch (without
    scikit-learn's warning about it).  ``fit`` leaves the parameters as it
    found them.

    Early stopping tunes the number of epochs on held-out data.  Given
    ``fit(X, y, groups)``, that validation set is whole groups (about
    ``validation_fraction`` of them, stratified, seeded): otherwise a point's
    re-touches would sit on both sides and stop training late.  As in
    scikit-learn, the weights of the best validation epoch are kept.
    """

    def fit(self, X, y, groups=None):
        X = as_matrix(X)
        # The batch is clipped to the data here, not by scikit-learn (whose warning is not thread-safe to silence).
        batch, stopping = self.batch_size, self.early_stopping
        if isinstance(batch, numbers.Integral) and not isinstance(batch, bool):
            usable = len(X) - (int(np.ceil(self.validation_fraction * len(X))) if stopping else 0)
            self.set_params(batch_size=int(min(batch, max(1, usable))))
        try:
            if not stopping or groups is None:
                return super().fit(X, y)
            return self._fit_grouped(X, np.asarray(y), np.asarray(groups))
        finally:
            self.set_params(batch_size=batch, early_stopping=stopping)

    def _fit_grouped(self, X, y, groups):
        smallest = int(np.bincount(np.unique(y, return_inverse=True)[1]).min())
        splits = int(min(max(2, round(1.0 / self.validation_fraction)), len(np.unique(groups)), smallest))
        if splits < 2:
            return super().fit(X, y)
        train, val = next(GroupFolds(splits, shuffle=True, random_state=self.random_state).split(X, y, groups))
        classes = np.unique(y)
        self.set_params(early_stopping=False, batch_size=int(min(self.batch_size, len(train))))
        best, best_score, stale = None, -np.inf, 0
        X_train, y_train, X_val, y_val = X[train], y[train], X[val], y[val]
        for epoch in range(self.max_iter):
            # partial_fit needs the classes on its first call only; given again, it checks them (unique_labels) each epoch.
            MLPClassifier.partial_fit(self, X_train, y_train, classes=None if epoch else classes)
            score = float(np.mean(MLPClassifier.predict(self, X_val) == y_val))
            if score > best_score + self.tol:
                best = ([c.copy() for c in self.coefs_], [b.copy() for b in self.intercepts_], epoch + 1)
                best_score, stale = score, 0
            else:
                stale += 1
                if stale >= self.n_iter_no_change:
                    break
        self.coefs_, self.intercepts_, self.n_iter_ = best
        self.best_validation_score_ = best_score
        return self


class KNN(ClassifierMixin, BaseEstimator):
    """k-nearest neighbours with k chosen by inner cross-validation.

    Parameters
    ----------
    ks : sequence of int
        Candidate k.  Those larger than an inner training fold are skipped.
    cv : int
        Inner folds (reduced to what the smallest class allows; with fewer
        than 2 groups in some class no search is possible and the smallest
        k is used).
    random_state : int
        Seeds the inner fold shuffle and every tie break.
    cv_rows : int or "auto"
        Training rows the inner folds score at most, and whose nearest
        other row sets ``scale_``: those of least content hash, a sample
        that ignores the rows' order.  The search then costs ``cv_rows``
        times the training set, not its square; smaller sets are scored whole.
        "auto" (the default) scores 20,000 rows, fewer when they would
        compare more than 2^28 pairs (never fewer than 2,000): sets of up
        to 16,384 rows are scored whole, and past that the search compares
        2^28 pairs whatever the set's size.

    Attributes
    ----------
    k_ : int
        The chosen k.  Equal inner scores are decided by a draw seeded with
        ``random_state``, never by the order of ``ks``.
    cv_scores_ : dict k -> mean inner accuracy
    classes_ : labels
    scale_ : float
        Distance scale of the posterior: the median distance from a
        training imprint to its nearest other training imprint.
    grid_rows_ : the training rows' integer codes and squared norms when
        they lie on the ADC's grid (else None), prepared once for every
        prediction.
    float_rows_ : the training rows and their squared norms, prepared once
        for every prediction of queries off the grid.

    Notes
    -----
    ``fit(X, y, groups)`` keeps every group (an object instance, a point)
    on one side of each inner fold, so k is never chosen by how well a
    point recognizes its own re-touches.

    Distances are Euclidean, computed so that they do not depend on the
    CPU or the thread count: imprints on an ADC's grid (multiples of
    1/255, as every acquired imprint is) are compared through their integer
    codes, where float64 sums are exact; other inputs have their squared
    distances rounded to 1e-9.  Neighbours at equal distance are ranked by
    a seeded hash of their content and label, and the inner folds are
    drawn over the training set sorted by label and that hash, so neither
    the CPU nor the order of the training set decides k or a tie.

    The posterior is the neighbours' vote made soft by distance, so that it
    carries evidence beyond the winner even at k = 1::

        p_c = (v_c + s_c / 2) / (k + 1 / 2),    s = softmax_c(-d_c / scale_)

    with ``v_c`` the votes of class c among the k nearest neighbours and
    ``d_c`` the distance to the nearest training imprint of class c.  The
    distance term sums to less than one vote, so the prediction (its
    argmax) is the majority vote; a tied vote goes to the class with the
    nearest imprint.

    Examples
    --------
    >>> X = np.r_[np.zeros((6, 2)), np.ones((6, 2))]
    >>> KNN().fit(X, np.repeat([0, 1], 6)).predict([[0.9, 0.9]])
    array([1])
    """

    def __init__(self, ks=(1, 3, 5, 7, 9), cv=3, random_state=0, cv_rows="auto"):
        self.ks = ks
        self.cv = cv
        self.random_state = random_state
        self.cv_rows = cv_rows

    def fit(self, X, y, groups=None):
        """Choose k on inner folds of (X, y) grouped by ``groups`` (if given), then fit on all of it."""
        X, y, groups = self._checked(X, y, groups)
        inner = self._inner(X, y, groups, np.arange(len(X)))
        ((hits, scale),) = _scan_training_sets(X, [inner], self._ks())
        return self._adopt(X, inner, hits, scale)

    def fit_subsets(self, X, y, groups=None, subsets=()):
        """The models :meth:`fit` gives on each subset of the rows of (X, y, groups), one at a time.

        One pass over the distances serves every subset's inner folds: a
        row's distances to the others are computed once, however many
        subsets score it (a subset's model is the same as its own ``fit``
        would give, to the bit).  The models are built as they are asked
        for, so only one is held at a time.

        Parameters
        ----------
        X, y, groups : as in :meth:`fit`
        subsets : sequence of (m_i,) int row indices, or bool masks

        Yields
        ------
        KNN, fitted on ``X[subsets[i]]``, in the order of ``subsets``
        """
        X, y, groups = self._checked(X, y, groups)
        rows = [np.flatnonzero(r) if np.asarray(r).dtype == bool else np.asarray(r, np.int64) for r in subsets]
        classes, codes = np.unique(y, return_inverse=True)
        # A subset that holds every class labels its rows as the whole set does: the whole set's keys are its own.
        whole = [np.unique(y[r]).size == classes.size for r in rows]
        keys = _row_keys(X, codes, self.random_state) if any(whole) else None
        inners = [self._inner(X, y, groups, r, keys if w else None) for r, w in zip(rows, whole)]
        found = _scan_training_sets(X, inners, self._ks())
        for inner, (hits, scale) in zip(inners, found):
            yield clone(self)._adopt(X, inner, hits, scale)

    def _ks(self) -> list:
        return sorted({int(k) for k in self.ks})

    def _checked(self, X, y, groups):
        ks = self._ks()
        if not ks or ks[0] < 1:
            raise ValueError(f"KNN: ks must hold positive integers, got {self.ks!r}")
        if not (isinstance(self.cv, numbers.Integral) and self.cv >= 2):
            raise ValueError(f"KNN: cv must be an integer >= 2, got {self.cv!r}")
        if not (self.cv_rows == "auto" or (isinstance(self.cv_rows, numbers.Integral) and self.cv_rows >= 1)):
            raise ValueError(f"KNN: cv_rows must be a positive integer or 'auto', got {self.cv_rows!r}")
        X = as_matrix(X)
        y = as_labels(y, len(X), "KNN")
        if groups is not None and np.shape(groups) != (len(X),):
            raise ValueError(f"KNN: groups must have shape ({len(X)},), got {np.shape(groups)}")
        return X, y, None if groups is None else np.asarray(groups)

    def _inner(self, X, y, groups, rows, keys=None) -> _InnerFolds:
        """The inner folds of the training set ``rows`` of (X, y, groups); ``keys`` the whole set's row keys
        (:func:`_row_keys`), when the training set holds every class."""
        part = X[rows]
        classes, codes = np.unique(y[rows], return_inverse=True)
        keys = _row_keys(part, codes, self.random_state) if keys is None else keys[rows]
        # A canonical order (label, then content hash): the inner folds, hence k, ignore the input's order.
        canonical = np.lexsort((keys, codes))
        codes, keys = codes[canonical], keys[canonical]
        groups = None if groups is None else groups[rows][canonical]
        folds = _inner_folds(codes, groups, self.cv)
        splits = list(_split(codes, groups, folds, self.random_state)) if folds >= 2 and len(classes) >= 2 else []
        scored = np.sort(np.argsort(keys, kind="stable")[: self._scored_rows(len(part))])
        return _InnerFolds(rows[canonical], classes, codes, keys, splits, scored, on_grid(part))

    def _scored_rows(self, n: int) -> int:
        """Rows the inner folds of a training set of ``n`` rows score at most (see ``cv_rows``)."""
        if self.cv_rows != "auto":
            return int(self.cv_rows)
        return int(min(_CV_ROWS, max(_MIN_CV_ROWS, _SCAN_PAIRS // max(n, 1))))

    def _adopt(self, X, inner: _InnerFolds, hits: dict, scale: float):
        """Fitted on the training set of ``inner``, rows of ``X``, with its inner folds' hits and distance scale."""
        ks = self._ks()
        self.classes_, self.scale_ = inner.classes, scale
        self.cv_scores_ = {}
        if inner.splits:
            self.cv_scores_ = {k: hits[k] / len(inner.scored) for k in ks}
            best = max(self.cv_scores_.values())
            tied = [k for k in ks if self.cv_scores_[k] == best]
            self.k_ = int(tied[np.random.default_rng(self.random_state).integers(len(tied))])
        else:
            self.k_ = ks[0]
        self.X_ = X[inner.rows]
        self.k_ = min(self.k_, len(self.X_))
        # Every prediction compares with the training rows as prepared here (integer codes on the grid): once.
        self.grid_rows_ = Rows.of(self.X_, True) if inner.exact else None
        self.float_rows_ = Rows.of(self.X_, False)
        self.codes_ = inner.codes
        self.tiebreak_ = inner.keys
        self.n_features_in_ = X.shape[1]
        return self

    def predict_proba(self, X):
        """Votes of the k neighbours softened by distance (see Notes; columns follow ``classes_``)."""
        check_is_fitted(self, "X_")
        X = as_matrix(X)
        check_n_features(self, X)
        out = np.empty((len(X), len(self.classes_)))
        rows = self.grid_rows_ if self.grid_rows_ is not None and on_grid(X) else self.float_rows_
        step = block_rows(len(self.X_))
        for start in range(0, len(X), step):  # a block of distances at a time: memory stays flat
            block = X[start : start + step]
            d2 = distances_to(block, rows)
            order = ranked(d2, self.tiebreak_, self.k_)
            dist = class_distances(d2, self.codes_, len(self.classes_))
            out[start : start + step] = _posterior(self.codes_[order], dist, self.scale_)
        return out

    def predict(self, X):
        proba = self.predict_proba(X)  # first: it tells an unfitted model by name
        return self.classes_[np.argmax(proba, axis=1)]


_SOFT = 0.5  # weight of the distance term: under one vote, so it never overturns a majority
# cv_rows="auto": rows scored at most, pairs compared at most, and rows scored at least.
_CV_ROWS, _SCAN_PAIRS, _MIN_CV_ROWS = 20000, 1 << 28, 2000


def _inner_folds(codes, groups, cv) -> int:
    """How many inner folds the smallest class allows (counting groups when given)."""
    if groups is None:
        return int(min(cv, np.bincount(codes).min()))
    pairs = np.unique(np.column_stack([codes, np.unique(groups, return_inverse=True)[1]]), axis=0)
    return int(min(cv, np.bincount(pairs[:, 0], minlength=codes.max() + 1).min()))


def _split(codes, groups, folds, seed):
    if groups is None:
        return StratifiedKFold(folds, shuffle=True, random_state=seed).split(codes, codes)
    return GroupFolds(folds, shuffle=True, random_state=seed).split(codes, codes, groups)


@dataclass(frozen=True, eq=False)
class _InnerFolds:
    """One training set's inner folds, in its canonical order: ``rows`` its rows of the whole set; ``splits``
    (train, test) and ``scored`` (the rows the folds score) positions in ``rows``; ``exact`` whether its rows lie
    on the ADC's grid."""

    rows: np.ndarray
    classes: np.ndarray
    codes: np.ndarray
    keys: np.ndarray
    splits: list
    scored: np.ndarray
    exact: bool


def _scan_training_sets(X, inners: list, ks) -> list[tuple[dict, float]]:
    """Each training set's inner-fold hits per k and distance scale, from one pass over the scored rows' distances.

    A block of the rows any set scores at a time, their distances to every
    row of ``X`` serve every set: each inner fold of a set reads its test
    rows' distances to its training rows, and the set's scale the distance
    to the nearest other row of the set.  Rows are independent in every
    step, and a distance is the same in any block, so the hits and scales
    are those of each set scanned alone, fold by fold.

    Returns
    -------
    list of (hits, scale), one per set: hits dict k -> right answers over the inner test folds (0 without
    splits); scale the median distance from a row to its nearest other row (1.0 when undefined or zero)
    """
    found = [None] * len(inners)
    # Sets on and off the ADC's grid compare rows differently: each kind in a pass of its own.
    for exact in (True, False):
        which = [i for i, inner in enumerate(inners) if inner.exact == exact]
        if which:
            for i, out in zip(which, _scan_pass(X, [inners[i] for i in which], ks, exact)):
                found[i] = out
    return found


def _scan_pass(X, inners: list, ks, exact: bool) -> list[tuple[dict, float]]:
    """:func:`_scan_training_sets` of sets whose rows all lie on the ADC's grid (``exact``) or none do."""
    scored = [inner.rows[inner.scored] for inner in inners]
    union = np.unique(np.concatenate(scored))
    hits = [{k: 0 for k in ks} for _ in inners]
    nearest = [[] for _ in inners]
    # Columns by the sets that hold them (runs whose minima give each set's nearest other row), then in the
    # canonical order of the largest set, so that each set reads its rows' distances in runs.
    member = np.zeros((len(inners), len(X)), bool)
    for s, inner in enumerate(inners):
        member[s, inner.rows] = True
    pattern = np.unique(member.T, axis=0, return_inverse=True)[1].reshape(-1)
    largest = max(inners, key=lambda inner: len(inner.rows)).rows
    after = np.full(len(X), len(X))
    after[largest] = np.arange(largest.size)
    order = np.lexsort((np.arange(len(X)), after, pattern))
    column = np.empty(len(X), np.int64)
    column[order] = np.arange(len(X))
    starts = np.flatnonzero(np.r_[True, np.diff(pattern[order]) != 0])
    runs_of = [np.flatnonzero(member[s, order[starts]]) for s in range(len(inners))]
    # Each set's scored rows by their place in the union, with their positions in the set.
    places, positions, folds = [], [], []
    for inner, rows in zip(inners, scored):
        by = np.argsort(rows, kind="stable")
        places.append(np.searchsorted(union, rows[by]))
        positions.append(inner.scored[by])
        fold = np.full(len(inner.rows), -1)
        for f, (_, test) in enumerate(inner.splits):
            fold[test] = f
        folds.append(fold)
    rows_all = Rows.of(X[order], exact)
    step = block_rows(len(X))
    for start in range(0, union.size, step):
        block = union[start : start + step]
        d2 = distances_to(X[block], rows_all)
        # A row is in its own inner test fold, never among its training rows: its distance to itself is read
        # only as the nearest other row's, where it does not count.
        d2[np.arange(block.size), column[block]] = np.inf
        lows = np.minimum.reduceat(d2, starts, axis=1)
        for s, inner in enumerate(inners):
            lo, hi = np.searchsorted(places[s], [start, start + block.size])
            if lo == hi:
                continue
            local, pos = places[s][lo:hi] - start, positions[s][lo:hi]
            n_classes = len(inner.classes)
            for f, (train, _) in enumerate(inner.splits):
                usable = [k for k in ks if k <= len(train)]
                mine = folds[s][pos] == f
                if not usable or not mine.any():
                    continue
                sub = d2[np.ix_(local[mine], column[inner.rows[train]])]
                ranks = ranked(sub, inner.keys[train], max(usable))
                dist = class_distances(sub, inner.codes[train], n_classes)
                for k in usable:
                    # The argmax does not depend on the scale, so the fold's own is not needed.
                    proba = _posterior(inner.codes[train][ranks[:, :k]], dist, 1.0)
                    hits[s][k] += int(np.sum(np.argmax(proba, axis=1) == inner.codes[pos[mine]]))
            nearest[s].append(lows[np.ix_(local, runs_of[s])].min(axis=1))
    out = []
    for s, inner in enumerate(inners):
        if len(inner.rows) < 2:
            out.append((hits[s], 1.0))
            continue
        scale = float(np.median(np.sqrt(np.concatenate(nearest[s]) if nearest[s] else np.empty(0))))
        out.append((hits[s], scale if scale > 0 else 1.0))
    return out


def _row_keys(X, codes, seed) -> np.ndarray:
    """A seeded 64-bit hash of each row's bytes and label: a tie-break that ignores the rows' order."""
    salt = int(seed).to_bytes(8, "little", signed=True)
    return np.array(
        [
            int.from_bytes(
                hashlib.blake2b(row.tobytes() + int(c).to_bytes(8, "little"), digest_size=8, salt=salt).digest(),
                "little",
            )
            for row, c in zip(np.ascontiguousarray(X, np.float64), codes)
        ],
        dtype=np.uint64,
    )


def _posterior(neighbour_codes, class_dist, scale):
    """(votes + _SOFT * softmax(-class_dist / scale)) / (k + _SOFT), rows of ``neighbour_codes`` (n, k)."""
    n, k = neighbour_codes.shape
    votes = np.zeros(class_dist.shape)
    np.add.at(votes, (np.arange(n)[:, None], neighbour_codes), 1.0)
    soft = np.exp(-(class_dist - class_dist.min(axis=1, keepdims=True)) / scale)
    soft /= soft.sum(axis=1, keepdims=True)
    return (votes + _SOFT * soft) / (k + _SOFT)


#: The recognizers: the five of the paper, then the place-aware one; class and default parameters.
CLASSIFIERS = Registry("classifier")
CLASSIFIERS.register("knn", (KNN, {}), "k-nearest neighbours, k tuned on grouped inner folds")
CLASSIFIERS.register("naive_bayes", (NaiveBayes, {}), "Gaussian naive Bayes")
CLASSIFIERS.register("decision_tree", (DecisionTree, {"random_state": 0}), "CART")
CLASSIFIERS.register("evolutionary_svm", (EvolutionarySVM, {}), "Mierswa's evolutionary SVM")
CLASSIFIERS.register(
    "deep",
    (
        DeepNet,
        {"hidden_layer_sizes": (128, 64), "early_stopping": True, "batch_size": 32, "max_iter": 500, "random_state": 0},
    ),
    "two-layer network",
)
#: The paper's five, which recognize single imprints wherever they were taken (Table 1).
PAPER_NAMES = CLASSIFIERS.names()
CLASSIFIERS.register(
    "place",
    (PlaceAware, {}),
    "place-aware likelihood of touch codebooks (instance protocol and policies only)",
)
NAMES = CLASSIFIERS.names()


def make(name: str, **params):
    """A new, unfitted classifier by name.

    Parameters
    ----------
    name : one of ``NAMES``
    **params
        Override the estimator's parameters (those ``get_params`` lists).

    Examples
    --------
    >>> make("knn", ks=(1, 3)).get_params()["ks"]
    (1, 3)
    >>> make("svm")
    Traceback (most recent call last):
    ...
    ValueError: unknown classifier 'svm'; choose from knn, naive_bayes, decision_tree, evolutionary_svm, deep, place
    """
    cls, defaults = CLASSIFIERS.get(name)
    estimator = cls(**defaults)
    valid = estimator.get_params()
    unknown = sorted(set(params) - set(valid))
    if unknown:
        raise ValueError(
            f"classifier {name!r} has no parameter {', '.join(unknown)}; valid: {', '.join(sorted(valid))}"
        )
    return estimator.set_params(**params)
