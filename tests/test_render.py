"""The renderer against geometry with known answers."""

import numpy as np
import pytest
from shapes import icosphere, plane

from meshsal.mesh import Mesh
from meshsal.mesh.embree import embree_scene
from meshsal.views.cameras import Camera, project, view_rig
from meshsal.views.render import render, render_views, surface_points
from meshsal.views.tracer import tracer

FRONT = Camera(direction=[0, 0, -1], up=[0, 1, 0])


@pytest.fixture(scope="module")
def sphere():
    return icosphere(radius=2.0, subdivisions=5, center=(1.0, -3.0, 0.5))


def test_rig_is_18_sets_of_4_views_90_degrees_apart_on_a_great_circle():
    rig = view_rig()
    assert len(rig) == 18 and all(len(s) == 4 for s in rig)
    for cams in rig:
        D = np.array([c.direction for c in cams])
        np.testing.assert_allclose(np.linalg.norm(D, axis=1), 1.0, atol=1e-12)
        np.testing.assert_allclose(
            D @ D.T, np.array([[1, 0, -1, 0], [0, 1, 0, -1], [-1, 0, 1, 0], [0, -1, 0, 1]]), atol=1e-12
        )
        axis = cams[0].up
        assert all(np.allclose(c.up, axis) for c in cams)
        np.testing.assert_allclose(D @ axis, 0.0, atol=1e-12)
    indices = [c.view_index for s in rig for c in s]
    assert indices == list(range(72))
    directions = np.array([c.direction for s in rig for c in s])
    assert len(np.unique(directions.round(6), axis=0)) == 72


def test_rig_sees_top_bottom_and_every_face():
    coarse = icosphere(subdivisions=2)
    views = render_views(coarse, [c for s in view_rig() for c in s], size=64)
    seen = np.unique(np.concatenate([v.face_id[v.mask] for v in views]))
    assert seen.size == coarse.n_faces
    directions = np.array([v.camera.direction for v in views])
    assert directions[:, 1].max() > 0.95 and directions[:, 1].min() < -0.95


@pytest.mark.parametrize("size", [65, 128])
def test_sphere_mask_covers_its_disk(sphere, size):
    view = render(sphere, FRONT, size=size)
    radius_px = 2.0 / view.pixel_size
    assert abs(view.mask.sum() / (np.pi * radius_px**2) - 1.0) < 0.01
    assert view.rgb.shape == (size, size, 3) and view.rgb.dtype == np.float32
    assert np.all(view.face_id[~view.mask] == -1) and np.all(np.isinf(view.depth[~view.mask]))
    assert np.all(view.face_id[view.mask] >= 0) and np.all(np.isfinite(view.depth[view.mask]))


def test_sphere_depth_at_centre_pixel_is_exact(sphere):
    view = render(sphere, FRONT, size=129)  # odd: the centre pixel's ray passes through the centre
    centre, radius = view.center, view.radius
    expected = 2.0 * radius - 2.0  # the eye sits 2 * radius before the centre; the sphere's radius is 2
    assert np.allclose(centre, [1.0, -3.0, 0.5])
    assert abs(view.depth[64, 64] - expected) < 1e-3


@pytest.mark.parametrize("projection", ["orthographic", "perspective"])
def test_each_pixel_sees_a_face_that_projects_onto_it(sphere, projection):
    camera = Camera(direction=[0.3, -0.2, -1.0], up=[0, 1, 0], projection=projection)
    view = render(sphere, camera, size=96)
    rows, cols = np.nonzero(view.mask)
    centroids = sphere.vertices[sphere.faces[view.face_id[rows, cols]]].mean(axis=1)
    offset = project(view, centroids) - np.stack([rows + 0.5, cols + 0.5], axis=1)
    assert np.abs(offset).max() < 1.5
    exact = project(view, surface_points(sphere, view, rows, cols))
    np.testing.assert_allclose(exact, np.stack([rows + 0.5, cols + 0.5], axis=1), atol=1e-2)


def test_perspective_sees_less_than_a_hemisphere(sphere):
    ortho = render(sphere, FRONT, size=64)
    persp = render(sphere, Camera(direction=[0, 0, -1], up=[0, 1, 0], projection="perspective"), size=64)
    seen = lambda v: np.unique(v.face_id[v.mask]).size  # noqa: E731
    assert seen(persp) < seen(ortho)


def test_headlight_shading_is_brightest_where_the_surface_faces_the_camera(sphere):
    view = render(sphere, FRONT, size=65)
    gray = view.rgb[..., 0]
    assert gray[32, 32] == pytest.approx(gray.max(), abs=0.02)
    assert gray[32, 32] > 0.75 and 0.2 < gray[view.mask].min() < 0.4


def test_vertex_colors_are_interpolated():
    plane = Mesh(
        vertices=[[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]],
        faces=[[0, 1, 2], [0, 2, 3]],
        vertex_colors=[[1, 0, 0], [1, 0, 0], [0, 0, 1], [0, 0, 1]],
    )
    view = render(plane, FRONT, size=64)
    red, blue = view.rgb[..., 0], view.rgb[..., 2]
    rows = np.arange(64)
    assert red[52, 32] > 0.8 and blue[12, 32] > 0.8 and view.mask[12:53, 12:53].all()
    assert np.all(np.diff(red[rows[view.mask[:, 32]], 32]) >= -1e-6)  # red fades towards the top


def test_textured_cow_shows_its_texture(shared_mesh):
    from meshsal import load_mesh

    cow = load_mesh(shared_mesh("spot/spot.obj"))
    assert cow.texture is not None and cow.uv is not None
    view = render(cow, view_rig()[0][1], size=192)  # side view
    rows, cols = np.nonzero(view.mask)
    face = view.face_id[rows, cols]
    uv = np.einsum("kc,kcd->kd", view.bary[rows, cols], cow.uv[face])
    H, W = cow.texture.shape[:2]
    texel = cow.texture[
        np.clip(((1 - uv[:, 1]) * H).astype(int), 0, H - 1), np.clip((uv[:, 0] * W).astype(int), 0, W - 1)
    ].mean(axis=1)
    shown = view.rgb[rows, cols].mean(axis=1)
    flat = render(cow.replace(texture=None, uv=None), view_rig()[0][1], size=192).rgb[rows, cols].mean(axis=1)
    # The texture's dark patches and eyes appear where the texture puts them, not a flat colour.
    assert np.corrcoef(texel, shown / flat)[0, 1] > 0.9
    assert (texel < 100).mean() > 0.05 and shown.std() > 0.1


def _every_pixel(mesh, view):
    """face_id and depth of a ray through every pixel centre, traced with no culling (the reference)."""
    size, cam = view.size, view.camera
    x = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    X, Y = np.meshgrid(x, -x)
    if cam.projection == "orthographic":
        half = view.radius * (1.0 + cam.margin)
        origins = view.eye + half * (X[..., None] * cam.right + Y[..., None] * cam.up)
        directions = np.broadcast_to(cam.direction, origins.shape)
    else:
        t = np.tan(np.deg2rad(cam.fov_deg) / 2.0)
        directions = cam.direction + t * (X[..., None] * cam.right + Y[..., None] * cam.up)
        directions = directions / np.linalg.norm(directions, axis=-1, keepdims=True)
        origins = np.broadcast_to(view.eye, directions.shape)
    hit = embree_scene(mesh).run(
        np.ascontiguousarray(origins.reshape(-1, 3), np.float32),
        np.ascontiguousarray(directions.reshape(-1, 3), np.float32),
        output=1,
    )
    depth = np.where(hit["primID"] >= 0, hit["tfar"] * (directions.reshape(-1, 3) @ cam.direction), np.inf)
    return hit["primID"].reshape(size, size), depth.reshape(size, size)


def _dumbbell():
    """Two spheres and the gap between them: a silhouette far from convex."""
    a, b = (
        icosphere(radius=1.0, subdivisions=3, center=(-2.0, 0, 0)),
        icosphere(radius=0.6, subdivisions=3, center=(2.0, 0.5, 0)),
    )
    return Mesh(vertices=np.vstack([a.vertices, b.vertices]), faces=np.vstack([a.faces, b.faces + a.n_vertices]))


@pytest.mark.parametrize("projection", ["orthographic", "perspective"])
def test_culled_rays_never_lose_a_hit(projection):
    # The renderer casts rays only inside the image of the convex hull; a ray through every pixel must agree.
    mesh = _dumbbell()
    cameras = [Camera(direction=c.direction, up=c.up, projection=projection) for s in view_rig()[::3] for c in s]
    for view in render_views(mesh, cameras, size=48):
        face_id, depth = _every_pixel(mesh, view)
        assert (face_id >= 0).sum() > 100
        # Float32 rounding of a ray's origin may flip the face hit on a shared edge, never hit or miss.
        np.testing.assert_array_equal(view.mask, face_id >= 0)
        assert (view.face_id != face_id).mean() < 0.01
        np.testing.assert_allclose(view.depth[view.mask], depth[view.mask], atol=1e-3)


def test_flat_mesh_has_no_3d_hull_and_still_renders_from_every_side():
    flat = plane(size=2.0, n=4)
    for camera in (
        FRONT,
        Camera(direction=[1.0, 0.0, -1e-3], up=[0, 1, 0]),
        Camera(direction=[0.6, 0.3, -0.7], up=[0, 1, 0]),
    ):
        view = render(flat, camera, size=40)
        face_id, _ = _every_pixel(flat, view)
        np.testing.assert_array_equal(view.mask, face_id >= 0)


def test_a_prebuilt_scene_renders_the_same_views(sphere):
    cameras = view_rig()[4]
    fresh = render_views(sphere, cameras, size=32)
    reused = render_views(sphere, cameras, size=32, scene=embree_scene(sphere, robust=False))
    traced = render_views(sphere, cameras, size=32, scene=tracer(sphere))
    robust = render_views(sphere, cameras, size=32, scene=embree_scene(sphere))
    for a, b, t, c in zip(fresh, reused, traced, robust):
        for other in (b, t):
            np.testing.assert_array_equal(a.face_id, other.face_id)
            np.testing.assert_array_equal(a.rgb, other.rgb)
        # A robust scene computes barycentrics another way: the same surface points, rounding apart.  A pixel
        # ray through a shared edge may report either face there (a tie, CPU-dependent), never a farther one.
        np.testing.assert_array_equal(a.mask, c.mask)
        np.testing.assert_allclose(a.depth[a.mask], c.depth[a.mask], rtol=1e-6)
        other = a.mask & (a.face_id != c.face_id)
        assert other.mean() < 0.01
        for fa, fc in zip(a.face_id[other], c.face_id[other]):
            assert set(sphere.faces[fa].tolist()) & set(sphere.faces[fc].tolist())  # neighbours at the tie
        same = a.mask & ~other
        np.testing.assert_allclose(a.bary[same], c.bary[same], atol=1e-4)


def test_vertex_ids_are_the_corners_of_the_face_each_pixel_sees(sphere):
    view = render(sphere, FRONT, size=32)
    np.testing.assert_array_equal(view.vertex_ids[view.mask], sphere.faces[view.face_id[view.mask]])
    assert np.all(view.vertex_ids[~view.mask] == -1) and view.vertex_ids.shape == (32, 32, 3)


def test_a_tracer_of_another_mesh_is_refused(sphere):
    with pytest.raises(ValueError, match="tracer of mesh"):
        render_views(sphere, view_rig()[0], size=16, scene=tracer(icosphere(subdivisions=1)))


def test_bad_inputs_raise():
    with pytest.raises(ValueError, match="parallel"):
        Camera(direction=[0, 0, 1], up=[0, 0, 2])
    with pytest.raises(ValueError, match="projection"):
        Camera(direction=[0, 0, 1], up=[0, 1, 0], projection="fisheye")
    with pytest.raises(ValueError, match="size"):
        render(icosphere(subdivisions=1), FRONT, size=0)
