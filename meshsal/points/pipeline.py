"""Interest points fused on the mesh from the saliency of 72 views, and the baselines.

The paper's pipeline (Rouhafzay, Pedneault & Cretu, 2017), done on the mesh:

1. render the 72 views of :func:`meshsal.views.render.view_rig` and compute each
   one's saliency map (:func:`meshsal.attention.saliency`, masked to the
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
   view's maximum); then non-maximum suppression: no two points closer than
   ``min_spacing`` (Euclidean), each on a distinct nearest vertex, and each
   touchable: the pad pressed along the point's normal meets the surface
   there first (:mod:`meshsal.points.touch`), else the next candidate takes its place;
5. keep the top ``n``.

Step 1 combines the eight channels with the paper's equal weights
(``combination="equal"``) or weights each by Itti's N(.) (``"itti"``).

``pad_width`` is the tactile pad's width in mesh units (default 32/150 of
the bounding-box diagonal: the 32 mm of a 16 x 16 pad at 2 mm pitch on an
object of 150 mm diagonal), and ``min_spacing`` defaults to half of it, so
that neighbouring touches do not share most of their contact.  On a small
object that spacing holds fewer points: the fill below stops when no more
fit, rather than overlapping touches.  Every length is relative to the
mesh's size, so translating or uniformly scaling a mesh leaves the chosen
vertices unchanged.  The baselines obey the same spacing and touch rule.

When fewer than ``n`` points survive the suppression, the rest are filled
from the peaks of the per-vertex mesh saliency (strongest first), then from
all vertices in order of mesh saliency, always under the same spacing; a
mesh too small to hold ``n`` points that far apart yields fewer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshsal.mesh.embree import embree_scene
from meshsal.mesh import Mesh, face_normals, vertex_normals
from meshsal.util.registry import Registry
from meshsal.points.sampling import farthest_points, field_peaks, random_surface_points
from meshsal.points.touch import default_pad_width, touchable

__all__ = [
    "METHODS",
    "POINT_METHODS",
    "InterestPoints",
    "interest_points",
    "default_min_spacing",
    "saliency_maps",
    "best_view_set",
    "map_peaks",
    "attention_points",
    "project_pixel_paper",
    "COMBINATIONS",
    "ATTENTION_METHODS",
    "MODEL_METHODS",
    "attention_combination",
    "ViewChannels",
    "view_channels",
    "attention_maps",
    "learned_points",
    "points_by_method",
]

#: How the attention channels are combined: the paper's equal weights, Itti's N(.) on each, or
#: weights learned from touches (``meshsal.points.learned``; given as ``weights``).
COMBINATIONS = ("equal", "itti", "learned")
#: The attention methods and the combination each uses ("attention" takes the one asked for).
ATTENTION_METHODS = {"attention": "equal", "attention_itti": "itti", "attention_learned": "learned"}
#: Methods that need a fitted ``meshsal.points.learned.TouchModel`` (``model=``).
MODEL_METHODS = ("learned", "attention_learned")

POINTS_FORMAT = "visuotactile.points"
POINTS_VERSION = 1
#: Candidates drawn per requested point by the random baseline (dart throwing).
RANDOM_POOL = 64


@dataclass(frozen=True, eq=False)
class InterestPoints:
    """Points chosen on a mesh, best first, in the mesh's own units and frame.

    Attributes
    ----------
    vertex_ids : (k,) int64
        The mesh vertex nearest each point (distinct).
    positions : (k, 3) float64
        Exact surface points (a peak's pixel mapped through face and
        barycentric coordinates; a vertex for vertex-based methods).
    normals : (k, 3) float64
        Unit outward normals: vertex normals interpolated at the point.
    scores : (k,) float64
        The value the method ranks by: for "attention", the saliency-map value
        at the point in the best set (a peak's own value; for filled points the
        largest value over the pixels showing the vertex); mesh saliency for
        "mesh_saliency", "random" and "uniform"; absolute mean curvature for
        "curvature".
    votes : (k,) int64
        How many of the 72 views found the point salient ("attention"; 0 otherwise).
    vertex_saliency : (n,) float64
        Mesh saliency of every vertex (:func:`meshsal.mesh.curvature.mesh_saliency`).
    views : tuple of tuples of int
        For each point, the indices (0-71) of the views that voted for it.
    method : str
    best_set : int
        Index (0-17) of the best set of 4 views; -1 for the baselines.
    min_spacing : float
        The spacing used, in mesh units.
    combination : str
        How the attention channels were combined ("equal", "itti"); "" for the baselines.
    untouchable : int
        Candidates skipped because the pad could not touch them first (-1: not tested).
    """

    vertex_ids: np.ndarray
    positions: np.ndarray
    normals: np.ndarray
    scores: np.ndarray
    votes: np.ndarray
    vertex_saliency: np.ndarray
    views: tuple
    method: str
    best_set: int
    min_spacing: float
    combination: str = ""
    untouchable: int = -1

    def __len__(self) -> int:
        return int(self.vertex_ids.size)

    def save(self, path, frame=None, source: str = "", settings: dict | None = None) -> None:
        """Write the points as a versioned ``points.json``, in the mesh file's own frame, atomically.

        Parameters
        ----------
        path : str or os.PathLike
        frame : meshsal.Similarity, optional
            The mesh's ``transform``: positions, normals and the spacing are
            written mapped back to the file's frame and units.
        source : str
            The mesh file (or object name) the points belong to.
        settings : dict, optional
            How they were chosen, recorded as given.

        Examples
        --------
        >>> import pathlib, tempfile
        >>> from meshsal import toys
        >>> pts = interest_points(toys.make("cup"), n=3, method="uniform")
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "points.json"
        >>> pts.save(path, source="cup")
        >>> again = InterestPoints.load(path)
        >>> again.method, bool(np.allclose(again.positions, pts.positions))
        ('uniform', True)
        """
        import json

        from meshsal.util.atomic import write_text
        from meshsal.mesh import Similarity

        frame = Similarity() if frame is None else frame
        positions = frame.to_source(self.positions)
        normals = frame.direction_to_source(self.normals)
        records = [{"id": k + 1, "vertex": int(self.vertex_ids[k]), "position": positions[k].tolist(),
                    "normal": normals[k].tolist(), "score": float(self.scores[k]), "votes": int(self.votes[k]),
                    "views": list(self.views[k])} for k in range(len(self))]
        document = {"format": POINTS_FORMAT, "version": POINTS_VERSION, "mesh": str(source),
                    "units": "source units and frame of the mesh file", "method": self.method,
                    "best_set": int(self.best_set), "min_spacing": float(frame.length_to_source(self.min_spacing)),
                    "combination": self.combination, "untouchable": int(self.untouchable),
                    "settings": settings or {}, "points": records,
                    "vertex_saliency": np.asarray(self.vertex_saliency, np.float64).tolist()}
        write_text(path, json.dumps(document, indent=1) + "\n")

    @classmethod
    def load(cls, path) -> InterestPoints:
        """Points from a ``points.json``, in the file's frame and units (ValueError naming the file).

        Files of this format's version 1 give every field back.  Older
        files without a ``format`` key give positions, normals and ids only
        (``vertex_ids`` -1, no scores, votes or saliency).
        """
        return _read_points(path)


@dataclass(frozen=True, eq=False)
class _LoadedPoints(InterestPoints):
    """Points read from a file, with the ids the file gave them (1..k when written by ``save``)."""

    ids: np.ndarray = None


def _read_points(path) -> InterestPoints:
    from pathlib import Path

    from meshsal.util.jsonfile import read_json

    path = Path(path)
    document = read_json(path, "points file")
    if not isinstance(document, dict) or not isinstance(document.get("points"), list):
        raise ValueError(f"{path}: expected an object with a 'points' list (as written by 'visuotactile points')")
    version = document.get("version", 0) if document.get("format", POINTS_FORMAT) == POINTS_FORMAT else None
    if version is None or not isinstance(version, int) or version > POINTS_VERSION:
        raise ValueError(f"{path}: not a points file this version reads (format {document.get('format')!r}, "
                         f"version {document.get('version')!r}; this reads {POINTS_FORMAT} up to {POINTS_VERSION})")
    items = document["points"]
    if not items:
        raise ValueError(f"{path}: the 'points' list is empty")
    positions, normals, ids, vertices, scores, votes, views = [], [], [], [], [], [], []
    for k, item in enumerate(items):
        where = f"{path}: points[{k}]"
        if not isinstance(item, dict):
            raise ValueError(f"{where} is not an object")
        for key, out in (("position", positions), ("normal", normals)):
            value = item.get(key)
            try:
                vector = np.asarray(value, dtype=np.float64)
            except (TypeError, ValueError):
                vector = None
            if vector is None or vector.shape != (3,) or not np.isfinite(vector).all():
                raise ValueError(f"{where}: '{key}' must be three finite numbers, got {value!r}")
            out.append(vector)
        if np.linalg.norm(normals[-1]) < 1e-12:
            raise ValueError(f"{where}: 'normal' is zero")
        point_id = item.get("id", k + 1)
        if isinstance(point_id, bool) or not isinstance(point_id, int):
            raise ValueError(f"{where}: 'id' must be an integer, got {point_id!r}")
        ids.append(point_id)
        vertices.append(int(item.get("vertex", -1)))
        scores.append(float(item.get("score", 0.0)))
        votes.append(int(item.get("votes", 0)))
        views.append(tuple(int(v) for v in item.get("views", ())))
    N = np.array(normals)
    return _LoadedPoints(vertex_ids=np.array(vertices, np.int64), positions=np.array(positions),
                         normals=N / np.linalg.norm(N, axis=1, keepdims=True), scores=np.array(scores),
                         votes=np.array(votes, np.int64),
                         vertex_saliency=np.asarray(document.get("vertex_saliency", []), np.float64),
                         views=tuple(views), method=str(document.get("method", "unknown")),
                         best_set=int(document.get("best_set", -1)),
                         min_spacing=float(document.get("min_spacing", 0.0)),
                         combination=str(document.get("combination", "")),
                         untouchable=int(document.get("untouchable", -1)), ids=np.array(ids, np.int64))


def attention_combination(method: str, combination: str = "equal") -> str:
    """The channel combination an attention method uses: its own, or ``combination`` for "attention" and others."""
    return ATTENTION_METHODS[method] if method in ATTENTION_METHODS and method != "attention" else combination


def default_min_spacing(mesh: Mesh, pad_width: float | None = None) -> float:
    """Half the pad's width (default :func:`meshsal.points.touch.default_pad_width`), in mesh units."""
    return 0.5 * (default_pad_width(mesh) if pad_width is None else float(pad_width))


def _check(mesh: Mesh, n, method, min_spacing, threshold, pad_width=None,
           combination="equal") -> tuple[int, float, float]:
    POINT_METHODS.get(method)
    if int(n) != n or n < 1:
        raise ValueError(f"n must be a positive integer, got {n!r}")
    if mesh.n_faces == 0:
        raise ValueError(f"mesh {mesh.name!r} has no faces: no surface to put points on")
    if not 0.0 <= threshold < 1.0:
        raise ValueError(f"threshold must lie in [0, 1), got {threshold}")
    if combination not in COMBINATIONS:
        raise ValueError(f"unknown combination {combination!r}; expected one of {COMBINATIONS}")
    pad = default_pad_width(mesh) if pad_width is None else float(pad_width)
    if not (np.isfinite(pad) and pad > 0):
        raise ValueError(f"pad_width must be a positive length, got {pad_width}")
    spacing = default_min_spacing(mesh, pad) if min_spacing is None else float(min_spacing)
    if not (np.isfinite(spacing) and spacing >= 0):
        raise ValueError(f"min_spacing must be a finite length >= 0, got {min_spacing}")
    return int(n), spacing, pad


def _check_field(mesh: Mesh, vertex_saliency) -> np.ndarray:
    field = np.asarray(vertex_saliency, dtype=np.float64)
    if field.shape != (mesh.n_vertices,):
        raise ValueError(f"vertex_saliency must have shape ({mesh.n_vertices},), got {field.shape}")
    return field


def _normals_at(mesh: Mesh, vn: np.ndarray, face_ids: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """Unit normals interpolated over faces; the face normal where they cancel."""
    n = np.einsum("kc,kcd->kd", bary, vn[mesh.faces[face_ids]])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    flat = face_normals(mesh.vertices, mesh.faces[face_ids])
    return np.where(length > 1e-12, n / np.maximum(length, 1e-300), flat)


def _nearest_corner(mesh: Mesh, face_ids: np.ndarray, bary: np.ndarray) -> np.ndarray:
    return mesh.faces[face_ids, np.argmax(bary, axis=1)].astype(np.int64)


@dataclass(frozen=True)
class _Candidates:
    """Points in priority order, with what is needed to report them."""

    vertex_ids: np.ndarray
    positions: np.ndarray
    normals: np.ndarray
    scores: np.ndarray


def _vertex_candidates(mesh: Mesh, vn: np.ndarray, ids: np.ndarray, scores: np.ndarray) -> _Candidates:
    ids = np.asarray(ids, dtype=np.int64)
    return _Candidates(ids, mesh.vertices[ids], vn[ids], np.asarray(scores, dtype=np.float64))


def _take(c: _Candidates, keep: np.ndarray) -> _Candidates:
    return _Candidates(c.vertex_ids[keep], c.positions[keep], c.normals[keep], c.scores[keep])


def _concat(parts) -> _Candidates:
    return _Candidates(*(np.concatenate([getattr(p, f) for p in parts])
                         for f in ("vertex_ids", "positions", "normals", "scores")))


class _TouchFilter:
    """Keeps only the candidates a pad can touch first; counts those it drops."""

    def __init__(self, mesh: Mesh, pad_width: float, tolerance: float | None):
        self.mesh, self.pad_width, self.tolerance = mesh, pad_width, tolerance
        self.scene = embree_scene(mesh)
        self.lost = 0

    def __call__(self, c: _Candidates) -> np.ndarray:
        return touchable(self.mesh, c.positions, c.normals, self.pad_width, self.tolerance, scene=self.scene)


def _suppress(more: _Candidates, chosen: _Candidates, n: int, spacing: float, touch) -> _Candidates:
    """Greedy suppression of ``more`` after ``chosen``; a candidate the pad cannot touch is skipped.

    A skipped candidate blocks nothing, so the next one in line takes its
    place exactly as if it had never been proposed.  Touch tests run in
    batches of the candidates next in line, each tested once at most.
    """
    from scipy.spatial import cKDTree

    need = n - chosen.vertex_ids.size
    if need <= 0 or more.vertex_ids.size == 0:
        return _take(more, np.empty(0, np.int64))
    tree = cKDTree(more.positions)
    # "No two closer than spacing": points exactly that far apart may both stay.
    radius = np.nextafter(spacing, 0.0) if spacing > 0 else 0.0
    alive = ~np.isin(more.vertex_ids, chosen.vertex_ids)
    for point in chosen.positions:
        alive[tree.query_ball_point(point, radius)] = False
    verdict = np.zeros(more.vertex_ids.size, np.int8)      # 0 untested, 1 touchable, -1 not
    picks = []
    i = 0
    while len(picks) < need:
        rest = np.flatnonzero(alive[i:])
        if rest.size == 0:
            break
        i += int(rest[0])
        if touch is not None and verdict[i] == 0:
            batch = i + np.flatnonzero(alive[i:] & (verdict[i:] == 0))[:need - len(picks)]
            verdict[batch] = np.where(touch(_take(more, batch)), 1, -1)
        alive[i] = False
        if touch is not None and verdict[i] < 0:
            touch.lost += 1
            continue
        picks.append(i)
        alive[tree.query_ball_point(more.positions[i], radius)] = False
        alive[more.vertex_ids == more.vertex_ids[i]] = False
    return _take(more, np.asarray(picks, np.int64))


def _select(first: _Candidates, fill_order: list, n: int, spacing: float, touch=None) -> _Candidates:
    """Suppression of ``first``, then of each fill source in turn, up to ``n`` (touchable) points."""
    empty = _Candidates(np.empty(0, np.int64), np.empty((0, 3)), np.empty((0, 3)), np.empty(0))
    chosen = _suppress(first, empty, n, spacing, touch)
    for make in fill_order:
        if chosen.vertex_ids.size >= n:
            break
        chosen = _concat([chosen, _suppress(make(), chosen, n, spacing, touch)])
    return chosen


def _saliency_fill(mesh: Mesh, vn: np.ndarray, vertex_saliency: np.ndarray, score_of) -> list:
    """Fill sources: mesh-saliency peaks, then every used vertex by mesh saliency."""
    def peaks():
        ids = field_peaks(vertex_saliency, mesh.faces)
        return _vertex_candidates(mesh, vn, ids, score_of(ids))

    def everything():
        used = np.unique(mesh.faces)
        ids = used[np.lexsort((used, -vertex_saliency[used]))]
        return _vertex_candidates(mesh, vn, ids, score_of(ids))

    return [peaks, everything]


def saliency_maps(mesh: Mesh, size: int = 128, vertex_saliency=None, quiet: bool = True,
                  weights=None, threads: int | None = None, combination: str = "equal"):
    """Render the 72 views of the rig and compute each one's saliency map.

    Parameters
    ----------
    mesh : Mesh
    size : int
        Image size in pixels.
    vertex_saliency : (n,) float64, optional
        Mesh saliency for the curvature channel (computed when omitted).
    quiet : bool
        No progress bar on stderr.
    weights : dict, optional
        Channel weights of :func:`meshsal.attention.saliency`.
    threads : int, optional
        Worker threads (default: the CPU count).
    combination : {"equal", "itti"}
        The paper's weighted sum, or each channel weighted by N(.) too.

    Returns
    -------
    views : list of 72 View, in rig order (view ``4 * s + k`` is camera ``k`` of set ``s``)
    maps : (72, size, size) float32 in [0, 1]
    """
    from meshsal.attention import saliency_views
    from meshsal.views.render import render_views, view_rig

    cameras = [c for s in view_rig() for c in s]
    views = render_views(mesh, cameras, size=size, threads=threads)
    results = saliency_views(views, mesh, weights=weights, vertex_saliency=vertex_saliency, threads=threads,
                             quiet=quiet, normalize=combination == "itti")
    maps = [r.map for r in results]
    return views, np.stack(maps).astype(np.float32)


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


def _salient_vertices(mesh: Mesh, views, maps: np.ndarray, threshold: float):
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


def _edge_graph(mesh: Mesh):
    from scipy import sparse

    F = mesh.faces
    a, b = F.ravel(), F[:, [1, 2, 0]].ravel()
    length = np.linalg.norm(mesh.vertices[a] - mesh.vertices[b], axis=1)
    # Zero-length edges would vanish from a sparse graph; keep them as tiny steps.
    length = np.maximum(length, 1e-12 * max(float(length.max()), 1e-300))
    n = mesh.n_vertices
    return sparse.coo_matrix((np.r_[length, length], (np.r_[a, b], np.r_[b, a])), shape=(n, n)).tocsr()


def _votes(graph, salient, vertex_ids: np.ndarray, radius: float, chunk: int = 32):
    """Views voting for each vertex: some vertex within ``radius`` along edges is salient there."""
    from scipy import sparse
    from scipy.sparse.csgraph import dijkstra

    found = []
    for start in range(0, vertex_ids.size, chunk):
        ids = vertex_ids[start:start + chunk]
        near = np.isfinite(dijkstra(graph, indices=ids, limit=radius))
        hits = (salient @ sparse.csr_matrix(near.T.astype(np.float32))).toarray() > 0
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


def attention_points(mesh: Mesh, views, maps: np.ndarray, vertex_saliency: np.ndarray, n: int = 15,
                     min_spacing: float | None = None, threshold: float = 0.5, pad_width: float | None = None,
                     touch: bool = True, touch_tolerance: float | None = None,
                     combination: str = "equal", method: str = "attention") -> InterestPoints:
    """Steps 2-5 of the pipeline on views and saliency maps already computed.

    Parameters
    ----------
    mesh : Mesh
    views : list of 72 View, maps : (72, H, W) float32
        From :func:`saliency_maps`.
    vertex_saliency : (n_vertices,) float64
    n : int
    min_spacing : float, optional
        Default half of ``pad_width`` (:func:`default_min_spacing`).
    threshold : float in [0, 1)
        Peaks and salient pixels exceed ``threshold`` times their map's maximum.
    pad_width, touch, touch_tolerance : as in :func:`interest_points`
    combination : str
        How ``maps`` were combined, recorded in the result.
    method : str
        The attention method's name recorded in the result ("attention" or "attention_itti").

    Returns
    -------
    InterestPoints
    """
    n, spacing, pad = _check(mesh, n, method, min_spacing, threshold, pad_width, combination)
    vertex_saliency = _check_field(mesh, vertex_saliency)
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
    positions = np.einsum("kc,kcd->kd", bary, mesh.vertices[mesh.faces[faces]])
    ids = _nearest_corner(mesh, faces, bary)

    graph = _edge_graph(mesh)
    salient = _salient_vertices(mesh, views, maps, threshold)
    votes, _ = _votes(graph, salient, ids, spacing)
    order = np.lexsort((np.arange(ids.size), -scores, -votes))
    peaks = _Candidates(ids[order], positions[order], _normals_at(mesh, vn, faces[order], bary[order]),
                        scores[order])
    seen = _best_set_values(mesh, views, maps, set_views)
    checker = _TouchFilter(mesh, pad, touch_tolerance) if touch else None
    chosen = _select(peaks, _saliency_fill(mesh, vn, vertex_saliency, lambda i: seen[i]), n, spacing, checker)
    votes, found = _votes(graph, salient, chosen.vertex_ids, spacing)
    return InterestPoints(vertex_ids=chosen.vertex_ids, positions=chosen.positions, normals=chosen.normals,
                          scores=chosen.scores, votes=votes, vertex_saliency=vertex_saliency, views=found,
                          method=method, best_set=best, min_spacing=spacing, combination=combination,
                          untouchable=checker.lost if checker else -1)


def _random_candidates(mesh, vn, n, rng, vertex_saliency):
    faces, bary = random_surface_points(mesh.vertices, mesh.faces, RANDOM_POOL * n, seed=rng)
    ids = _nearest_corner(mesh, faces, bary)
    positions = np.einsum("kc,kcd->kd", bary, mesh.vertices[mesh.faces[faces]])
    return _Candidates(ids, positions, _normals_at(mesh, vn, faces, bary), vertex_saliency[ids]), vertex_saliency


def _uniform_candidates(mesh, vn, n, rng, vertex_saliency):
    used = np.unique(mesh.faces)
    order = used[farthest_points(mesh.vertices[used], 4 * n, start=int(rng.integers(used.size)))]
    return _vertex_candidates(mesh, vn, order, vertex_saliency[order]), vertex_saliency


def _peak_candidates(field):
    def candidates(mesh, vn, n, rng, vertex_saliency):
        values = field(mesh, vertex_saliency)
        ids = field_peaks(values, mesh.faces)
        return _vertex_candidates(mesh, vn, ids, values[ids]), values

    return candidates


def _abs_mean_curvature(mesh, vertex_saliency):
    from meshsal.mesh.curvature import mean_curvature

    return np.abs(mean_curvature(mesh.vertices, mesh.faces))


#: The interest-point methods.  A baseline's value maps (mesh, vertex normals, n, generator, mesh
#: saliency) to its first candidates and the field that ranks the fill; "attention" is the paper's pipeline.
POINT_METHODS = Registry("interest-point method")
POINT_METHODS.register("attention", None, "the paper's visual attention (equal channel weights)")
POINT_METHODS.register("attention_itti", None, "the paper's visual attention, each channel weighted by Itti's N(.)")
POINT_METHODS.register("attention_learned", None, "the paper's visual attention, channel weights learned from touches")
POINT_METHODS.register("learned", None, "points by touch distinctiveness predicted from vision (meshsal.points.learned)")
POINT_METHODS.register("random", _random_candidates, "area-weighted random surface points")
POINT_METHODS.register("uniform", _uniform_candidates, "farthest-point sampling")
POINT_METHODS.register("mesh_saliency", _peak_candidates(lambda mesh, s: s), "peaks of Lee et al.'s mesh saliency")
POINT_METHODS.register("curvature", _peak_candidates(_abs_mean_curvature), "peaks of absolute mean curvature")
METHODS = POINT_METHODS.names()


@dataclass(frozen=True, eq=False)
class ViewChannels:
    """A mesh's 72 rendered views and their eight channel maps: render once, combine as each method needs.

    ``views`` list of 72 View in rig order; ``results`` the matching
    ``meshsal.attention.SaliencyResult`` (their ``channels`` are what count).
    """

    views: list
    results: list


def view_channels(mesh: Mesh, size: int = 128, vertex_saliency=None, threads: int | None = None,
                  quiet: bool = True) -> ViewChannels:
    """Render the rig's 72 views and compute each one's channels (arguments as in :func:`saliency_maps`)."""
    from meshsal.attention import saliency_views
    from meshsal.views.render import render_views, view_rig

    cameras = [c for s in view_rig() for c in s]
    views = render_views(mesh, cameras, size=size, threads=threads)
    return ViewChannels(views, saliency_views(views, mesh, vertex_saliency=vertex_saliency, threads=threads,
                                              quiet=quiet, normalize=False))


def attention_maps(seen: ViewChannels, combination: str = "equal", weights=None) -> np.ndarray:
    """(72, H, W) float32 saliency maps combined from channels already computed.

    The same maps as :func:`saliency_maps` with that ``combination`` and
    ``weights`` ("learned" is a weighted sum with the given weights).
    """
    from meshsal.attention import combine_maps

    return np.stack([combine_maps(r.channels, v.mask, weights, normalize=combination == "itti")
                     for v, r in zip(seen.views, seen.results)]).astype(np.float32)


def learned_points(mesh: Mesh, pool: np.ndarray, features: np.ndarray, model, vertex_saliency: np.ndarray,
                   n: int = 15, min_spacing: float | None = None, pad_width: float | None = None,
                   touch: bool = True, touch_tolerance: float | None = None) -> InterestPoints:
    """The "learned" method on a candidate pool whose features are known.

    Candidates are ranked by ``model.predict(features)`` (ties by pool
    order), then chosen under the same spacing and touch rules as every
    method, with the same mesh-saliency fill.

    Parameters
    ----------
    mesh : Mesh
    pool : (k,) int vertex ids (:func:`meshsal.points.learned.candidate_pool`)
    features : (k, len(meshsal.points.learned.FEATURES)) float (:func:`meshsal.points.learned.point_features`)
    model : meshsal.points.learned.TouchModel
    vertex_saliency : (n_vertices,) float64
    n, min_spacing, pad_width, touch, touch_tolerance : as in :func:`interest_points`

    Returns
    -------
    InterestPoints (``scores`` the predicted distinctiveness; filled points score below every pool point)
    """
    n, spacing, pad = _check(mesh, n, "learned", min_spacing, 0.0, pad_width)
    vertex_saliency = _check_field(mesh, vertex_saliency)
    pool = np.asarray(pool, dtype=np.int64)
    predicted = np.asarray(model.predict(features), dtype=np.float64)
    if predicted.shape != pool.shape:
        raise ValueError(f"{pool.size} pool vertices but {predicted.size} rows of features")
    order = np.lexsort((np.arange(pool.size), -predicted))
    vn = vertex_normals(mesh.vertices, mesh.faces)
    floor = float(predicted.min()) - 1.0 if predicted.size else 0.0
    first = _vertex_candidates(mesh, vn, pool[order], predicted[order])
    return _without_views(mesh, vn, first, lambda i: np.full(i.size, floor), vertex_saliency, "learned", n,
                          spacing, pad, touch, touch_tolerance)


def _without_views(mesh: Mesh, vn, first: _Candidates, fill_score, vertex_saliency, method, n, spacing, pad, touch,
                   touch_tolerance) -> InterestPoints:
    """A method that needs no view of its own: ``first`` candidates, then the mesh-saliency fill, under the rules."""
    checker = _TouchFilter(mesh, pad, touch_tolerance) if touch else None
    chosen = _select(first, _saliency_fill(mesh, vn, vertex_saliency, fill_score), n, spacing, checker)
    return InterestPoints(vertex_ids=chosen.vertex_ids, positions=chosen.positions, normals=chosen.normals,
                          scores=chosen.scores, votes=np.zeros(chosen.vertex_ids.size, np.int64),
                          vertex_saliency=vertex_saliency, views=tuple(() for _ in range(chosen.vertex_ids.size)),
                          method=method, best_set=-1, min_spacing=spacing,
                          untouchable=checker.lost if checker else -1)


def points_by_method(mesh: Mesh, methods, n: int = 15, seed=0, min_spacing: float | None = None, size: int = 128,
                     threshold: float = 0.5, quiet: bool = True, weights=None, vertex_saliency=None,
                     threads: int | None = None, combination: str = "equal", pad_width: float | None = None,
                     touch: bool = True, touch_tolerance: float | None = None, model=None,
                     seen: ViewChannels | None = None) -> dict:
    """:func:`interest_points` of several methods on one mesh, rendering and computing channels once.

    Parameters are those of :func:`interest_points`, plus ``seen``: the
    mesh's :func:`view_channels` if already computed (else rendered here
    when a method needs the views).  "attention_learned" uses
    ``model.channel_weights``; "attention" with ``combination="learned"``
    uses ``weights``.

    Returns
    -------
    dict method -> InterestPoints, for each of ``methods`` (the same as one
    :func:`interest_points` call each)
    """
    from meshsal.mesh.curvature import mesh_saliency

    methods = list(dict.fromkeys(methods))
    checked = {m: _check(mesh, n, m, min_spacing, threshold, pad_width, combination) for m in methods}
    for m in methods:
        if m in MODEL_METHODS and model is None:
            raise ValueError(f"method {m!r} needs a fitted touch model (model=, a meshsal.points.learned.TouchModel)")
        if m == "attention" and combination == "learned" and weights is None:
            raise ValueError("combination 'learned' needs channel weights (weights=, e.g. a TouchModel's "
                             "channel_weights)")
    if vertex_saliency is None:
        vertex_saliency = mesh_saliency(mesh)
    vertex_saliency = _check_field(mesh, vertex_saliency)
    if seen is None and any(m in ATTENTION_METHODS or m in MODEL_METHODS for m in methods):
        seen = view_channels(mesh, size=size, vertex_saliency=vertex_saliency, threads=threads, quiet=quiet)
    vn = vertex_normals(mesh.vertices, mesh.faces)
    combined = {}

    def maps_of(mode, mode_weights):
        # "attention" and "learned" both read the equal-weight maps: combine each set once.
        key = (mode, None if mode_weights is None else tuple(sorted(mode_weights.items())))
        if key not in combined:
            combined[key] = attention_maps(seen, mode, mode_weights)
        return combined[key]

    out = {}
    for m in methods:
        n, spacing, pad = checked[m]
        if m in ATTENTION_METHODS:
            mode = attention_combination(m, combination)
            maps = maps_of(mode, model.channel_weights if m == "attention_learned" else weights)
            out[m] = attention_points(mesh, seen.views, maps, vertex_saliency, n=n, min_spacing=spacing,
                                      threshold=threshold, pad_width=pad, touch=touch,
                                      touch_tolerance=touch_tolerance, combination=mode, method=m)
        elif m == "learned":
            from meshsal.points.learned import candidate_pool, point_features

            pool = candidate_pool(mesh, n)
            features = point_features(mesh, seen.views, seen.results, maps_of("equal", None), vertex_saliency, pool,
                                      spacing, threshold)
            out[m] = learned_points(mesh, pool, features, model, vertex_saliency, n=n, min_spacing=spacing,
                                    pad_width=pad, touch=touch, touch_tolerance=touch_tolerance)
        else:
            first, field = POINT_METHODS.get(m)(mesh, vn, n, np.random.default_rng(seed), vertex_saliency)
            out[m] = _without_views(mesh, vn, first, lambda i: field[i], vertex_saliency, m, n, spacing, pad, touch,
                                    touch_tolerance)
    return out


def interest_points(mesh: Mesh, n: int = 15, method: str = "attention", seed=0,
                    min_spacing: float | None = None, size: int = 128, threshold: float = 0.5,
                    quiet: bool = True, weights=None, vertex_saliency=None,
                    threads: int | None = None, combination: str = "equal", pad_width: float | None = None,
                    touch: bool = True, touch_tolerance: float | None = None, model=None) -> InterestPoints:
    """Choose ``n`` interest points on a mesh (module docstring for the pipeline).

    Parameters
    ----------
    mesh : Mesh
    n : int
        How many points (fewer only if the mesh cannot hold ``n`` at ``min_spacing``).
    method : {"attention", "attention_itti", "attention_learned", "learned", "random", "uniform", \
"mesh_saliency", "curvature"}
        "attention": the paper's pipeline; "attention_itti": the same with
        ``combination="itti"``; "attention_learned": with a model's learned
        channel weights; "learned": the candidates of
        :func:`meshsal.points.learned.candidate_pool` ranked by a model's predicted
        touch distinctiveness (:func:`learned_points`).  Baselines: "random", area-weighted
        uniform surface samples in random order; "uniform", farthest-point
        sampling of the vertices from a random start; "mesh_saliency", peaks
        of Lee et al.'s mesh saliency; "curvature", peaks of absolute mean
        curvature.  All keep the same minimum spacing.
    seed : int
        Seeds the random baselines (the attention pipeline is deterministic).
    min_spacing : float, optional
        No two points closer than this (mesh units); default half of ``pad_width``.
    size : int
        View size in pixels ("attention").
    threshold : float in [0, 1)
        Peak and salient-pixel threshold relative to each map's maximum.
    quiet : bool
        No progress bar on stderr.
    weights : dict, optional
        Channel weights of the attention model.
    vertex_saliency : (n_vertices,) float64, optional
        Precomputed mesh saliency.
    threads : int, optional
        Rendering and attention threads ("attention"; default: the CPU
        count).  The points do not depend on it.
    combination : {"equal", "itti"}
        "attention": the paper's equal-weight sum of the channels, or each
        channel weighted by Itti's N(.) as well.  Recorded in the result.
    pad_width : float, optional
        The tactile pad's width, mesh units (default
        :func:`meshsal.points.touch.default_pad_width`).
    touch : bool
        Skip candidates the pad, pressed along their normal, would not meet
        first (:func:`meshsal.points.touch.touchable`); the result's
        ``untouchable`` counts them.
    touch_tolerance : float, optional
        How far above the point the first contact may lie (default
        ``pad_width / 32``: 1 mm of a 32 mm pad).
    model : meshsal.points.learned.TouchModel, optional
        Needed by "learned" (points by predicted touch distinctiveness) and
        "attention_learned" (the model's channel weights).

    Returns
    -------
    InterestPoints

    Examples
    --------
    >>> import meshsal
    >>> pts = meshsal.interest_points(meshsal.objects.toys.make("cup"), n=15, size=64)
    >>> pts.positions.shape, pts.normals.shape, len(pts.views)
    ((15, 3), (15, 3), 15)
    """
    return points_by_method(mesh, [method], n=n, seed=seed, min_spacing=min_spacing, size=size,
                            threshold=threshold, quiet=quiet, weights=weights, vertex_saliency=vertex_saliency,
                            threads=threads, combination=combination, pad_width=pad_width, touch=touch,
                            touch_tolerance=touch_tolerance, model=model)[method]


def _spherical(view):
    """The paper's camera parameters: azimuth, elevation (y up), distance, roll, pixels per unit."""
    cam = view.camera
    e = view.eye - view.center
    distance = float(np.linalg.norm(e))
    e = e / distance
    elevation = float(np.arcsin(np.clip(e[1], -1.0, 1.0)))
    azimuth = float(np.arctan2(e[0], e[2]))
    forward = -e
    up_s = np.array([-np.sin(elevation) * np.sin(azimuth), np.cos(elevation),
                     -np.sin(elevation) * np.cos(azimuth)])
    roll = float(np.arctan2(np.cross(up_s, cam.up) @ forward, up_s @ cam.up))
    return azimuth, elevation, distance, roll, 1.0 / view.pixel_size


def project_pixel_paper(view, rows, cols, mesh: Mesh) -> np.ndarray:
    """The paper's analytic 2-D to 3-D projection of pixels onto the mesh.

    From the view's camera in spherical coordinates about the framed centre
    (azimuth about +y, elevation, distance, plus the roll of the camera's up
    vector about its axis) and the image scale in pixels per world unit, the
    pixel centre is placed on the image plane and a ray perpendicular to that
    plane (orthographic views; for perspective views, the ray from the eye
    through that point) is intersected with the mesh by Embree.  The exact
    alternative used by the pipeline is :func:`meshsal.views.render.surface_points`.

    Parameters
    ----------
    view : View
    rows, cols : int or (k,) int
        Pixel indices (row 0 at the top).
    mesh : Mesh
        The rendered mesh.

    Returns
    -------
    (k, 3) float64 surface points; NaN rows where the ray misses the mesh.
    """
    rows = np.atleast_1d(np.asarray(rows, dtype=np.float64))
    cols = np.atleast_1d(np.asarray(cols, dtype=np.float64))
    azimuth, elevation, distance, roll, ppu = _spherical(view)
    e = np.array([np.cos(elevation) * np.sin(azimuth), np.sin(elevation), np.cos(elevation) * np.cos(azimuth)])
    forward = -e
    up_s = np.array([-np.sin(elevation) * np.sin(azimuth), np.cos(elevation),
                     -np.sin(elevation) * np.cos(azimuth)])
    up = np.cos(roll) * up_s + np.sin(roll) * np.cross(forward, up_s)
    right = np.cross(forward, up)
    eye = view.center + distance * e
    half = view.size / 2.0
    x = (cols + 0.5 - half) / ppu
    y = (half - rows - 0.5) / ppu
    if view.camera.projection == "orthographic":
        origins = eye + x[:, None] * right + y[:, None] * up
        directions = np.broadcast_to(forward, origins.shape)
    else:
        # The image plane through the centre, as the pixel size is measured there.
        on_plane = view.center + x[:, None] * right + y[:, None] * up
        origins = np.broadcast_to(eye, on_plane.shape)
        directions = on_plane - eye
        directions = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    hit = embree_scene(mesh).run(np.ascontiguousarray(origins, np.float32), np.ascontiguousarray(directions, np.float32),
                    output=1)
    out = np.full((rows.size, 3), np.nan)
    ok = hit["primID"] >= 0
    f = hit["primID"][ok]
    u, v = hit["u"][ok].astype(np.float64), hit["v"][ok].astype(np.float64)
    corners = mesh.vertices[mesh.faces[f]]
    out[ok] = (1 - u - v)[:, None] * corners[:, 0] + u[:, None] * corners[:, 1] + v[:, None] * corners[:, 2]
    return out
