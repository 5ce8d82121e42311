"""Touchable points: the pad, pressed along the normal, meets the surface at the point first."""

import numpy as np
import pytest
import shapes
from models import one_feature_model

from meshsal.mesh import Mesh
from meshsal.points import METHODS, MODEL_METHODS, interest_points
from meshsal.points.touch import PAD_WIDTH, contact_gap, pad_rays, pad_touches, touchable

PAD = 32.0


def step(height=10.0):
    """Two 100-unit-wide floors, the one at x > 0 ``height`` higher, joined by a wall at x = 0."""
    V = [
        [-100, -100, 0],
        [0, -100, 0],
        [0, 100, 0],
        [-100, 100, 0],
        [0, -100, height],
        [100, -100, height],
        [100, 100, height],
        [0, 100, height],
    ]
    F = [[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7], [1, 4, 7], [1, 7, 2]]
    return Mesh(vertices=np.array(V, float), faces=np.array(F))


def spiky_ball(spikes=12, height=18.0, seed=0):
    """A sphere of radius 50 with narrow spikes: their feet are concave, where a pad lands on a tip."""
    sphere = shapes.icosphere(radius=50.0, subdivisions=4)
    V = sphere.vertices.copy()
    rng = np.random.default_rng(seed)
    tips = rng.choice(len(V), spikes, replace=False)
    for t in tips:
        angle = np.arccos(np.clip(V @ V[t] / 2500.0, -1, 1))
        V *= (1 + (height / 50.0) * np.exp(-(angle**2) / (2 * 0.05**2)))[:, None]
    return Mesh(vertices=V, faces=sphere.faces, name="spiky")


def test_gap_beside_a_step_is_the_step_height():
    mesh = step(10.0)
    reach = PAD / np.sqrt(2)  # the disc a rolled pad may sweep
    x = np.array([-5.0, -15.0, -reach + 1.0, -reach - 1.0, -60.0])
    positions = np.c_[x, np.zeros_like(x), np.zeros_like(x)]
    gaps = contact_gap(mesh, positions, np.tile([0, 0, 1.0], (x.size, 1)), PAD)
    np.testing.assert_allclose(gaps, [10, 10, 10, 0, 0], atol=1e-3)
    assert touchable(mesh, positions, np.tile([0, 0, 1.0], (x.size, 1)), PAD).tolist() == [
        False,
        False,
        False,
        True,
        True,
    ]


def test_every_point_of_a_sphere_is_touchable():
    mesh = shapes.sphere(radius=40.0, n=40)
    ids = np.arange(0, mesh.n_vertices, 7)
    normals = mesh.vertices[ids] / np.linalg.norm(mesh.vertices[ids], axis=1, keepdims=True)
    gaps = contact_gap(mesh, mesh.vertices[ids], normals, PAD)
    assert gaps.max() < 0.3


def test_gap_is_invariant_to_moving_and_scaling_the_mesh():
    mesh = spiky_ball()
    ids = np.arange(0, mesh.n_vertices, 97)
    from meshsal.mesh import vertex_normals

    N = vertex_normals(mesh.vertices, mesh.faces)[ids]
    gaps = contact_gap(mesh, mesh.vertices[ids], N, PAD)
    moved = mesh.replace(vertices=2.0 * mesh.vertices + [5.0, -3.0, 1.0])
    again = contact_gap(moved, moved.vertices[ids], N, 2 * PAD)
    np.testing.assert_allclose(again, 2 * gaps, atol=2e-3)
    assert (gaps > 1.0).any() and (gaps < 1e-3).any()


def test_verdicts_are_the_whole_grid_s_for_every_vertex():
    """The coarse rays refuse most points early; what is refused or kept is exactly contact_gap's verdict."""
    from meshsal.mesh import vertex_normals

    mesh = spiky_ball(spikes=30)
    N = vertex_normals(mesh.vertices, mesh.faces)
    gaps = contact_gap(mesh, mesh.vertices, N, PAD)
    for tolerance in (None, 0.0, 0.5, 3.0):
        limit = PAD / 32 if tolerance is None else tolerance
        expected = gaps <= limit
        assert (~expected).sum() > 100 and expected.sum() > 100
        assert np.array_equal(touchable(mesh, mesh.vertices, N, PAD, tolerance), expected)
    rays = pad_rays(mesh, PAD)
    assert np.array_equal(pad_touches(rays, mesh.vertices, N), gaps <= PAD / 32)
    assert 0 < rays.coarse.sum() < rays.coarse.size / 10


def pole(x, y, width=0.4, height=10.0):
    """A 200-unit floor at z = 0 with a thin square pole, ``width`` across and ``height`` high, at (x, y)."""
    floor_v = [[-100, -100, 0], [100, -100, 0], [100, 100, 0], [-100, 100, 0]]
    h = width / 2
    box = [
        [x - h, y - h, 0],
        [x + h, y - h, 0],
        [x + h, y + h, 0],
        [x - h, y + h, 0],
        [x - h, y - h, height],
        [x + h, y - h, height],
        [x + h, y + h, height],
        [x - h, y + h, height],
    ]
    box_f = [
        [4, 5, 6],
        [4, 6, 7],
        [0, 1, 5],
        [0, 5, 4],
        [1, 2, 6],
        [1, 6, 5],
        [2, 3, 7],
        [2, 7, 6],
        [3, 0, 4],
        [3, 4, 7],
    ]
    V = np.array(floor_v + box, float)
    F = np.array([[0, 1, 2], [0, 2, 3]] + [[a + 4, b + 4, c + 4] for a, b, c in box_f])
    return Mesh(vertices=V, faces=F)


def test_an_obstacle_only_a_fine_ray_sees_still_refuses_the_point():
    from meshsal.mesh.geometry import tangent_frames

    point, up = [[0.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]]
    rays = pad_rays(pole(0, 0), PAD)
    step = np.diff(np.unique(rays.offsets[:, 0]))[0]
    # One grid step off the centre: a ray of the fine grid only.
    on_fine = np.isclose(rays.offsets, [0.0, step]).all(axis=1)
    assert on_fine.sum() == 1 and not rays.coarse[on_fine].any()
    (u,), (v,) = tangent_frames(np.array(up))

    def at(a, b):
        return (a * u + b * v)[:2]

    mesh = pole(*at(0.0, step))
    assert contact_gap(mesh, point, up, PAD)[0] == pytest.approx(10.0, abs=1e-3)
    assert touchable(mesh, point, up, PAD).tolist() == [False]
    # Between two fine rays it goes unseen by both tests alike.
    between = pole(*at(0.5 * step, 1.5 * step), width=0.2)
    assert contact_gap(between, point, up, PAD)[0] < 1e-3 and touchable(between, point, up, PAD).tolist() == [True]


def test_bad_inputs():
    mesh = step()
    with pytest.raises(ValueError, match="pad_width"):
        contact_gap(mesh, [[0, 0, 0]], [[0, 0, 1]], 0.0)
    with pytest.raises(ValueError, match="non-zero"):
        contact_gap(mesh, [[0, 0, 0]], [[0, 0, 0]], PAD)
    with pytest.raises(ValueError, match="differ in shape"):
        contact_gap(mesh, [[0, 0, 0], [1, 0, 0]], [[0, 0, 1]], PAD)
    with pytest.raises(ValueError, match="tolerance"):
        touchable(mesh, [[0, 0, 0]], [[0, 0, 1]], PAD, tolerance=-1.0)


@pytest.mark.parametrize("method", METHODS)
def test_every_method_proposes_only_touchable_points(method):
    mesh = spiky_ball()
    pad = PAD_WIDTH
    model = one_feature_model("curvature") if method in MODEL_METHODS else None
    pts = interest_points(mesh, n=10, method=method, size=48, seed=3, model=model)
    assert pts.untouchable >= 0
    assert touchable(mesh, pts.positions, pts.normals, pad).all()
    assert pts.min_spacing == pytest.approx(pad / 2)


def test_the_check_changes_what_is_chosen():
    """Without the check some method lands beside a spike; with it, the count of skipped candidates says so."""
    mesh = spiky_ball()
    pad = PAD_WIDTH
    lost = {}
    for method in ("uniform", "random", "mesh_saliency", "curvature"):
        free = interest_points(mesh, n=10, method=method, seed=3, touch=False)
        assert free.untouchable == -1
        checked = interest_points(mesh, n=10, method=method, seed=3)
        lost[method] = checked.untouchable
        if not touchable(mesh, free.positions, free.normals, pad).all():
            assert checked.untouchable > 0
    assert sum(lost.values()) > 0


def test_spacing_follows_the_pad():
    mesh = shapes.sphere(radius=40.0, n=40)
    pts = interest_points(mesh, n=8, method="uniform", pad_width=20.0)
    assert pts.min_spacing == 10.0
    d = np.linalg.norm(pts.positions[:, None] - pts.positions[None], axis=2)
    assert d[np.triu_indices(len(pts), 1)].min() >= 10.0
