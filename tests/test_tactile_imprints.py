"""Simulated imprints against shapes with known answers, and the fast path against the exact one."""

import numpy as np
import pytest
import shapes

import tactile
from tactile import Sensor
from tactile.section import imprints_exact
from tactile.sensor import sample_grid, sensor_poses, tangent_frames


def taxel_centres(sensor: Sensor):
    """(rows, cols) in-plane x (right) and y (up) of each taxel centre, mm."""
    x = (np.arange(sensor.cols) + 0.5 - sensor.cols / 2) * sensor.pitch_mm
    y = -(np.arange(sensor.rows) + 0.5 - sensor.rows / 2) * sensor.pitch_mm
    return np.meshgrid(x, y)


def ncc(a, b) -> float:
    """Normalized cross-correlation; two blank images are identical (1), one blank one not (0)."""
    a, b = a.ravel() - a.mean(), b.ravel() - b.mean()
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    if na < 1e-9 or nb < 1e-9:
        return 1.0 if na < 1e-9 and nb < 1e-9 else 0.0
    return float(a @ b / (na * nb))


def test_flat_plane_is_uniform_in_pressure_mode_and_blank_in_contour_mode():
    plane = shapes.plane()
    # A slightly wrong normal: the "pca" fit settles the pad flat on the plane anyway.
    for plane_rule in ("pca", "paper"):
        img = tactile.imprint(plane, [3.7, 0.0, -2.1], [0.1, 1.0, 0.05], Sensor(mode="pressure", plane=plane_rule))
        assert img.shape == (16, 16) and img.dtype == np.float32
        np.testing.assert_allclose(img, 1.0, atol=1e-5)
    assert np.abs(tactile.imprint(plane, [3.7, 0.0, -2.1], [0, 1, 0], Sensor(mode="contour"))).max() == 0.0


@pytest.mark.parametrize("radius,depth", [(40.0, 3.0), (25.0, 2.0)])
def test_sphere_pressed_gives_disk_of_known_radius(radius, depth):
    sensor = Sensor(mode="pressure", depth_mm=depth)
    img = tactile.imprint(shapes.sphere(radius), [0.0, radius, 0.0], [0.0, 1.0, 0.0], sensor)
    r = np.sqrt(2 * radius * depth - depth**2)
    x, y = taxel_centres(sensor)
    dist = np.hypot(x, y)
    touched = img > 0
    assert dist[touched].max() <= r + sensor.pitch_mm
    assert touched[dist <= r - sensor.pitch_mm].all()
    # Equivalent disc radius from the touched area, within one taxel.
    assert abs(np.sqrt(touched.sum() / np.pi) * sensor.pitch_mm - r) <= sensor.pitch_mm
    # Penetration at the centre is nearly full, and falls off outwards.
    assert img[7:9, 7:9].min() > 0.95
    assert img[8, 8] > img[8, 11] > img[8, 13]


def test_cylinder_gives_band_along_its_axis():
    radius, depth = 20.0, 2.0
    sensor = Sensor(mode="pressure", depth_mm=depth)
    img = tactile.imprint(shapes.cylinder(radius), [0.0, radius, 0.0], [0.0, 1.0, 0.0], sensor)
    # Axis x is the image's right (up is -z at the +y pole): every column is the same.
    np.testing.assert_allclose(img, np.repeat(img[:, :1], sensor.cols, axis=1), atol=1e-5)
    half_width = np.sqrt(2 * radius * depth - depth**2)
    _, y = taxel_centres(sensor)
    touched = img[:, 0] > 0
    assert np.abs(y[:, 0][touched]).max() <= half_width + sensor.pitch_mm
    assert touched[np.abs(y[:, 0]) <= half_width - sensor.pitch_mm].all()
    contour = tactile.imprint(shapes.cylinder(radius), [0.0, radius, 0.0], [0.0, 1.0, 0.0], Sensor(depth_mm=depth))
    np.testing.assert_allclose(contour, np.repeat(contour[:, :1], sensor.cols, axis=1), atol=1e-5)
    assert contour.max() > 0.5


def test_cube_edge_fills_half_the_image():
    # 0.25 mm inside the top face from the edge x = 30; the three nearest
    # vertices lie on the top face, so the "paper" plane is the top face.
    cube = shapes.box(half=30.0, n=60)
    point, normal = [29.75, 30.0, 0.1], [0.0, 1.0, 0.0]
    img = tactile.imprint(cube, point, normal, Sensor(mode="pressure", plane="paper"))
    assert abs(img.mean() - 0.5) <= 1 / 16
    np.testing.assert_allclose(img[:, :8], 1.0)
    np.testing.assert_allclose(img[:, 9:], 0.0)
    # In contour mode all four planes cut the side face at the edge: one bright line.
    contour = tactile.imprint(cube, point, normal, Sensor(plane="paper"))
    assert contour[:, [0, 1, 2, 3, 4, 5, 12, 13, 14, 15]].max() == 0.0
    assert contour[:, 7:9].max(axis=1).min() > 0.5


@pytest.mark.parametrize("mode", ["contour", "pressure"])
def test_turning_the_pad_90_degrees_is_rot90(mode):
    surface = shapes.bumps()
    sensor = Sensor(mode=mode)
    base = tactile.imprint(surface, [3.0, 0.0, 2.0], [0.0, 1.0, 0.0], sensor)
    assert base.max() > 0.3
    for k in (1, 2, 3):
        turned = tactile.imprint(surface, [3.0, 0.0, 2.0], [0.0, 1.0, 0.0], sensor, angle_deg=90.0 * k)
        np.testing.assert_allclose(turned, np.rot90(base, k), atol=1e-4)


def test_contour_rings_on_sphere_are_nested_and_ordered_by_depth():
    radius, depth = 49.0, 2.0
    sensor = Sensor(rows=32, cols=32, pitch_mm=1.0, depth_mm=depth)
    img = tactile.imprint(shapes.sphere(radius, n=48), [0.0, radius, 0.0], [0.0, 1.0, 0.0], sensor)
    x, y = taxel_centres(sensor)
    dist = np.hypot(x, y)
    levels = depth * np.arange(1, 5) / 4
    rings = np.sqrt(2 * radius * levels - levels**2)  # 7.0, 9.9, 12.1, 14.0 mm
    gray = [img[np.abs(dist - r) <= 0.5].mean() for r in rings]
    assert np.all(np.diff(gray) > 0), gray
    # Gray level ~ k/4 for plane k: the deepest ring is about four times the shallowest.
    assert 2.5 < gray[3] / gray[0] < 5.5, gray
    assert img[dist < rings[0] - 2].max() == 0.0
    assert img[dist > rings[3] + 2].max() == 0.0


def test_single_imprint_equals_batch_and_shapes():
    surface = shapes.bumps()
    P = np.array([[3.0, 0.0, 2.0], [-10.0, 0.0, 5.0], [0.0, 0.0, -12.0]])
    N = np.tile([0.0, 1.0, 0.0], (3, 1))
    sensor = Sensor(rows=12, cols=20)
    batch = tactile.imprints(surface, P, N, sensor, angles_deg=[0.0, 30.0, -45.0])
    assert batch.shape == (3, 12, 20) and batch.dtype == np.float32
    assert 0.0 <= batch.min() and batch.max() <= 1.0
    for i, angle in enumerate([0.0, 30.0, -45.0]):
        np.testing.assert_array_equal(tactile.imprint(surface, P[i], N[i], sensor, angle), batch[i])
    assert tactile.imprints(surface, np.zeros((0, 3)), np.zeros((0, 3)), sensor).shape == (0, 12, 20)


def test_surface_facing_away_or_missing_gives_nothing():
    sphere = shapes.sphere(20.0)
    # Pad beside the sphere: nothing under it.
    assert tactile.imprint(sphere, [60.0, 0.0, 0.0], [0.0, 1.0, 0.0], Sensor(mode="pressure")).max() == 0.0
    # Pad above the sphere: it moves down until it meets the surface (a guarded move);
    # only the fitted plane can differ slightly, as it sees less of the sphere from there.
    sensor = Sensor(mode="pressure")
    above = tactile.imprint(sphere, [0.0, 35.0, 0.0], [0.0, 1.0, 0.0], sensor)
    assert above.max() > 0.9
    np.testing.assert_allclose(above, tactile.imprint(sphere, [0.0, 20.0, 0.0], [0.0, 1.0, 0.0], sensor), atol=0.05)
    # Pad inside a larger sphere: every face the rays meet faces away from it.
    big = shapes.sphere(40.0)
    assert tactile.imprint(big, [0.0, -30.0, 0.0], [0.0, 1.0, 0.0], Sensor(mode="pressure", plane="paper")).max() == 0.0


def test_tangent_frames_are_orthonormal_and_upright():
    rng = np.random.default_rng(3)
    N = rng.normal(size=(50, 3))
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    up, right = tangent_frames(N, rng.uniform(0, 360, 50))
    for a, b in ((up, right), (up, N), (right, N)):
        np.testing.assert_allclose((a * b).sum(1), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.cross(right, up), N, atol=1e-12)
    up0, _ = tangent_frames(np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]))
    np.testing.assert_allclose(up0, [[0, 1, 0], [0, 1, 0]], atol=1e-12)


def test_pca_plane_ignores_the_far_side_of_a_thin_part():
    # A 1 mm thick slab: the bottom faces point the other way and must not cancel the top.
    slab = shapes.box(half=1.0, n=4)
    slab = slab.replace(vertices=slab.vertices * [40.0, 0.5, 40.0])
    poses = sensor_poses(slab, [[2.0, 0.5, 3.0]], [[0.2, 1.0, 0.0]], Sensor())
    np.testing.assert_allclose(poses.normals[0], [0.0, 1.0, 0.0], atol=1e-9)


def test_sample_grid_is_symmetric():
    xs, ys = sample_grid(Sensor(rows=4, cols=4, supersample=3))
    np.testing.assert_array_equal(xs, -xs[::-1])
    np.testing.assert_array_equal(ys, -xs)


@pytest.mark.parametrize(
    "bad",
    [
        dict(mode="tactile"),
        dict(plane="normal"),
        dict(rows=0),
        dict(cols=2.5),
        dict(pitch_mm=-1.0),
        dict(depth_mm=float("nan")),
        dict(supersample=0),
        dict(pitch_mm="wide"),
    ],
)
def test_sensor_rejects_bad_fields(bad):
    with pytest.raises(ValueError, match="Sensor"):
        Sensor(**bad)


def test_bad_points_are_rejected():
    plane = shapes.plane()
    with pytest.raises(ValueError, match="normals"):
        tactile.imprints(plane, np.zeros((2, 3)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="non-zero"):
        tactile.imprint(plane, [0, 0, 0], [0, 0, 0])
    with pytest.raises(ValueError, match="angles_deg"):
        tactile.imprints(plane, np.zeros((2, 3)), np.ones((2, 3)), angles_deg=[1.0])
    with pytest.raises(ValueError, match="finite"):
        tactile.imprint(plane, [np.nan, 0, 0], [0, 1, 0])


def test_exact_path_matches_rays_on_a_sphere_in_pressure_mode():
    sphere = shapes.sphere(30.0)
    P = np.array([[0.0, 30.0, 0.0], [30.0 * np.sin(0.5), 30.0 * np.cos(0.5), 0.0]])
    sensor = Sensor(mode="pressure")
    fast = tactile.imprints(sphere, P, P, sensor, angles_deg=[0.0, 20.0])
    exact = imprints_exact(sphere, P, P, sensor, angles_deg=[0.0, 20.0])
    # Both sample the same surface at the same points: float32 rays vs float64 barycentrics.
    np.testing.assert_allclose(fast, exact, atol=1e-3)


@pytest.mark.parametrize("name", ["cow.obj", "fandisk.obj", "rocker-arm.obj"])
def test_fast_path_agrees_with_exact_sections_on_shared_meshes(shared_mesh, name):
    """Contour imprints at 30 random vertices: ray-cast iso-lines vs exact plane sections.

    They agree closely where the pad sees the surface it touches.  They
    differ most where the exact planes also cut surfaces the pad cannot
    reach: the far wall of a thin part (a cow's ear or leg, the rocker arm's
    web), faces turned away from the pad and surfaces hidden under an
    overhang all cross the slicing planes inside the footprint, so the exact
    image has contours the rays never see.  Grazing walls add a smaller
    difference: a plane meets them over a short segment that the height
    field resolves only to a sample.
    """
    import meshsal

    mesh = meshsal.scale_to(meshsal.load_mesh(shared_mesh(name)), 150.0)
    rng = np.random.default_rng(7)
    ids = rng.choice(mesh.n_vertices, 30, replace=False)
    P, N = mesh.vertices[ids], meshsal.vertex_normals(mesh.vertices, mesh.faces)[ids]
    sensor = Sensor()
    fast = tactile.imprints(mesh, P, N, sensor)
    exact = imprints_exact(mesh, P, N, sensor)
    scores = np.array([ncc(a, b) for a, b in zip(fast, exact)])
    assert np.median(scores) >= 0.9, np.sort(scores)
    assert np.percentile(scores, 10) >= 0.7, np.sort(scores)


def test_prebuilt_scene_gives_the_same_imprints_and_a_foreign_scene_is_refused():
    from meshsal.mesh.embree import embree_scene

    surface = shapes.bumps()
    P = np.array([[3.0, 0.0, 2.0], [-10.0, 0.0, 5.0]])
    N = np.tile([0.0, 1.0, 0.0], (2, 1))
    sensor = Sensor(mode="pressure")
    scene = embree_scene(surface)
    np.testing.assert_array_equal(
        tactile.imprints(surface, P, N, sensor, scene=scene), tactile.imprints(surface, P, N, sensor)
    )
    np.testing.assert_array_equal(
        tactile.imprint(surface, P[0], N[0], sensor, scene=scene), tactile.imprint(surface, P[0], N[0], sensor)
    )
    # The scene of the mesh before scaling, and of another mesh, are caught.
    scaled = surface.replace(vertices=surface.vertices * 1.5)
    with pytest.raises(ValueError, match="scene does not hold mesh"):
        tactile.imprints(scaled, P, N, sensor, scene=scene)
    with pytest.raises(ValueError, match="scene does not hold mesh"):
        tactile.imprints(shapes.sphere(20.0), P, N, sensor, scene=scene)
    with pytest.raises(ValueError, match="Embree scene"):
        tactile.imprints(surface, P, N, sensor, scene="scene")


def test_a_scene_is_recognized_through_a_fold_of_its_own_mesh():
    # A decimation can fold a surface so that a small face lies just above a large one: a probe from above the
    # large face meets the small one first.  The scene still holds its mesh; the mesh moved along the faces'
    # normal, or scaled, is still refused.
    from meshsal.mesh import Mesh
    from meshsal.mesh.embree import embree_scene
    from tactile.raycast import mesh_scene

    V = np.array([[-10.0, -10, 0], [10, -10, 0], [0, 10, 0], [-1, -5, 0.1], [1, -5, 0.1], [0, -1, 0.1]])
    folded = Mesh(vertices=V, faces=np.array([[0, 1, 2], [3, 4, 5]]))
    scene = embree_scene(folded)
    assert mesh_scene(folded, scene) is scene
    for other in (folded.replace(vertices=V + [0.0, 0.0, 0.5]), folded.replace(vertices=V * 1.5)):
        with pytest.raises(ValueError, match="scene does not hold mesh"):
            mesh_scene(other, scene)


def test_thread_chunks_do_not_change_the_imprints():
    surface = shapes.bumps()
    rng = np.random.default_rng(4)
    P = np.column_stack([rng.uniform(-20, 20, 40), np.zeros(40), rng.uniform(-20, 20, 40)])
    N = np.tile([0.0, 1.0, 0.0], (40, 1))
    angles = rng.uniform(0, 360, 40)
    one = tactile.imprints(surface, P, N, Sensor(), angles, workers=1)
    np.testing.assert_array_equal(tactile.imprints(surface, P, N, Sensor(), angles, workers=3), one)
    for i in (0, 17, 39):
        np.testing.assert_array_equal(tactile.imprint(surface, P[i], N[i], Sensor(), angles[i]), one[i])


def test_pad_whose_centre_is_off_the_edge_still_sees_the_surface_under_it():
    # The plane ends at x = 100; the pad centre is 5 mm beyond it, so its
    # centre rays meet nothing and the columns over the plane carry the imprint.
    plane = shapes.plane(size=200.0)
    img = tactile.imprint(plane, [105.0, 0.0, 0.0], [0.0, 1.0, 0.0], Sensor(mode="pressure", plane="paper"))
    x, _ = taxel_centres(Sensor())
    # At the +y pole the image's up is -z and its right +x: x_world = 105 + x.
    over = 105.0 + x < 100.0 - 1.0
    beyond = 105.0 + x > 100.0 + 1.0
    assert over.sum() == 16 * 5 and beyond.sum() == 16 * 10
    np.testing.assert_allclose(img[over], 1.0, atol=1e-5)
    np.testing.assert_allclose(img[beyond], 0.0)


def test_pca_fit_of_a_few_points_equals_their_fit_in_a_large_batch():
    # A few points look only at the surface near them; a large batch sums
    # over the whole mesh: both must give the same planes.
    surface = shapes.bumps(n=120)
    rng = np.random.default_rng(9)
    P = np.column_stack([rng.uniform(-30, 30, 12), np.zeros(12), rng.uniform(-30, 30, 12)])
    N = np.tile([0.0, 1.0, 0.0], (12, 1)) + rng.normal(scale=0.2, size=(12, 3))
    batch = sensor_poses(surface, P, N, Sensor()).normals
    for i in range(12):
        np.testing.assert_allclose(
            sensor_poses(surface, P[i : i + 1], N[i : i + 1], Sensor()).normals[0], batch[i], atol=1e-12
        )


def test_contour_lines_match_their_definition_plane_by_plane():
    from tactile.image import contour_lines, plane_depths

    rng = np.random.default_rng(2)
    sensor = Sensor(depth_mm=2.0)
    depth = np.round(rng.uniform(0.0, 2.6, (3, 20, 24)), 1)  # ties with the plane depths included
    depth[depth > 2.2] = np.inf
    expected = np.zeros(depth.shape, dtype=np.float32)
    padded = np.pad(depth, ((0, 0), (1, 1), (1, 1)), mode="edge")
    for k, level in enumerate(plane_depths(sensor), start=1):
        inside = padded <= level
        neighbours_inside = inside[:, :-2, 1:-1] & inside[:, 2:, 1:-1] & inside[:, 1:-1, :-2] & inside[:, 1:-1, 2:]
        expected[inside[:, 1:-1, 1:-1] & ~neighbours_inside] = k / 4
    np.testing.assert_array_equal(contour_lines(depth, sensor), expected)
