"""The Embree scene: the direct buffer copy builds the very scene embreex's own path builds."""

import sys
from types import SimpleNamespace

import numpy as np
import pytest

from meshsal.mesh.embree import _attach_directly, _scene_handle, embree_scene, is_robust
from shapes import bumps, icosphere


def _embreex_scene(mesh, robust):
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    scene = rtcs.EmbreeScene(robust=robust)
    TriangleMesh(scene, mesh.vertices.astype(np.float32), mesh.faces.astype(np.int32))
    return scene


@pytest.mark.parametrize("robust", [True, False], ids=["robust", "fast"])
@pytest.mark.parametrize("mesh", [icosphere(radius=3.0, subdivisions=4), bumps(n=40)], ids=["sphere", "bumps"])
def test_scene_answers_every_ray_as_embreex_own_build_does(mesh, robust):
    rng = np.random.default_rng(0)
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    origins = (rng.normal(size=(5000, 3)) * 5.0 * np.linalg.norm(hi - lo)).astype(np.float32)
    directions = (rng.uniform(lo, hi, size=origins.shape) - origins).astype(np.float32)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    ours = embree_scene(mesh, robust=robust).run(origins, directions, output=1)
    theirs = _embreex_scene(mesh, robust).run(origins, directions, output=1)
    hits = theirs["primID"] >= 0
    assert 500 < hits.sum() < 5000
    np.testing.assert_array_equal(ours["primID"], theirs["primID"])
    for key in ("tfar", "u", "v"):
        np.testing.assert_array_equal(ours[key][hits], theirs[key][hits])


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
