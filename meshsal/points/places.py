"""Candidate places to touch that depend on the shape alone: found again on every instance of an object.

A touch is recognized when training touched the same place, and a policy
that chooses touch by touch must predict what a place would feel like on
each object it might be.  Both need candidates that an instance offers
whatever its pose, size and paint: :func:`candidate_pool` (farthest-point
samples from the vertex farthest from the vertices' mean, the learned
method's candidates) and :func:`candidate_places` (that pool, then the
strongest peaks of mesh saliency outside it, so that geometry's most
distinctive places are always among the candidates).

:func:`signatures` locates a point on its shape whatever the pose and size:
its distances to the first :data:`LANDMARKS` pool places, which every
instance finds again, over the distance between the first two.  Under the
hypothesis "the object is j", a place of a test instance is the place of j
with the nearest signature.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from meshsal.mesh import Mesh, normal_defined
from meshsal.points.sampling import farthest_points, field_peaks
from meshsal.util.quantiles import percentiles

__all__ = [
    "POOL_FACTOR",
    "PEAK_FACTOR",
    "LANDMARKS",
    "candidate_pool",
    "candidate_places",
    "signatures",
    "similarity_fit",
    "RegistrationPlaces",
    "registration_places",
    "register",
    "landmarks_in",
]

#: Candidates per requested point in a pool.
POOL_FACTOR = 20
#: Mesh-saliency peaks per requested point added to the pool by :func:`candidate_places`.
PEAK_FACTOR = 2
#: The first pool places (found again on every instance) that :func:`signatures` locates points against.
LANDMARKS = 8


def candidate_pool(mesh: Mesh, n: int = 15) -> np.ndarray:
    """``POOL_FACTOR * n`` vertices spread over the surface, in farthest-point order.

    The first is the vertex farthest from the vertices' mean, so the pool
    depends on the shape alone: a turned, resized or repainted instance of an
    object offers the same candidates, and whatever a model picks among them
    can be found again on the next instance.

    Returns
    -------
    (k,) int64 vertex ids (k <= POOL_FACTOR * n: all used vertices on a small mesh)

    Examples
    --------
    >>> import meshsal
    >>> candidate_pool(meshsal.objects.toys.make("cup"), n=2).shape
    (40,)
    """
    # Only vertices a pad can be pressed along (with a normal): the same set on every instance.
    used = np.flatnonzero(normal_defined(mesh.vertices, mesh.faces))
    points = mesh.vertices[used]
    start = int(np.argmax(np.linalg.norm(points - points.mean(axis=0), axis=1)))
    return used[farthest_points(points, min(POOL_FACTOR * int(n), used.size), start=start)]


def candidate_places(
    mesh: Mesh, vertex_saliency: np.ndarray, n: int = 15, pool: np.ndarray | None = None
) -> np.ndarray:
    """:func:`candidate_pool`, then the ``PEAK_FACTOR * n`` strongest mesh-saliency peaks not in it.

    Parameters
    ----------
    mesh : Mesh
    vertex_saliency : (n_vertices,) float64, :func:`meshsal.mesh.curvature.mesh_saliency`
    n : int
        Points a method would choose; the candidates scale with it.
    pool : (k,) int, optional
        ``candidate_pool(mesh, n)`` when the caller has it already.

    Returns
    -------
    (P,) int64 vertex ids, distinct: the pool in farthest-point order, then peaks strongest first

    Examples
    --------
    >>> import meshsal
    >>> cup = meshsal.objects.toys.make("cup")
    >>> places = candidate_places(cup, meshsal.mesh_saliency(cup), n=2)
    >>> places.size, bool(np.all(places[:40] == candidate_pool(cup, n=2)))
    (44, True)
    """
    pool = candidate_pool(mesh, n) if pool is None else np.asarray(pool, np.int64)
    peaks = field_peaks(np.asarray(vertex_saliency, dtype=np.float64), mesh.faces)
    peaks = peaks[normal_defined(mesh.vertices, mesh.faces)[peaks]]
    return np.concatenate([pool, peaks[~np.isin(peaks, pool)][: PEAK_FACTOR * int(n)]]).astype(np.int64)


def signatures(positions, landmarks) -> np.ndarray:
    """Where each point lies on its shape, whatever the pose and size: (k, L) float64, or (k, J, L) against J
    landmark sets at once.

    A point's distances to the ``L`` landmarks (the first :data:`LANDMARKS`
    places of the instance's :func:`candidate_pool`), over the distance between
    the first two landmarks.  Invariant to rotation, translation and uniform
    scale; a shape symmetric under a turn that keeps the landmarks gives its
    symmetric points one signature, which is also all a touch can tell apart.

    Parameters
    ----------
    positions : (k, 3) float64
    landmarks : (L, 3) float64, in the same frame; or (J, L, 3), J sets (e.g. J objects' landmarks laid
        onto one instance, ``meshsal.points.frames.lay_landmarks``), each against its own first two

    Examples
    --------
    >>> X = np.array([[0.0, 0, 0], [10, 0, 0], [0, 5, 0]])
    >>> signatures(X, X).round(3).tolist()[2]
    [0.5, 1.118, 0.0]
    >>> turned = X @ np.array([[0.0, 1, 0], [-1, 0, 0], [0, 0, 1]]) * 3 + 7     # turned, scaled, moved
    >>> bool(np.allclose(signatures(turned, turned), signatures(X, X)))
    True
    >>> signatures(X, np.stack([X, 2 * X])).shape
    (3, 2, 3)
    """
    X = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    L = np.asarray(landmarks, dtype=np.float64)
    if L.ndim == 3:
        return _signatures_of_sets(X, L)
    L = L.reshape(-1, 3)
    d = np.linalg.norm(X[:, None, :] - L[None, :, :], axis=2)
    scale = float(np.linalg.norm(L[1] - L[0])) if len(L) > 1 else 0.0
    return d / scale if scale > 0 else d


def _signatures_of_sets(X: np.ndarray, L: np.ndarray) -> np.ndarray:
    """:func:`signatures` of points (k, 3) against J landmark sets (J, L, 3): (k, J, L), a landmark column at a
    time (no (k, J, L, 3) array)."""
    (J, n, _), out = L.shape, np.empty((len(X), *L.shape[:2]))
    for m in range(n):
        out[:, :, m] = np.linalg.norm(X[:, None, :] - L[None, :, m, :], axis=2)
    scale = np.linalg.norm(L[:, 1] - L[:, 0], axis=1) if n > 1 else np.zeros(J)
    out /= np.where(scale > 0, scale, 1.0)[None, :, None]
    return out


def similarity_fit(source, target) -> tuple[float, np.ndarray, np.ndarray]:
    """The similarity ``target ≈ s R source + t`` of least squares over corresponding points (Umeyama's solution).

    Parameters
    ----------
    source, target : (k, 3) float64, k >= 3 corresponding points; or (b, k, 3) for b fits at once

    Returns
    -------
    s : float, R : (3, 3) float64 proper rotation, t : (3,) float64 (with a leading (b,) axis for b fits)

    Examples
    --------
    >>> A = np.array([[0.0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 3]])
    >>> turn = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    >>> s, R, t = similarity_fit(A, 2.0 * A @ turn.T + 5.0)
    >>> round(float(s), 6), bool(np.allclose(R, turn)), bool(np.allclose(t, 5.0))
    (2.0, True, True)
    """
    A, B = np.asarray(source, np.float64), np.asarray(target, np.float64)
    batch = A.ndim == 3
    A, B = (A, B) if batch else (A[None], B[None])
    s, R, t = _fit_onto(_centered(A), B)
    return (s, R, t) if batch else (float(s[0]), R[0], t[0])


def _centered(A: np.ndarray) -> tuple:
    """The source side of :func:`similarity_fit` for (b, k, 3) points: their means, the centred points, their
    variances (shared by every target they are fitted onto)."""
    ma = A.mean(axis=1, keepdims=True)
    A0 = A - ma
    return ma, A0, (A0**2).sum(axis=(1, 2)) / A.shape[1]


def _fit_onto(source: tuple, B: np.ndarray) -> tuple:
    """:func:`similarity_fit` of :func:`_centered` sources onto (b, k, 3) targets: (b,) s, (b, 3, 3) R, (b, 3) t."""
    ma, A0, var = source
    mb = B.mean(axis=1, keepdims=True)
    B0 = B - mb
    U, S, Vt = np.linalg.svd(np.einsum("bki,bkj->bij", B0, A0) / A0.shape[1])
    sign = np.where(np.linalg.det(U @ Vt) < 0, -1.0, 1.0)
    D = np.ones((len(A0), 3))
    D[:, 2] = sign
    R = (U * D[:, None, :]) @ Vt
    s = np.where(var > 0, (S * D).sum(axis=1) / np.where(var > 0, var, 1.0), 1.0)
    t = mb[:, 0] - s[:, None] * np.einsum("bij,bj->bi", R, ma[:, 0])
    return s, R, t


# Moving places paired at a time (:func:`_pairs`).
_PAIR_ROWS = 8


def _pairs(gm: np.ndarray, gf: np.ndarray, keep: int) -> np.ndarray:
    """For each moving signature (row of ``gm``, (m, L)), the fixed one (row of ``gf``, (n, L)) nearest on the
    ``keep`` coordinates that agree best: (m,) int64 indices into ``gf``.

    A few moving rows at a time keep their (rows, n, L) differences in
    cache (1.6x faster at 330 places); each row pairs on its own, so the
    pairs are those of all rows at once, bit for bit.  Fewer than 8 squares
    are summed first to last, one (rows, n) plane at a time, as NumPy's
    reduction over so short an axis sums them (it sums 8 or more pairwise).
    """
    pair = np.empty(len(gm), np.int64)
    for a in range(0, len(gm), _PAIR_ROWS):
        d = np.partition(np.abs(gm[a : a + _PAIR_ROWS, None, :] - gf[None, :, :]), keep - 1, axis=2)[:, :, :keep]
        if keep < 8:
            d *= d
            total = d[:, :, 0].copy()
            for c in range(1, keep):
                total += d[:, :, c]
        else:
            total = (d**2).sum(axis=2)
        pair[a : a + _PAIR_ROWS] = np.argmin(total, axis=1)
    return pair


@dataclass(frozen=True, eq=False)
class RegistrationPlaces:
    """Places with what :func:`register` reads of them, computed once: pass one in place of the (m, 3) array
    when the same places are registered many times (a test instance onto every object it might be).

    ``positions`` (m, 3) float64, starting with their landmarks; ``signatures``
    (m, min(LANDMARKS, m)) float64 against those landmarks; ``spread`` float,
    the root-mean-square distance of the places from their mean.  The k-d tree
    of the places and the RANSAC's centred triples of a seed are built when
    first needed.

    Examples
    --------
    >>> pts = np.random.default_rng(0).normal(size=(60, 3)) * [40, 20, 10]
    >>> once = registration_places(pts)
    >>> all(np.array_equal(a, b) for a, b in zip(register(once, 2 * pts), register(pts, 2 * pts)))
    True
    """

    positions: np.ndarray
    signatures: np.ndarray
    spread: float
    _sources: dict = field(default_factory=dict, repr=False)

    def __len__(self) -> int:
        return len(self.positions)

    @functools.cached_property
    def tree(self):
        """scipy.spatial.cKDTree of the places."""
        from scipy.spatial import cKDTree

        return cKDTree(self.positions)

    def sources(self, seed: int, rounds: int) -> tuple:
        """The RANSAC's (rounds, 3) triples of a numeric seed and their centred points (:func:`_centered`)."""
        key = (seed, rounds)
        if key not in self._sources:
            picks = _seeded_samples(seed, rounds, len(self))
            self._sources[key] = (picks, _centered(self.positions[picks]))
        return self._sources[key]


def registration_places(points) -> RegistrationPlaces:
    """:class:`RegistrationPlaces` of (m, 3) places (returned as they are when they already are)."""
    if isinstance(points, RegistrationPlaces):
        return points
    X = np.asarray(points, np.float64)
    spread = float(np.sqrt(((X - X.mean(axis=0)) ** 2).sum(axis=1).mean()))
    return RegistrationPlaces(X, signatures(X, X[:LANDMARKS]), spread)


def register(
    moving, fixed, rng=0, rounds: int = 200, keep: int = 5, refine: int = 10
) -> tuple[float, np.ndarray, np.ndarray]:
    """The similarity that lays the candidate places of one instance onto those of another of the same shape.

    Both sets are places of :func:`candidate_places` (or any samples of the
    surfaces that start with their own :data:`LANDMARKS`), in any pose and
    size and from any tessellation.  Each moving place is first paired with
    the fixed place of the nearest :func:`signatures`, compared on the
    ``keep`` of their :data:`LANDMARKS` coordinates that agree best (a
    landmark that another tessellation moved spoils only its own
    coordinate); a seeded RANSAC over those pairs finds the similarity most
    of them agree with, and up to ``refine`` rounds of trimmed closest-point
    fitting refine it (stopping early once a round pairs the places as the
    last one did: its fit would repeat the last one).  Where a shape is
    symmetric, one of its symmetric poses is found: its symmetric places
    feel alike anyway.

    Parameters
    ----------
    moving, fixed : (m, 3), (n, 3) float64, each starting with its landmarks, or :class:`RegistrationPlaces`
    rng : numpy Generator or int, the RANSAC's draws
    rounds : int, RANSAC samples
    keep : int, signature coordinates compared per pair
    refine : int, closest-point rounds at most

    Returns
    -------
    s, R, t : ``fixed ≈ s R moving + t``

    Examples
    --------
    >>> pts = np.random.default_rng(0).normal(size=(60, 3)) * [40, 20, 10]
    >>> turn = np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]])
    >>> s, R, t = register(pts, 1.5 * pts @ turn.T - 3.0)
    >>> round(s, 6), bool(np.allclose(R, turn))
    (1.5, True)
    """
    moving, fixed = registration_places(moving), registration_places(fixed)
    M, F = moving.positions, fixed.positions
    L = min(LANDMARKS, len(M), len(F))
    if L > 1:  # signatures against the first L landmarks are the first L columns of those against more
        gm, gf = moving.signatures[:, :L], fixed.signatures[:, :L]
    else:
        gm, gf = signatures(M, M[:L]), signatures(F, F[:L])
    pair = _pairs(gm, gf, min(keep, L))
    scale = fixed.spread
    size = scale / max(moving.spread, 1e-300)
    tol = 0.05 * scale
    if isinstance(rng, (int, np.integer)):
        picks, source = moving.sources(int(rng), rounds)
    else:
        picks = _samples(rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng), rounds, len(M))
        source = _centered(M[picks])
    S, R, T = _fit_onto(source, F[pair[picks]])
    counts = (_misfits(S, R, T, M, F[pair]) < tol).sum(axis=1)
    counts[~_plausible(S, size)] = -1
    b = int(np.argmax(counts))
    if counts[b] < 0:  # every sample collapses the shape: the sizes and centroids are all that can be matched
        return float(size), np.eye(3), F.mean(axis=0) - size * M.mean(axis=0)
    s, R, t = float(S[b]), R[b], T[b]
    inliers = np.linalg.norm(s * M @ R.T + t - F[pair], axis=1) < tol
    if inliers.sum() >= 3:
        s, R, t = _unless_collapsed(similarity_fit(M[inliers], F[pair[inliers]]), (s, R, t), size)
    last = None
    for _ in range(refine):
        dist, nearest = fixed.tree.query(s * M @ R.T + t)
        close = dist <= percentiles(dist[None], 80.0)[0]  # np.quantile(dist, 0.8), bit for bit
        kept = nearest[close]
        if last is not None and np.array_equal(close, last[0]) and np.array_equal(kept, last[1]):
            break  # the same pairs as the last round: its fit, which gave (s, R, t), again
        last = (close, kept)
        s, R, t = _unless_collapsed(similarity_fit(M[close], F[kept]), (s, R, t), size)
    return float(s), R, t


def _samples(rng: np.random.Generator, rounds: int, m: int) -> np.ndarray:
    """(rounds, 3) int64: the RANSAC's triples of distinct indices below ``m``, drawn from ``rng``."""
    return np.argsort(rng.random((rounds, m)), axis=1)[:, :3]


@functools.lru_cache(maxsize=16)
def _seeded_samples(seed: int, rounds: int, m: int) -> np.ndarray:
    """:func:`_samples` of a new generator seeded ``seed``: drawn once per seed and size (a test instance is
    registered onto many objects with one seed), read-only."""
    picks = _samples(np.random.default_rng(seed), rounds, m)
    picks.flags.writeable = False
    return picks


def _misfits(S, R, T, M, target) -> np.ndarray:
    """(b, k) distances from ``S[b] R[b] M[k] + T[b]`` to ``target[k]``, for b similarities at once.

    Coordinate by coordinate on (b, k) arrays, in place (a new array of
    that size per operation costs more than the arithmetic); each sum is
    taken in the order ``np.einsum("bij,kj->bki")`` takes it, so the
    distances are those of the einsum and ``np.linalg.norm``, bit for bit,
    at a fraction of the cost.
    """
    x, y, z = M[:, 0], M[:, 1], M[:, 2]
    out = np.empty((len(S), len(M)))
    d = np.empty_like(out)
    term = np.empty_like(out)
    for i in range(3):
        np.multiply(R[:, i, 0, None], x, out=d)
        d += np.multiply(R[:, i, 2, None], z, out=term)
        d += np.multiply(R[:, i, 1, None], y, out=term)
        d *= S[:, None]
        d += T[:, i, None]
        d -= target[:, i]
        if i == 0:
            np.multiply(d, d, out=out)
        else:
            out += np.multiply(d, d, out=d)
    return np.sqrt(out, out=out)


def _plausible(s, size: float):
    """Whether scales ``s`` keep the moving shape within a thousandfold of the size that matches the fixed one.

    A fit to places of another shape can shrink every place onto a few
    fixed ones (scale 0): such a fit locates nothing, and dividing by it
    would give infinite landmarks.
    """
    s = np.asarray(s, np.float64)
    return np.isfinite(s) & (s > 1e-3 * size) & (s < 1e3 * size)


def _unless_collapsed(fit, previous, size: float):
    """``fit`` when its scale is :func:`_plausible`, else ``previous``."""
    return fit if bool(_plausible(fit[0], size)) else previous


def landmarks_in(moving, fixed, rng=0) -> np.ndarray:
    """The landmarks of ``fixed`` laid onto ``moving``'s frame by :func:`register`: (LANDMARKS, 3) float64.

    Points of ``moving`` located against them (:func:`signatures`) are
    located as the places of ``fixed`` are, even where another tessellation
    gave ``moving`` landmarks of its own elsewhere.  Either may be
    :class:`RegistrationPlaces`.
    """
    fixed = registration_places(fixed)
    s, R, t = register(moving, fixed, rng)
    L = fixed.positions[:LANDMARKS]
    return ((L - t) @ R) / s
