"""Drop training imprints that look alike across objects (the paper's NCC > 0.85 rule)."""

from __future__ import annotations

import numpy as np

__all__ = ["normalized_rows", "select_by_similarity"]

# Rows of the similarity matrix computed at once: bounds memory to
# _BLOCK x N floats however many imprints there are.
_BLOCK = 2048


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
    Z, flat = normalized_rows(X)
    y = np.asarray(y).reshape(-1)
    if y.shape[0] != Z.shape[0]:
        raise ValueError(f"labels must have one entry per imprint ({Z.shape[0]}), got {y.shape[0]}")
    threshold = float(threshold)
    if not -1.0 <= threshold <= 1.0:
        raise ValueError(f"threshold must be in [-1, 1], got {threshold}")
    n = Z.shape[0]
    keep = np.ones(n, dtype=bool)
    for start in range(0, n, _BLOCK):
        rows = slice(start, min(start + _BLOCK, n))
        S = Z[rows] @ Z.T
        S[flat[rows][:, None] & flat[None, :]] = 1.0
        S[y[rows][:, None] == y[None, :]] = -np.inf
        keep[rows] = ~(S > threshold).any(axis=1)
    return keep
