"""The selection every point method shares: candidates in priority order, spaced, touchable, filled.

A method proposes :class:`Candidates`, best first.  :func:`select` keeps
them greedily under the :class:`~meshsal.points.rules.Rules`: no two closer
than ``min_spacing`` (Euclidean), each on a distinct nearest vertex, each
with a defined normal and, with the touch check, each a point the pad
pressed along its normal meets first (:class:`TouchFilter`); a refused
candidate blocks nothing, so the next in line takes its place.  When fewer
than ``n`` survive, the rest are filled from the peaks of the per-vertex
mesh saliency (strongest first), then from all vertices in order of mesh
saliency (:func:`saliency_fill`), always under the same rules; a mesh too
small to hold ``n`` points that far apart yields fewer.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from meshsal.mesh import Mesh, face_normals, normal_defined
from meshsal.points.record import InterestPoints
from meshsal.points.rules import Rules
from meshsal.points.sampling import field_peaks, suppress
from meshsal.points.touch import pad_rays, pad_touches

__all__ = [
    "Candidates",
    "vertex_candidates",
    "surface_candidates",
    "TouchFilter",
    "select",
    "saliency_fill",
    "choose_without_views",
]


@dataclass(frozen=True)
class Candidates:
    """Points in priority order, with what is needed to report them: (k,) ids, (k, 3) positions and normals,
    (k,) scores."""

    vertex_ids: np.ndarray
    positions: np.ndarray
    normals: np.ndarray
    scores: np.ndarray

    def __len__(self) -> int:
        return int(self.vertex_ids.size)

    def take(self, keep) -> Candidates:
        """The candidates at ``keep`` (indices or a mask), in that order."""
        return Candidates(self.vertex_ids[keep], self.positions[keep], self.normals[keep], self.scores[keep])

    @staticmethod
    def concat(parts) -> Candidates:
        return Candidates(
            *(np.concatenate([getattr(p, f) for p in parts]) for f in ("vertex_ids", "positions", "normals", "scores"))
        )

    @staticmethod
    def empty() -> Candidates:
        return Candidates(np.empty(0, np.int64), np.empty((0, 3)), np.empty((0, 3)), np.empty(0))


def vertex_candidates(mesh: Mesh, vn: np.ndarray, ids, scores) -> Candidates:
    """Vertices ``ids`` (best first) with their normals ``vn[ids]`` and ``scores``."""
    ids = np.asarray(ids, dtype=np.int64)
    return Candidates(ids, mesh.vertices[ids], vn[ids], np.asarray(scores, dtype=np.float64))


def surface_candidates(mesh: Mesh, vn: np.ndarray, face_ids, bary, scores) -> Candidates:
    """Surface points by face and barycentric weights (best first), on their nearest corner.

    Normals are the vertex normals interpolated at the point, the face
    normal where they cancel.
    """
    face_ids = np.asarray(face_ids, dtype=np.int64)
    bary = np.asarray(bary, dtype=np.float64)
    positions = np.einsum("kc,kcd->kd", bary, mesh.vertices[mesh.faces[face_ids]])
    n = np.einsum("kc,kcd->kd", bary, vn[mesh.faces[face_ids]])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    flat = face_normals(mesh.vertices, mesh.faces[face_ids])
    normals = np.where(length > 1e-12, n / np.maximum(length, 1e-300), flat)
    ids = mesh.faces[face_ids, np.argmax(bary, axis=1)].astype(np.int64)
    return Candidates(ids, positions, normals, np.asarray(scores, dtype=np.float64))


class TouchFilter:
    """Whether the pad can touch candidates first (:func:`meshsal.points.touch.pad_touches`), on one mesh.

    Its rays (the scene, their start height) are built once and shared by every call of one selection.
    ``scene``, the mesh's robust Embree scene (:func:`meshsal.mesh.embree.embree_scene`), is built when
    omitted; pass the one the caller holds so that one mesh has one.
    """

    def __init__(self, mesh: Mesh, rules: Rules, scene=None):
        self.rays, self.tolerance = pad_rays(mesh, rules.pad_width, scene=scene), rules.touch_tolerance

    def __call__(self, c: Candidates) -> np.ndarray:
        return pad_touches(self.rays, c.positions, c.normals, self.tolerance)


def select(
    first: Candidates, fill: list, rules: Rules, touch: TouchFilter | None = None, usable: np.ndarray | None = None
) -> tuple[Candidates, int]:
    """Up to ``rules.n`` candidates from ``first``, then from each fill source in turn.

    Parameters
    ----------
    first : Candidates, best first
    fill : list of callables returning Candidates, asked in order only while points are missing
    rules : Rules
    touch : TouchFilter, optional
    usable : (n_vertices,) bool, optional
        Vertices a point may be on (``meshsal.mesh.normal_defined``): a
        candidate whose nearest vertex has no normal is never chosen.

    Returns
    -------
    chosen : Candidates
    untouchable : int
        Candidates skipped because the pad could not touch them first (-1 without ``touch``).
    """
    chosen, refused = _suppress(first, Candidates.empty(), rules, touch, usable)
    for make in fill:
        if len(chosen) >= rules.n:
            break
        more, lost = _suppress(make(), chosen, rules, touch, usable)
        chosen, refused = Candidates.concat([chosen, more]), refused + lost
    return chosen, (refused if touch is not None else -1)


def _suppress(more: Candidates, chosen: Candidates, rules: Rules, touch, usable) -> tuple[Candidates, int]:
    # A point without a normal, or on a vertex without one, cannot be pressed along it.
    keep = np.linalg.norm(more.normals, axis=1) > 1e-12
    if usable is not None:
        keep &= usable[more.vertex_ids]
    more = more.take(keep)
    need = rules.n - len(chosen)
    if need <= 0 or len(more) == 0:
        return more.take(np.empty(0, np.int64)), 0
    accept = None if touch is None else (lambda batch: touch(more.take(batch)))
    kept = suppress(
        more.positions, rules.min_spacing, need, more.vertex_ids, chosen.positions, chosen.vertex_ids, accept
    )
    return more.take(kept.chosen), kept.refused


def saliency_fill(mesh: Mesh, vn: np.ndarray, vertex_saliency: np.ndarray, score_of: Callable) -> list:
    """Fill sources: mesh-saliency peaks, then every used vertex by mesh saliency; ``score_of(ids)`` scores them."""

    def peaks():
        ids = field_peaks(vertex_saliency, mesh.faces)
        return vertex_candidates(mesh, vn, ids, score_of(ids))

    def everything():
        used = np.unique(mesh.faces)
        ids = used[np.lexsort((used, -vertex_saliency[used]))]
        return vertex_candidates(mesh, vn, ids, score_of(ids))

    return [peaks, everything]


def choose_without_views(
    mesh: Mesh,
    vn: np.ndarray,
    vertex_saliency: np.ndarray,
    first: Candidates,
    fill_score: Callable,
    rules: Rules,
    method: str,
    scene=None,
    touch: TouchFilter | None = None,
) -> InterestPoints:
    """A method that needs no view of its own: ``first``, then the mesh-saliency fill scored by ``fill_score``.

    ``touch`` is the touch check the methods of one call share; without it one
    is built on ``scene``, the mesh's Embree scene (built when omitted).
    """
    checker = (touch or TouchFilter(mesh, rules, scene)) if rules.touch else None
    chosen, lost = select(
        first,
        saliency_fill(mesh, vn, vertex_saliency, fill_score),
        rules,
        checker,
        normal_defined(mesh.vertices, mesh.faces),
    )
    return InterestPoints(
        vertex_ids=chosen.vertex_ids,
        positions=chosen.positions,
        normals=chosen.normals,
        scores=chosen.scores,
        votes=np.zeros(len(chosen), np.int64),
        vertex_saliency=vertex_saliency,
        views=tuple(() for _ in range(len(chosen))),
        method=method,
        best_set=-1,
        min_spacing=rules.min_spacing,
        untouchable=lost,
        frame=mesh.transform,
    )
