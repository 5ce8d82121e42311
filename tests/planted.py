"""A planted sphere for the point tests: one bump, one red spot, and what a point set on it is measured by."""

import igl
import numpy as np
import shapes

from meshsal.mesh import Mesh


def icosphere(level):
    sphere = shapes.icosphere(subdivisions=level)
    return sphere.vertices, sphere.faces


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


BUMP = unit([0.0, 0.6, 0.8])
SPOT = unit([0.8, -0.2, -0.4])


def planted_sphere(radius=50.0):
    """A grey sphere with one bump and one red spot; returns the mesh and each vertex's angle to both."""
    V, F = icosphere(4)
    to_bump = np.arccos(np.clip(V @ BUMP, -1, 1))
    to_spot = np.arccos(np.clip(V @ SPOT, -1, 1))
    V = V * (1 + 0.15 * np.exp(-(to_bump**2) / (2 * 0.1**2)))[:, None]
    C = np.full(V.shape, 0.6, np.float32)
    C[to_spot < 0.2] = [0.9, 0.1, 0.1]
    return Mesh(vertices=V * radius, faces=F, vertex_colors=C, name="planted"), to_bump, to_spot


def pairwise_min(P):
    d = np.linalg.norm(P[:, None] - P[None], axis=2)
    return d[np.triu_indices(len(P), 1)].min()


def distance_to_surface(points, mesh):
    d2 = igl.point_mesh_squared_distance(np.asarray(points, float), mesh.vertices, mesh.faces.astype(np.int64))[0]
    return np.sqrt(d2)
