"""Candidate places to touch that depend on the shape alone: found again on every instance of an object.

A touch is recognized when training touched the same place, and a policy
that chooses touch by touch must predict what a place would feel like on
each object it might be.  Both need candidates that an instance offers
whatever its pose, size and paint: :func:`candidate_pool` (farthest-point
samples from the vertex farthest from the vertices' mean, the learned
method's candidates) and :func:`candidate_places` (that pool, then the
strongest peaks of mesh saliency outside it, so that geometry's most
distinctive places are always among the candidates).
"""

from __future__ import annotations

import numpy as np

from meshsal.mesh import Mesh, normal_defined
from meshsal.points.sampling import farthest_points, field_peaks

__all__ = ["POOL_FACTOR", "PEAK_FACTOR", "candidate_pool", "candidate_places"]

#: Candidates per requested point in a pool.
POOL_FACTOR = 20
#: Mesh-saliency peaks per requested point added to the pool by :func:`candidate_places`.
PEAK_FACTOR = 2


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
