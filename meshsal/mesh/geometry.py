"""Geometry derived from ``(vertices, faces)`` arrays: normals, areas, adjacency, bounds.

Plain functions in the style of libigl: nothing is cached on the mesh.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "face_normals",
    "face_areas",
    "area_vectors",
    "vertex_area_vectors",
    "vertex_normals",
    "normal_defined",
    "NORMAL_TOLERANCE",
    "bounding_sphere",
    "surface_distance",
    "closed_orientation",
    "half_edges",
    "vertex_adjacency",
    "edge_graph",
    "ring_max",
    "tangent_frames",
]

#: A vertex has a normal when the area vectors of its faces sum to more than this fraction of their
#: total length: far above rounding (1e-16), so a face and its flipped twin, whose vectors cancel up
#: to rounding in whatever corner order they are written, leave their vertices without one.
NORMAL_TOLERANCE = 1e-9


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit normals of the faces, (m, 3) float64; zero for degenerate faces."""
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces)
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0)


def face_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Areas of the faces, (m,) float64."""
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces)
    return 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)


def area_vectors(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Each face's ``(b - a) x (c - a)``: its normal times twice its area, (m, 3) float64.

    The same numbers as ``np.cross`` on the gathered corners, computed one
    coordinate at a time on contiguous arrays: four times faster.

    Examples
    --------
    >>> area_vectors(np.eye(3), [[0, 1, 2]]).tolist()
    [[1.0, 1.0, 1.0]]
    """
    X = np.ascontiguousarray(np.asarray(vertices, dtype=np.float64).T)
    corners = np.ascontiguousarray(np.asarray(faces, dtype=np.int64).reshape(-1, 3).T)
    (xa, xb, xc), (ya, yb, yc), (za, zb, zc) = (X[d][corners] for d in range(3))
    ux, uy, uz = xb - xa, yb - ya, zb - za
    vx, vy, vz = xc - xa, yc - ya, zc - za
    return np.stack([uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx], axis=1)


def vertex_area_vectors(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Each vertex's area-weighted normal before normalizing: the sum of its faces' :func:`area_vectors`.

    Its direction is the vertex's :func:`vertex_normals`; its length is at
    most twice the area of the vertex's faces, less where they turn away
    from each other.

    Parameters
    ----------
    vertices, faces : (n, 3) float64 and (m, 3) int

    Returns
    -------
    (n, 3) float64; zero at vertices no face uses.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    >>> vertex_area_vectors(V, [[0, 1, 2], [0, 3, 1]]).tolist()  # two right triangles folded along the x axis
    [[0.0, 1.0, 1.0], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]]
    """
    F = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    N = area_vectors(vertices, F)
    corners, n = F.T.reshape(-1), len(vertices)
    return np.stack([np.bincount(corners, weights=np.tile(N[:, d], 3), minlength=n) for d in range(3)], axis=1)


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals, (n, 3) float64; zero at isolated vertices.

    The directions of :func:`vertex_area_vectors`, summed by libigl.
    """
    import igl

    V = np.ascontiguousarray(vertices, dtype=np.float64)
    F = np.ascontiguousarray(faces, dtype=np.int64)
    # libigl sums in C++, three times faster than NumPy's bincount; it leaves NaN where no face adds.
    N = igl.per_vertex_normals(V, F, igl.PER_VERTEX_NORMALS_WEIGHTING_TYPE_AREA)
    return np.nan_to_num(N, copy=False, nan=0.0)


def normal_defined(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Whether each vertex has an area-weighted normal, (n,) bool.

    A vertex has none when no face uses it, or when the area vectors of its
    faces cancel: their sum is at most :data:`NORMAL_TOLERANCE` times the
    sum of their lengths.  That happens at the corners of a face and its
    flipped twin when no other face meets them (a double-sided triangle),
    and along a flat fold, where a surface turns back onto itself.  There
    :func:`vertex_normals` is zero or a direction made of rounding errors,
    so no pad can be pressed along it: such a vertex must not be an
    interest point.

    Parameters
    ----------
    vertices, faces : (n, 3) float64 and (m, 3) int

    Returns
    -------
    (n,) bool

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [5, 5, 5]], float)
    >>> normal_defined(V, [[0, 1, 2], [0, 2, 1], [0, 1, 3]]).tolist()  # 2 meets a face and its twin only
    [True, True, False, True, False]
    """
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    n = V.shape[0]
    if F.size == 0:
        return np.zeros(n, dtype=bool)
    N = area_vectors(V, F)
    total = np.bincount(F.T.reshape(-1), np.tile(np.sqrt(np.einsum("ij,ij->i", N, N)), 3), minlength=n)
    summed = vertex_area_vectors(V, F)
    return np.sqrt(np.einsum("ij,ij->i", summed, summed)) > NORMAL_TOLERANCE * total


def closed_orientation(vertices: np.ndarray, faces: np.ndarray) -> int:
    """Whether the faces bound a solid, and which way they face.

    Returns
    -------
    int
        +1 if every edge joins exactly two faces that run along it in
        opposite directions (closed, edge-manifold, consistently oriented)
        and the enclosed volume is positive (normals point out); -1 for such
        a surface with its normals pointing in; 0 for any other surface.

    Examples
    --------
    >>> tetra = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    >>> closed_orientation(tetra, [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    1
    >>> closed_orientation(tetra, [[0, 2, 1], [0, 1, 3], [0, 3, 2]])  # one face missing
    0
    """
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(F) < 4:
        return 0
    start, end = half_edges(F)
    if np.any(start == end):
        return 0
    # One sort pairs each edge's two uses: its key, and which way the use runs along it.
    n = int(F.max()) + 1
    key = np.sort((np.minimum(start, end) * n + np.maximum(start, end)) * 2 + (start < end))
    forward, backward = key[0::2], key[1::2]
    if not (
        np.array_equal(forward >> 1, backward >> 1)
        and np.all(forward & 1 == 0)
        and np.all(backward & 1 == 1)
        and np.all((forward[1:] >> 1) > (backward[:-1] >> 1))
    ):
        return 0
    # Six times the enclosed volume: the sum of det(a, b, c) over the faces.
    (xa, xb, xc), (ya, yb, yc), (za, zb, zc) = (np.take(V[:, d], F.T) for d in range(3))
    volume = np.sum(xa * (yb * zc - yc * zb) + ya * (zb * xc - zc * xb) + za * (xb * yc - xc * yb))
    return int(np.sign(volume))


def bounding_sphere(vertices: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and radius of a sphere enclosing all vertices.

    The centre is the bounding box centre, so the sphere is tight to within
    a factor sqrt(3) and moves with the mesh under similarity transforms.

    Returns
    -------
    center : (3,) float64
    radius : float
    """
    V = np.asarray(vertices, dtype=np.float64)
    # Reducing the transposed (3, n) view runs along contiguous memory: several times faster.
    center = 0.5 * (V.T.min(axis=1) + V.T.max(axis=1))
    offset = V - center
    return center, float(np.sqrt(np.einsum("ij,ij->i", offset, offset).max()))


def surface_distance(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Distance from each point to the nearest point of the surface, (k,) float64.

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int
    points : (k, 3) float

    Examples
    --------
    >>> V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    >>> surface_distance(V, np.array([[0, 1, 2]]), [[0.2, 0.2, 0.5], [2.0, 0.0, 0.0]]).round(6).tolist()
    [0.5, 1.0]
    """
    import igl

    V = np.ascontiguousarray(vertices, dtype=np.float64)
    F = np.ascontiguousarray(faces, dtype=np.int64)
    P = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
    if len(P) == 0:
        return np.zeros(0)
    squared, _, _ = igl.point_mesh_squared_distance(P, V, F)
    return np.sqrt(squared)


def half_edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each face corner's directed edge to the next corner: (3m,) int64 start and end vertex ids.

    Examples
    --------
    >>> [a.tolist() for a in half_edges([[0, 1, 2]])]
    [[0, 1, 2], [1, 2, 0]]
    """
    F = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    return F.ravel(), F[:, [1, 2, 0]].ravel()


def vertex_adjacency(faces: np.ndarray, n_vertices: int):
    """Symmetric vertex adjacency of the mesh edges as a scipy CSR matrix of ones, (n, n)."""
    from scipy import sparse

    i, j = half_edges(faces)
    A = sparse.coo_matrix((np.ones(i.size), (i, j)), shape=(n_vertices, n_vertices)).tocsr()
    A = ((A + A.T) > 0).astype(np.float64)
    return A.tocsr()


def edge_graph(vertices: np.ndarray, faces: np.ndarray):
    """The mesh's edges as a symmetric (n, n) scipy CSR graph weighted by their lengths, each edge once.

    Shortest paths along it (``scipy.sparse.csgraph.dijkstra``) are distances
    along mesh edges.  A zero-length edge keeps a tiny positive weight, so it
    still joins its two vertices.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [3, 0, 0], [0, 4, 0], [3, 4, 0.]])
    >>> G = edge_graph(V, [[0, 1, 2], [1, 3, 2]])
    >>> float(G[0, 1]), float(G[1, 2]), float(G[2, 1])
    (3.0, 5.0, 5.0)
    """
    import igl
    from scipy import sparse

    V = np.asarray(vertices, dtype=np.float64)
    E = igl.edges(np.ascontiguousarray(faces, dtype=np.int64))
    length = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    length = np.maximum(length, 1e-12 * max(float(length.max(initial=0.0)), 1e-300))
    n = len(V)
    return sparse.coo_matrix(
        (np.r_[length, length], (np.r_[E[:, 0], E[:, 1]], np.r_[E[:, 1], E[:, 0]])), shape=(n, n)
    ).tocsr()


def ring_max(adjacency, values: np.ndarray) -> np.ndarray:
    """The largest of ``values`` over each vertex's 1-ring, (n,) float64; -inf for a vertex without neighbours.

    Parameters
    ----------
    adjacency : (n, n) scipy CSR, e.g. :func:`vertex_adjacency`
    values : (n,) float

    Examples
    --------
    >>> A = vertex_adjacency([[0, 1, 2]], 4)
    >>> ring_max(A, np.array([1.0, 2.0, 3.0, 9.0])).tolist()
    [3.0, 3.0, 2.0, -inf]
    """
    values = np.asarray(values, dtype=np.float64)
    heads = np.flatnonzero(np.diff(adjacency.indptr))
    out = np.full(adjacency.shape[0], -np.inf)
    out[heads] = np.maximum.reduceat(values[adjacency.indices], adjacency.indptr[heads])
    return out


# Within 10 degrees of the poles world +y projects too short to orient a frame.
_POLE_COS = float(np.cos(np.deg2rad(10.0)))


def tangent_frames(normals: np.ndarray, angles_deg=None) -> tuple[np.ndarray, np.ndarray]:
    """Deterministic tangent axes ``(ups, rights)`` for unit normals, turned by ``angles_deg``.

    The frame of a tactile pad's image (``tactile``) and of the disc a pad
    sweeps in the touch check (``meshsal.points.touch``).

    At angle 0 the image's up is world +y projected onto the pad plane, so
    imprints of a y-up object appear upright.  Within 10 degrees of the
    poles (normal near +-y) it is -z for a normal near +y (looking down, the
    back of the object is up) and +z near -y.  ``right = cross(up, normal)``.
    A positive angle turns the pad's axes clockwise as seen from outside
    (the new up is ``cos a * up + sin a * right``), so the image content turns
    counter-clockwise: 90 degrees gives exactly ``np.rot90(image)`` (k=1) of
    the unturned image on a square pad.

    Parameters
    ----------
    normals : (k, 3) float64, unit
    angles_deg : (k,) float64, optional

    Returns
    -------
    ups, rights : (k, 3) float64

    Examples
    --------
    >>> up, right = tangent_frames(np.array([[0.0, 0.0, 1.0]]))
    >>> up.round(6).tolist(), right.round(6).tolist()
    ([[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    """
    N = np.asarray(normals, dtype=np.float64)
    ny = N[:, 1]
    ref = np.zeros_like(N)
    polar = np.abs(ny) > _POLE_COS
    ref[~polar, 1] = 1.0
    ref[polar, 2] = -np.sign(ny[polar])
    up = ref - (ref * N).sum(1, keepdims=True) * N
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    right = np.cross(up, N)
    if angles_deg is not None:
        a = np.deg2rad(np.asarray(angles_deg, dtype=np.float64))[:, None]
        c, s = np.cos(a), np.sin(a)
        up, right = c * up + s * right, c * right - s * up
    return up, right
