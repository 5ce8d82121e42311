"""The learned touch saliency: features, the model, distinctiveness, and that no test instance trains it."""

import dataclasses
import json

import numpy as np
import pytest
from models import one_feature_model
from shapes import icosphere

from classify.experiment import samples as dataset
from classify.experiment.stages import ObjectSet, Runtime, SampleKey, instance_stage
from classify.experiment.survey import Survey, distinctiveness, fit_replicate_model
from classify.runtime.cluster import Inline
from meshsal.attention import CHANNELS
from meshsal.mesh.curvature import mesh_saliency
from meshsal.objects import toys, ycb
from meshsal.objects.instances import InstanceSpec, make_instance, random_rotation
from meshsal.points import attention_maps, interest_points, learned_points, points_by_method, view_channels
from meshsal.points.learned import FEATURES, POOL_FACTOR, TouchModel, candidate_pool, fit_touch_model, point_features
from meshsal.points.touch import touchable


def bumpy_sphere():
    """A sphere with one bump: the bump's vertices have the highest mean curvature."""
    mesh = icosphere(50.0, 4)
    V = mesh.vertices.copy()
    direction = V / np.linalg.norm(V, axis=1, keepdims=True)
    top = np.array([0.0, 0.0, 1.0])
    bump = 8.0 * np.exp(-((np.arccos(np.clip(direction @ top, -1, 1)) / 0.12) ** 2))
    return mesh.replace(vertices=V + direction * bump[:, None]), top


# ---------------------------------------------------------------- the model


def test_ridge_recovers_a_planted_linear_rule_and_weights_pick_the_channel():
    rng = np.random.default_rng(1)
    X = rng.random((400, len(FEATURES)))
    y = 2.0 * X[:, FEATURES.index("entropy_mean")] - 1.0 * X[:, FEATURES.index("curvature")]
    model = fit_touch_model(X, y, alpha=1e-6, trained_on=("a/1",))
    assert np.allclose(model.predict(X), y, atol=1e-4)
    weights = model.channel_weights
    assert max(weights, key=weights.get) == "entropy"
    assert np.mean(list(weights.values())) == pytest.approx(1.0)
    assert model.trained_on == ("a/1",)


def test_no_channel_predicts_anything_gives_equal_weights():
    rng = np.random.default_rng(2)
    X = rng.random((100, len(FEATURES)))
    y = -X[:, : len(CHANNELS)].sum(axis=1)  # every channel hurts: no non-negative weight helps
    assert fit_touch_model(X, y).channel_weights == dict.fromkeys(CHANNELS, 1.0)


@pytest.mark.parametrize(
    "features, target, message",
    [
        (np.zeros((5, 3)), np.zeros(5), "shape"),
        (np.zeros((5, len(FEATURES))), np.zeros(4), "target"),
        (np.zeros((1, len(FEATURES))), np.zeros(1), "at least 2"),
        (np.full((3, len(FEATURES)), np.nan), np.zeros(3), "finite"),
    ],
)
def test_bad_training_data_is_refused(features, target, message):
    with pytest.raises(ValueError, match=message):
        fit_touch_model(features, target)


def test_model_file_round_trip_and_bad_files(tmp_path):
    rng = np.random.default_rng(3)
    model = fit_touch_model(
        rng.random((60, len(FEATURES))), rng.random(60), trained_on=("cow/1", "cup/2"), view_size=48
    )
    path = tmp_path / "m.json"
    model.save(path)
    again = TouchModel.load(path)
    X = rng.random((7, len(FEATURES)))
    assert np.allclose(again.predict(X), model.predict(X)) and again.trained_on == model.trained_on
    assert again.channel_weights == pytest.approx(model.channel_weights)
    assert again.view_size == 48
    document = json.loads(path.read_text())
    (tmp_path / "unsized.json").write_text(json.dumps({k: v for k, v in document.items() if k != "view_size"}))
    assert TouchModel.load(tmp_path / "unsized.json").view_size is None  # the size is optional in a file
    document["coef"] = document["coef"][:3]
    (tmp_path / "short.json").write_text(json.dumps(document))
    with pytest.raises(ValueError, match="short.json.*malformed"):
        TouchModel.load(tmp_path / "short.json")
    (tmp_path / "other.json").write_text('{"points": []}')
    with pytest.raises(ValueError, match="other.json: not a touch model"):
        TouchModel.load(tmp_path / "other.json")


# ---------------------------------------------------------------- distinctiveness


def test_distinctiveness_leaves_the_instance_out():
    # Object 0's instance 1 has an exact twin of each touch on the same instance: that must not count.
    D = np.array([[0.0], [0.0], [1.0], [3.0], [3.2]])
    y = np.array([0, 0, 0, 1, 1])
    inst = np.array([1, 1, 2, 1, 2])
    m = distinctiveness(D, y, inst)
    # Row 0: nearest same-object touch on another instance is at 1.0, nearest other object at 3.0.
    assert m[0] == pytest.approx((3.0 - 1.0) / (3.0 + 1.0))
    assert m[2] == pytest.approx((2.0 - 1.0) / 3.0)
    assert m[3] == pytest.approx((2.0 - 0.2) / 2.2)


def test_a_confusable_touch_has_a_negative_margin():
    D = np.array([[0.0], [5.0], [0.1], [5.1]])
    m = distinctiveness(D, np.array([0, 0, 1, 1]), np.array([1, 2, 1, 2]))
    assert (m < 0).all()  # each touch lies nearer the other object's touch than its own object's


# ---------------------------------------------------------------- features and points


def test_pool_spreads_over_the_surface_from_its_farthest_vertex():
    mesh, top = bumpy_sphere()
    pool = candidate_pool(mesh, n=5)
    assert pool.size == POOL_FACTOR * 5 == np.unique(pool).size
    assert mesh.vertices[pool[0]] @ top == pytest.approx(np.abs(mesh.vertices @ top).max())  # the bump's tip
    # Farthest points: no two of the first 12 closer than a third of the radius.
    P = mesh.vertices[pool[:12]]
    d = np.linalg.norm(P[:, None] - P[None], axis=2) + np.eye(12) * 1e9
    assert d.min() > 50.0 / 3


def test_pool_is_the_same_on_a_turned_resized_instance():
    mesh, _ = bumpy_sphere()
    # Roughened, so that no two candidates tie for farthest (a sphere's symmetry would).
    mesh = mesh.replace(vertices=mesh.vertices * np.random.default_rng(0).uniform(0.99, 1.01, (mesh.n_vertices, 1)))
    spec = InstanceSpec(random_rotation(np.random.default_rng(3)), 1.04, 0, 0.0, 1.0)
    assert candidate_pool(make_instance(mesh, spec), n=5).tolist() == candidate_pool(mesh, n=5).tolist()


def test_point_features_know_the_bump():
    mesh, top = bumpy_sphere()
    vs = mesh_saliency(mesh)
    seen = view_channels(mesh, size=48, vertex_saliency=vs, threads=1)
    ids = np.array([int(np.argmax(mesh.vertices @ top)), int(np.argmin(mesh.vertices @ top))])
    F = point_features(mesh, seen.views, seen.results, attention_maps(seen), vs, ids, spacing=5.0)
    assert F.shape == (2, len(FEATURES)) and np.isfinite(F).all()
    col = {name: F[:, k] for k, name in enumerate(FEATURES)}
    assert col["curvature"][0] > 5 * col["curvature"][1]  # the bump's tip against the sphere's bottom
    assert col["mesh_saliency"][0] > col["mesh_saliency"][1]
    assert ((col["views"] >= 1) & (col["views"] <= 72)).all()
    assert all(0.0 <= col[f"{c}_mean"].min() and col[f"{c}_mean"].max() <= 1.0 for c in CHANNELS)


def test_learned_points_go_where_the_model_says():
    mesh, top = icosphere(50.0, 3), np.array([0.0, 0.0, 1.0])
    vs = mesh_saliency(mesh)
    pool = candidate_pool(mesh, n=6)
    height = mesh.vertices[pool] @ top
    features = np.zeros((pool.size, len(FEATURES)))
    features[:, FEATURES.index("votes")] = height  # a model that wants the top
    pts = learned_points(mesh, pool, features, one_feature_model("votes"), vs, n=6)
    assert pts.method == "learned" and len(pts) == 6
    assert mesh.vertices[pts.vertex_ids[0]] @ top == pytest.approx(height.max())
    assert np.all(np.diff(pts.scores) <= 0)
    assert touchable(mesh, pts.positions, pts.normals, 2 * pts.min_spacing).all()
    flipped = learned_points(mesh, pool, -features, one_feature_model("votes"), vs, n=6)
    assert mesh.vertices[flipped.vertex_ids[0]] @ top == pytest.approx(height.min())


def test_model_methods_need_a_model_and_share_one_render():
    mesh = toys.make("cup")
    with pytest.raises(ValueError, match="needs a fitted touch model"):
        interest_points(mesh, method="learned")
    with pytest.raises(ValueError, match="needs channel weights"):
        interest_points(mesh, method="attention", combination="learned")
    model = one_feature_model("curvature")
    many = points_by_method(
        mesh, ["attention", "learned", "attention_learned", "uniform"], n=5, size=48, threads=1, model=model
    )
    for method, pts in many.items():
        alone = interest_points(mesh, n=5, method=method, size=48, threads=1, model=model)
        assert alone.vertex_ids.tolist() == pts.vertex_ids.tolist(), method
    assert many["attention_learned"].combination == "learned"
    # Equal learned weights are the paper's combination.
    assert many["attention_learned"].vertex_ids.tolist() == many["attention"].vertex_ids.tolist()


# ---------------------------------------------------------------- no test instance trains the model


def test_replicate_model_ignores_whatever_the_test_instance_holds():
    rng = np.random.default_rng(4)

    def survey(label):
        return Survey(np.arange(30), rng.random((30, len(FEATURES))), rng.random((30, 5)) + label)

    surveys = {(name, j): survey(k) for k, name in enumerate(["cow", "cup"]) for j in (1, 2)}
    clean = fit_replicate_model(surveys)
    poisoned = dict(surveys)
    poisoned["cow", 0] = Survey(np.arange(30), np.full((30, len(FEATURES)), np.nan), np.zeros((30, 5)))
    model = fit_replicate_model(poisoned)
    assert np.array_equal(model.coef, clean.coef) and model.intercept == clean.intercept
    assert set(model.trained_on) == {"cow/1", "cow/2", "cup/1", "cup/2"}


def test_the_instance_stage_trains_each_model_on_training_instances_only():
    settings = dataset.Settings(n_points=3, view_size=48, train_instances=2, train_sessions=1)
    names = ("cow", "cup")
    nominal = tuple(dataset.nominal_mesh(toys.make(n), settings) for n in names)
    stage = instance_stage(ObjectSet(names, nominal), ["uniform", "learned"], settings, 2, Runtime(Inline(), None, 1))
    samples, models = stage.samples, stage.models
    assert len(models) == 2
    for model in models:
        assert sorted(model.trained_on) == ["cow/1", "cow/2", "cup/1", "cup/2"]
        assert model.view_size == 48  # the size its surveys' views were rendered at
    assert models[0].coef.tolist() != models[1].coef.tolist()  # each replicate its own instances
    for r in range(2):
        for i in range(2):
            for j in range(3):
                imprints = samples[SampleKey(r, "learned", i, j)].imprints
                assert imprints.shape[:2] == (1, 3)
    # The test instance's survey is never touched: it has no descriptors to train on.
    test_survey = dataset.instance_samples(
        dataset.SampleTask(nominal[0], "cow", (), settings, 0, 0, survey=True)
    ).survey
    assert test_survey.descriptors is None and test_survey.features.shape[1] == len(FEATURES)


def test_every_instance_of_an_object_offers_the_same_candidates():
    settings = dataset.Settings(n_points=3, view_size=32)
    nominal = dataset.nominal_mesh(ycb.load("banana"), settings)
    pools = [
        dataset.instance_samples(dataset.SampleTask(nominal, "banana", (), settings, r, j, survey=True)).survey.pool
        for r, j in [(0, 0), (0, 1), (1, 2)]
    ]
    assert pools[0].size == 3 * POOL_FACTOR
    assert pools[0].tolist() == pools[1].tolist() == pools[2].tolist()


def test_a_batch_of_single_meshes_refuses_the_learned_methods():
    from classify.batch import BatchSettings

    with pytest.raises(ValueError, match="learned.*touch model"):
        BatchSettings(methods=("uniform", "learned"))


def test_cli_learned_points_from_a_model_file(tmp_path, capsys):
    from classify.cli import main

    def points(out, *options):
        return main(
            ["points", "cup", *options, "--n-points", "4", "--view-size", "32", "--quiet", "--out", str(tmp_path / out)]
        )

    assert points("none", "--method", "learned") != 0
    assert "--model" in capsys.readouterr().err
    assert not (tmp_path / "none" / "points.json").exists()
    model_path = tmp_path / "model.json"
    one_feature_model("curvature").save(model_path)
    assert points("o", "--method", "learned", "--model", str(model_path)) == 0
    document = json.loads((tmp_path / "o" / "points.json").read_text())
    assert document["method"] == "learned" and len(document["points"]) == 4
    assert document["settings"]["model"] == str(model_path)
    assert points("w", "--method", "attention_learned", "--model", str(model_path)) == 0
    document = json.loads((tmp_path / "w" / "points.json").read_text())
    assert document["combination"] == "learned"
    assert document["settings"]["channel_weights"] == dict.fromkeys(CHANNELS, 1.0)
    assert "warning" not in capsys.readouterr().err  # a model that records no size
    dataclasses.replace(one_feature_model("curvature"), view_size=64).save(model_path)
    assert points("s", "--method", "learned", "--model", str(model_path)) == 0
    err = capsys.readouterr().err
    assert "features were measured on views of 64 pixels, these are 32" in err and "--view-size 64" in err


def test_a_learned_baseline_runs_both_protocols_and_compares_where_it_can():
    from classify.experiment import run_experiment

    settings = dataset.Settings(n_points=3, view_size=48, train_instances=2, train_sessions=1)
    result = run_experiment(
        ["cow", "cup"],
        methods=("learned", "uniform"),
        baseline="learned",
        replicates=1,
        folds=2,
        repeats=1,
        classifiers=("knn",),
        settings=settings,
        cache_dir=None,
        quiet=True,
        n_jobs=1,
    )
    assert {c.method for c in result.cells if c.protocol == "paper"} == {"uniform"}
    assert {(c.method, c.protocol) for c in result.comparisons} == {("uniform", "instance")}
