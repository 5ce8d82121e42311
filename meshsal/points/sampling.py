"""Points on a mesh: random and farthest-point samples, field peaks, non-maximum suppression.

The building blocks of every interest-point method in :mod:`meshsal.points`.
Spacing is Euclidean: two points closer than ``min_spacing`` in 3-D would
share a tactile sensor's footprint whatever the path between them on the
surface.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from meshsal.mesh.geometry import face_areas, ring_max, vertex_adjacency

__all__ = [
    "random_surface_points",
    "farthest_points",
    "field_peaks",
    "Suppression",
    "suppress",
]


def random_surface_points(vertices: np.ndarray, faces: np.ndarray, n: int, seed=0):
    """Uniform random points on the surface (faces drawn by area).

    Parameters
    ----------
    vertices : (n_v, 3) float64
    faces : (m, 3) int
    n : int
    seed : int or numpy Generator

    Returns
    -------
    face_ids : (n,) int64
    bary : (n, 3) float64
        Barycentric weights of each face's vertices; the point is
        ``bary @ vertices[faces[face_id]]``.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]]); F = np.array([[0, 1, 2]])
    >>> f, b = random_surface_points(V, F, 4, seed=1)
    >>> f.tolist(), bool(np.allclose(b.sum(axis=1), 1))
    ([0, 0, 0, 0], True)
    """
    rng = np.random.default_rng(seed)
    area = face_areas(vertices, faces)
    if not area.sum() > 0:
        raise ValueError("cannot sample a surface of zero area")
    face_ids = rng.choice(area.size, size=int(n), p=area / area.sum())
    r1, r2 = rng.random(int(n)), rng.random(int(n))
    # Folding the unit square onto the triangle keeps the density uniform.
    s = np.sqrt(r1)
    bary = np.stack([1.0 - s, s * (1.0 - r2), s * r2], axis=1)
    return face_ids.astype(np.int64), bary


def farthest_points(points: np.ndarray, n: int, start: int = 0) -> np.ndarray:
    """Greedy farthest-point sampling: each new point is the farthest from those chosen.

    Parameters
    ----------
    points : (k, 3) float64
    n : int
        How many to choose (at most ``k``).
    start : int
        Index of the first point.

    Returns
    -------
    (min(n, k),) int64 indices into ``points``, in the order chosen.

    Examples
    --------
    >>> P = np.array([[0, 0, 0], [1, 0, 0], [0.1, 0, 0], [0.5, 0, 0.]])
    >>> farthest_points(P, 3).tolist()
    [0, 1, 3]
    """
    P = np.asarray(points, dtype=np.float64)
    n = min(int(n), P.shape[0])
    chosen = np.empty(n, dtype=np.int64)
    if n == 0:
        return chosen
    chosen[0] = start
    # One contiguous column per axis and reused buffers: the same sums as np.linalg.norm's
    # ((dx^2 + dy^2) + dz^2), at a third of its cost per step.
    columns = np.ascontiguousarray(P.T)
    dist = np.full(P.shape[0], np.inf)
    d, t = np.empty_like(dist), np.empty_like(dist)
    for i in range(n):
        if i:
            chosen[i] = int(np.argmax(dist))
        d.fill(0.0)
        for axis, c in enumerate(columns):
            np.subtract(c, P[chosen[i], axis], out=t)
            np.multiply(t, t, out=t)
            np.add(d, t, out=d)
        np.sqrt(d, out=d)
        np.minimum(dist, d, out=dist)
    return chosen


def field_peaks(field: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Vertices where a per-vertex field beats every neighbour of its 1-ring.

    Parameters
    ----------
    field : (n,) float
    faces : (m, 3) int

    Returns
    -------
    (k,) int64 vertex ids, strongest first (ties by index); isolated vertices are left out.

    Examples
    --------
    >>> F = np.array([[0, 1, 2], [1, 3, 2]])
    >>> field_peaks(np.array([0.0, 5.0, 1.0, 2.0]), F).tolist()
    [1]
    """
    f = np.asarray(field, dtype=np.float64)
    adjacency = vertex_adjacency(faces, f.size)
    has_ring = np.diff(adjacency.indptr) > 0
    peaks = np.flatnonzero(has_ring & (f > ring_max(adjacency, f)))
    return peaks[np.lexsort((peaks, -f[peaks]))]


@dataclass(frozen=True)
class Suppression:
    """What :func:`suppress` kept: indices in the order chosen, and how many candidates ``accept`` refused."""

    chosen: np.ndarray
    refused: int = 0


def suppress(
    points: np.ndarray,
    min_spacing: float,
    n: int | None = None,
    ids: np.ndarray | None = None,
    taken_points: np.ndarray | None = None,
    taken_ids: np.ndarray | None = None,
    accept: Callable[[np.ndarray], np.ndarray] | None = None,
) -> Suppression:
    """Greedy selection in the given order, skipping points too close to one already chosen.

    Candidates must come sorted by priority (best first).  A candidate is
    skipped if it lies closer than ``min_spacing`` to a chosen or already
    ``taken`` point, or shares an id (e.g. its nearest vertex) with one.
    ``accept``, when given, is asked about the candidates next in line, each
    candidate once, in batches of as many as are still wanted or, when more,
    as many as it has refused so far; its verdict on a candidate must not
    depend on the batch, so the batches change only how often it is asked.
    A refused candidate blocks nothing, so the next in line takes its place
    exactly as if it had never been proposed.

    Parameters
    ----------
    points : (k, 3) float64, best first
    min_spacing : float >= 0
    n : int, optional
        Stop after this many (default: as many as fit).
    ids : (k,) int, optional
        Labels that must stay distinct (e.g. vertex ids).
    taken_points : (t, 3) float64, optional
        Points already chosen by an earlier pass.
    taken_ids : (t,) int, optional
    accept : callable, optional
        ``accept(indices) -> (len(indices),) bool`` for indices into ``points``.

    Returns
    -------
    Suppression
        ``chosen`` (j,) int64 indices into ``points``, no two closer than
        ``min_spacing``; ``refused`` the candidates reached in line that
        ``accept`` refused.

    Examples
    --------
    >>> P = np.array([[0, 0, 0], [0.05, 0, 0], [1, 0, 0], [0.5, 0, 0.]])
    >>> s = suppress(P, 0.4, accept=lambda i: i != 0)
    >>> s.chosen.tolist(), s.refused
    ([1, 2, 3], 1)
    """
    from scipy.spatial import cKDTree

    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if not min_spacing >= 0:
        raise ValueError(f"min_spacing must be >= 0, got {min_spacing}")
    limit = P.shape[0] if n is None else int(n)
    ids = None if ids is None else np.asarray(ids)
    if P.shape[0] == 0 or limit <= 0:
        return Suppression(np.empty(0, dtype=np.int64))
    alive = np.ones(P.shape[0], dtype=bool)
    tree = cKDTree(P)
    # Spacing is "no two closer than": points exactly min_spacing apart may both stay.
    radius = np.nextafter(min_spacing, 0.0) if min_spacing > 0 else 0.0

    def block(point, label):
        alive[tree.query_ball_point(point, radius)] = False
        if ids is not None and label is not None:
            alive[ids == label] = False

    if taken_points is not None:
        taken_points = np.asarray(taken_points, dtype=np.float64).reshape(-1, 3)
        labels = [None] * len(taken_points) if taken_ids is None else list(taken_ids)
        for point, label in zip(taken_points, labels):
            block(point, label)
    verdict = np.zeros(P.shape[0], np.int8)  # 0 not asked, 1 accepted, -1 refused
    chosen, refused = [], 0
    i = 0
    while len(chosen) < limit:
        ahead = i + np.flatnonzero(alive[i:])
        if ahead.size == 0:
            break
        if accept is not None and verdict[ahead[0]] == 0:
            # Where many are refused, many more are asked at once: one call for the thousand
            # refusals on a concave mesh's way to its last point, instead of a thousand calls.
            batch = ahead[verdict[ahead] == 0][: max(limit - len(chosen), refused)]
            verdict[batch] = np.where(np.asarray(accept(batch), bool), 1, -1)
        # Along the line while verdicts are known: refused ones are passed over, chosen ones block.
        for i in ahead:
            if not alive[i]:
                continue
            if accept is not None and verdict[i] == 0:
                break
            alive[i] = False
            if verdict[i] < 0:
                refused += 1
                continue
            chosen.append(int(i))
            block(P[i], None if ids is None else ids[i])
            if len(chosen) == limit:
                break
    return Suppression(np.asarray(chosen, dtype=np.int64), refused)
