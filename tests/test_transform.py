"""scale_to and normalize: sizes, centres, and the way back to the file's frame."""

import numpy as np
import pytest

from meshsal.mesh import Mesh, MeshError, bounding_sphere
from meshsal.mesh.io import load_mesh, save_ply
from meshsal.mesh.transform import normalize, scale_to


def box_mesh(lo=(2.0, -1.0, 5.0), size=(3.0, 4.0, 12.0)):
    """An axis-aligned box (8 corners, 12 triangles) with known diagonal."""
    corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=np.float64)
    V = np.asarray(lo) + corners * np.asarray(size)
    F = [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
         [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]  # fmt: skip
    colors = np.linspace(0, 1, 24).reshape(8, 3)
    return Mesh(vertices=V, faces=F, vertex_colors=colors, name="box")


def test_scale_to_sets_diagonal_and_centres_box():
    out = scale_to(box_mesh(), diagonal_mm=26.0)  # source diagonal is sqrt(9+16+144) = 13
    lo, hi = out.vertices.min(axis=0), out.vertices.max(axis=0)
    assert np.linalg.norm(hi - lo) == pytest.approx(26.0)
    np.testing.assert_allclose(lo + hi, 0.0, atol=1e-12)
    np.testing.assert_allclose(hi - lo, [6.0, 8.0, 24.0])
    assert out.transform.scale == pytest.approx(2.0)


def test_scale_to_default_is_150mm():
    out = scale_to(box_mesh())
    assert np.linalg.norm(np.ptp(out.vertices, axis=0)) == pytest.approx(150.0)


def test_scale_to_keeps_everything_but_vertices():
    mesh = box_mesh()
    out = scale_to(mesh, 10.0)
    np.testing.assert_array_equal(out.faces, mesh.faces)
    np.testing.assert_array_equal(out.vertex_colors, mesh.vertex_colors)
    assert out.name == "box"
    np.testing.assert_array_equal(mesh.vertices, box_mesh().vertices)  # input untouched


def test_normalize_gives_unit_sphere_at_origin():
    out = normalize(box_mesh())
    center, radius = bounding_sphere(out.vertices)
    np.testing.assert_allclose(center, 0.0, atol=1e-12)
    assert radius == pytest.approx(1.0)
    assert np.linalg.norm(out.vertices, axis=1).max() == pytest.approx(1.0)


def test_chained_transforms_map_back_to_file_coordinates(tmp_path):
    rng = np.random.default_rng(3)
    V = rng.normal(size=(30, 3)) * [40.0, 2.0, 7.0] + [1000.0, -50.0, 3.0]
    F = rng.integers(0, 30, (60, 3))
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    path = tmp_path / "cloud.ply"
    save_ply(path, Mesh(vertices=V, faces=F))
    loaded = load_mesh(path)
    source = loaded.vertices.copy()
    for out in (
        scale_to(normalize(loaded), 150.0),
        normalize(scale_to(loaded, 80.0)),
        scale_to(scale_to(loaded, 3.0), 150.0),
        normalize(normalize(loaded)),
    ):
        np.testing.assert_allclose(out.transform.to_source(out.vertices), source, rtol=0, atol=1e-9)
        np.testing.assert_allclose(out.transform.apply(source), out.vertices, rtol=0, atol=1e-9)
    # Lengths map back too: the final 150 mm diagonal is the source diagonal.
    out = scale_to(normalize(loaded), 150.0)
    assert out.transform.length_to_source(150.0) == pytest.approx(np.linalg.norm(np.ptp(source, axis=0)))


def test_transform_composes_with_an_existing_one():
    mesh = box_mesh()
    first = scale_to(mesh, 1.0)
    second = normalize(first)
    np.testing.assert_allclose(second.transform.to_source(second.vertices), mesh.vertices, atol=1e-12)
    # Diagonal 13 -> 1 (scale 1/13), then the box's corner radius 0.5 -> 1 (scale 2).
    assert second.transform.scale == pytest.approx(2.0 / 13.0)


@pytest.mark.parametrize("bad", [0.0, -5.0, np.inf, np.nan, "big", None])
def test_scale_to_rejects_bad_diagonal(bad):
    with pytest.raises(ValueError, match="diagonal_mm"):
        scale_to(box_mesh(), bad)


@pytest.mark.parametrize("function", [scale_to, normalize])
def test_zero_extent_mesh_is_rejected(function):
    mesh = Mesh(vertices=np.ones((3, 3)), faces=[[0, 1, 2]], name="dot")
    with pytest.raises(MeshError, match="'dot'.*zero extent"):
        function(mesh)


@pytest.mark.parametrize("function", [scale_to, normalize])
def test_empty_mesh_is_rejected(function):
    with pytest.raises(MeshError, match="without vertices"):
        function(Mesh(vertices=np.zeros((0, 3)), faces=np.zeros((0, 3))))
