"""The baselines: where a method that does not look would touch.

Each maps ``(mesh, vertex normals, n, generator, mesh saliency)`` to its
first candidates, best first, and the per-vertex field that ranks the fill
(:func:`meshsal.points.select.choose_without_views`):

* "random": area-weighted uniform surface samples in random order;
* "uniform": farthest-point sampling of the vertices from a random start;
* "mesh_saliency": peaks of Lee et al.'s mesh saliency;
* "curvature": peaks of absolute mean curvature.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from meshsal.mesh.curvature import mean_curvature
from meshsal.points.sampling import farthest_points, field_peaks, random_surface_points
from meshsal.points.select import surface_candidates, vertex_candidates

__all__ = ["RANDOM_POOL", "random_candidates", "uniform_candidates", "mesh_saliency_candidates", "curvature_candidates"]

#: Candidates drawn per requested point by the random baseline (dart throwing).
RANDOM_POOL = 64


def random_candidates(mesh, vn, n, rng, vertex_saliency):
    faces, bary = random_surface_points(mesh.vertices, mesh.faces, RANDOM_POOL * n, seed=rng)
    found = surface_candidates(mesh, vn, faces, bary, np.zeros(len(faces)))
    return dataclasses.replace(found, scores=vertex_saliency[found.vertex_ids]), vertex_saliency


def uniform_candidates(mesh, vn, n, rng, vertex_saliency):
    used = np.unique(mesh.faces)
    order = used[farthest_points(mesh.vertices[used], 4 * n, start=int(rng.integers(used.size)))]
    return vertex_candidates(mesh, vn, order, vertex_saliency[order]), vertex_saliency


def _peaks_of(values, mesh, vn):
    ids = field_peaks(values, mesh.faces)
    return vertex_candidates(mesh, vn, ids, values[ids]), values


def mesh_saliency_candidates(mesh, vn, n, rng, vertex_saliency):
    return _peaks_of(vertex_saliency, mesh, vn)


def curvature_candidates(mesh, vn, n, rng, vertex_saliency):
    return _peaks_of(np.abs(mean_curvature(mesh.vertices, mesh.faces)), mesh, vn)
