"""Banks: each object's training touches grouped by place, as the place-aware recognizer holds them.

An entry is one place of an object (its touches on every training
instance, pooled by place key), located by its signature; a bank is one
object's entries, with a k-d tree over their signatures and a fixed
place-free subsample of its touches (``classify.recognizers.place``).
"""

from __future__ import annotations

import numpy as np

from classify.runtime.cluster import release_free_memory

__all__ = [
    "Bank",
    "BankStack",
    "RESIDUAL_ROWS",
    "entries",
    "evenly_spaced",
    "free_d2",
    "free_subsample",
    "lse",
    "sample_d2",
    "spacing",
    "within_place_whitening",
]


def lse(a: np.ndarray, axis: int, keepdims: bool = False) -> np.ndarray:
    """log(sum(exp(a))) along ``axis``, -inf where every term is -inf (a lean ``scipy.special.logsumexp``)."""
    top = np.max(a, axis=axis, keepdims=True)
    top = np.where(np.isfinite(top), top, 0.0)
    with np.errstate(divide="ignore"):
        out = np.log(np.exp(a - top).sum(axis=axis, keepdims=True)) + top
    return out if keepdims else np.squeeze(out, axis=axis)


class Bank:
    """One object's entries: signatures (E, L), standardized samples (E, S, d), each sample's instance (E, S; -1
    pads), and a place-free subsample (F, d) with its instances (F,)."""

    def __init__(self, keys, signatures, samples, instances, free, free_instances, match_width):
        from scipy.spatial import cKDTree

        # Distances to an entry's samples are taken in float32: a fraction of the memory traffic, and far
        # finer than the kernel's width.
        self.keys, self.signatures, self.instances = keys, signatures, instances
        self.samples = np.ascontiguousarray(samples, np.float32)
        self.free, self.free_instances, self.match_width = free, free_instances, match_width
        self.tree = cKDTree(signatures)
        self.sq = np.einsum("esd,esd->es", self.samples, self.samples)
        self.free_sq = np.einsum("fd,fd->f", free, free)


#: Bytes of lent bank samples between two hand-backs of the heap's freed pages while a stack is built.
_RELEASE_EVERY = 1 << 26


class BankStack:
    """Every object's bank in padded arrays, to score a touch under all objects in one pass.

    Built from the banks: signatures (C, E, L) and their squared norms (C, E),
    inf past an object's entries; the entries' samples, squared norms and
    instances stacked object after object, with one empty entry last (every
    sample -1) that a pick past an object's entries points to; the
    place-free samples (C, F, d) and their instances (C, F), -1 past an
    object's.  With ``lend``, each bank then reads its samples, their
    squared norms and instances, and its place-free samples, from views of
    the stack's (the same values), as soon as they are copied, and the
    pages of its own go back to the system (``release_free_memory``): the
    samples are held once, and never twice even while the stack is built
    (at 1,000 objects they are hundreds of megabytes per process).
    """

    def __init__(self, banks: list, lend: bool = False):
        C, E = len(banks), max(len(b.keys) for b in banks)
        L, d = banks[0].signatures.shape[1], banks[0].samples.shape[2]
        S, F = max(b.samples.shape[1] for b in banks), max(len(b.free) for b in banks)
        self.entries = np.array([len(b.keys) for b in banks], np.int64)
        self.starts = np.r_[0, np.cumsum(self.entries)[:-1]]
        self.signatures, self.sig_sq = np.zeros((C, E, L)), np.full((C, E), np.inf)
        total = int(self.entries.sum())
        # Zeros are mapped, not written: an object's rows take memory as its bank's are copied and let go.
        self.samples = np.zeros((total + 1, S, d), np.float32)
        self.sq = np.zeros((total + 1, S), np.float32)
        self.instances = np.full((total + 1, S), -1, np.int64)
        self.free, self.free_sq = np.zeros((C, F, d)), np.zeros((C, F))
        self.free_instances = np.full((C, F), -1, np.int64)
        self.match_width = np.array([b.match_width for b in banks], np.float64)
        lent = 0
        for c, (b, a) in enumerate(zip(banks, self.starts)):
            e, s, f = len(b.keys), b.samples.shape[1], len(b.free)
            self.signatures[c, :e] = b.signatures
            self.sig_sq[c, :e] = np.einsum("el,el->e", b.signatures, b.signatures)
            self.samples[a : a + e, :s], self.sq[a : a + e, :s] = b.samples, b.sq
            self.instances[a : a + e, :s] = b.instances
            self.free[c, :f], self.free_sq[c, :f], self.free_instances[c, :f] = b.free, b.free_sq, b.free_instances
            if lend:
                lent += b.samples.nbytes
                b.samples, b.sq, b.instances = (x[a : a + e, :s] for x in (self.samples, self.sq, self.instances))
                b.free, b.free_sq, b.free_instances = (x[c, :f] for x in (self.free, self.free_sq, self.free_instances))
                # A bank's arrays, below the mmap threshold, came from the heap: their pages go back as they go, or
                # every bank would stay resident beside the stack.
                if lent >= _RELEASE_EVERY or c == C - 1:
                    release_free_memory()
                    lent = 0

    def match(self, G: np.ndarray, neighbours: int) -> tuple[np.ndarray, np.ndarray]:
        """(m, C, K) stacked entry rows and log weights (summing to one) of places G (m, L), the same under every
        object, or (m, C, L), each object's own: each object's ``neighbours`` entries of nearest signature,
        weighted as ``PlaceAware`` weighs them."""
        (C, E, L), m = self.signatures.shape, len(G)
        K = min(int(neighbours), E)
        if G.ndim == 3:
            d2 = np.matmul(G.transpose(1, 0, 2), self.signatures.transpose(0, 2, 1)).transpose(1, 0, 2).copy()
            norms = np.einsum("mcl,mcl->mc", G, G)[:, :, None]
        else:
            d2 = (G @ self.signatures.reshape(C * E, L).T).reshape(m, C, E)
            norms = np.einsum("ml,ml->m", G, G)[:, None, None]
        d2 *= -2.0
        d2 += norms
        d2 += self.sig_sq[None]  # inf past an object's entries
        np.maximum(d2, 0.0, out=d2)
        pick = np.argpartition(d2, K - 1, axis=2)[..., :K] if K < E else np.tile(np.arange(E), (m, C, 1))
        near = np.take_along_axis(d2, pick, axis=2)
        order = np.argsort(near, axis=2, kind="stable")
        pick, near = np.take_along_axis(pick, order, axis=2), np.take_along_axis(near, order, axis=2)
        real = pick < self.entries[None, :, None]
        with np.errstate(invalid="ignore"):
            logw = np.where(real, -0.5 * (near - near[..., :1]) / self.match_width[None, :, None] ** 2, -np.inf)
        rows = np.where(real, self.starts[None, :, None] + pick, len(self.samples) - 1)
        return rows, logw - lse(logw, axis=2, keepdims=True)


def entries(keys, Z, signatures, instances):
    """Group one object's touches by place key: sorted keys, (E, L) signatures, (E, S, d) samples, (E, S)
    instances (-1 pads)."""
    order = np.lexsort((instances, keys))
    keys, Z, signatures, instances = keys[order], Z[order], signatures[order], instances[order]
    unique, start, count = np.unique(keys, return_index=True, return_counts=True)
    S = int(count.max())
    samples = np.zeros((unique.size, S, Z.shape[1]))
    inst = np.full((unique.size, S), -1, np.int64)
    for e, (a, c) in enumerate(zip(start, count)):
        samples[e, :c] = Z[a : a + c]
        inst[e, :c] = instances[a : a + c]
    return unique, signatures[start], samples, inst


def evenly_spaced(n: int, size: int) -> np.ndarray:
    """Indices of at most ``size`` of ``n`` positions, evenly spaced from the first to the last, increasing.

    Positions are truncated (``shortlist.spread`` rounds them): the
    place-aware fit picks its place-free touches and held-out touches so.

    Examples
    --------
    >>> evenly_spaced(10, 4).tolist()
    [0, 3, 6, 9]
    >>> evenly_spaced(8, 3).tolist()
    [0, 3, 7]
    """
    return np.unique(np.linspace(0, n - 1, min(size, n)).astype(np.int64))


def free_subsample(keys, instances, size: int) -> np.ndarray:
    """Indices of one object's place-free subsample among its touches: about ``size`` of them, in place order.

    The picks are evenly spaced over the touches in place order (each place's
    touches by instance), so they spread over the places.  Leaving a training
    instance out must leave samples of the object, or the place-free term and
    the screening would never name it for that instance's touches.  When the
    spacing takes every pick from one instance (it aliases with places that
    each hold as many touches as the step) and the object has others, each
    instance's own touches are spread over instead, by their share of the
    touches and at least one each.

    Parameters
    ----------
    keys : (n,) int64, each touch's place key
    instances : (n,) int64, each touch's training instance
    size : int

    Returns
    -------
    (F,) int64, F <= n, ordered by place key, then instance

    Examples
    --------
    Place 0 touched four times on instances 1 and 2, place 1 once on
    instance 1: two evenly spaced picks, the first touch and the last, are
    both instance 1's.

    >>> keys, inst = np.array([0] * 8 + [1]), np.array([1] * 4 + [2] * 4 + [1])
    >>> inst[free_subsample(keys, inst, 2)].tolist()
    [1, 2]
    """
    keys, instances = np.asarray(keys, np.int64), np.asarray(instances, np.int64)
    n = len(keys)
    order = np.lexsort((instances, keys))
    pick = order[evenly_spaced(n, size)]
    ids, counts = np.unique(instances, return_counts=True)
    if np.unique(instances[pick]).size > 1 or ids.size == 1:
        return pick
    taken, placed = np.zeros(n, bool), instances[order]
    for v, count in zip(ids, counts):
        own = np.flatnonzero(placed == v)  # positions in place order
        share = min(count, max(1, round(size * count / n)))
        taken[own[evenly_spaced(count, share)]] = True
    return order[taken]


def spacing(signatures) -> float:
    """Median distance from an entry's signature to its nearest other entry's."""
    from scipy.spatial import cKDTree

    if len(signatures) < 2:
        return 1.0
    d = cKDTree(signatures).query(signatures, k=2)[0][:, 1]
    d = d[d > 0]
    return float(np.median(d)) if d.size else 1.0


#: Residual rows ``within_place_whitening`` holds at once (44 MB of 42 float64 descriptors).
RESIDUAL_ROWS = 1 << 17


def within_place_whitening(Z, y, keys, rows: int = RESIDUAL_ROWS) -> np.ndarray:
    """(d, d) map that makes the touches of one place spread alike in every direction: the inverse square root
    of the pooled covariance of the touches about their place's mean, shrunk towards its diagonal.

    The residuals are formed ``rows`` at a time, never as a touch-sized array
    (a thousand objects' codebooks are millions of touches); up to ``rows``
    touches they are one block, one product.
    """
    _, group = np.unique(np.c_[y, keys], axis=0, return_inverse=True)
    group = group.reshape(-1)
    means = np.zeros((group.max() + 1, Z.shape[1]))
    np.add.at(means, group, Z)
    means /= np.bincount(group)[:, None]
    W = np.zeros((Z.shape[1], Z.shape[1]))
    for a in range(0, len(Z), rows):
        R = means[group[a : a + rows]]
        np.subtract(Z[a : a + rows], R, out=R)
        W += R.T @ R
    W /= max(len(Z) - group.max() - 1, 1)
    W = 0.9 * W + 0.1 * np.diag(np.diag(W)) + 1e-6 * np.trace(W) / len(W) * np.eye(len(W))
    vals, vecs = np.linalg.eigh(W)
    return vecs @ np.diag(1.0 / np.sqrt(vals)) @ vecs.T


def sample_d2(bank, Z, idx, exclude):
    """Squared distances from each touch Z (n, d) to the samples of its matched entries ``idx`` (n, ...): (n, ...,
    S); inf for padding and for samples of the touch's excluded instance (n,).  ``bank`` is a :class:`Bank`
    (``idx`` (n, K)) or a :class:`BankStack` (``idx`` (n, C, K) stacked rows)."""
    Y = bank.samples[idx]  # (n, ..., S, d)
    z = Z.astype(np.float32)
    lead = (slice(None),) + (None,) * idx.ndim
    d2 = np.einsum("nd,nd->n", z, z)[lead] + bank.sq[idx] - 2.0 * np.einsum("nd,n...sd->n...s", z, Y)
    d2 = d2.astype(np.float64)
    inst = bank.instances[idx]
    bad = (inst < 0) | (inst == exclude[lead])
    return np.where(bad, np.inf, np.maximum(d2, 0.0))


def free_d2(bank, Z, exclude):
    """Squared distances from each touch Z (n, d) to the place-free samples of ``bank``: (n, F) for a
    :class:`Bank`, (n, C, F) for a :class:`BankStack`; inf for padding and for samples of the touch's excluded
    instance (n,)."""
    shape = bank.free.shape[:-1]
    lead = (slice(None),) + (None,) * len(shape)
    fd2 = np.einsum("nd,nd->n", Z, Z)[lead] + bank.free_sq[None]
    fd2 -= 2.0 * (Z @ bank.free.reshape(-1, Z.shape[1]).T).reshape(len(Z), *shape)
    np.maximum(fd2, 0.0, out=fd2)
    inst = bank.free_instances[None]
    fd2[np.broadcast_to((inst < 0) | (inst == exclude[lead]), fd2.shape)] = np.inf
    return fd2
