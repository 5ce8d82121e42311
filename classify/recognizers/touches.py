"""Single touches: how a classifier is fitted on touches and asked about them.

A :class:`Recognizer` names the classifier (``classify.make``), its
parameters, whether similarity selection filters its training imprints, and
what it sees (raw taxels or roll-invariant descriptors).  Training touches
are grouped by the place they touched (:func:`point_groups`), so tuning
inside a classifier never validates on a twin of a training touch.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass

import numpy as np

from classify.recognizers.classifiers import make

__all__ = ["Recognizer", "point_groups", "fit", "posteriors"]


def point_groups(labels, points, instances=None) -> np.ndarray:
    """One group id per imprint: the rank of its (object, point), or of its (object, instance, point).

    Examples
    --------
    >>> point_groups(np.array([0, 0, 1, 0]), np.array([3, 3, 3, 250000])).tolist()
    [0, 0, 2, 1]
    """
    keys = [labels, points] if instances is None else [labels, instances, points]
    keys = np.stack([np.asarray(k, np.int64).reshape(-1) for k in keys])
    return np.unique(keys, axis=1, return_inverse=True)[1].reshape(-1).astype(np.int64)


def _model(name: str, params: dict):
    return make(name, **params.get(name, {}))


def fit(name: str, params: dict, X, y, groups=None):
    """``classify.make(name, **params[name])`` fitted on ``X, y``, with ``groups`` where its fit takes them."""
    model = _model(name, params)
    if "groups" in inspect.signature(model.fit).parameters:
        return model.fit(X, y, groups=groups)
    return model.fit(X, y)


def posteriors(model, X, n_classes: int) -> np.ndarray:
    """(len(X), n_classes) posteriors of a fitted classifier, zero for classes it never saw."""
    out = np.zeros((len(X), n_classes))
    out[:, model.classes_] = model.predict_proba(X)
    return out


@dataclass(frozen=True)
class Recognizer:
    """How a job recognizes: the classifier and its parameters, selection and its threshold, the features.

    Selection compares raw imprints (the paper's rule); the classifier sees
    ``tactile.features.describe(imprints, features)``.
    """

    classifier: str
    selection: bool = False
    params: dict = None
    threshold: float = 0.85
    features: str = "raw"

    def fit(self, X, y, groups):
        return fit(self.classifier, self.params or {}, X, y, groups)

    def fit_subsets(self, X, y, groups, subsets):
        """:meth:`fit` on each subset of the rows of ``(X, y, groups)``, one model at a time (an iterator).

        A kNN's fits share one pass over the distances
        (``classify.recognizers.classifiers.KNN.fit_subsets``); other
        classifiers are fitted subset by subset, as each model is asked for,
        or together where the classifier can (:meth:`fit_each`).
        """
        model = _model(self.classifier, self.params or {})
        if hasattr(model, "fit_subsets"):
            return model.fit_subsets(X, y, groups, subsets)
        X, y = np.asarray(X), np.asarray(y)
        part = [(rows, None if groups is None else np.asarray(groups)[rows]) for rows in subsets]
        if hasattr(model, "fit_each"):
            return iter(self.fit_each([(X[rows], y[rows], g) for rows, g in part]))
        return (self.fit(X[rows], y[rows], g) for rows, g in part)

    def fit_each(self, sets) -> list:
        """:meth:`fit` on each ``(X, y, groups)`` of ``sets``: the same models, fitted together where the
        classifier can (the evolutionary SVM solves the duals of all sets in one loop)."""
        model = _model(self.classifier, self.params or {})
        if hasattr(model, "fit_each"):
            return model.fit_each([(X, y) for X, y, _ in sets])
        return [self.fit(X, y, groups) for X, y, groups in sets]
