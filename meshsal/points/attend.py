"""The paper's interest points, steps 2-5, on the mesh: the best set of views, its salient peaks, votes.

The paper's pipeline (Rouhafzay, Pedneault & Cretu, 2017), done on the mesh:

1. render the 72 views of :func:`meshsal.views.cameras.view_rig` and compute
   each one's saliency map (:mod:`meshsal.attention.rig`, masked to the
   object; the mesh saliency of the curvature channel is computed once);
2. choose the best set of 4 views: the highest average saliency level, where
   a view's level is the accumulated saliency divided by the image's pixel
   count (so a set that shows more salient surface wins);
3. find the salient peaks of the best set's maps (local maxima above
   ``threshold`` times the map's maximum) and map each one onto the surface
   exactly through ``face_id`` and ``bary``;
4. rank the peaks by votes, then by saliency value.  A view votes for a peak
   when some vertex within ``min_spacing`` of it (along mesh edges) lies
   under a salient pixel of that view (value above ``threshold`` times the
   view's maximum); then the selection every method shares
   (:mod:`meshsal.points.select`): spaced, touchable, filled from mesh
   saliency's peaks;
5. keep the top ``n``.
"""

from __future__ import annotations

import numpy as np

from meshsal.mesh import Mesh, normal_defined, vertex_normals
from meshsal.mesh.geometry import edge_graph
from meshsal.points.record import InterestPoints
from meshsal.points.rules import PointOptions, Rules
from meshsal.points.select import TouchFilter, saliency_fill, select, surface_candidates

__all__ = ["best_view_set", "map_peaks", "salient_vertices", "view_votes", "attention_points", "check_field"]


def check_field(mesh: Mesh, vertex_saliency) -> np.ndarray:
    """``vertex_saliency`` as (n_vertices,) float64; ValueError if its shape is not the mesh's."""
    field = np.asarray(vertex_saliency, dtype=np.float64)
    if field.shape != (mesh.n_vertices,):
        raise ValueError(f"vertex_saliency must have shape ({mesh.n_vertices},), got {field.shape}")
    return field


def best_view_set(maps: np.ndarray, views_per_set: int = 4) -> int:
    """Index of the set of views with the highest average saliency level.

    A view's level is its map's sum over the image's pixel count; sets are
    consecutive groups of ``views_per_set`` maps; ties go to the lower index.

    Examples
    --------
    >>> maps = np.zeros((8, 4, 4), np.float32); maps[5, :2] = 1.0
    >>> best_view_set(maps)
    1
    """
    maps = np.asarray(maps, dtype=np.float64)
    if maps.ndim != 3 or maps.shape[0] % views_per_set:
        raise ValueError(f"expected (k * {views_per_set}, H, W) maps, got shape {maps.shape}")
    level = maps.reshape(maps.shape[0], -1).mean(axis=1)
    return int(np.argmax(level.reshape(-1, views_per_set).mean(axis=1)))


def map_peaks(saliency_map: np.ndarray, mask: np.ndarray, threshold: float = 0.5, radius: int | None = None):
    """Local maxima of a saliency map above ``threshold`` times its maximum.

    A pixel is a peak when it equals the maximum of its ``(2 radius + 1)``
    square neighbourhood, lies on the object and exceeds the threshold.

    Parameters
    ----------
    saliency_map : (H, W) float
    mask : (H, W) bool
    threshold : float in [0, 1)
    radius : int, optional
        Neighbourhood radius in pixels; default ``max(1, H // 64)`` so that
        the peaks do not depend on the image size.

    Returns
    -------
    rows, cols : (k,) int64, strongest first (ties in raster order)

    Examples
    --------
    >>> m = np.zeros((9, 9), np.float32); m[2, 3] = 1.0; m[6, 6] = 0.7; m[6, 2] = 0.2
    >>> [r.tolist() for r in map_peaks(m, np.ones((9, 9), bool))]
    [[2, 6], [3, 6]]
    """
    import cv2

    m = np.asarray(saliency_map, dtype=np.float32)
    top = float(m[mask].max()) if np.any(mask) else 0.0
    if top <= 0:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    r = max(1, m.shape[0] // 64) if radius is None else int(radius)
    local_max = cv2.dilate(m, np.ones((2 * r + 1, 2 * r + 1), np.uint8))
    rows, cols = np.nonzero((m >= local_max) & mask & (m > threshold * top))
    order = np.lexsort((cols, rows, -m[rows, cols]))
    return rows[order].astype(np.int64), cols[order].astype(np.int64)


def salient_vertices(mesh: Mesh, views, maps: np.ndarray, threshold: float):
    """(72, n) sparse 0/1: the vertices of faces under each view's salient pixels."""
    from scipy import sparse

    rows, cols = [], []
    for k, (view, m) in enumerate(zip(views, maps)):
        hot = view.mask & (m > threshold * m.max()) if m.max() > 0 else np.zeros_like(view.mask)
        verts = mesh.faces[view.face_id[hot]].ravel()
        rows.append(np.full(verts.size, k))
        cols.append(verts)
    r, c = np.concatenate(rows), np.concatenate(cols)
    # Repeated (view, vertex) pairs add up; only non-zero matters.
    counts = sparse.csr_matrix((np.ones(r.size, np.float32), (r, c)), shape=(len(views), mesh.n_vertices))
    counts.data[:] = 1.0
    return counts


def view_votes(graph, salient, vertex_ids: np.ndarray, radius: float, chunk: int = 32):
    """Views voting for each vertex: some vertex within ``radius`` along ``graph`` is salient there.

    ``graph`` is the mesh's :func:`meshsal.mesh.geometry.edge_graph`.

    Returns
    -------
    votes : (k,) int64, how many views vote for each of ``vertex_ids``
    views : tuple of k tuples of int, which views
    """
    from scipy.sparse.csgraph import dijkstra

    found = []
    for start in range(0, vertex_ids.size, chunk):
        ids = vertex_ids[start : start + chunk]
        near = np.isfinite(dijkstra(graph, indices=ids, limit=radius))
        # Sparse views times a dense 0/1 block: whole counts, so the same hits as any other product.
        hits = np.asarray(salient @ near.T.astype(np.float32)) > 0
        found.extend(tuple(np.flatnonzero(hits[:, j]).tolist()) for j in range(ids.size))
    return np.array([len(f) for f in found], dtype=np.int64), tuple(found)


def _best_set_values(mesh: Mesh, views, maps, set_views) -> np.ndarray:
    """Per vertex, the largest best-set map value over pixels showing one of its faces."""
    best = np.zeros(mesh.n_vertices)
    for k in set_views:
        hit = views[k].mask
        corners = mesh.faces[views[k].face_id[hit]]
        values = np.repeat(maps[k][hit].astype(np.float64), 3)
        np.maximum.at(best, corners.ravel(), values)
    return best


def attention_points(
    mesh: Mesh,
    views,
    maps: np.ndarray,
    vertex_saliency: np.ndarray,
    rules: Rules | None = None,
    combination: str = "equal",
    method: str = "attention",
    scene=None,
    touch: TouchFilter | None = None,
    **changes,
) -> InterestPoints:
    """Steps 2-5 of the pipeline on views and saliency maps already computed.

    Parameters
    ----------
    mesh : Mesh
    views : list of 72 View, maps : (72, H, W) float32
        From :func:`meshsal.attention.rig.saliency_maps`.
    vertex_saliency : (n_vertices,) float64
    rules : Rules, optional
        Default: ``PointOptions(**changes).rules(mesh)`` (``n``, ``min_spacing``,
        ``threshold``, ``pad_width``, ``touch``, ``touch_tolerance`` as in
        :class:`~meshsal.points.rules.PointOptions`).
    combination : str
        How ``maps`` were combined, recorded in the result.
    method : str
        The attention method's name recorded in the result ("attention", "attention_itti"...).
    scene : optional
        The mesh's Embree scene (:func:`meshsal.mesh.embree.embree_scene`) for the touch check, built
        when omitted.
    touch : TouchFilter, optional
        The touch check the methods of one call share (built on ``scene`` when omitted).

    Returns
    -------
    InterestPoints
    """
    rules = PointOptions(**changes).rules(mesh) if rules is None else rules
    threshold, spacing = rules.threshold, rules.min_spacing
    vertex_saliency = check_field(mesh, vertex_saliency)
    maps = np.asarray(maps)
    if maps.shape[0] != len(views):
        raise ValueError(f"got {len(views)} views but {maps.shape[0]} saliency maps")
    vn = vertex_normals(mesh.vertices, mesh.faces)
    best = best_view_set(maps)
    set_views = range(4 * best, 4 * best + 4)
    faces, bary, scores = [], [], []
    for k in set_views:
        rows, cols = map_peaks(maps[k], views[k].mask, threshold)
        faces.append(views[k].face_id[rows, cols].astype(np.int64))
        bary.append(views[k].bary[rows, cols].astype(np.float64))
        scores.append(maps[k][rows, cols].astype(np.float64))
    faces, bary, scores = np.concatenate(faces), np.concatenate(bary), np.concatenate(scores)
    bary /= bary.sum(axis=1, keepdims=True)
    found = surface_candidates(mesh, vn, faces, bary, scores)

    graph = edge_graph(mesh.vertices, mesh.faces)
    salient = salient_vertices(mesh, views, maps, threshold)
    votes, _ = view_votes(graph, salient, found.vertex_ids, spacing)
    peaks = found.take(np.lexsort((np.arange(len(found)), -scores, -votes)))
    seen = _best_set_values(mesh, views, maps, set_views)
    checker = (touch or TouchFilter(mesh, rules, scene)) if rules.touch else None
    chosen, lost = select(
        peaks,
        saliency_fill(mesh, vn, vertex_saliency, lambda i: seen[i]),
        rules,
        checker,
        normal_defined(mesh.vertices, mesh.faces),
    )
    votes, voters = view_votes(graph, salient, chosen.vertex_ids, spacing)
    return InterestPoints(
        vertex_ids=chosen.vertex_ids,
        positions=chosen.positions,
        normals=chosen.normals,
        scores=chosen.scores,
        votes=votes,
        vertex_saliency=vertex_saliency,
        views=voters,
        method=method,
        best_set=best,
        min_spacing=spacing,
        combination=combination,
        untouchable=lost,
        frame=mesh.transform,
    )
