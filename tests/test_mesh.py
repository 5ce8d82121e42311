"""Derived mesh quantities against known answers."""

import numpy as np
import pytest
from shapes import icosphere, plane

from meshsal.mesh import closed_orientation, surface_distance, vertex_normals
from meshsal.mesh.geometry import vertex_area_vectors


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
    A = vertex_area_vectors(V, F)  # the same sums before normalizing: twice the area along each face's normal
    np.testing.assert_allclose(A[0], [0.0, 4.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(A[[1, 2, 3, 4]], [[0, 0, 1], [0, 0, 1], [0, 4, 0], [0, 4, 0]], atol=1e-12)
    np.testing.assert_array_equal(A[5], 0.0)


def test_vertex_area_vectors_point_along_the_vertex_normals():
    sphere = icosphere(radius=3.0, subdivisions=3)
    V = sphere.vertices * [1.0, 0.5, 2.0]  # an ellipsoid: faces of many sizes and turns
    A = vertex_area_vectors(V, sphere.faces)
    np.testing.assert_allclose(
        A / np.linalg.norm(A, axis=1, keepdims=True), vertex_normals(V, sphere.faces), atol=1e-12
    )


def test_a_degenerate_face_adds_nothing_to_its_corners():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0]], float)
    N = vertex_normals(V, np.array([[0, 1, 2], [0, 1, 3]]))  # the second face is a segment
    np.testing.assert_allclose(N[:3], [[0, 0, 1]] * 3, atol=1e-12)
    np.testing.assert_array_equal(N[3], 0.0)


def _two_spheres():
    a, b = icosphere(subdivisions=2), icosphere(subdivisions=1, center=(5.0, 0, 0))
    return np.vstack([a.vertices, b.vertices]), np.vstack([a.faces, b.faces + a.n_vertices])


def test_closed_orientation_tells_outward_from_inward_normals():
    sphere = icosphere(radius=2.0, subdivisions=3, center=(4.0, -1.0, 2.0))
    assert closed_orientation(sphere.vertices, sphere.faces) == 1
    assert closed_orientation(sphere.vertices, sphere.faces[:, ::-1]) == -1
    assert closed_orientation(*_two_spheres()) == 1


@pytest.mark.parametrize(
    "damage", ["a face missing", "a face flipped", "a face doubled", "a fin on an edge", "a repeated corner", "a plane"]
)
def test_closed_orientation_is_zero_for_anything_but_a_consistently_oriented_closed_surface(damage):
    sphere = icosphere(subdivisions=2)
    V, F = sphere.vertices, sphere.faces.copy()
    if damage == "a face missing":
        F = F[1:]
    elif damage == "a face flipped":
        F[7] = F[7, ::-1]
    elif damage == "a face doubled":
        F = np.vstack([F, F[:1]])
    elif damage == "a fin on an edge":  # a third and fourth face on edge (F[0, 0], F[0, 1])
        V = np.vstack([V, [[0.0, 0.0, 0.0]]])
        a, b = F[0, :2]
        F = np.vstack([F, [[a, b, len(V) - 1], [b, a, len(V) - 1]]])
    elif damage == "a repeated corner":
        F[3, 2] = F[3, 0]
    else:
        flat = plane(size=2.0, n=3)
        V, F = flat.vertices, flat.faces
    assert closed_orientation(V, F) == 0


def test_edge_graph_distances_are_lengths_along_edges_counted_once():
    from scipy.sparse.csgraph import dijkstra

    from meshsal.mesh.geometry import edge_graph

    sphere = icosphere(radius=1.0, subdivisions=2)
    graph = edge_graph(sphere.vertices, sphere.faces)
    d = dijkstra(graph, indices=[0])[0]
    ring = np.unique(sphere.faces[(sphere.faces == 0).any(axis=1)])
    ring = ring[ring != 0]
    # Each neighbour of a closed mesh's vertex is one edge away, however many faces share that edge.
    np.testing.assert_allclose(d[ring], np.linalg.norm(sphere.vertices[ring] - sphere.vertices[0], axis=1))


def test_surface_distance_of_a_square_and_a_sphere_has_the_known_answers():
    square = plane(size=200.0, n=10)
    rng = np.random.default_rng(0)
    above = np.c_[rng.uniform(-100, 100, 50), rng.uniform(-30, 30, 50), rng.uniform(-100, 100, 50)]
    np.testing.assert_allclose(surface_distance(square.vertices, square.faces, above), np.abs(above[:, 1]), atol=1e-9)
    # Beyond the edge x = 100 the nearest point is on the edge.
    beyond = np.array([[130.0, 40.0, 0.0], [100.0, 0.0, 160.0]])
    np.testing.assert_allclose(surface_distance(square.vertices, square.faces, beyond), [50.0, 60.0], atol=1e-9)
    ball = icosphere(radius=1.0, subdivisions=4)
    directions = rng.normal(size=(40, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    # The faceted sphere lies within its chord sag (under 1 % at this subdivision) inside the true one.
    got = surface_distance(ball.vertices, ball.faces, 1.5 * directions)
    assert np.all((got >= 0.5 - 1e-12) & (got <= 0.51))
    assert surface_distance(ball.vertices, ball.faces, np.zeros((0, 3))).shape == (0,)


@pytest.mark.parametrize(
    "faces, nan_at, message",
    [
        ([[0, 1, 7]], None, "mesh 'tri': face index out of range (0..7 for 3 vertices)"),
        ([[0, -1, 2]], None, "mesh 'tri': face index out of range (-1..2 for 3 vertices)"),
        (np.array([[0, 1, 2**32 + 1]]), None, f"mesh 'tri': face index out of range (0..{2**32 + 1} for 3 vertices)"),
        ([[0, 1, 2]], 2, "mesh 'tri': vertex 2 has non-finite coordinates"),
    ],
)
def test_a_mesh_record_refuses_what_no_stage_could_take(faces, nan_at, message):
    from meshsal.mesh import Mesh, MeshError

    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    if nan_at is not None:
        V[nan_at, 1] = np.nan
    with pytest.raises(MeshError) as caught:
        Mesh(vertices=V, faces=faces, name="tri")
    assert str(caught.value) == message
    good = Mesh(vertices=np.nan_to_num(V), faces=[[0, 1, 2]], name="tri")
    with pytest.raises(MeshError, match="non-finite"):
        good.replace(vertices=V * np.inf)  # replace checks as the constructor does
    assert Mesh(vertices=np.zeros((0, 3)), faces=np.zeros((0, 3), int)).n_faces == 0  # empty is still a record
