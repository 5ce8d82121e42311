"""Intervals and paired comparisons of recognition rates.

A rate is measured per replicate (a fresh draw of instances, devices and
folds) and per object, so its uncertainty has two sources: which replicates
were drawn and which objects the set happens to hold.  The intervals here
resample both, independently and with replacement (a two-way bootstrap,
percentile interval), from a seeded generator.  Given the objects' names,
the columns are resampled in the order of the names, so the order the
objects were given in changes no interval.  Methods compared on the same
replicates and objects are compared through their paired differences, with
the same bootstrap and a Wilcoxon signed-rank test over replicates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

__all__ = ["Summary", "Difference", "bootstrap_means", "summarize", "paired_difference"]

BOOTSTRAP = 4000


@dataclass(frozen=True)
class Summary:
    """A rate (percent) over replicates and objects.

    ``std`` is the spread of the per-replicate rates (each the mean over the
    objects); ``ci_low``/``ci_high`` bound a 95 % two-way bootstrap interval
    of the mean.
    """

    mean: float
    std: float
    ci_low: float
    ci_high: float
    replicates: int


@dataclass(frozen=True)
class Difference:
    """``a - b`` in percentage points, paired by replicate and object.

    ``p_value`` is the two-sided Wilcoxon signed-rank test of the
    per-replicate differences (1.0 when they are all zero).
    """

    mean: float
    ci_low: float
    ci_high: float
    p_value: float
    replicates: int


def _matrix(rates) -> np.ndarray:
    R = np.asarray(rates, dtype=np.float64)
    if R.ndim == 1:
        R = R[:, None]
    if R.ndim != 2 or R.size == 0:
        raise ValueError(f"rates must be a non-empty (replicates, objects) array, got shape {R.shape}")
    if not np.isfinite(R).all():
        raise ValueError("rates must be finite")
    return R


def bootstrap_means(rates, n_boot: int = BOOTSTRAP, seed: int = 0) -> np.ndarray:
    """Means of ``n_boot`` two-way bootstrap resamples of a (replicates, objects) matrix.

    Replicates and objects are resampled independently, with replacement.

    Examples
    --------
    >>> m = bootstrap_means(np.full((5, 3), 80.0), n_boot=10)
    >>> m.shape, bool(np.allclose(m, 80.0))
    ((10,), True)
    """
    R = _matrix(rates)
    rng = np.random.default_rng(seed)
    rows = rng.integers(0, R.shape[0], (n_boot, R.shape[0]))
    cols = rng.integers(0, R.shape[1], (n_boot, R.shape[1]))
    # Mean of R[rows][:, cols] without the (n_boot, r, c) array: count how often each cell is drawn.
    row_counts = np.zeros((n_boot, R.shape[0]))
    col_counts = np.zeros((n_boot, R.shape[1]))
    np.add.at(row_counts, (np.arange(n_boot)[:, None], rows), 1.0)
    np.add.at(col_counts, (np.arange(n_boot)[:, None], cols), 1.0)
    return np.einsum("br,rc,bc->b", row_counts, R, col_counts) / (R.shape[0] * R.shape[1])


def _by_name(R: np.ndarray, names) -> np.ndarray:
    """The columns in the order of their objects' names (as given when ``names`` is None)."""
    if names is None:
        return R
    names = list(names)
    if len(names) != R.shape[1] or len(set(names)) != len(names):
        raise ValueError(f"expected {R.shape[1]} distinct object names, got {names}")
    return R[:, np.argsort(names, kind="stable")]


def _interval(rates, seed, names=None) -> tuple[float, float]:
    R = _by_name(_matrix(rates), names)
    if R.size == 1:
        return float(R[0, 0]), float(R[0, 0])
    low, high = np.quantile(bootstrap_means(R, seed=seed), [0.025, 0.975])
    return float(low), float(high)


def summarize(rates, seed: int = 0, names=None) -> Summary:
    """Mean, per-replicate spread and 95 % bootstrap interval of a (replicates, objects) rate matrix.

    ``names`` (one per column) makes the interval independent of the column order.

    Examples
    --------
    >>> s = summarize([[100.0, 50.0], [100.0, 50.0]])
    >>> s.mean, s.std, s.ci_low, s.ci_high
    (75.0, 0.0, 50.0, 100.0)
    """
    R = _matrix(rates)
    per_replicate = R.mean(axis=1)
    std = float(per_replicate.std(ddof=1)) if len(per_replicate) > 1 else 0.0
    low, high = _interval(R, seed, names)
    return Summary(float(R.mean()), std, low, high, int(R.shape[0]))


def paired_difference(a, b, seed: int = 0, names=None) -> Difference:
    """The paired difference ``a - b`` of two (replicates, objects) rate matrices.

    ``names`` (one per column) makes the interval independent of the column order.

    Examples
    --------
    >>> d = paired_difference([[90.0, 80.0]] * 6, [[80.0, 70.0]] * 6)
    >>> d.mean, d.ci_low, d.ci_high, round(d.p_value, 4)
    (10.0, 10.0, 10.0, 0.0312)
    """
    A, B = _matrix(a), _matrix(b)
    if A.shape != B.shape:
        raise ValueError(f"paired rates must have equal shapes, got {A.shape} and {B.shape}")
    D = A - B
    per_replicate = D.mean(axis=1)
    if np.allclose(per_replicate, 0.0, atol=1e-12):
        p = 1.0
    else:
        p = float(stats.wilcoxon(per_replicate, zero_method="zsplit").pvalue)
    low, high = _interval(D, seed, names)
    return Difference(float(D.mean()), low, high, p, int(D.shape[0]))
