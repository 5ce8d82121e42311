"""Signed distance primitives, smooth unions and marching-cubes meshing against known answers."""

import igl
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from meshsal.mesh import face_areas
from meshsal.objects import sdf


def _signed_volume(V, F):
    return np.einsum("ij,ij->i", V[F[:, 0]], np.cross(V[F[:, 1]], V[F[:, 2]])).sum() / 6.0


def _gradient_norm(fn, P, h=1e-5):
    g = np.stack([(fn(P + h * e) - fn(P - h * e)) / (2 * h) for e in np.eye(3)], axis=1)
    return np.linalg.norm(g, axis=1)


EXACT = {
    "sphere": lambda P: sdf.sphere(P, [1, 2, 3], 4.0),
    "capsule": lambda P: sdf.capsule(P, [0, 0, 0], [3, 4, 5], 1.5),
    "round_cone": lambda P: sdf.round_cone(P, [0, 0, 0], [2, 6, 1], 3.0, 1.0),
    "cylinder": lambda P: sdf.cylinder(P, [0, -2, 0], [1, 3, 2], 2.0, 0.5),
    "round_box": lambda P: sdf.round_box(P, [0, 0, 0], [3, 2, 1], 0.4, sdf.rotation([1, 1, 0], 30)),
    "torus": lambda P: sdf.torus(P, [0, 1, 0], 4.0, 1.0, sdf.rotation([1, 0, 0], 40)),
    "prism": lambda P: sdf.prism(P, [[0, 0], [4, -1], [5, 3], [2, 1], [0, 4]], [0, 0, 0], 1.0, 0.3),
    "rounded_plate": lambda P: sdf.rounded_plate(P, [0, 0, 0], [4, 3], 1.5, 0.8, 0.3),
    "rounded_ring": lambda P: sdf.rounded_ring(P, [0, 0, 0], [4, 3], 1.5, 0.6),
}


@pytest.mark.parametrize("name", sorted(EXACT))
def test_exact_primitives_have_unit_gradient(name):
    # A true distance field has |grad d| = 1 except on its medial axis (a null set).
    P = np.random.default_rng(1).uniform(-8, 8, (2000, 3))
    norms = _gradient_norm(EXACT[name], P)
    assert np.mean(np.abs(norms - 1.0) < 1e-4) > 0.97
    assert norms.max() < 1.0 + 1e-4


@pytest.mark.parametrize("name", sorted(EXACT))
def test_exact_primitives_meshed_surface_lies_on_zero_set(name):
    V, F = sdf.mesh_field(EXACT[name], [-10] * 3, [10] * 3, 0.25, snap=0.0)
    # Linear interpolation along grid edges: tiny errors, largest at sharp creases.
    err = np.abs(EXACT[name](V))
    assert np.median(err) < 0.01
    assert err.max() < 0.1
    assert _signed_volume(V, F) > 0
    # The default snapping moves the surface by at most snap * spacing more.
    V, F = sdf.mesh_field(EXACT[name], [-10] * 3, [10] * 3, 0.25)
    assert np.abs(EXACT[name](V)).max() < err.max() + 0.05 * 0.25 + 1e-3
    assert _signed_volume(V, F) > 0


def test_known_distances():
    p = np.array([[0.0, 0.0, 0.0]])
    assert sdf.sphere(p, [3, 4, 0], 1.0)[0] == pytest.approx(4.0)
    assert sdf.capsule(np.array([[5.0, 0, 5]]), [0, 0, 0], [0, 0, 10], 1.0)[0] == pytest.approx(4.0)
    assert sdf.capsule(np.array([[0.0, 0, 13]]), [0, 0, 0], [0, 0, 10], 1.0)[0] == pytest.approx(2.0)
    assert sdf.cylinder(np.array([[3.0, 0, 14]]), [0, 0, 0], [0, 0, 10], 2.0)[0] == pytest.approx(np.hypot(1, 4))
    assert sdf.round_box(np.array([[5.0, 5, 0]]), [0, 0, 0], [2, 2, 2])[0] == pytest.approx(np.hypot(3, 3))
    assert sdf.round_box(np.array([[0.0, 0, 0]]), [0, 0, 0], [2, 3, 4], 1.0)[0] == pytest.approx(-2.0)
    assert sdf.torus(np.array([[0.0, 3, 0]]), [0, 0, 0], 4.0, 1.0)[0] == pytest.approx(4.0)
    tri = [[0, 0], [10, 0], [0, 10]]
    assert sdf.prism(np.array([[1.0, 0, 1]]), tri, [0, 0, 0], 5.0)[0] == pytest.approx(-1.0)
    assert sdf.prism(np.array([[-3.0, 0, 5]]), tri, [0, 0, 0], 5.0)[0] == pytest.approx(3.0)
    assert sdf.rounded_ring(np.array([[0.0, 0, 0]]), [0, 0, 0], [5, 5], 5.0, 1.0)[0] == pytest.approx(4.0)


def test_round_cone_equal_radii_is_capsule():
    P = np.random.default_rng(2).uniform(-10, 10, (500, 3))
    np.testing.assert_allclose(
        sdf.round_cone(P, [1, 0, 0], [2, 5, 3], 2.0, 2.0), sdf.capsule(P, [1, 0, 0], [2, 5, 3], 2.0), atol=1e-9
    )


def test_round_cone_side_is_the_tangent_line():
    # Axis z, radii 3 -> 1 over length 10: the side is tangent to both spheres with
    # outward normal (cos phi, 0, sin phi), sin phi = (ra - rb) / L.
    ra, rb, L = 3.0, 1.0, 10.0
    s = (ra - rb) / L
    n = np.array([np.sqrt(1 - s * s), 0.0, s])
    A, B = ra * n, np.array([0, 0, L]) + rb * n
    on_side = A + np.linspace(0, 1, 7)[:, None] * (B - A)
    d = sdf.round_cone(on_side, [0, 0, 0], [0, 0, L], ra, rb)
    np.testing.assert_allclose(d, 0.0, atol=1e-9)
    np.testing.assert_allclose(sdf.round_cone(on_side + 2.5 * n, [0, 0, 0], [0, 0, L], ra, rb), 2.5, atol=1e-9)
    assert sdf.round_cone(np.array([[0.0, 0, -5]]), [0, 0, 0], [0, 0, L], ra, rb)[0] == pytest.approx(2.0)
    assert sdf.round_cone(np.array([[0.0, 0, 15]]), [0, 0, 0], [0, 0, L], ra, rb)[0] == pytest.approx(4.0)


def test_round_cone_rejects_a_sphere_inside_the_other():
    with pytest.raises(ValueError, match="segment length"):
        sdf.round_cone(np.zeros((1, 3)), [0, 0, 0], [0, 0, 1], 3.0, 1.0)


def test_ellipsoid_zero_set_and_axis_ends():
    radii = np.array([3.0, 5.0, 8.0])
    u = np.random.default_rng(3).normal(size=(300, 3))
    on = radii * u / np.linalg.norm(u, axis=1, keepdims=True)
    np.testing.assert_allclose(sdf.ellipsoid(on, [0, 0, 0], radii), 0.0, atol=1e-9)
    ends = np.array([[0.0, 9.0, 0], [0, 0, -10.0], [4.0, 0, 0]])
    np.testing.assert_allclose(sdf.ellipsoid(ends, [0, 0, 0], radii), [4.0, 2.0, 1.0])
    assert sdf.ellipsoid(np.zeros((1, 3)), [0, 0, 0], radii)[0] == pytest.approx(-3.0)
    assert sdf.ellipsoid(np.array([[0, 0, 1e-9]]), [0, 0, 0], radii)[0] == pytest.approx(-3.0)


def test_rotation_is_proper_and_turns_the_right_way():
    R = sdf.rotation([0.3, -1.0, 2.0], 73.0)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(sdf.rotation([1, 0, 0], 90.0) @ [0, 1, 0], [0, 0, 1], atol=1e-12)


def test_rotated_part_is_the_rotated_shape():
    R = sdf.rotation([0, 0, 1], 90.0)
    # A box long along local x, turned to lie along world y.
    P = np.array([[0.0, 9.0, 0.0], [9.0, 0.0, 0.0]])
    d = sdf.round_box(P, [0, 0, 0], [10, 1, 1], 0.0, R)
    np.testing.assert_allclose(d, [-1.0, 8.0])


@settings(max_examples=200, deadline=None)
@given(st.floats(-50, 50), st.floats(-50, 50), st.floats(0.01, 20), st.floats(-1, 1))
def test_smooth_union_bounds_and_continuity(a, b, k, delta):
    m = sdf.smooth_union(np.array([a]), np.array([b]), k)[0]
    # Never above the hard union, never more than k/4 below it; exact when far apart.
    assert m <= min(a, b) + 1e-12
    assert m >= min(a, b) - k / 4 - 1e-12
    if abs(a - b) >= k:
        assert m == pytest.approx(min(a, b))
    # 1-Lipschitz in each argument, hence continuous.
    m2 = sdf.smooth_union(np.array([a + delta]), np.array([b - delta]), k)[0]
    assert abs(m2 - m) <= abs(delta) + 1e-9


def test_smooth_union_is_smooth_across_the_blend_edge():
    a = np.linspace(-3, 3, 6001)
    m = sdf.smooth_union(a, np.zeros_like(a), 2.0)
    slope = np.diff(m) / np.diff(a)
    assert np.abs(np.diff(slope)).max() < 1e-2  # no kink anywhere
    assert sdf.smooth_union(np.array([0.0]), np.array([0.0]), 2.0)[0] == pytest.approx(-0.5)


def test_smooth_subtract_carves():
    P = np.array([[0.0, 0, 0], [9.0, 0, 0]])
    d = sdf.smooth_subtract(sdf.sphere(P, [0, 0, 0], 10.0), sdf.sphere(P, [0, 0, 0], 5.0), 1.0)
    assert d[0] == pytest.approx(5.0)
    assert d[1] == pytest.approx(-1.0)


def test_meshed_sphere_volume_and_area_match_analytic():
    r = 20.0
    V, F = sdf.mesh_field(lambda P: sdf.sphere(P, [1, 2, 3], r), [-20, -19, -18], [22, 23, 24], 0.8)
    assert _signed_volume(V, F) == pytest.approx(4 / 3 * np.pi * r**3, rel=0.01)
    assert face_areas(V, F).sum() == pytest.approx(4 * np.pi * r**2, rel=0.02)
    assert len(igl.boundary_facets(F)[0]) == 0
    assert igl.is_edge_manifold(F)[0]


def test_blended_spheres_form_one_closed_surface():
    def field(P):
        return sdf.smooth_union(sdf.sphere(P, [0, 0, 0], 8.0), sdf.sphere(P, [15, 0, 0], 6.0), 5.0)

    V, F = sdf.mesh_field(field, [-10, -10, -10], [23, 10, 10], 0.7)
    assert len(igl.boundary_facets(F)[0]) == 0
    assert igl.is_edge_manifold(F)[0]
    # Euler characteristic 2: a single sphere-like component.
    edges = np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1), axis=0)
    assert len(V) - len(edges) + len(F) == 2


def test_coarse_to_fine_sampling_matches_full_sampling_near_the_surface():
    def field(P):
        d = sdf.smooth_union(sdf.capsule(P, [-8, 0, 0], [8, 3, 0], 3.0), sdf.torus(P, [0, 0, 2], 6.0, 1.5), 2.0)
        return sdf.smooth_union(d, sdf.round_box(P, [0, -4, 0], [6, 2, 3], 1.0), 1.5)

    full, axes = sdf.sample_grid(field, [-12] * 3, [12] * 3, 0.5, levels=0)
    fast, axes_fast = sdf.sample_grid(field, [-12] * 3, [12] * 3, 0.5, levels=3)
    assert full.shape == fast.shape
    for a, b in zip(axes, axes_fast):
        np.testing.assert_allclose(a, b)
    assert np.array_equal(np.sign(full), np.sign(fast))
    # Far nodes may keep a coarser node's value; every node within 3 steps of the surface is exact.
    near = np.abs(full) < 1.5
    assert near.sum() > 10000
    np.testing.assert_array_equal(full[near], fast[near])
    assert not np.array_equal(full, fast)


def test_coarse_to_fine_sampling_keeps_signs_with_ellipsoids():
    def field(P):
        d = sdf.ellipsoid(P, [0, -4, 0], [9, 2, 3], sdf.rotation([1, 1, 1], 35))
        return sdf.smooth_union(d, sdf.ellipsoid(P, [2, 3, 1], [1.5, 6, 2]), 2.0)

    full, _ = sdf.sample_grid(field, [-12] * 3, [12] * 3, 0.5, levels=0)
    fast, _ = sdf.sample_grid(field, [-12] * 3, [12] * 3, 0.5, levels=3)
    assert np.array_equal(np.sign(full), np.sign(fast))
    near = np.abs(full) < 1.0
    np.testing.assert_array_equal(full[near], fast[near])


def test_ellipsoid_is_continuous_inside():
    radii = np.array([9.0, 2.0, 3.0])
    P = np.random.default_rng(4).uniform(-9, 9, (20000, 3))
    P = P[np.linalg.norm(P / radii, axis=1) < 1.2]
    step = np.random.default_rng(5).normal(size=P.shape)
    step *= 1e-3 / np.linalg.norm(step, axis=1, keepdims=True)
    slope = np.abs(sdf.ellipsoid(P + step, [0, 0, 0], radii) - sdf.ellipsoid(P, [0, 0, 0], radii)) / 1e-3
    assert slope.max() < radii.max() / radii.min()


def test_sample_grid_rejects_bad_arguments():
    with pytest.raises(ValueError, match="hi > lo"):
        sdf.sample_grid(lambda P: sdf.sphere(P, [0, 0, 0], 1.0), [1, 0, 0], [0, 1, 1], 0.1)
    with pytest.raises(ValueError, match="spacing"):
        sdf.sample_grid(lambda P: sdf.sphere(P, [0, 0, 0], 1.0), [0] * 3, [1] * 3, 0.0)
    with pytest.raises(ValueError, match="levels"):
        sdf.sample_grid(lambda P: sdf.sphere(P, [0, 0, 0], 1.0), [0] * 3, [1] * 3, 0.1, levels=-1)


def test_mesh_field_snapping_removes_slivers_where_the_surface_meets_grid_nodes():
    # Centred on a node with an integer radius, the capsule passes exactly through many nodes of the unit grid.
    def field(P):
        return sdf.capsule(P, [0, 0, -3], [0, 0, 3], 3.0)

    V0, F0 = sdf.mesh_field(field, [-7] * 3, [7] * 3, 1.0, snap=0.0)
    assert face_areas(V0, F0).min() < 1e-9
    V, F = sdf.mesh_field(field, [-7] * 3, [7] * 3, 1.0, snap=0.05)
    assert face_areas(V, F).min() > 0.5 * 0.05**2
    assert len(F) == len(F0)  # same topology, only vertices moved
    assert len(igl.boundary_facets(F)[0]) == 0 and igl.is_edge_manifold(F)[0]
    # The surface moves by at most snap * spacing, plus linear interpolation error.
    assert np.abs(field(V)).max() < 0.05 + 0.02


def test_mesh_field_rejects_a_bad_snap():
    for snap in (-0.1, 0.5):
        with pytest.raises(ValueError, match="snap"):
            sdf.mesh_field(lambda P: sdf.sphere(P, [0, 0, 0], 3.0), [-5] * 3, [5] * 3, 1.0, snap=snap)


def test_mesh_field_refuses_a_surface_cut_by_the_grid():
    with pytest.raises(ValueError, match="border"):
        sdf.mesh_field(lambda P: sdf.sphere(P, [0, 0, 0], 10.0), [-5] * 3, [5] * 3, 1.0)


def test_mesh_field_refuses_an_empty_field():
    with pytest.raises(ValueError, match="nothing to mesh"):
        sdf.mesh_field(lambda P: sdf.sphere(P, [100, 0, 0], 1.0), [-5] * 3, [5] * 3, 1.0)


def test_points_must_be_k_by_3():
    with pytest.raises(ValueError, match=r"\(k, 3\)"):
        sdf.sphere(np.zeros((4, 2)), [0, 0, 0], 1.0)
