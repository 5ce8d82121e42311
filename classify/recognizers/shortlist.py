"""Shortlists of hypotheses: the few objects a touch's place-aware likelihood is worth computing for.

The place-aware recognizer (:mod:`classify.recognizers.place`) scores a
touch under an object by matching the touched place to that object's places
(a registration of the test instance per object) and by a kernel density
over the object's codebook touches there.  Done under every object, the
work per touch grows with the number of objects, and an experiment's with
its square.  A shortlist keeps it flat: every object gets a cheap score (the
squared distance from the touch to its nearest place-free sample, one matrix
product over all objects), and only the ``H`` nearest objects get the
place-aware terms.  The others keep a lower bound of their likelihood (the
place-free term's nearest kernel), so a touch that resembles nothing of an
object never raises it.  With no more objects than ``H`` every object is on
the shortlist and nothing is approximated.

:class:`SparseRows` holds posteriors that way: the values of a row's
shortlisted objects, and one value shared by every other object.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "EXACT_PLACES",
    "SCREEN_ROWS",
    "SHORTLIST",
    "FreeStack",
    "SparseRows",
    "knn_shortlist",
    "nearest_classes",
    "spread",
]

#: Objects scored in full per touch, and hypotheses a forecast holds, by default.
SHORTLIST = 16
#: Of a touch's shortlist, the objects under which its place is located in full (by registration), by default.
EXACT_PLACES = 8
#: Distances of this many (touch, sample) pairs are held at once.
_BLOCK = 1 << 22


@dataclass(frozen=True, eq=False)
class FreeStack:
    """Every object's place-free samples in one matrix, for screening all objects with a matrix product.

    ``ids`` (V,) int64 the training instances; ``rows`` (N, d + 1) float32,
    each sample ``f`` as ``(-2 f, |f|^2)``, grouped by instance, then by
    object; ``counts`` (V, C) int64 each object's samples of each instance.
    A touch ``z`` times a row, with a 1 appended, is ``|f|^2 - 2 z.f``: its
    squared distance to ``f`` less ``|z|^2``, from the product alone.  The
    least over each (instance, object) group is then one reduction, and a
    touch that leaves out an instance drops that instance's groups, so no
    mask over the samples is needed and no row is padding.
    """

    ids: np.ndarray
    rows: np.ndarray
    counts: np.ndarray

    @staticmethod
    def of(frees: list, instances: list) -> FreeStack:
        """From per-object (F_c, d) samples and (F_c,) instances."""
        ids = np.unique(np.concatenate([np.asarray(i, np.int64) for i in instances]))
        C, d = len(frees), np.asarray(frees[0]).shape[1]
        parts = [[np.asarray(f, np.float32)[np.asarray(i) == v] for f, i in zip(frees, instances)] for v in ids]
        counts = np.array([[len(p) for p in row] for row in parts], np.int64).reshape(-1, C)
        samples = np.concatenate([p for row in parts for p in row]).reshape(-1, d)
        rows = np.empty((len(samples), d + 1), np.float32)
        rows[:, :d] = -2.0 * samples  # a power of two: exact
        rows[:, d] = np.einsum("fd,fd->f", samples, samples)
        return FreeStack(ids, rows, counts)

    def nearest(self, Z: np.ndarray, exclude: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Squared distance from each touch to each object's nearest sample, and how many samples count.

        Parameters
        ----------
        Z : (n, d) float64, standardized descriptors
        exclude : (n,) int64, a training instance whose samples each touch leaves out (-1: none)

        Returns
        -------
        d2 : (n, C) float64 (inf where every sample is left out)
        count : (n, C) int64
        """
        (V, C), n = self.counts.shape, len(Z)
        exclude = np.asarray(exclude, np.int64)
        count = np.tile(self.counts.sum(axis=0), (n, 1))
        for v, per in zip(self.ids, self.counts):
            count[exclude == v] -= per
        # Each (instance, object) group with a sample, by its first row; the others stay inf.
        held = np.flatnonzero(self.counts.ravel() > 0)
        starts = np.r_[0, np.cumsum(self.counts.ravel())[:-1]][held]
        d2 = np.empty((n, C))
        step = max(1, _BLOCK // len(self.rows))
        products = np.empty((min(step, n), len(self.rows)), np.float32)
        for a in range(0, n, step):
            m = len(Z[a : a + step])
            z = np.ones((m, Z.shape[1] + 1), np.float32)
            z[:, :-1] = Z[a : a + m]
            g = np.matmul(z, self.rows.T, out=products[:m])
            groups = np.full((m, V * C), np.inf, np.float32)
            groups[:, held] = np.minimum.reduceat(g, starts, axis=1)
            groups = groups.reshape(m, V, C)
            for j, v in enumerate(self.ids):
                groups[exclude[a : a + m] == v, j] = np.inf
            low = groups.min(axis=1) + np.einsum("nd,nd->n", z[:, :-1], z[:, :-1])[:, None]
            d2[a : a + m] = np.maximum(low, 0.0)
        return d2, count


def spread(n: int, k: int) -> np.ndarray:
    """Indices of at most ``k`` of ``n`` rows, evenly spread over them (all of them when ``n <= k``), increasing.

    Examples
    --------
    >>> spread(10, 4).tolist()
    [0, 3, 6, 9]
    """
    return np.unique(np.linspace(0, n - 1, min(n, k)).round().astype(np.int64))


def nearest_classes(d2: np.ndarray, H: int) -> np.ndarray:
    """(n, H) int64, each row's ``H`` objects of least ``d2``, in increasing object index.

    Examples
    --------
    >>> nearest_classes(np.array([[3.0, 0.5, 2.0, 0.1]]), 2).tolist()
    [[1, 3]]
    """
    n, C = d2.shape
    if H >= C:
        return np.tile(np.arange(C), (n, 1))
    return np.sort(np.argpartition(d2, H - 1, axis=1)[:, :H], axis=1)


@dataclass(frozen=True, eq=False)
class SparseRows:
    """Posteriors over many objects, each row kept at its shortlisted objects.

    ``values`` (..., T) float64 the posterior of each shortlisted object,
    ``classes`` (..., T) signed integers, which objects (increasing), ``rest`` (...)
    float64 the posterior of every other object, ``n_classes`` C.
    """

    values: np.ndarray
    classes: np.ndarray
    rest: np.ndarray
    n_classes: int

    def __getitem__(self, index) -> SparseRows:
        return SparseRows(self.values[index], self.classes[index], self.rest[index], self.n_classes)

    @property
    def dense(self) -> bool:
        """Whether every row holds every object, in order."""
        return self.values.shape[-1] == self.n_classes

    def over(self, classes: np.ndarray) -> np.ndarray:
        """(..., len(classes)) the posterior of ``classes`` in each row.

        Examples
        --------
        >>> rows = SparseRows(np.array([[0.6, 0.3]]), np.array([[0, 2]]), np.array([0.05]), 4)
        >>> rows.over(np.array([2, 3])).tolist()
        [[0.3, 0.05]]
        """
        classes = np.asarray(classes, np.int64)
        if self.dense and np.array_equal(classes, np.arange(self.n_classes)):
            return self.values.copy()
        pos = np.full(self.n_classes, -1, np.int64)
        pos[classes] = np.arange(classes.size)
        out = np.repeat(self.rest[..., None], classes.size, axis=-1)
        col = pos[self.classes]
        hit = np.nonzero(col >= 0)
        out[(*hit[:-1], col[hit])] = self.values[hit]
        return out


#: Training rows per object that screen a query's candidate objects in :func:`knn_shortlist`.
SCREEN_ROWS = 16


def knn_shortlist(model, X, H: int, candidates: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A fitted :class:`~classify.recognizers.classifiers.KNN`'s posteriors of each row's ``H`` most probable
    objects, computed against the training rows of a few candidate objects only.

    Each row's ``candidates`` objects (default ``2 H``) are those whose
    :data:`SCREEN_ROWS` training rows, spread over each object's rows, lie
    nearest; its neighbours and its distances to each object are then read
    among those objects' training rows, with the same distances, tie breaks
    and posterior as ``model.predict_proba``, the posterior normalized over
    the candidates.  A row costs the candidates' rows and the screening
    rows, not the whole training set; the screening still reads every
    object, on :data:`SCREEN_ROWS` rows of each.  With every object a
    candidate, the values are ``predict_proba``'s, bit for bit.

    Parameters
    ----------
    model : KNN, fitted
    X : (n, d) float64, queries
    H : int, objects kept per row
    candidates : int, objects screened in per row (at least ``H``)

    Returns
    -------
    values : (n, min(H, C)) float64, classes : (n, min(H, C)) int64 (indices into ``model.classes_``, increasing)
    """
    from classify.recognizers.classifiers import _posterior
    from classify.recognizers.distances import Rows, distances_to, on_grid, ranked

    X = np.asarray(X, np.float64)
    codes, C = model.codes_, len(model.classes_)
    J = min(C, max(int(H), int(candidates or 2 * H)))
    starts = np.searchsorted(codes, np.arange(C + 1))
    exact = model.grid_rows_ is not None and on_grid(X)
    every = model.grid_rows_ if exact else model.float_rows_
    rows_of = [
        Rows(every.values[starts[c] : starts[c + 1]], every.sq[starts[c] : starts[c + 1]], exact) for c in range(C)
    ]
    if J < C:
        picks = np.concatenate([starts[c] + spread(starts[c + 1] - starts[c], SCREEN_ROWS) for c in range(C)])
        screen = Rows(every.values[picks], every.sq[picks], exact)
        first = np.searchsorted(codes[picks], np.arange(C))
    R = int(np.diff(starts).max())
    T = min(int(H), C)
    values, classes = np.empty((len(X), T)), np.empty((len(X), T), np.int64)
    step = max(1, _BLOCK // (J * R))
    for a in range(0, len(X), step):
        q = X[a : a + step]
        if J < C:
            cand = nearest_classes(np.minimum.reduceat(distances_to(q, screen), first, axis=1), J)
        else:
            cand = np.tile(np.arange(C), (len(q), 1))
        d2 = np.full((len(q), J, R), np.inf)
        tie = np.zeros((len(q), J, R), np.uint64)
        # The (row, slot) pairs of each candidate object, object by object: one sort, not a scan per object.
        pairs = np.argsort(cand.ravel(), kind="stable")
        bounds = np.searchsorted(cand.ravel()[pairs], np.arange(C + 1))
        for c in np.flatnonzero(np.diff(bounds)):
            who, slot = np.divmod(pairs[bounds[c] : bounds[c + 1]], J)
            m = starts[c + 1] - starts[c]
            d2[who, slot, :m] = distances_to(q[who], rows_of[c])
            tie[who, slot, :m] = model.tiebreak_[starts[c] : starts[c + 1]]
        flat = d2.reshape(len(q), J * R)
        order = ranked(flat, tie.reshape(len(q), J * R), model.k_)
        # The neighbours' slots stand for their objects: KNN's posterior over the candidates.
        P = _posterior(order // R, np.sqrt(d2.min(axis=2)), model.scale_)
        top = np.sort(nearest_classes(-P, T), axis=1) if T < J else np.tile(np.arange(J), (len(q), 1))
        # Back to object indices, in increasing order.
        objects = np.take_along_axis(cand, top, axis=1)
        by = np.argsort(objects, axis=1)
        classes[a : a + step] = np.take_along_axis(objects, by, axis=1)
        values[a : a + step] = np.take_along_axis(np.take_along_axis(P, top, axis=1), by, axis=1)
    return values, classes
