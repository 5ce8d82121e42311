"""Derived mesh quantities against known answers."""

import numpy as np

from meshsal.mesh import vertex_normals
from shapes import icosphere


def test_sphere_vertex_normals_point_radially_outwards():
    sphere = icosphere(radius=3.0, subdivisions=3, center=(1.0, 2.0, -1.0))
    radial = sphere.vertices - [1.0, 2.0, -1.0]
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    N = vertex_normals(sphere.vertices, sphere.faces)
    np.testing.assert_allclose(np.linalg.norm(N, axis=1), 1.0, atol=1e-12)
    assert np.degrees(np.arccos(np.clip((N * radial).sum(axis=1), -1, 1))).max() < 1.0


def test_normals_are_area_weighted_and_zero_at_isolated_vertices():
    # Vertex 0 is shared by a unit triangle in the xy-plane and one four times larger in the xz-plane.
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 2], [2, 0, 0], [5, 5, 5]], float)
    F = np.array([[0, 1, 2], [0, 3, 4]])
    N = vertex_normals(V, F)
    expected = np.array([0.0, 4.0, 1.0]) / np.sqrt(17.0)  # (0,0,1) * area 0.5 + (0,1,0) * area 2
    np.testing.assert_allclose(N[0], expected, atol=1e-12)
    np.testing.assert_allclose(N[1], [0, 0, 1], atol=1e-12)
    np.testing.assert_array_equal(N[5], 0.0)
