"""One record of a mesh being worked on: each thing computed once, what is given kept, the same points."""

import dataclasses
from collections import Counter

import numpy as np
import pytest
import shapes
from quick import SMALL

import meshsal
from classify.experiment.samples import SampleTask, instance_samples
from meshsal.attention import rig
from meshsal.mesh import embree
from meshsal.points import PointOptions, Workpiece, method_points, points_by_method
from meshsal.views import tracer as tracer_module


@pytest.fixture
def counted(monkeypatch):
    """Counts of whole-mesh Embree scenes built (by robustness and face count) and of renderings."""
    scenes, renders = Counter(), Counter()
    real_scene, real_views = embree.embree_scene, rig._rig_views

    def scene(mesh, *args, robust=True, **kwargs):
        scenes[robust, mesh.n_faces] += 1
        return real_scene(mesh, *args, robust=robust, **kwargs)

    def views(mesh, *args, **kwargs):
        renders[mesh.n_faces] += 1
        return real_views(mesh, *args, **kwargs)

    monkeypatch.setattr(embree, "embree_scene", scene)
    monkeypatch.setattr(tracer_module, "embree_scene", scene)
    monkeypatch.setattr(rig, "_rig_views", views)
    return scenes, renders


def test_each_thing_is_computed_once_and_what_is_given_is_kept(counted):
    scenes, renders = counted
    mesh = shapes.sphere(radius=40.0, n=12)
    piece = Workpiece(mesh, view_size=32, threads=1)
    assert piece.scene is piece.scene and piece.seen is piece.seen
    # The renderer's camera rays take Embree's fast traversal: the only other scene of the mesh.
    once = {(True, mesh.n_faces): 1, (False, mesh.n_faces): 1}
    assert scenes == once and renders == {mesh.n_faces: 1}
    assert piece.vertex_saliency.shape == (mesh.n_vertices,) and piece.vertex_normals.shape == (mesh.n_vertices, 3)
    given = np.linspace(0.0, 1.0, mesh.n_vertices)
    other = Workpiece.of(mesh, scene=piece.scene, vertex_saliency=given, seen=piece.seen, view_size=32)
    assert other.scene is piece.scene and other.seen is piece.seen
    np.testing.assert_array_equal(other.vertex_saliency, given)
    assert scenes == once and renders == {mesh.n_faces: 1}
    assert Workpiece.of(piece) is piece


def test_bad_workpieces_are_refused_with_what_is_wrong():
    mesh = shapes.sphere(radius=40.0, n=8)
    with pytest.raises(ValueError, match="needs a meshsal.Mesh, got ndarray"):
        Workpiece.of(mesh.vertices)
    with pytest.raises(ValueError, match="vertex_saliency must have shape"):
        Workpiece.of(mesh, vertex_saliency=np.zeros(3))
    with pytest.raises(ValueError, match="renders 64-pixel views, but the options ask for 32"):
        points_by_method(Workpiece(mesh, view_size=64), ["attention"], PointOptions(n=3, size=32))


def test_a_workpiece_gives_the_points_a_mesh_gives_and_keeps_what_they_computed(counted):
    scenes, renders = counted
    cup = meshsal.objects.toys.make("cup")
    options = PointOptions(n=5, size=32, seed=3, threads=1)
    methods = ["attention", "uniform", "mesh_saliency"]
    plain = method_points(cup, methods, options)
    piece = Workpiece(cup, view_size=32, threads=1)
    shared = method_points(piece, methods, options)
    for m in methods:
        np.testing.assert_array_equal(plain[m].positions, shared[m].positions)
        np.testing.assert_array_equal(plain[m].vertex_ids, shared[m].vertex_ids)
    # Each call built one robust scene for every method's touch check and rendered once.
    assert scenes[True, cup.n_faces] == 2 and renders == {cup.n_faces: 2}
    # What the call computed stays with the workpiece: a second call renders nothing and builds no scene.
    again = method_points(piece, ["attention"], options)
    np.testing.assert_array_equal(again["attention"].positions, shared["attention"].positions)
    assert scenes[True, cup.n_faces] == 2 and renders == {cup.n_faces: 2}


def test_an_instance_of_the_experiment_has_one_robust_scene_and_one_rendering(counted):
    scenes, renders = counted
    settings = dataclasses.replace(SMALL, view_size=32)
    task = SampleTask(
        nominal=meshsal.objects.toys.make("cup"),
        name="cup",
        methods=("mesh_saliency", "uniform", "attention"),
        settings=settings,
        replicate=0,
        index=1,
        survey=True,
        places=True,
        codebook=True,
        threads=1,
    )
    samples = instance_samples(task)
    assert samples.places.codebook is not None and samples.survey is not None
    (faces,) = renders
    # Points, touch checks, imprints, survey, places and codebooks share one robust scene; the
    # renderer's camera rays take Embree's fast traversal, the only other scene of the mesh.
    assert scenes == {(True, faces): 1, (False, faces): 1} and renders == {faces: 1}
    # Methods that do not look render nothing.
    scenes.clear(), renders.clear()
    instance_samples(dataclasses.replace(task, methods=("uniform",), survey=False, places=False))
    assert renders == {} and scenes == {(True, faces): 1}


def test_the_learned_pass_takes_the_survey_s_mesh_saliency_and_chooses_the_same_points(monkeypatch):
    from models import one_feature_model

    from meshsal.mesh import curvature

    settings = dataclasses.replace(SMALL, view_size=32)
    nominal = meshsal.objects.toys.make("cup")
    plain = instance_samples(SampleTask(nominal, "cup", ("uniform",), settings, 0, 1, survey=True, threads=1))
    survey = plain.survey
    assert survey.vertex_saliency.shape == (nominal.n_vertices,)
    round_trip = type(survey).from_arrays(survey.to_arrays())
    np.testing.assert_array_equal(round_trip.vertex_saliency, survey.vertex_saliency)
    learned = SampleTask(
        nominal, "cup", ("learned",), settings, 0, 1, model=one_feature_model("votes"), surveyed=survey, threads=1
    )
    without = instance_samples(dataclasses.replace(learned, surveyed=dataclasses.replace(survey, vertex_saliency=None)))

    def refused(*args, **kwargs):
        raise AssertionError("mesh saliency computed again")

    monkeypatch.setattr(curvature, "mesh_saliency", refused)
    taken = instance_samples(learned)
    for name in ("positions", "normals", "imprints"):
        np.testing.assert_array_equal(
            getattr(taken.by_method["learned"], name), getattr(without.by_method["learned"], name)
        )
