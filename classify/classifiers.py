"""The five recognizers of the paper, as scikit-learn estimators.

``make(name, **params)`` builds one by name (``NAMES``).  All of them take
imprints as 256-vectors (16x16 flattened row-major, as in the paper) and
also accept the (N, 16, 16) stack of an ``ImprintSet`` directly, flattening
it; they all have fit / predict / predict_proba / get_params, so they can be
cloned, grid-searched and cross-validated like any scikit-learn classifier.

====================  ==========================================================
``knn``               k-nearest neighbours, k chosen by an inner stratified
                      cross-validation over ``ks`` on the training set
``naive_bayes``       Gaussian naive Bayes
``decision_tree``     CART (gini), seeded
``evolutionary_svm``  Mierswa's evolutionary SVM (see ``classify.evolutionary_svm``)
``deep``              feed-forward network, two hidden layers (128, 64), ReLU,
                      Adam on mini-batches of 32, early stopping on a 10 %
                      validation split, seeded
====================  ==========================================================
"""

from __future__ import annotations

import numbers
import warnings

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.model_selection import StratifiedKFold
from sklearn.naive_bayes import GaussianNB
from sklearn.neighbors import NearestNeighbors
from sklearn.neural_network import MLPClassifier
from sklearn.tree import DecisionTreeClassifier
from sklearn.utils.validation import check_is_fitted

from classify import NAMES
from classify.evolutionary_svm import EvolutionarySVM, as_matrix

__all__ = ["NAMES", "make", "as_matrix", "KNN", "NaiveBayes", "DecisionTree", "EvolutionarySVM", "DeepNet"]


class _Flatten:
    """Mixin: flatten (N, rows, cols) inputs before the wrapped estimator sees them."""

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
    scikit-learn's warning about it).
    """

    def fit(self, X, y):
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="Got `batch_size` less than 1 or larger than sample size")
            return super().fit(X, y)


class KNN(ClassifierMixin, BaseEstimator):
    """k-nearest neighbours with k chosen by inner cross-validation.

    Parameters
    ----------
    ks : sequence of int
        Candidate k.  Those larger than an inner training fold are skipped.
    cv : int
        Inner stratified folds (reduced to the smallest class's count; with
        fewer than 2 samples in some class no search is possible and the
        smallest k is used).
    metric : str
        Distance, as in :class:`sklearn.neighbors.NearestNeighbors`.
    random_state : int
        Seed of the inner fold shuffle.

    Attributes
    ----------
    k_ : int
        The chosen k (ties go to the smaller k).
    cv_scores_ : dict k -> mean inner accuracy
    classes_ : labels
    scale_ : float
        Distance scale of the posterior: the median distance from a
        training imprint to its nearest other training imprint.

    Notes
    -----
    The posterior is the neighbours' vote made soft by distance, so that
    it carries evidence beyond the winner even at k = 1 (where plain vote
    fractions are one-hot and multiplying the posteriors of several
    touches, as ``classify.experiment`` does, only repeats ties)::

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

    def __init__(self, ks=(1, 3, 5, 7, 9), cv=3, metric="euclidean", random_state=0):
        self.ks = ks
        self.cv = cv
        self.metric = metric
        self.random_state = random_state

    def fit(self, X, y):
        """Choose k on inner folds of (X, y), then fit on all of it."""
        ks = sorted({int(k) for k in self.ks})
        if not ks or ks[0] < 1:
            raise ValueError(f"KNN: ks must hold positive integers, got {self.ks!r}")
        if not (isinstance(self.cv, numbers.Integral) and self.cv >= 2):
            raise ValueError(f"KNN: cv must be an integer >= 2, got {self.cv!r}")
        X = as_matrix(X)
        y = np.asarray(y)
        if y.shape != (len(X),):
            raise ValueError(f"KNN: y must have shape ({len(X)},), got {y.shape}")
        self.classes_, codes = np.unique(y, return_inverse=True)
        folds = min(self.cv, np.bincount(codes).min())
        self.cv_scores_ = {}
        if folds >= 2 and len(self.classes_) >= 2:
            hits = {k: 0 for k in ks}
            split = StratifiedKFold(folds, shuffle=True, random_state=self.random_state)
            for train, test in split.split(X, codes):
                usable = [k for k in ks if k <= len(train)]
                if not usable:
                    continue
                nn = NearestNeighbors(n_neighbors=usable[-1], metric=self.metric).fit(X[train])
                order = nn.kneighbors(X[test], return_distance=False)
                neighbour_codes = codes[train][order]
                class_nn = _per_class_neighbours(X[train], codes[train], len(self.classes_), self.metric)
                dist = _class_distances(class_nn, X[test])
                for k in usable:
                    # The argmax does not depend on the scale, so the fold's own is not needed.
                    proba = _posterior(neighbour_codes[:, :k], dist, 1.0)
                    hits[k] += int(np.sum(np.argmax(proba, axis=1) == codes[test]))
            self.cv_scores_ = {k: hits[k] / len(X) for k in ks}
            self.k_ = max(ks, key=lambda k: (self.cv_scores_[k], -k))
        else:
            self.k_ = ks[0]
        self.k_ = min(self.k_, len(X))
        self.model_ = NearestNeighbors(n_neighbors=self.k_, metric=self.metric).fit(X)
        self.codes_ = codes
        self.class_neighbours_ = _per_class_neighbours(X, codes, len(self.classes_), self.metric)
        self.scale_ = _distance_scale(self.model_, X)
        self.n_features_in_ = X.shape[1]
        return self

    def predict_proba(self, X):
        """Votes of the k neighbours softened by distance (see Notes; columns follow ``classes_``)."""
        check_is_fitted(self, "model_")
        X = as_matrix(X)
        order = self.model_.kneighbors(X, return_distance=False)
        return _posterior(self.codes_[order], _class_distances(self.class_neighbours_, X), self.scale_)

    def predict(self, X):
        return self.classes_[np.argmax(self.predict_proba(X), axis=1)]


_SOFT = 0.5  # weight of the distance term: under one vote, so it never overturns a majority


def _per_class_neighbours(X, codes, n_classes, metric):
    """One 1-nearest-neighbour index per class code."""
    return [NearestNeighbors(n_neighbors=1, metric=metric).fit(X[codes == c]) for c in range(n_classes)]


def _class_distances(class_neighbours, X):
    """(n, n_classes) distance from each row of X to the nearest training sample of each class."""
    return np.column_stack([nn.kneighbors(X)[0][:, 0] for nn in class_neighbours])


def _distance_scale(model, X):
    """Median distance from a training sample to its nearest other one (1.0 when undefined or zero)."""
    if len(X) < 2:
        return 1.0
    scale = float(np.median(model.kneighbors(X, n_neighbors=2)[0][:, 1]))
    return scale if scale > 0 else 1.0


def _posterior(neighbour_codes, class_dist, scale):
    """(votes + _SOFT * softmax(-class_dist / scale)) / (k + _SOFT), rows of ``neighbour_codes`` (n, k)."""
    n, k = neighbour_codes.shape
    votes = np.zeros(class_dist.shape)
    np.add.at(votes, (np.arange(n)[:, None], neighbour_codes), 1.0)
    soft = np.exp(-(class_dist - class_dist.min(axis=1, keepdims=True)) / scale)
    soft /= soft.sum(axis=1, keepdims=True)
    return (votes + _SOFT * soft) / (k + _SOFT)


_FACTORIES = {
    "knn": (KNN, {}),
    "naive_bayes": (NaiveBayes, {}),
    "decision_tree": (DecisionTree, {"random_state": 0}),
    "evolutionary_svm": (EvolutionarySVM, {}),
    "deep": (DeepNet, {"hidden_layer_sizes": (128, 64), "early_stopping": True, "batch_size": 32,
                         "max_iter": 500, "random_state": 0}),
}


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
    ValueError: unknown classifier 'svm'; choose one of knn, naive_bayes, decision_tree, evolutionary_svm, deep
    """
    if name not in _FACTORIES:
        raise ValueError(f"unknown classifier {name!r}; choose one of {', '.join(NAMES)}")
    cls, defaults = _FACTORIES[name]
    estimator = cls(**defaults)
    valid = estimator.get_params()
    unknown = sorted(set(params) - set(valid))
    if unknown:
        raise ValueError(f"classifier {name!r} has no parameter {', '.join(unknown)}; "
                           f"valid: {', '.join(sorted(valid))}")
    return estimator.set_params(**params)
