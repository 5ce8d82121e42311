"""The Embree scene: the direct buffer copy builds the very scene embreex's own path builds, in the device whose
instruction set $VISUOTACTILE_EMBREE_CONFIG chooses."""

import sys
from types import SimpleNamespace

import numpy as np
import pytest
from shapes import bumps, icosphere

from meshsal.mesh import Mesh
from meshsal.mesh.embree import Scene, _attach_directly, _scene_handle, embree_device, embree_scene, is_robust
from meshsal.mesh.rounding import OtherRounding, rounded_otherwise
from meshsal.util.reproducible import EMBREE_VARIABLE, cpu_flags


def _embreex_scene(mesh, robust):
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    scene = rtcs.EmbreeScene(device=embree_device(), robust=robust)
    TriangleMesh(scene, mesh.vertices.astype(np.float32), mesh.faces.astype(np.int32))
    return scene


def _rays(mesh, n=5000, seed=0):
    rng = np.random.default_rng(seed)
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    origins = (rng.normal(size=(n, 3)) * 5.0 * np.linalg.norm(hi - lo)).astype(np.float32)
    directions = (rng.uniform(lo, hi, size=origins.shape) - origins).astype(np.float32)
    return origins, directions / np.linalg.norm(directions, axis=1, keepdims=True)


@pytest.mark.parametrize("robust", [True, False], ids=["robust", "fast"])
@pytest.mark.parametrize("mesh", [icosphere(radius=3.0, subdivisions=4), bumps(n=40)], ids=["sphere", "bumps"])
def test_scene_answers_every_ray_as_embreex_own_build_does(mesh, robust):
    origins, directions = _rays(mesh)
    ours = embree_scene(mesh, robust=robust).embree.run(origins, directions, output=1)
    theirs = _embreex_scene(mesh, robust).run(origins, directions, output=1)
    hits = theirs["primID"] >= 0
    assert 500 < hits.sum() < 5000
    np.testing.assert_array_equal(ours["primID"], theirs["primID"])
    for key in ("tfar", "u", "v", "Ng"):
        np.testing.assert_array_equal(ours[key][hits], theirs[key][hits])


def test_hits_with_representable_answers_are_exact():
    square = Mesh(vertices=[[0, 0, 0], [4, 0, 0], [0, 4, 0], [4, 4, 0]], faces=[[0, 1, 2], [3, 2, 1]])
    origins = np.array([[1, 2, 3], [0.5, 0.25, 96], [3, 3, 0.125]], np.float32)
    hit = embree_scene(square).run(origins, np.array([[0, 0, -1]], np.float32), output=1)
    assert hit["primID"].tolist() == [0, 0, 1]
    np.testing.assert_array_equal(hit["tfar"], [3, 96, 0.125])
    np.testing.assert_array_equal(hit["u"], [0.25, 0.125, 0.25])
    np.testing.assert_array_equal(hit["v"], [0.5, 0.0625, 0.25])


@pytest.mark.parametrize("mesh", [icosphere(radius=3.0, subdivisions=4), bumps(n=40)], ids=["sphere", "bumps"])
def test_hits_are_the_exact_crossing_rounded_to_float32(mesh):
    origins, directions = _rays(mesh)
    scene = embree_scene(mesh)
    hit, embrees = scene.run(origins, directions, output=1), scene.embree.run(origins, directions, output=1)
    np.testing.assert_array_equal(hit["primID"] >= 0, embrees["primID"] >= 0)
    hits = np.flatnonzero(hit["primID"] >= 0)
    assert hits.size > 500
    # Another face than Embree's only across an edge of both, where float32 put the crossing on the wrong side.
    moved = np.flatnonzero(hit["primID"] != embrees["primID"])
    assert moved.size <= 5
    for i in moved:
        assert len(set(mesh.faces[hit["primID"][i]]) & set(mesh.faces[embrees["primID"][i]])) == 2
    V = mesh.vertices.astype(np.float32).astype(np.float64)
    a, b, c = (V[mesh.faces[hit["primID"][hits], j]] for j in range(3))
    o, d = origins[hits].astype(np.float64), directions[hits].astype(np.float64)
    # o + t d = a + u (b - a) + v (c - a), solved in float64.
    t, u, v = np.linalg.solve(np.stack([-d, b - a, c - a], axis=2), (o - a)[..., None])[..., 0].T
    for key, exact in (("tfar", t), ("u", u), ("v", v)):
        # Within one float32 step, plus float64's own error where u, v are near 0 (Embree's up to 1e-4 off).
        error = np.abs(hit[key][hits] - exact)
        assert np.all(error <= np.spacing(np.abs(exact).astype(np.float32)) + 1e-7), key
        assert error.mean() < np.abs(embrees[key][hits] - exact).mean(), key


def test_a_scene_gives_the_same_hits_whatever_embrees_last_bits_and_its_choice_at_an_edge():
    mesh = bumps(n=40)
    origins, directions = _rays(mesh, n=20000)
    scene = embree_scene(mesh)
    stand_in = OtherRounding(scene.embree, 0.5, np.random.default_rng(1), settled=scene)
    other = Scene(embree=stand_in, corners=scene.corners, mesh=scene.mesh)
    ours, theirs = scene.run(origins, directions, output=1), other.run(origins, directions, output=1)
    assert (ours["primID"] >= 0).sum() > 2000 and stand_in.turned > 0
    for key in ("primID", "tfar", "u", "v", "Ng"):
        np.testing.assert_array_equal(ours[key], theirs[key])


def _square(seam):
    """Two triangles meeting on the diagonal x + y = 4 of a 4 x 4 square at z = 0, facing +z; with ``seam`` the
    second has corners of its own at the same places (as across a texture seam)."""
    V = [[0, 0, 0], [4, 0, 0], [0, 4, 0], [4, 4, 0]]
    if seam:
        return Mesh(vertices=V + [[0, 4, 0], [4, 0, 0]], faces=[[0, 1, 2], [3, 4, 5]])
    return Mesh(vertices=V, faces=[[0, 1, 2], [3, 2, 1]])


@pytest.mark.parametrize("seam", [False, True], ids=["shared-corners", "seam"])
def test_a_ray_through_an_edge_meets_the_lower_face_of_two_facing_it(seam):
    scene = embree_scene(_square(seam))
    assert scene.neighbors.tolist() == [[1, -1, -1], [0, -1, -1]]
    origins = np.array([[1, 3, 2], [2, 2, 5], [3.5, 0.5, 1], [3, 3, 1]], np.float32)
    down = np.array([[0, 0, -1]], np.float32)
    hit = scene.run(origins, down, output=1)
    assert hit["primID"].tolist() == [0, 0, 0, 1]
    np.testing.assert_array_equal(hit["tfar"], [2, 5, 1, 1])
    np.testing.assert_array_equal(hit["Ng"], [[0, 0, 16]] * 4)
    # Embree's other face for the three on the edge: the same answer.
    swapped = SimpleNamespace(run=lambda *a, **k: {**scene.embree.run(*a, **k), "primID": np.ones(4, np.int32)})
    again = Scene(embree=swapped, corners=scene.corners, mesh=scene.mesh).run(origins, down, output=1)
    for key in ("primID", "tfar", "u", "v", "Ng"):
        np.testing.assert_array_equal(again[key], hit[key])


def test_a_ray_through_an_edge_meets_the_face_facing_it_first():
    # A ridge along the y axis: face 0 turns its back to a ray coming down, face 1 (its corners flipped) faces it.
    ridge = Mesh(vertices=[[0, -1, 0], [0, 1, 0], [1, 0, -1], [-1, 0, -1]], faces=[[0, 1, 2], [0, 1, 3]])
    scene = embree_scene(ridge)
    hit = scene.run(np.array([[0, 0.25, 5]], np.float32), np.array([[0, 0, -1]], np.float32), output=1)
    assert hit["primID"].tolist() == [1] and hit["tfar"][0] == 5
    assert float(hit["Ng"][0] @ [0, 0, -1]) < 0


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the direct copy is checked where CI runs: Linux")
def test_the_direct_copy_is_taken_with_this_embreex():
    from embreex import rtcore_scene as rtcs

    assert _attach_directly(rtcs.EmbreeScene(), icosphere(subdivisions=1))


def test_an_object_of_another_layout_is_never_read_as_a_scene():
    assert _scene_handle(SimpleNamespace(is_committed=0)) is None


def test_robustness_is_read_from_the_scene():
    sphere = icosphere(subdivisions=1)
    assert is_robust(embree_scene(sphere))
    assert not is_robust(embree_scene(sphere, robust=False))
    assert not is_robust(SimpleNamespace(is_committed=1, run=None))


def _hits(mesh):
    return embree_scene(mesh).embree.run(*_rays(mesh), output=1)  # Embree's own rounding


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the device is configured where CI runs: Linux")
def test_every_scene_is_created_in_one_device_made_with_the_configuration(monkeypatch):
    monkeypatch.setenv(EMBREE_VARIABLE, "isa=sse2")
    assert embree_device() is not None and embree_device() is embree_device()
    monkeypatch.setenv(EMBREE_VARIABLE, "")
    assert embree_device() is None  # embreex's own device per scene


# Embree's AVX-512 kernels need the Skylake-X set; a CPU without it runs AVX2 at best.
_AVX512_SKX = {"avx512f", "avx512cd", "avx512dq", "avx512bw", "avx512vl"}


@pytest.mark.skipif("avx2" not in (cpu_flags() or ()), reason="needs a CPU whose own choice is above SSE2")
def test_the_configuration_reaches_embree_sse2_kernels_round_differently_from_the_cpus_own(monkeypatch):
    own = "avx512" if _AVX512_SKX <= cpu_flags() else "avx2"
    mesh = bumps(n=40)
    monkeypatch.setenv(EMBREE_VARIABLE, "isa=sse2")
    sse2 = _hits(mesh)
    monkeypatch.setenv(EMBREE_VARIABLE, "")
    native = _hits(mesh)
    monkeypatch.setenv(EMBREE_VARIABLE, f"isa={own}")
    chosen = _hits(mesh)
    hit = native["primID"] >= 0
    assert hit.sum() > 500
    assert not np.array_equal(sse2["tfar"][hit], native["tfar"][hit])  # FMA or not: the last bits differ
    for key in ("primID", "tfar", "u", "v"):
        np.testing.assert_array_equal(chosen[key], native[key])  # the CPU's own choice is its best instruction set


@pytest.mark.skipif("avx2" not in (cpu_flags() or ()), reason="needs a CPU whose own choice is above SSE2")
def test_a_scenes_distances_and_barycentrics_do_not_depend_on_embrees_instruction_set(monkeypatch):
    mesh = bumps(n=40)
    origins, directions = _rays(mesh)
    monkeypatch.setenv(EMBREE_VARIABLE, "isa=sse2")
    sse2 = embree_scene(mesh).run(origins, directions, output=1)
    monkeypatch.setenv(EMBREE_VARIABLE, "")
    native = embree_scene(mesh).run(origins, directions, output=1)
    same = (sse2["primID"] == native["primID"]) & (sse2["primID"] >= 0)
    assert same.sum() > 500
    for key in ("tfar", "u", "v"):
        np.testing.assert_array_equal(sse2[key][same], native[key][same])


@pytest.mark.skipif("avx512f" in (cpu_flags() or ()), reason="needs a CPU without AVX-512")
def test_a_configuration_embree_refuses_is_an_error_naming_the_variable(monkeypatch):
    monkeypatch.setenv(EMBREE_VARIABLE, "isa=avx512")
    with pytest.raises(ValueError, match=f"{EMBREE_VARIABLE}='isa=avx512'.*CPU does not support"):
        embree_scene(icosphere(subdivisions=1))


def _cow_views():
    import meshsal
    from meshsal.views import cameras, render

    rig = [c for s in cameras.view_rig()[:2] for c in s]
    return render.render_views(meshsal.objects.toys.make("cow"), rig, size=48, threads=1)


@pytest.mark.parametrize("share", [0.0, 0.1, 1.0], ids=["as-rounded", "a-tenth-rounded-otherwise", "all"])
def test_views_do_not_depend_on_how_the_cpu_rounds_embrees_hits(share):
    # With every share, each hit near an edge goes to the face across it, as another rounding may choose.
    views = _cow_views()
    with rounded_otherwise(share, seed=0) as stand_ins:
        again = _cow_views()
    assert sum(stand_in.turned for stand_in in stand_ins) > 0
    assert sum(stand_in.moved for stand_in in stand_ins) > 0 or share == 0.0
    for view, other_view in zip(views, again):
        np.testing.assert_array_equal(view.face_id, other_view.face_id)
        for key in ("rgb", "bary", "depth"):
            np.testing.assert_array_equal(getattr(view, key), getattr(other_view, key))


def test_the_same_rounding_around_the_settled_hits_moves_the_views():
    # The stand-in has teeth: placed where the settling cannot absorb it, it changes what the views hold.
    views = _cow_views()
    with rounded_otherwise(0.1, seed=0, where="settled") as stand_ins:
        again = _cow_views()
    assert stand_ins and all(not isinstance(s, Scene) for s in stand_ins)
    assert any(not np.array_equal(a.face_id, b.face_id) for a, b in zip(views, again))
    assert any(not np.array_equal(a.depth, b.depth) for a, b in zip(views, again))


def test_rounded_otherwise_restores_the_scenes_and_refuses_an_unknown_place():
    import meshsal.mesh.embree as embree_module

    with pytest.raises(ValueError, match="where must be one of"):
        with rounded_otherwise(where="elsewhere"):
            pass
    with pytest.raises(RuntimeError), rounded_otherwise():
        raise RuntimeError
    assert embree_module.Scene is Scene and isinstance(embree_scene(bumps(n=8)), Scene)


def test_imprints_do_not_depend_on_how_the_cpu_rounds_embrees_hits():
    import tactile

    surface = bumps(n=40)
    rng = np.random.default_rng(4)
    P = np.column_stack([rng.uniform(-20, 20, 30), np.zeros(30), rng.uniform(-20, 20, 30)])
    N = np.tile([0.0, 1.0, 0.0], (30, 1))
    sensor = tactile.Sensor(supersample=2, mode="pressure")  # depths themselves, not their contour levels
    scene = embree_scene(surface)
    other = Scene(
        embree=OtherRounding(scene.embree, 1.0, np.random.default_rng(2)), corners=scene.corners, mesh=scene.mesh
    )
    ours = tactile.imprints(surface, P, N, sensor, scene=scene)
    assert np.count_nonzero(ours) > 0
    np.testing.assert_array_equal(ours, tactile.imprints(surface, P, N, sensor, scene=other))


def test_neighbours_are_found_by_position_and_only_across_edges_of_two_faces():
    from meshsal.mesh.embree import _neighbors

    # Faces 0 and 1 share the edge (0, 1), face 1 with its corners flipped; faces 2, 3, 4 make a fin on (4, 5);
    # face 5 meets face 0 on (0, 2) through a vertex of its own at vertex 0's place (a seam).
    V = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [5, 5, 0], [6, 5, 0], [5, 6, 0], [5, 5, 1], [5, 5, -1]]
    V += [[0, 0, 0], [-1, 0, 0]]
    F = [[0, 1, 2], [1, 0, 3], [4, 5, 6], [4, 5, 7], [4, 5, 8], [9, 2, 10]]
    found = _neighbors(Mesh(vertices=V, faces=F))
    assert found[[0, 1, 5]].tolist() == [[-1, 5, 1], [-1, -1, 0], [-1, -1, 0]]
    assert found[2:5, 2].tolist() == [-1, -1, -1]  # a fin's edge has three faces: none is the other
