"""The connectivity of a triangle mesh: its edges, duplicate faces, orientation, fans and boundary loops.

Plain functions on ``(vertices, faces)`` arrays that :mod:`meshsal.mesh.repair`
runs in turn (its table says what each finds and does).  They change the
connectivity only, never a position: faces are dropped when another face
holds the same three vertices, turned, or given copies of their vertices.
"""

from __future__ import annotations

import numpy as np

from meshsal.mesh.geometry import area_vectors, half_edges

__all__ = [
    "Edges",
    "drop_duplicate_faces",
    "orient_patches",
    "radial_pairs",
    "split_fans",
    "boundary_loops",
    "flip_faces",
]


class Edges:
    """The undirected edges of a face list, each with its half-edges (one per face corner).

    Half-edge ``h = 3 f + i`` runs from ``F[f, i]`` to ``F[f, (i + 1) % 3]``;
    corner ``h`` is vertex ``F[f, i]`` of face ``f``.  One sort groups the
    half-edges by edge: ``order[starts[e]:starts[e] + counts[e]]`` are edge
    ``e``'s, in increasing order.

    Parameters
    ----------
    F : (m, 3) int64
    n : int
        More than the largest vertex index.

    Attributes
    ----------
    forward : (3m,) bool
        Whether each half-edge runs from the smaller vertex index to the larger.
    order, starts, counts : int64 arrays
        The grouping above.
    pairs : (k, 2) int64
        The two half-edges of each edge with exactly two faces.

    Examples
    --------
    >>> e = Edges(np.array([[0, 1, 2], [2, 1, 3]]), 4)
    >>> e.pairs.tolist(), e.consistent().tolist(), e.boundary().size
    ([[1, 3]], [True], 4)
    """

    def __init__(self, F: np.ndarray, n: int):
        start, end = half_edges(F)
        self.forward = start < end
        key = np.minimum(start, end) * n + np.maximum(start, end)
        size = len(key)
        if n * n * max(size, 1) < 2**62:
            # Sorting the keys with the half-edge in their low digits: twice as fast as an argsort.
            packed = np.sort(key * size + np.arange(size))
            ks, self.order = packed // size, packed % size
        else:
            self.order = np.argsort(key, kind="stable")
            ks = key[self.order]
        self.starts = np.flatnonzero(np.concatenate([[True], ks[1:] != ks[:-1]]))
        self.counts = np.diff(np.append(self.starts, len(ks)))
        two = self.starts[self.counts == 2]
        self.pairs = np.stack([self.order[two], self.order[two + 1]], axis=1)  # (k, 2) half-edges

    def consistent(self) -> np.ndarray:
        """For each two-face edge, whether its faces run along it in opposite directions."""
        return self.forward[self.pairs[:, 0]] != self.forward[self.pairs[:, 1]]

    def boundary(self) -> np.ndarray:
        """The half-edges of one-face edges."""
        return self.order[self.starts[self.counts == 1]]

    def nonmanifold(self) -> np.ndarray:
        """The half-edges of edges with more than two faces."""
        return self.order[np.repeat(self.counts > 2, self.counts)]

    def maybe_duplicated(self) -> bool:
        """Whether a face may repeat another's vertices: an edge with more than two faces, two faces running
        the same way along an edge, or two faces joined along all three of their edges."""
        if np.any(self.counts > 2) or not self.consistent().all():
            return True
        partner = np.full(len(self.forward), -1, dtype=np.int64)
        partner[self.pairs[:, 0]] = self.pairs[:, 1] // 3
        partner[self.pairs[:, 1]] = self.pairs[:, 0] // 3
        partner = partner.reshape(-1, 3)
        return bool(np.any((partner[:, 0] >= 0) & (partner[:, 0] == partner[:, 1]) & (partner[:, 1] == partner[:, 2])))


def _face_groups(F: np.ndarray, n: int) -> np.ndarray:
    """One integer per face, equal for faces on the same three vertices."""
    S = np.sort(F, axis=1)
    if n < 2**21:
        return (S[:, 0] * n + S[:, 1]) * n + S[:, 2]
    return np.unique(S, axis=0, return_inverse=True)[1].reshape(-1)


def drop_duplicate_faces(F: np.ndarray, UV, n: int):
    """Keep one face of each set of faces on the same three vertices.

    The copy kept is the one whose directed edges best agree with the faces
    around it that have no copy (each edge a neighbour runs the other way
    counts +1, the same way -1), the first in file order on a tie: of a
    double-sided face, the side its component faces is kept.

    Parameters
    ----------
    F : (m, 3) int64
    UV : (m, 3, 2) or None
        Kept with their faces.
    n : int
        The number of vertices.

    Returns
    -------
    F, UV : the faces kept, in file order
    duplicates : int
        Copies dropped that ran the same way round as the face kept.
    twins : int
        Copies dropped that ran the other way round (double-sided faces).

    Examples
    --------
    >>> F = np.array([[0, 1, 2], [2, 1, 0], [0, 2, 3], [3, 0, 2]])   # a twin, a duplicate
    >>> kept, _, duplicates, twins = drop_duplicate_faces(F, None, 4)
    >>> kept.tolist(), duplicates, twins
    ([[0, 1, 2], [0, 2, 3]], 1, 1)
    """
    key = _face_groups(F, n)
    order = np.argsort(key, kind="stable")
    ks = key[order]
    starts = np.concatenate([[True], ks[1:] != ks[:-1]])
    group = np.empty(len(F), dtype=np.int64)
    group[order] = np.cumsum(starts) - 1
    size = np.bincount(group)
    copied = size[group] > 1
    if not copied.any():
        return F, UV, 0, 0
    # Orientation of each face: with its smallest vertex first, are the other two increasing?
    rotate = np.argmin(F, axis=1)
    rows = np.arange(len(F))
    sign = F[rows, (rotate + 1) % 3] < F[rows, (rotate + 2) % 3]
    # Directed edges of the faces that have no copy: the neighbours every copy is scored against.
    alone = F[~copied]
    directed = np.sort(np.concatenate([alone[:, i] * n + alone[:, (i + 1) % 3] for i in range(3)]))
    candidates = np.flatnonzero(copied)
    score = np.zeros(len(candidates), dtype=np.int64)
    for i in range(3):
        u, v = F[candidates, i], F[candidates, (i + 1) % 3]
        score += _occurrences(directed, v * n + u) - _occurrences(directed, u * n + v)
    best = candidates[np.lexsort((candidates, -score, group[candidates]))]
    first_of_group = np.concatenate([[True], group[best][1:] != group[best][:-1]])
    kept = best[first_of_group]
    keep = ~copied
    keep[kept] = True
    kept_sign = np.zeros(size.size, dtype=bool)
    kept_sign[group[kept]] = sign[kept]
    dropped = ~keep
    twins = int(np.count_nonzero(dropped & (sign != kept_sign[group])))
    return F[keep], None if UV is None else UV[keep], int(np.count_nonzero(dropped)) - twins, twins


def _occurrences(sorted_keys: np.ndarray, keys: np.ndarray) -> np.ndarray:
    return np.searchsorted(sorted_keys, keys, side="right") - np.searchsorted(sorted_keys, keys, side="left")


def flip_faces(F, UV, which):
    """Turn the faces ``which`` (indices or a mask): ``(a, b, c)`` becomes ``(a, c, b)``, their uv likewise."""
    F = F.copy()
    F[which] = F[which][:, [0, 2, 1]]
    if UV is not None:
        UV = UV.copy()
        UV[which] = UV[which][:, [0, 2, 1]]
    return F, UV


def orient_patches(V: np.ndarray, F: np.ndarray, UV):
    """Orient each patch of faces joined by two-face edges consistently (libigl ``bfs_orient``).

    A patch keeps the orientation of most of its area as the faces have it;
    a turned face ``(a, b, c)`` becomes ``(a, c, b)``, its uv likewise.

    Returns
    -------
    F : (m, 3) int64
    UV : (m, 3, 2) or None
    flipped : int
        Faces turned.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    >>> F, _, flipped = orient_patches(V, np.array([[0, 1, 2], [1, 2, 3]]), None)
    >>> F.tolist(), flipped
    ([[0, 1, 2], [1, 3, 2]], 1)
    """
    import igl

    FF, patch = igl.bfs_orient(np.ascontiguousarray(F))
    flip = np.any(FF != F, axis=1)
    N = area_vectors(V, F)
    area = np.sqrt(np.einsum("ij,ij->i", N, N))
    flipped = np.bincount(patch, area * flip)
    total = np.bincount(patch, area)
    flip ^= (flipped > 0.5 * total)[patch]
    F, UV = flip_faces(F, UV, flip)
    return F, UV, int(np.count_nonzero(flip))


def _next_corner(h: np.ndarray) -> np.ndarray:
    """The next corner (or half-edge) of the same face."""
    return h - h % 3 + (h % 3 + 1) % 3


def _fans(pairs: np.ndarray, n_corners: int) -> tuple[int, np.ndarray]:
    """The fans of faces around each vertex: connected components of face corners.

    Each corner ``c`` (vertex ``v`` of its face) is joined to ``v``'s corner
    in the face across its outgoing half-edge ``c``, when ``c`` is paired
    with a half-edge of that face running the other way.  The graph has one
    link per corner at most, so it is built row by row, with no sort.
    """
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    around = np.full(n_corners, -1, dtype=np.int64)
    around[pairs[:, 0]] = _next_corner(pairs[:, 1])
    around[pairs[:, 1]] = _next_corner(pairs[:, 0])
    has = around >= 0
    indptr = np.concatenate([[0], np.cumsum(has)])
    graph = csr_matrix((np.ones(indptr[-1], dtype=np.int8), around[has], indptr), shape=(n_corners, n_corners))
    return connected_components(graph, directed=True, connection="weak")


def radial_pairs(V: np.ndarray, F: np.ndarray, edges: Edges) -> np.ndarray:
    """Pairs of half-edges that bound one solid at each edge with more than two faces, (k, 2) int64.

    Where two solids touch along an edge (two boxes sharing one), the edge
    holds four faces.  Sorted by angle around the edge, a face whose back
    (its solid side) looks at the next face's back bounds a wedge of solid
    with it: a face run against the edge's direction followed by one run
    along it.  Those two are paired, so that each solid stays closed when
    :func:`split_fans` cuts the edge; a face with no such neighbour (a fin)
    is cut off alone.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [0, 0, 1], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], float)
    >>> F = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4], [1, 0, 5]])   # four fins around one edge
    >>> radial_pairs(V, F, Edges(F, 6)).tolist()   # faces 3 and 0, 1 and 2 (half-edges 3 f + i) bound solids
    [[9, 0], [3, 6]]
    """
    big = np.repeat(edges.counts > 2, edges.counts)
    if not big.any():
        return np.zeros((0, 2), dtype=np.int64)
    group = np.repeat(np.arange(len(edges.counts)), edges.counts)[big]
    h = edges.order[big]
    f, i = h // 3, h % 3
    start, end, third = F[f, i], F[f, (i + 1) % 3], F[f, (i + 2) % 3]
    lo = np.minimum(start, end)
    axis = V[np.maximum(start, end)] - V[lo]
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    out = V[third] - V[lo]
    out -= np.einsum("ij,ij->i", out, axis)[:, None] * axis
    first = np.flatnonzero(np.concatenate([[True], group[1:] != group[:-1]]))
    rank = np.cumsum(np.concatenate([[True], group[1:] != group[:-1]])) - 1
    e1 = out[first][rank]
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(axis, e1)
    angle = np.arctan2(np.einsum("ij,ij->i", out, e2), np.einsum("ij,ij->i", out, e1))
    o = np.lexsort((angle, group))
    h, group = h[o], group[o]
    # The next half-edge around the edge, cyclically within each group.
    after = np.arange(len(h)) + 1
    last = np.concatenate([group[1:] != group[:-1], [True]])
    after[last] = first
    along = edges.forward[h]
    take = ~along & along[after]
    return np.stack([h[take], h[after[take]]], axis=1)


def split_fans(V: np.ndarray, F: np.ndarray, C, edges: Edges):
    """Give each fan of faces around a vertex its own copy of the vertex.

    Corners of two faces are joined across each edge the two share, running
    it in opposite directions; at an edge with more than two faces, the
    faces that bound one solid are joined (:func:`radial_pairs`), any other
    is cut off.  Two faces that run the same way along an edge (a
    non-orientable strip) are cut apart there.  So a fin is cut off as
    libigl's ``split_nonmanifold`` cuts it, but two boxes that share an
    edge stay closed.  Where a face cut off at an edge still reaches the
    faces kept there around both its ends, libigl's ``split_nonmanifold``
    (which stitches the faces together again only where the result stays
    manifold) finishes the job, so the result is always edge- and
    vertex-manifold.  The vertex order is kept: the fan holding a vertex's
    first corner keeps the vertex; the others get copies at the end, in
    order of their first corner.  Every vertex must be used by a face.

    Parameters
    ----------
    V : (n, 3) float64
    F : (m, 3) int64
    C : (n, 3) vertex colours or None
    edges : Edges of ``F``

    Returns
    -------
    None when every vertex has one fan, else
    V, F, C : with the copies
    split : int
        Vertices that had several fans.
    added : int
        Copies made.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], float)
    >>> F = np.array([[0, 1, 2], [0, 3, 4]])                   # two triangles meeting at a vertex
    >>> V2, F2, _, split, added = split_fans(V, F, None, Edges(F, 5))
    >>> F2.tolist(), split, added
    ([[0, 1, 2], [5, 3, 4]], 1, 1)
    """
    n = len(V)
    pairs = np.concatenate([edges.pairs[edges.consistent()], radial_pairs(V, F, edges)])
    n_fans, fan = _fans(pairs, F.size)
    if n_fans == n:
        if not np.any(edges.counts > 2):
            return None
        source = np.arange(n)  # every vertex one fan, yet a face cut off at an edge reaches round both its ends
    else:
        fan_vertex = np.empty(n_fans, dtype=np.int64)
        fan_vertex[fan] = F.reshape(-1)
        F, source = _keep_order(fan.reshape(-1, 3), fan_vertex, n)
    if np.any(Edges(F, len(source)).counts > 2):
        # A face cut off at an edge but joined to the faces kept there around both its ends: libigl
        # stitches the mesh again from separate faces, merging only what stays manifold.
        import igl

        SF, SVI = igl.split_nonmanifold(np.ascontiguousarray(F))
        F, again = _keep_order(SF, SVI, len(source))
        source = source[again]
    copies = np.bincount(source, minlength=n)
    return V[source], F, None if C is None else C[source], int(np.count_nonzero(copies > 1)), len(source) - n


def _keep_order(F: np.ndarray, origin: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Number the vertex copies in ``F`` (copy ``j`` of vertex ``origin[j]``, each of ``0..n-1`` copied) in order.

    The copy holding a vertex's first corner gets the vertex's index; the
    others get ``n, n + 1, ...`` in order of their first corner.  Returns
    the faces and, for each new index, the vertex it copies.
    """
    corners = F.reshape(-1)
    first = np.full(len(origin), corners.size, dtype=np.int64)
    np.minimum.at(first, corners, np.arange(corners.size))
    by_first = np.argsort(first, kind="stable")
    _, leading = np.unique(origin[by_first], return_index=True)
    primary = np.zeros(len(origin), dtype=bool)
    primary[by_first[leading]] = True
    extra = by_first[~primary[by_first]]
    index = np.empty(len(origin), dtype=np.int64)
    index[primary] = origin[primary]
    index[extra] = n + np.arange(extra.size)
    return index[F], np.concatenate([np.arange(n), origin[extra]])


def boundary_loops(F: np.ndarray, boundary: np.ndarray, n: int) -> int:
    """How many loops the boundary half-edges form."""
    if boundary.size == 0:
        return 0
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    flat = F.reshape(-1)
    start = flat[boundary]
    end = flat[_next_corner(boundary)]
    graph = coo_matrix((np.ones(start.size, dtype=np.int8), (start, end)), shape=(n, n))
    count, _ = connected_components(graph, directed=False)
    touched = np.zeros(n, dtype=bool)
    touched[start] = touched[end] = True
    return int(count - (n - np.count_nonzero(touched)))
