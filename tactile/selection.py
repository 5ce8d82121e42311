"""Drop training imprints that look alike across objects (the paper's NCC > 0.85 rule)."""

from __future__ import annotations

import numpy as np

__all__ = ["normalized_rows", "select_by_similarity", "select_leaving_out"]

# Similarities computed at once (32 MB of float64): a block of rows of the
# N x N matrix, fewer rows the more imprints there are, so memory stays flat.
_CELLS = 1 << 22


def normalized_rows(X) -> tuple[np.ndarray, np.ndarray]:
    """Zero-mean, unit-norm rows of (N, ...) imprints, as (N, D) float64, and a flat-row mask.

    The dot product of two such rows is their normalized cross-correlation
    (NCC).  A flat imprint (all taxels equal) has no NCC; its row is zero and
    it is flagged in the mask.
    """
    X = np.asarray(X, dtype=np.float64)
    if X.ndim < 2:
        raise ValueError(f"imprints must have shape (N, rows, cols) or (N, D), got {X.shape}")
    Z = X.reshape(X.shape[0], -1)
    if not np.isfinite(Z).all():
        raise ValueError("imprints must be finite")
    Z = Z - Z.mean(axis=1, keepdims=True)
    norm = np.linalg.norm(Z, axis=1)
    flat = norm <= 1e-12 * np.maximum(1.0, np.abs(X.reshape(X.shape[0], -1)).max(axis=1, initial=0.0))
    return np.where(flat[:, None], 0.0, Z / np.where(flat, 1.0, norm)[:, None]), flat


def select_by_similarity(X, y, threshold: float = 0.85) -> np.ndarray:
    """Keep mask dropping each imprint too similar to an imprint of another object.

    Following the paper, the similarity of two imprints is their normalized
    cross-correlation (NCC, in [-1, 1]: the cosine between the mean-removed
    images), computed for all pairs as one matrix product of normalized
    vectors.  Imprint i is dropped when its NCC with any imprint of a
    different label exceeds ``threshold``; both members of such a pair go,
    since neither can tell its object apart.  Pairs within one object never
    cause a drop.  Flat imprints (all taxels equal, where NCC is undefined)
    count as identical to each other and unlike everything else, so flat
    imprints of two objects are dropped too.

    Parameters
    ----------
    X : (N, rows, cols) or (N, D) array_like
        Imprints.
    y : (N,) array_like
        Object labels.
    threshold : float
        In [-1, 1]; the paper uses 0.85.

    Returns
    -------
    keep : (N,) bool

    Examples
    --------
    >>> a, b, c = np.eye(4), np.eye(4)[::-1], np.triu(np.ones((4, 4)))
    >>> X = np.stack([a, a + 0.01 * np.arange(16).reshape(4, 4), b, c])
    >>> select_by_similarity(X, [0, 1, 0, 1]).tolist()
    [False, False, True, True]
    """
    return ~_alike_in_groups(X, y, np.zeros(len(np.asarray(y).reshape(-1)), np.int64), 1, threshold)[:, 0]


def select_leaving_out(X, y, groups, threshold: float = 0.85) -> tuple[np.ndarray, np.ndarray]:
    """:func:`select_by_similarity` of the set without each group in turn, and of the whole set, in one pass.

    Leaving a group out removes its imprints and every pair they are in:
    an imprint survives without group g when no imprint of another object
    outside g is too similar to it.  One matrix product over the whole set
    serves every group (the NCC of a pair does not depend on the others).

    Parameters
    ----------
    X, y, threshold : as :func:`select_by_similarity` takes them
    groups : (N,) array_like of int
        E.g. each imprint's training instance.

    Returns
    -------
    ids : (G,) the groups, sorted
    keep : (G + 1, N) bool
        Row g: the keep mask of the set without group ``ids[g]`` (False on
        that group's imprints); the last row: the whole set's.

    Examples
    --------
    >>> a, b = np.eye(4), np.eye(4)[::-1]
    >>> X = np.stack([a, a + 0.01 * np.arange(16).reshape(4, 4), b, b])
    >>> ids, keep = select_leaving_out(X, [0, 1, 0, 1], [1, 2, 1, 1])
    >>> ids.tolist(), keep.tolist()
    ([1, 2], [[False, True, False, False], [True, False, False, False], [False, False, False, False]])
    """
    groups = np.asarray(groups).reshape(-1)
    ids, codes = np.unique(groups, return_inverse=True)
    alike = _alike_in_groups(X, y, codes, len(ids), threshold)
    keep = np.empty((len(ids) + 1, len(groups)), bool)
    for g in range(len(ids)):
        keep[g] = ~np.delete(alike, g, axis=1).any(axis=1) & (codes != g)
    keep[-1] = ~alike.any(axis=1)
    return ids, keep


def _alike_in_groups(X, y, codes: np.ndarray, n_groups: int, threshold) -> np.ndarray:
    """(N, n_groups) bool: whether each imprint has an imprint of another object in group g with NCC above
    ``threshold`` (``codes`` (N,) int in [0, n_groups))."""
    Z, flat = normalized_rows(X)
    y = np.asarray(y).reshape(-1)
    for what, values in (("labels", y), ("groups", codes)):
        if values.shape[0] != Z.shape[0]:
            raise ValueError(f"{what} must have one entry per imprint ({Z.shape[0]}), got {values.shape[0]}")
    threshold = float(threshold)
    if not -1.0 <= threshold <= 1.0:
        raise ValueError(f"threshold must be in [-1, 1], got {threshold}")
    n = Z.shape[0]
    alike = np.zeros((n, n_groups), dtype=bool)
    columns = [codes == g for g in range(n_groups)]
    step = max(1, _CELLS // max(n, 1))
    for start in range(0, n, step):
        rows = slice(start, min(start + step, n))
        S = Z[rows] @ Z.T
        S[flat[rows][:, None] & flat[None, :]] = 1.0
        S[y[rows][:, None] == y[None, :]] = -np.inf
        over = S > threshold
        for g, mine in enumerate(columns):
            alike[rows, g] = over[:, mine].any(axis=1)
    return alike
