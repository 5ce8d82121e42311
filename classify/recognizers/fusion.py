"""Several touches, one decision: calibrated posteriors multiplied over distinct points.

Multiplying posteriors is only as good as the posteriors: a naive Bayes
that says 0.9999 for the wrong object, or a tree that says exactly 1, turns
the product into a plurality vote.  So each classifier's posteriors are
first calibrated on held-out data (folds grouped by training instance, so a
held-out imprint never shares its object instance with the model that
scored it): mixed with the uniform distribution, then tempered,

    p'_c  ∝  ((1 - eps) p_c + eps / C) ** (1 / T),

with ``(eps, T)`` minimizing the held-out negative log-likelihood over a
fixed grid.  Both steps are monotone, so a single touch's decision never
changes; only how firmly it counts in a product does.

Touch sets are k distinct points of one test instance: every one of the
C(n, k) sets when there are at most ``count`` of them (the table then says
how many there were), else ``count`` distinct sets drawn at random.  Ties of
the fused score are broken at random, with the replicate's generator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import combinations

import numpy as np

__all__ = ["Calibration", "calibration_rows", "fit_calibration", "calibrate", "calibrate_rows", "touch_sets", "fuse"]

_EPS_GRID = (1e-4, 1e-3, 1e-2, 0.03, 0.1, 0.3)
_T_GRID = tuple(float(t) for t in np.round(np.geomspace(0.1, 20.0, 24), 6))
_TINY = 1e-12
#: Posteriors :func:`fit_calibration` calibrates at once (16 MB of float64).
_CELLS = 1 << 21


@dataclass(frozen=True)
class Calibration:
    """Uniform mixing ``eps`` and temperature ``T`` (identity: eps 0, T 1; fitted eps is at least 1e-4)."""

    eps: float = 0.0
    temperature: float = 1.0


def calibrate(proba, calibration: Calibration) -> np.ndarray:
    """Calibrated posteriors, rows summing to one, (n, C) float64.

    Examples
    --------
    >>> calibrate([[1.0, 0.0]], Calibration(eps=0.1, temperature=1.0)).round(3).tolist()
    [[0.95, 0.05]]
    """
    P = np.asarray(proba, dtype=np.float64)
    C = P.shape[1]
    mixed = (1.0 - calibration.eps) * P + calibration.eps / C
    logp = np.log(np.maximum(mixed, _TINY)) / calibration.temperature
    logp -= logp.max(axis=1, keepdims=True)
    out = np.exp(logp)
    return out / out.sum(axis=1, keepdims=True)


def calibrate_rows(values, rest, n_classes: int, calibration: Calibration) -> tuple[np.ndarray, np.ndarray]:
    """:func:`calibrate` of posteriors kept sparse: each row's listed values (n, T) and the one value ``rest``
    (n,) of its other ``n_classes - T`` objects; the calibrated (n, T) and (n,).

    Examples
    --------
    >>> v, r = calibrate_rows(np.array([[0.6, 0.3]]), np.array([0.05]), 4, Calibration(eps=0.1, temperature=2.0))
    >>> full = calibrate([[0.6, 0.3, 0.05, 0.05]], Calibration(eps=0.1, temperature=2.0))
    >>> bool(np.allclose(v, full[:, :2]) and np.allclose(r, full[:, 2]))
    True
    """
    V, r = np.asarray(values, np.float64), np.asarray(rest, np.float64)
    C, T = int(n_classes), V.shape[1]
    logv = np.log(np.maximum((1.0 - calibration.eps) * V + calibration.eps / C, _TINY)) / calibration.temperature
    logr = np.log(np.maximum((1.0 - calibration.eps) * r + calibration.eps / C, _TINY)) / calibration.temperature
    top = np.maximum(logv.max(axis=1), logr)
    ev, er = np.exp(logv - top[:, None]), np.exp(logr - top)
    total = ev.sum(axis=1) + (C - T) * er
    return ev / total[:, None], er / total


#: Rows a calibration is fitted on at most.
CALIBRATION_ROWS = 20000
#: Posteriors a calibration is fitted on at most (rows x objects), so that its cost grows no faster than the
#: number of objects; never fewer than ``_MIN_ROWS`` rows.
CALIBRATION_CELLS = 1 << 23
_MIN_ROWS = 2000


def calibration_rows(n_classes: int) -> int:
    """Held-out rows :func:`fit_calibration` scores at most with ``n_classes`` objects.

    Examples
    --------
    >>> calibration_rows(16), calibration_rows(999), calibration_rows(10**6)
    (20000, 8397, 2000)
    """
    return int(min(CALIBRATION_ROWS, max(_MIN_ROWS, CALIBRATION_CELLS // max(int(n_classes), 1))))


def fit_calibration(proba, y, rows: int | None = None) -> Calibration:
    """The ``(eps, T)`` of the grid minimizing the negative log-likelihood of held-out ``proba``.

    Parameters
    ----------
    proba : (n, C) posteriors of held-out samples
    y : (n,) int, true column of each row
    rows : int, optional
        Rows the grid is scored on at most, evenly spread over the n
        (default :func:`calibration_rows` of C): two numbers are fitted, and
        the cost stays that of ``rows`` x C.

    Examples
    --------
    >>> overconfident = np.array([[1.0, 0.0]] * 7 + [[0.0, 1.0]] * 3)
    >>> cal = fit_calibration(overconfident, [0] * 5 + [1] * 2 + [1] * 3)   # 2 of 7 "sure" zeros are wrong
    >>> round(float(calibrate([[1.0, 0.0]], cal)[0, 1]), 1)       # no longer a certainty
    0.2
    """
    P = np.asarray(proba, dtype=np.float64)
    y = np.asarray(y, dtype=np.int64)
    if P.ndim != 2 or y.shape != (P.shape[0],):
        raise ValueError(f"proba must be (n, C) and y (n,), got {P.shape} and {y.shape}")
    if len(y) == 0:
        return Calibration()
    rows = calibration_rows(P.shape[1]) if rows is None else rows
    if len(y) > rows:
        from classify.recognizers.shortlist import spread

        pick = spread(len(y), rows)
        P, y = P[pick], y[pick]
    grid = [Calibration(eps, t) for eps in _EPS_GRID for t in _T_GRID]
    truth = np.empty((len(grid), len(y)))
    # A block of rows at a time: calibration is row by row, and a block holds at most _CELLS values whatever
    # the number of objects.
    step = max(1, _CELLS // P.shape[1])
    for a in range(0, len(y), step):
        _score_block(P[a : a + step], y[a : a + step], truth[:, a : a + step])
    best, best_nll = Calibration(), math.inf
    for cal, p in zip(grid, truth):
        nll = -float(np.mean(np.log(np.maximum(p, _TINY))))
        if nll < best_nll - 1e-12:
            best, best_nll = cal, nll
    return best


def _score_block(P: np.ndarray, y: np.ndarray, out: np.ndarray) -> None:
    """:func:`calibrate`'s posterior of the true column of each row of ``P`` (b, C) at every grid point, bit for
    bit, into ``out`` (grid, b): each mixing's logarithms and row maxima serve all its temperatures (a
    positive divisor keeps the maximum where it is, so max(L) / T is max(L / T))."""
    C = P.shape[1]
    rows = np.arange(len(y))
    scaled = np.empty_like(P)
    g = 0
    for eps in _EPS_GRID:
        logs = np.log(np.maximum((1.0 - eps) * P + eps / C, _TINY))
        top = logs.max(axis=1)
        for t in _T_GRID:
            np.divide(logs, t, out=scaled)
            scaled -= (top / t)[:, None]
            np.exp(scaled, out=scaled)
            out[g] = scaled[rows, y] / scaled.sum(axis=1)
            g += 1


def touch_sets(n_points: int, k: int, count: int, rng: np.random.Generator) -> np.ndarray:
    """Distinct sets of ``k`` distinct point indices out of ``n_points``, (s, k) int64.

    All ``C(n_points, k)`` sets (in lexicographic order) when there are at
    most ``count``; else ``count`` distinct random sets.

    Examples
    --------
    >>> touch_sets(15, 15, 50, np.random.default_rng(0)).shape     # one set of all 15 points
    (1, 15)
    >>> s = touch_sets(15, 3, 50, np.random.default_rng(0))
    >>> s.shape, len({tuple(r) for r in s.tolist()})
    ((50, 3), 50)
    """
    if not 1 <= k <= n_points:
        raise ValueError(f"touches must be within 1..{n_points}, got {k}")
    if count < 1:
        raise ValueError(f"count must be positive, got {count}")
    if math.comb(n_points, k) <= count:
        return np.array(list(combinations(range(n_points), k)), dtype=np.int64).reshape(-1, k)
    chosen: dict[tuple, None] = {}
    while len(chosen) < count:
        for row in np.sort(np.argsort(rng.random((count, n_points)), axis=1)[:, :k], axis=1):
            chosen.setdefault(tuple(int(v) for v in row), None)
            if len(chosen) == count:
                break
    return np.array(list(chosen), dtype=np.int64)


def fuse(proba, sets, rng: np.random.Generator) -> np.ndarray:
    """Class index maximizing the product of posteriors over each set of touches.

    Parameters
    ----------
    proba : (n_points, C) calibrated posteriors of single touches
    sets : (s, k) indices into ``proba``
    rng : breaks ties (scores equal to within 1e-9) at random

    Returns
    -------
    (s,) int64

    Examples
    --------
    >>> p = np.array([[0.5, 0.5], [0.5, 0.5]])
    >>> picks = fuse(p, np.zeros((200, 1), int), np.random.default_rng(0))
    >>> 60 < int(picks.sum()) < 140       # a tie goes either way, not to index 0
    True
    """
    logp = np.log(np.maximum(np.asarray(proba, dtype=np.float64), _TINY))
    score = logp[np.asarray(sets)].sum(axis=1)
    top = score.max(axis=1, keepdims=True)
    tied = score >= top - 1e-9 * np.maximum(1.0, np.abs(top))
    # A random key per candidate, kept only where tied: the argmax is a uniform pick among the ties.
    keys = np.where(tied, rng.random(score.shape), -1.0)
    return np.argmax(keys, axis=1).astype(np.int64)
