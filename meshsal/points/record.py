"""The record of chosen points, :class:`InterestPoints`, and its files: ``points.json``, ``points.csv`` and arrays.

``points.json`` (format ``visuotactile.points``, version 2) holds every
point's id (from 0, as capture sessions and probe plans number them),
vertex, position, normal, score, votes and views, the mesh saliency, the
settings and the frame the points were chosen in, positions and normals in
the mesh file's own units and frame; :meth:`InterestPoints.load` reads it
back and checks it (version 1 files, whose ids count from 1, are read with
ids from 0).  Every writer of points goes through
:meth:`InterestPoints.records` (JSON, CSV) or :meth:`InterestPoints.to_arrays`
(archives such as a batch store's entries).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from meshsal.mesh import Similarity

__all__ = ["InterestPoints", "POINTS_FORMAT", "POINTS_VERSION"]

POINTS_FORMAT = "visuotactile.points"
POINTS_VERSION = 2


@dataclass(frozen=True, eq=False)
class InterestPoints:
    """Points chosen on a mesh, best first, in the mesh's units and frame; ``frame`` leads back to its file's.

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
    frame : meshsal.Similarity
        The mesh's ``transform`` when the points were chosen: it maps them back to the mesh file's frame and
        units, in which :meth:`save` and :meth:`save_csv` write them.
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
    frame: Similarity = field(default_factory=Similarity)

    def __len__(self) -> int:
        return int(self.vertex_ids.size)

    def save(self, path, frame: Similarity | None = None, source: str = "", settings: dict | None = None) -> None:
        """Write the points as a versioned ``points.json``, in the mesh file's own frame, atomically.

        Parameters
        ----------
        path : str or os.PathLike
        frame : meshsal.Similarity, optional
            Maps the points back to the file's frame and units (default
            :attr:`frame`, the transform of the mesh they were chosen on);
            written with them.
        source : str
            The mesh file (or object name) the points belong to.
        settings : dict, optional
            How they were chosen, recorded as given.

        Examples
        --------
        >>> import pathlib, tempfile
        >>> from meshsal.mesh.transform import scale_to_principal
        >>> from meshsal.objects import toys
        >>> from meshsal.points import interest_points
        >>> cup = toys.make("cup")
        >>> pts = interest_points(scale_to_principal(cup, 300.0), n=3, method="uniform")
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "points.json"
        >>> pts.save(path, source="cup")              # in the cup's own frame: its file's millimetres
        >>> again = InterestPoints.load(path)
        >>> again.method, again.ids.tolist(), bool(np.allclose(again.positions, pts.frame.to_source(pts.positions)))
        ('uniform', [0, 1, 2], True)
        """
        import json

        from meshsal.util.atomic import write_text

        frame = self.frame if frame is None else frame
        document = {
            "format": POINTS_FORMAT,
            "version": POINTS_VERSION,
            "mesh": str(source),
            "units": "source units and frame of the mesh file",
            "method": self.method,
            "best_set": int(self.best_set),
            "min_spacing": float(frame.length_to_source(self.min_spacing)),
            "combination": self.combination,
            "untouchable": int(self.untouchable),
            # scale * rotation @ p + offset maps a point of the file to the frame the points were chosen in.
            "frame": {
                "scale": float(frame.scale),
                "rotation": np.asarray(frame.rotation, np.float64).tolist(),
                "offset": np.asarray(frame.offset, np.float64).tolist(),
            },
            "settings": settings or {},
            "points": self.records(frame),
            "vertex_saliency": np.asarray(self.vertex_saliency, np.float64).tolist(),
        }
        write_text(path, json.dumps(document, indent=1) + "\n")

    def records(self, frame: Similarity | None = None) -> list[dict]:
        """One dict per point (``id`` from 0, ``vertex``, ``position``, ``normal``, ``score``, ``votes``,
        ``views``), positions and normals mapped back through ``frame`` (default :attr:`frame`)."""
        frame = self.frame if frame is None else frame
        positions = frame.to_source(self.positions)
        normals = frame.direction_to_source(self.normals)
        return [
            {
                "id": k,
                "vertex": int(self.vertex_ids[k]),
                "position": positions[k].tolist(),
                "normal": normals[k].tolist(),
                "score": float(self.scores[k]),
                "votes": int(self.votes[k]),
                "views": list(self.views[k]),
            }
            for k in range(len(self))
        ]

    def save_csv(self, path, frame: Similarity | None = None) -> None:
        """Write ``id,vertex,x,y,z,nx,ny,nz,score,votes``, one row per point (ids from 0), in the file's frame
        (``frame``, default :attr:`frame`), atomically."""
        from meshsal.util.atomic import write_text

        lines = ["id,vertex,x,y,z,nx,ny,nz,score,votes"]
        for r in self.records(frame):
            lines.append(
                ",".join(
                    [str(r["id"]), str(r["vertex"])]
                    + [repr(float(v)) for v in r["position"]]
                    + [repr(float(v)) for v in r["normal"]]
                    + [repr(r["score"]), str(r["votes"])]
                )
            )
        write_text(path, "\n".join(lines) + "\n")

    def to_arrays(self) -> tuple[dict, dict]:
        """The points as NumPy arrays and a JSON-ready dict, for an archive (:meth:`from_arrays` reads them back).

        They stay in the mesh's current frame: the archive keeps :attr:`frame` if it needs it.

        Returns
        -------
        arrays : dict ``vertex_ids``, ``positions``, ``normals``, ``scores``, ``votes``
        meta : dict ``best_set``, ``min_spacing``, ``combination``, ``untouchable``, ``views``
        """
        arrays = {
            key: np.asarray(getattr(self, key)) for key in ("vertex_ids", "positions", "normals", "scores", "votes")
        }
        meta = {
            "best_set": int(self.best_set),
            "min_spacing": float(self.min_spacing),
            "combination": self.combination,
            "untouchable": int(self.untouchable),
            "views": [list(v) for v in self.views],
        }
        return arrays, meta

    @classmethod
    def from_arrays(cls, arrays: dict, meta: dict, vertex_saliency: np.ndarray, method: str) -> InterestPoints:
        """Points from :meth:`to_arrays`' output and the mesh saliency they were chosen with.

        Examples
        --------
        >>> from meshsal.objects import toys
        >>> from meshsal.points import interest_points
        >>> pts = interest_points(toys.make("cup"), n=3, method="uniform")
        >>> again = InterestPoints.from_arrays(*pts.to_arrays(), pts.vertex_saliency, "uniform")
        >>> bool(np.array_equal(again.positions, pts.positions)), again.views == pts.views
        (True, True)
        """
        return cls(
            vertex_ids=arrays["vertex_ids"],
            positions=arrays["positions"],
            normals=arrays["normals"],
            scores=arrays["scores"],
            votes=arrays["votes"],
            vertex_saliency=vertex_saliency,
            views=tuple(tuple(v) for v in meta["views"]),
            method=method,
            best_set=meta["best_set"],
            min_spacing=meta["min_spacing"],
            combination=meta.get("combination", ""),
            untouchable=meta.get("untouchable", -1),
        )

    @classmethod
    def load(cls, path) -> InterestPoints:
        """Points from a ``points.json``, in the file's frame and units (ValueError naming the file).

        Files of this format give every field back, with ``ids`` (from 0).
        Version 1 files numbered their points from 1: their ids are read
        one less, so that every file numbers from 0.  Older files without a
        ``format`` key give positions, normals and ids only (``vertex_ids``
        -1, no scores, votes or saliency).
        """
        return _read_points(path)


@dataclass(frozen=True, eq=False)
class _LoadedPoints(InterestPoints):
    """Points read from a file, with the ids the file gave them (0..k-1 when written by ``save``)."""

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
        raise ValueError(
            f"{path}: not a points file this version reads (format {document.get('format')!r}, "
            f"version {document.get('version')!r}; this reads {POINTS_FORMAT} up to {POINTS_VERSION})"
        )
    items = document["points"]
    if not items:
        raise ValueError(f"{path}: the 'points' list is empty")
    first = 1 if version < 2 else 0  # version 1 and older files numbered their points from 1
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
        point_id = item.get("id", k + first)
        if isinstance(point_id, bool) or not isinstance(point_id, int):
            raise ValueError(f"{where}: 'id' must be an integer, got {point_id!r}")
        ids.append(point_id - first)
        vertices.append(int(item.get("vertex", -1)))
        scores.append(float(item.get("score", 0.0)))
        votes.append(int(item.get("votes", 0)))
        views.append(tuple(int(v) for v in item.get("views", ())))
    N = np.array(normals)
    return _LoadedPoints(
        vertex_ids=np.array(vertices, np.int64),
        positions=np.array(positions),
        normals=N / np.linalg.norm(N, axis=1, keepdims=True),
        scores=np.array(scores),
        votes=np.array(votes, np.int64),
        vertex_saliency=np.asarray(document.get("vertex_saliency", []), np.float64),
        views=tuple(views),
        method=str(document.get("method", "unknown")),
        best_set=int(document.get("best_set", -1)),
        min_spacing=float(document.get("min_spacing", 0.0)),
        combination=str(document.get("combination", "")),
        untouchable=int(document.get("untouchable", -1)),
        ids=np.array(ids, np.int64),
    )
