"""Mean curvature and Lee et al.'s mesh saliency on shapes with known answers."""

import igl
import numpy as np
import pytest
import shapes
from scipy.spatial import cKDTree

from meshsal.mesh import Mesh
from meshsal.mesh.curvature import gaussian_average, mean_curvature, mesh_saliency, vertex_areas


def icosphere(level):
    sphere = shapes.icosphere(subdivisions=level)
    return sphere.vertices, sphere.faces


def bumpy_sphere(direction, level=5, height=0.12, width=0.08):
    V, F = icosphere(level)
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    angle = np.arccos(np.clip(V @ d, -1, 1))
    V = V * (1 + height * np.exp(-(angle**2) / (2 * width**2)))[:, None]
    return V, F, angle


def rotation(seed):
    q = np.random.default_rng(seed).normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


@pytest.mark.parametrize("radius", [0.5, 1.0, 40.0])
def test_mean_curvature_of_sphere_is_inverse_radius(radius):
    V, F = icosphere(4)
    H = mean_curvature(V * radius, F)
    assert H.shape == (V.shape[0],) and H.dtype == np.float64
    np.testing.assert_allclose(H, 1.0 / radius, rtol=1e-3)


def test_mean_curvature_sign_flips_with_orientation():
    V, F = icosphere(3)
    assert np.all(mean_curvature(V, F[:, ::-1]) < 0)


def test_mean_curvature_of_plane_is_zero():
    # Interior vertices of a flat grid; boundary vertices only lose the in-plane part.
    GV, F = igl.triangulated_grid(12, 9)
    V = np.c_[GV * [3.0, 2.0], np.full(len(GV), 0.7)]
    np.testing.assert_allclose(mean_curvature(V, F), 0.0, atol=1e-9)


def test_mean_curvature_of_cylinder_is_half_inverse_radius():
    GV, F = igl.triangulated_grid(65, 20)
    theta, z = GV[:, 0] * 2 * np.pi, GV[:, 1] * 3.0
    V = np.c_[2.0 * np.cos(theta), 2.0 * np.sin(theta), z]
    # Weld the seam so the tube is closed around its axis.
    seam = np.isclose(GV[:, 0], 1.0)
    target = np.flatnonzero(np.isclose(GV[:, 0], 0.0))
    remap = np.arange(len(V))
    remap[np.flatnonzero(seam)] = target[np.argsort(GV[target, 1])][np.argsort(np.argsort(GV[seam, 1]))]
    F = remap[F]
    if np.dot(np.cross(*(V[F[0, 1:]] - V[F[0, 0]])), V[F[0, 0]] * [1, 1, 0]) < 0:
        F = F[:, ::-1]
    H = mean_curvature(V, F)
    interior = (z > 0.3) & (z < 2.7) & ~seam
    np.testing.assert_allclose(H[interior], 0.25, rtol=0.02)


def brute_force_average(V, f, w, sigma, max_cells=None):
    """The definition itself: Gaussian weights over KD-tree pairs within 2 sigma.

    ``max_cells`` is ignored: it is there so this can stand in for ``gaussian_average``.
    """
    D = cKDTree(V).sparse_distance_matrix(cKDTree(V), 2 * sigma, output_type="coo_matrix")
    k = np.exp(-(D.data**2) / (2 * sigma**2)) * w[D.col]
    return np.bincount(D.row, k * f[D.col], len(V)) / np.bincount(D.row, k, len(V))


@pytest.mark.parametrize("max_cells", [None, 8_000])
def test_gaussian_average_matches_brute_force(max_cells):
    # A smooth random field plus noise on a sphere; 8 000 cells force a grid spacing near sigma.
    V, F = icosphere(4)
    rng = np.random.default_rng(3)
    f = np.sin(V @ rng.normal(size=3) * 4) + rng.normal(scale=0.3, size=V.shape[0])
    w = vertex_areas(V, F)
    sigma = 0.12
    exact = brute_force_average(V, f, w, sigma)
    fast = gaussian_average(V, f, w, sigma, max_cells=max_cells)
    assert np.corrcoef(exact, fast)[0, 1] > 0.99
    assert np.abs(exact - fast).mean() < 0.05 * np.ptp(exact)
    assert np.abs(exact - fast).max() < 0.15 * np.ptp(exact)


def test_mesh_saliency_agrees_with_the_definition(monkeypatch):
    import meshsal.mesh.curvature

    V, F = icosphere(4)
    rng = np.random.default_rng(8)
    for d in rng.normal(size=(3, 3)):
        angle = np.arccos(np.clip(V @ (d / np.linalg.norm(d)), -1, 1))
        V = V * (1 + rng.uniform(0.05, 0.15) * np.exp(-(angle**2) / (2 * 0.15**2)))[:, None]
    mesh = Mesh(vertices=V, faces=F)
    fast = mesh_saliency(mesh)
    monkeypatch.setattr(meshsal.mesh.curvature, "gaussian_average", brute_force_average)
    exact = mesh_saliency(mesh)
    assert np.corrcoef(fast, exact)[0, 1] > 0.98


def test_gaussian_average_of_constant_is_constant():
    V, F = icosphere(3)
    np.testing.assert_allclose(gaussian_average(V, np.full(len(V), -2.5), vertex_areas(V, F), 0.05), -2.5)


@pytest.mark.parametrize("direction", [(0.3, 0.8, 0.5), (-1.0, 0.1, 0.2), (0.0, 0.0, -1.0)])
def test_bump_holds_the_highest_saliency(direction):
    V, F, angle = bumpy_sphere(direction)
    s = mesh_saliency(Mesh(vertices=V, faces=F))
    assert s.shape == (len(V),) and s.dtype == np.float64 and np.all(s >= 0)
    bump = angle < 0.3
    assert angle[np.argmax(s)] < 0.1
    assert s[bump].max() > 5 * s[~bump].max()


def test_saliency_is_invariant_to_scale_and_translation():
    V, F, _ = bumpy_sphere((0.2, -0.5, 0.9))
    a = mesh_saliency(Mesh(vertices=V, faces=F))
    b = mesh_saliency(Mesh(vertices=V * 1000.0 + [5e3, -2e3, 7e3], faces=F))
    assert np.corrcoef(a, b)[0, 1] >= 0.999


@pytest.mark.parametrize("seed", [0, 1])
def test_saliency_is_invariant_to_rotation(seed):
    V, F, _ = bumpy_sphere((0.6, 0.6, -0.2))
    a = mesh_saliency(Mesh(vertices=V, faces=F))
    b = mesh_saliency(Mesh(vertices=V @ rotation(seed).T, faces=F))
    assert np.corrcoef(a, b)[0, 1] >= 0.99


def test_two_bumps_both_stand_out_over_the_sphere():
    V, F = icosphere(5)
    bumps = [np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0])]
    r = np.ones(len(V))
    for d in bumps:
        r += 0.12 * np.exp(-(np.arccos(np.clip(V @ d, -1, 1)) ** 2) / (2 * 0.08**2))
    s = mesh_saliency(Mesh(vertices=V * r[:, None], faces=F))
    far = np.all([np.arccos(np.clip(V @ d, -1, 1)) > 0.3 for d in bumps], axis=0)
    for d in bumps:
        near = np.arccos(np.clip(V @ d, -1, 1)) < 0.1
        assert s[near].max() > 5 * s[far].max()


def test_degenerate_mesh_is_rejected():
    V = np.zeros((3, 3))
    with pytest.raises(ValueError, match="coincide"):
        mesh_saliency(Mesh(vertices=V, faces=[[0, 1, 2]]))


def test_degenerate_faces_keep_everything_finite():
    V, F, angle = bumpy_sphere((0.0, 1.0, 0.0), level=4)
    # A collinear triangle off to the side and a face repeating a vertex.
    n = len(V)
    V = np.vstack([V, [[3, 0, 0], [4, 0, 0], [5, 0, 0]]])
    F = np.vstack([F, [[n, n + 1, n + 2], [0, 0, 1]]])
    assert np.all(np.isfinite(mean_curvature(V, F)))
    s = mesh_saliency(Mesh(vertices=V, faces=F))
    assert np.all(np.isfinite(s))
    assert angle[np.argmax(s[:n])] < 0.1
