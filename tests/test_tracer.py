"""The tracer: Embree's robust first hits, found through its fast traversal.

The stimulus is a ray along an axis through a vertex of a closed sphere: the
fast traversal lets about one such ray in a hundred slip between the faces
that meet there.  The sphere is turned off its mirror planes, so that no ray
also meets a vertex on its way out.
"""

import numpy as np
import pytest

from meshsal.embree import embree_scene
from meshsal.mesh import Mesh
from meshsal.tracer import _LOCAL_RAYS, Tracer, tracer
from shapes import icosphere

CENTER = np.array([0.1, 0.2, 0.3])


def _sphere(subdivisions: int, inward: bool = False) -> Mesh:
    sphere = icosphere(radius=1.3, subdivisions=subdivisions)
    turn, _ = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))
    sphere = sphere.replace(vertices=sphere.vertices @ turn.T + CENTER)
    return sphere.replace(faces=sphere.faces[:, ::-1].copy()) if inward else sphere


def _rays_through_vertices(mesh: Mesh):
    """Rays along the six axis directions through every vertex they meet head-on.

    Returns origins and directions, (k, 3) float32 each.  Near the
    silhouette a ray may only touch a vertex, which is a tie, so those are left out.
    """
    V = mesh.vertices.astype(np.float32)
    radial = mesh.vertices - CENTER
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    origins, directions = [], []
    for axis in range(3):
        for sign in (1.0, -1.0):
            d = np.zeros(3, np.float32)
            d[axis] = -sign
            o = V[radial @ d < -0.3].copy()
            o[:, axis] = sign * 100.0  # exact in float32: the ray passes exactly through the vertex
            origins.append(o)
            directions.append(np.broadcast_to(d, o.shape))
    return np.vstack(origins), np.ascontiguousarray(np.vstack(directions))


def _point(mesh: Mesh, hit: dict) -> np.ndarray:
    """The surface points of hits, from their faces and barycentrics."""
    corners = mesh.vertices[mesh.faces[hit["primID"]]]
    u, v = hit["u"].astype(np.float64), hit["v"].astype(np.float64)
    return corners[:, 0] * (1 - u - v)[:, None] + corners[:, 1] * u[:, None] + corners[:, 2] * v[:, None]


def _run(scene, origins, directions):
    return scene.run(origins, directions, dists=np.inf, output=1)


def _slipped(mesh: Mesh, origins, directions, robust: dict) -> np.ndarray:
    """Which rays the fast scene alone answers wrongly."""
    fast = _run(embree_scene(mesh, robust=False), origins, directions)
    return (fast["primID"] < 0) | (fast["tfar"] > robust["tfar"] + 1e-3)


def _assert_robust_answers(mesh: Mesh, ours: dict, robust: dict):
    np.testing.assert_allclose(ours["tfar"], robust["tfar"], rtol=1e-6)
    # Through a vertex every face around it is a right answer: the point hit is the vertex itself.
    np.testing.assert_allclose(_point(mesh, ours), _point(mesh, robust), atol=1e-5)


@pytest.mark.parametrize("inward", [False, True], ids=["outward", "inward"])
def test_the_few_rays_that_slip_are_traced_again_near_their_lines(inward):
    mesh = _sphere(3, inward)
    origins, directions = _rays_through_vertices(mesh)
    robust = _run(embree_scene(mesh), origins, directions)
    assert np.all(robust["primID"] >= 0)
    slipped = _slipped(mesh, origins, directions, robust)
    trace = tracer(mesh)
    assert trace.facing() == (-1 if inward else 1)
    # One call per axis direction, each with a few slipped rays: small local scenes answer them.
    calls = np.flatnonzero(np.any(np.diff(directions, axis=0), axis=1)) + 1
    assert slipped.sum() >= 3 and max(s.sum() for s in np.split(slipped, calls)) <= _LOCAL_RAYS
    hits = [trace.first_hits(o, d[:1]) for o, d in zip(np.split(origins, calls), np.split(directions, calls))]
    _assert_robust_answers(mesh, {key: np.concatenate([h[key] for h in hits]) for key in hits[0]}, robust)


def test_many_rays_that_slip_at_once_are_traced_again_in_the_whole_robust_scene():
    mesh = _sphere(4)
    origins, directions = _rays_through_vertices(mesh)  # one call, each ray with its own direction
    robust = _run(embree_scene(mesh), origins, directions)
    assert _slipped(mesh, origins, directions, robust).sum() > _LOCAL_RAYS
    _assert_robust_answers(mesh, tracer(mesh).first_hits(origins, directions), robust)


def _refuse():
    raise AssertionError("the whole robust scene was asked for")


def test_rays_that_do_not_slip_are_answered_by_the_fast_scene_alone():
    mesh = _sphere(3)
    rng = np.random.default_rng(0)
    directions = rng.normal(size=(5000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    origins = CENTER - 10.0 * directions + rng.uniform(-1.0, 1.0, size=(5000, 3))
    origins, directions = origins.astype(np.float32), directions.astype(np.float32)
    trace = Tracer(mesh=mesh, fast=embree_scene(mesh, robust=False), facing=lambda: 1, robust=_refuse,
                   reach=_refuse)
    ours = trace.first_hits(origins, directions)
    robust = _run(embree_scene(mesh), origins, directions)
    assert 1000 < (robust["primID"] >= 0).sum() < 5000
    np.testing.assert_array_equal(ours["primID"] >= 0, robust["primID"] >= 0)
    np.testing.assert_allclose(ours["tfar"], robust["tfar"], rtol=1e-6)


def test_an_open_surface_is_traced_robustly_from_the_start():
    sphere = _sphere(2)
    mesh = sphere.replace(faces=sphere.faces[1:])
    origins, directions = _rays_through_vertices(mesh)
    trace = tracer(mesh)
    assert trace.facing() == 0
    ours = trace.first_hits(origins, directions)
    theirs = _run(embree_scene(mesh), origins, directions)
    for key in ("primID", "u", "v", "tfar"):
        np.testing.assert_array_equal(ours[key], theirs[key])


def test_a_robust_scene_answers_every_ray_itself():
    mesh = _sphere(2)
    scene = embree_scene(mesh)
    trace = tracer(mesh, scene)
    assert trace.fast is None and trace.robust() is scene
    origins, directions = _rays_through_vertices(mesh)
    np.testing.assert_array_equal(trace.first_hits(origins, directions)["primID"],
                                  _run(scene, origins, directions)["primID"])


def test_misses_stay_misses():
    trace = tracer(_sphere(2))
    hit = trace.first_hits(np.array([[5.0, 5.0, 100.0]], np.float32), np.array([[0, 0, -1]], np.float32))
    assert hit["primID"][0] == -1 and np.isinf(hit["tfar"][0])


def test_a_mesh_without_faces_is_refused():
    with pytest.raises(ValueError, match="no faces"):
        tracer(Mesh(vertices=np.zeros((3, 3)), faces=np.zeros((0, 3), np.int32), name="empty"))


def test_renders_of_a_scanned_bust_match_a_robust_scene_though_rays_slip(shared_mesh):
    from meshsal import load_mesh
    from meshsal.render import render_views, view_rig

    bust = load_mesh(shared_mesh("nefertiti.obj"))
    cameras = [c for s in view_rig() for c in s]
    fast_scene = embree_scene(bust, robust=False)
    unchecked = Tracer(mesh=bust, fast=None, facing=lambda: 0, robust=lambda: fast_scene, reach=_refuse)
    fast_alone = render_views(bust, cameras, scene=unchecked)
    robust = render_views(bust, cameras, scene=embree_scene(bust))
    ours = render_views(bust, cameras)
    # Some pixel rays slip through the fast scene on to a face deeper inside...
    assert sum(np.sum(a.depth[a.mask] > r.depth[a.mask] + 1.0) for a, r in zip(fast_alone, robust)) >= 1
    # ... and none of that reaches the views: rounding apart, which is largest on faces seen edge-on.
    for a, r in zip(ours, robust):
        np.testing.assert_array_equal(a.mask, r.mask)
        np.testing.assert_allclose(a.depth[a.mask], r.depth[r.mask], atol=0.01 * a.pixel_size)
        assert np.mean(a.face_id != r.face_id) < 1e-3  # ties on shared edges
