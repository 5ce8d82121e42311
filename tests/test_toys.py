"""The six procedural toys: closed manifold meshes at toy size, painted, deterministic."""

import warnings

import igl
import numpy as np
import pytest

from meshsal import load_mesh
from meshsal.mesh import face_areas
from meshsal.mesh.io import MeshRepairWarning, save_ply
from meshsal.objects import toy_shapes, toys


@pytest.fixture(scope="module")
def toy():
    """name -> the toy built with seed 0, built once per module."""
    cache = {}

    def get(name):
        if name not in cache:
            cache[name] = toys.make(name)
        return cache[name]

    return get


def _luminance(C):
    return C @ np.array([0.299, 0.587, 0.114])


def _saturation(C):
    return (C.max(axis=1) - C.min(axis=1)) / np.maximum(C.max(axis=1), 1e-9)


def test_names():
    assert toys.NAMES == ("cow", "glasses", "cup", "hand", "plane", "dromedary")


def test_unknown_name_lists_the_valid_ones():
    with pytest.raises(ValueError, match="unknown toy 'horse'.*cow, glasses, cup, hand, plane, dromedary"):
        toys.make("horse")


@pytest.mark.parametrize("name", toys.NAMES)
def test_closed_edge_manifold_and_consistently_oriented(toy, name):
    F = toy(name).faces.astype(np.int64)
    assert len(igl.boundary_facets(F)[0]) == 0
    assert igl.is_edge_manifold(F)[0]
    # Every undirected edge is shared by exactly two faces, which traverse it in opposite directions.
    directed = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    assert len(np.unique(directed, axis=0)) == len(directed)
    _, counts = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    assert np.all(counts == 2)


@pytest.mark.parametrize("name", toys.NAMES)
def test_outward_orientation_and_no_degenerate_faces(toy, name):
    m = toy(name)
    V, F = m.vertices, m.faces
    volume = np.einsum("ij,ij->i", V[F[:, 0]], np.cross(V[F[:, 1]], V[F[:, 2]])).sum() / 6.0
    assert volume > 0
    assert face_areas(V, F).min() > 0
    assert len(np.unique(F)) == m.n_vertices  # no unreferenced vertices


@pytest.mark.parametrize("name", toys.NAMES)
def test_every_face_area_clears_the_documented_margin(toy, name):
    m = toy(name)
    diagonal = np.linalg.norm(m.vertices.max(axis=0) - m.vertices.min(axis=0))
    assert face_areas(m.vertices, m.faces).min() / diagonal**2 > toys.MIN_FACE_AREA
    # The margin itself sits far above the loader's zero-area threshold.
    assert toys.MIN_FACE_AREA >= 1e3 * 1e-14


@pytest.mark.parametrize("name", toys.NAMES)
def test_saved_toy_loads_back_without_repair(toy, tmp_path, name):
    m = toy(name)
    path = tmp_path / f"{name}.ply"
    save_ply(path, m)
    with warnings.catch_warnings():
        warnings.simplefilter("error", MeshRepairWarning)
        back = load_mesh(path)
    assert (back.n_vertices, back.n_faces) == (m.n_vertices, m.n_faces)
    np.testing.assert_array_equal(back.faces, m.faces)
    np.testing.assert_allclose(back.vertices, m.vertices, rtol=0, atol=1e-4)


@pytest.mark.parametrize("name", toys.NAMES)
def test_size_and_face_count(toy, name):
    m = toy(name)
    assert 5000 <= m.n_faces <= 60000
    extent = m.vertices.max(axis=0) - m.vertices.min(axis=0)
    assert 100.0 <= extent.max() <= 250.0
    assert m.name == name
    assert m.vertices.dtype == np.float64 and m.faces.dtype == np.int32


@pytest.mark.parametrize("name", toys.NAMES)
def test_painted_not_flat(toy, name):
    C = toy(name).vertex_colors
    assert C is not None and C.shape == toy(name).vertices.shape
    assert np.all((C >= 0) & (C <= 1))
    assert len(np.unique(C.round(2), axis=0)) >= 2
    assert C.std(axis=0).max() > 0.05


@pytest.mark.parametrize("name", toys.NAMES)
def test_same_seed_gives_identical_arrays(toy, name):
    again = toys.make(name, seed=0)
    first = toy(name)
    assert np.array_equal(first.vertices, again.vertices)
    assert np.array_equal(first.faces, again.faces)
    assert np.array_equal(first.vertex_colors, again.vertex_colors)


def test_seed_moves_the_cow_patches_but_not_the_cow(toy):
    other = toys.make("cow", seed=1)
    assert np.array_equal(toy("cow").vertices, other.vertices)
    assert not np.array_equal(toy("cow").vertex_colors, other.vertex_colors)


def test_cow_is_white_with_dark_patches_and_a_pink_muzzle_in_front(toy):
    m = toy("cow")
    C, V = m.vertex_colors, m.vertices
    lum = _luminance(C)
    assert 0.05 < np.mean(lum < 0.2) < 0.6
    assert np.mean((lum > 0.85) & (_saturation(C) < 0.1)) > 0.25
    pink = (C[:, 0] > 0.85) & (C[:, 1] > 0.55) & (C[:, 1] < 0.75) & (C[:, 2] > 0.55) & (C[:, 2] < 0.75)
    assert pink.any()
    # Facing +z: the muzzle is the front-most part; standing on its hooves at the bottom.
    assert V[pink, 2].max() > V[:, 2].max() - 15.0
    assert V[:, 1].min() == pytest.approx(0.0, abs=1.0)
    extent = V.max(axis=0) - V.min(axis=0)
    assert extent[2] > extent[1] > extent[0]


def test_glasses_have_dark_lenses_in_front_of_a_coloured_frame(toy):
    m = toy("glasses")
    C, V = m.vertex_colors, m.vertices
    lens = _luminance(C) < 0.15
    frame = _saturation(C) > 0.5
    assert lens.mean() > 0.1 and frame.mean() > 0.2
    assert V[lens, 2].min() > V[:, 2].max() - 10.0  # the lenses sit at the front, temples run back
    assert V[:, 2].min() < V[:, 2].max() - 100.0


def test_cup_rim_has_its_own_colour_at_the_top(toy):
    m = toy("cup")
    C, V = m.vertex_colors, m.vertices
    rim = _luminance(C) > 0.9
    body = _saturation(C) > 0.5
    assert rim.any() and body.mean() > 0.3
    assert V[rim, 1].min() > V[:, 1].max() - 8.0
    # The handle sticks out on +x; the cup is otherwise round about y.
    assert V[:, 0].max() > -V[:, 0].min() + 20.0
    assert V[:, 2].max() == pytest.approx(-V[:, 2].min(), abs=1.0)


def test_hand_has_nails_on_the_back_of_raised_fingers(toy):
    m = toy("hand")
    C, V = m.vertex_colors, m.vertices
    nail = _luminance(C) > 0.85
    assert 0.005 < nail.mean() < 0.1
    assert V[nail, 1].min() > 0.5 * (V[:, 1].min() + V[:, 1].max())
    assert V[nail, 2].mean() > V[~nail, 2].mean() + 5.0


def test_plane_has_coloured_wings_and_dark_windows(toy):
    m = toy("plane")
    C, V = m.vertex_colors, m.vertices
    livery = _saturation(C) > 0.5
    window = (_luminance(C) < 0.25) & (C[:, 2] > C[:, 0] + 0.08)
    assert livery.mean() > 0.2 and window.any()
    # Wings span x; windows run along the fuselage.
    assert V[livery, 0].max() - V[livery, 0].min() > 180.0
    assert np.abs(V[window, 0]).max() < 15.0
    assert V[window, 2].max() - V[window, 2].min() > 100.0


def test_dromedary_has_a_darker_hump_and_dark_eyes_in_front(toy):
    m = toy("dromedary")
    C, V = m.vertex_colors, m.vertices
    lum = _luminance(C)
    hump = (np.abs(V[:, 2]) < 15.0) & (V[:, 1] > 140.0)
    flank = (np.abs(V[:, 2]) < 30.0) & (V[:, 1] > 90.0) & (V[:, 1] < 115.0) & (np.abs(V[:, 0]) > 20.0)
    assert hump.any() and flank.any()
    assert lum[hump].mean() < lum[flank].mean() - 0.05
    eye = lum < 0.1
    assert eye.any() and V[eye, 2].min() > V[:, 2].max() - 40.0


@pytest.mark.parametrize("name", ["hand", "cup"])
def test_culled_field_matches_the_full_field_near_the_surface(name):
    # make() evaluates each part only near its own box; that must not move the surface.
    shape = getattr(toy_shapes, name)()
    field, lo, hi = toys._shape_field(shape)
    P = np.random.default_rng(0).uniform(lo - 10.0, hi + 10.0, (60000, 3))
    exact, culled = toys._field(shape.parts, P), field(P)
    assert np.all(culled <= exact + 1e-9)  # a lower bound far away
    assert np.array_equal(exact > 0, culled > 0)
    near = np.abs(exact) < 4.0 * shape.spacing
    assert near.sum() > 1000
    np.testing.assert_allclose(culled[near], exact[near], rtol=0, atol=1e-9)
