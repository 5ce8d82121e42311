"""The evaluation protocols: grouped folds, no leakage, instance-disjoint calibration, seeded fusion."""

import dataclasses

import numpy as np
import pytest

import classify
import tactile
from classify.experiment import protocols
from classify.experiment.protocols import InstanceData, InstanceJob, PaperJob
from classify.recognizers import touches
from classify.recognizers.touches import Recognizer


def _tagged_pool(n_objects=3, per_object=20, seed=0):
    """Imprints whose first taxel holds their own index, so any row can be traced back."""
    rng = np.random.default_rng(seed)
    y = np.repeat(np.arange(n_objects), per_object)
    X = rng.uniform(0, 1, (len(y), 16, 16)).astype(np.float32)
    X[np.arange(len(y)), 4, 4] += 3 * y  # a class signal
    X[:, 0, 0] = np.arange(len(y))
    return X, y


def test_paper_splits_partition_each_repeat_keep_groups_whole_and_reshuffle():
    y = np.repeat([0, 1, 2], [10, 12, 15])
    groups = np.concatenate([np.arange(10) // 2, 100 + np.arange(12) // 2, 200 + np.arange(15) // 3])
    splits = protocols.paper_splits(y, groups, folds=5, repeats=3, seed=7)
    assert len(splits) == 15
    for r in range(3):
        mine = [s for s in splits if s.repeat == r]
        tests = np.concatenate([s.test for s in mine])
        assert sorted(tests.tolist()) == list(range(len(y)))  # each imprint tested once per repeat
        for s in mine:
            assert not set(groups[s.train].tolist()) & set(groups[s.test].tolist())  # no point on both sides
            assert np.all(np.bincount(y[s.test], minlength=3) >= 1)  # stratified over objects
    first = [s.test.tolist() for s in splits if s.repeat == 0]
    second = [s.test.tolist() for s in splits if s.repeat == 1]
    assert first != second
    again = protocols.paper_splits(y, groups, folds=5, repeats=3, seed=7)
    assert all(np.array_equal(a.test, b.test) for a, b in zip(splits, again))


def test_paper_splits_refuse_too_few_points_per_object_naming_them():
    with pytest.raises(ValueError, match="at least 5 points per object; 0 has 3 "):
        protocols.paper_splits(np.repeat([0, 1], [3, 10]), folds=5)
    with pytest.raises(ValueError, match="at least 5 points per object; cup has 3, tet has 4 "):
        protocols.paper_splits(np.repeat([0, 1, 2], [3, 4, 10]), folds=5, names=["cup", "tet", "ball"])


def test_paper_job_never_trains_or_selects_on_a_test_imprint(monkeypatch):
    X, y = _tagged_pool()
    groups = np.arange(len(y))
    selected, fits = [], []

    def spy_select(Xs, ys, threshold=0.85):
        selected.append(Xs[:, 0, 0].astype(int))
        return Xs[:, 0, 0].astype(int) % 3 != 0  # drop some training imprints

    real_fit = touches.fit

    def spy_fit(name, params, X_train, y_train, g):
        fits.append(X_train[:, 0].astype(int))
        model = real_fit(name, params, X_train, y_train, g)
        model.spied_training_tags = fits[-1]
        return model

    def spy_proba(model, X_test, n):
        assert not set(model.spied_training_tags.tolist()) & set(X_test[:, 0].astype(int).tolist())
        predicted.append(X_test[:, 0].astype(int))
        return real_proba(model, X_test, n)

    real_proba, predicted = touches.posteriors, []
    monkeypatch.setattr(tactile, "select_by_similarity", spy_select, raising=False)
    monkeypatch.setattr(touches, "fit", spy_fit)
    monkeypatch.setattr(touches, "posteriors", spy_proba)
    splits = protocols.paper_splits(y, groups, 5, 1, 3)
    (out,) = protocols.paper_job(PaperJob(X, y, groups, splits, (Recognizer("naive_bayes", True, {}, 0.85),), 3))
    assert len(selected) == len(fits) == len(predicted) == 5
    assert sorted(np.concatenate(predicted).tolist()) == list(range(len(y)))  # each imprint predicted once
    for rows, trained, split in zip(selected, fits, splits):
        assert sorted(rows.tolist()) == sorted(split.train.tolist())  # selection saw the training fold only
        assert not set(trained.tolist()) & set(split.test.tolist())
        assert np.all(trained % 3 != 0)  # the fit used the selected fold
    assert out.confusion[:, 2].sum() == len(y) and out.rates.shape == (3,)  # (true, predicted, count) pairs
    assert out.kept == pytest.approx(2 / 3, abs=0.05)


def _instance_data(n_objects=3, train_instances=3, sessions=2, k=5, seed=0):
    """Training imprints tagged with a unique id in taxel (0, 0) (1e-6 per id, too faint to matter);
    test imprints tagged >= 10000."""
    rng = np.random.default_rng(seed)
    X, y, inst, point = [], [], [], []
    for o in range(n_objects):
        for j in range(1, train_instances + 1):
            for _ in range(sessions):
                img = rng.uniform(0, 0.2, (k, 16, 16))
                img[:, 3 * o : 3 * o + 3, 5:9] = 0.9
                X.append(img)
                y += [o] * k
                inst += [j] * k
                point += list(range(k))
    X = np.concatenate(X).astype(np.float32)
    X[:, 0, 0] = np.arange(len(X)) * 1e-6
    test = []
    for o in range(n_objects):
        img = rng.uniform(0, 0.2, (k, 16, 16)).astype(np.float32)
        img[:, 3 * o : 3 * o + 3, 5:9] = 0.9
        img[:, 0, 0] = (10000 + 100 * o + np.arange(k)) * 1e-6
        test.append(img)
    return InstanceData(
        X, np.array(y), np.array(inst), np.array(point), tuple(test), tuple(f"obj{o}" for o in range(n_objects))
    )


def _tag(X):
    X = np.asarray(X)
    return np.round(X.reshape(len(X), -1)[:, 0] * 1e6).astype(int)


def test_instance_job_calibrates_on_held_out_instances_and_never_trains_on_the_test(monkeypatch):
    data = _instance_data()
    models, scored = {}, []
    real_proba = touches.posteriors

    def spy_proba(model, X, n):
        # The raw features are the imprints: each training row's tag is in the model's own rows.
        models.setdefault(id(model), _tag(model.X_))
        scored.append((_tag(model.X_), _tag(X)))
        return real_proba(model, X, n)

    monkeypatch.setattr(touches, "posteriors", spy_proba)
    out = protocols.instance_job(InstanceJob(data, Recognizer("knn", False, {}, 0.85), 5, 50, 0, 0))
    assert len(models) == 4  # 3 held-out instances, then all of them
    held_out = []
    for trained, held in scored[:3]:  # each held-out instance is scored by the model that never saw it
        trained_instances = set(data.train_instance[trained].tolist())
        held_instances = set(data.train_instance[held].tolist())
        assert len(held_instances) == 1 and trained_instances == {1, 2, 3} - held_instances
        held_out += held_instances
    assert sorted(held_out) == [1, 2, 3]
    scored = [tags for _, tags in scored]
    assert all(np.all(tags < 10000) for tags in models.values())  # no test imprint ever trains
    assert sorted(np.concatenate(scored[3:]).tolist()) == sorted(np.concatenate([_tag(t) for t in data.test]).tolist())
    assert out.rates.shape == (5, 3) and np.all(out.rates[0] == 100.0)
    assert out.sets.tolist() == [5, 10, 10, 5, 1]  # C(5, k): fewer than 50 exist


def _one_by_one(self, sets):
    return [self.fit(X, y, groups) for X, y, groups in sets]


def test_protocols_fitting_the_evolutionary_svms_together_give_the_outcomes_of_fitting_them_one_by_one(monkeypatch):
    """The folds' (and the calibration's) duals are solved in one loop: the outcomes are those of one fit at a time."""
    rec = Recognizer("evolutionary_svm", True, {"evolutionary_svm": {"max_generations": 60}}, 0.85)
    X, y = _tagged_pool(seed=2)
    groups = np.arange(len(y)) // 2
    paper = PaperJob(X, y, groups, protocols.paper_splits(y, groups, 4, 1, 5), (rec,), 3)
    instance = InstanceJob(_instance_data(seed=5), rec, 3, 6, 2, 1)
    together = protocols.paper_job(paper)[0], protocols.instance_job(instance)
    monkeypatch.setattr(Recognizer, "fit_each", _one_by_one)
    alone = protocols.paper_job(paper)[0], protocols.instance_job(instance)
    for a, b in zip(together, alone):
        for name in ("rates", "confusion", "kept"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert np.array_equal(together[1].stop_correct, alone[1].stop_correct)


def test_instance_selection_drops_per_held_out_set_what_selection_of_that_set_drops(monkeypatch):
    # Object 1's imprints of instance 2 copy object 0's: they go wherever both are in the training set.
    data = _instance_data()
    X, y, inst = data.train_X.copy(), data.train_y, data.train_instance
    X[(y == 1) & (inst == 2)] = X[(y == 0) & (inst == 2)]
    data = dataclasses.replace(data, train_X=X)
    fitted = []
    real = Recognizer.fit_subsets

    def spy(self, F, labels, groups, subsets):
        fitted.extend(subsets)
        return real(self, F, labels, groups, subsets)

    monkeypatch.setattr(Recognizer, "fit_subsets", spy)
    protocols.instance_job(InstanceJob(data, Recognizer("naive_bayes", True, {}, 0.85), 5, 7, 11, 2))
    sets = [np.flatnonzero(inst != held) for held in (1, 2, 3)] + [np.arange(len(inst))]
    expected = [protocols.select_training(X, y, rows) for rows in sets]
    assert len(fitted) == 4 and all(np.array_equal(a, b) for a, b in zip(fitted, expected))
    # With instance 2 held out every imprint stays; with it in, its copies and what they resemble go.
    assert [len(rows) == len(kept) for rows, kept in zip(sets, expected)] == [False, True, False, False]


def test_instance_job_is_paired_and_deterministic():
    data = _instance_data(seed=3)
    a = protocols.instance_job(InstanceJob(data, Recognizer("naive_bayes", True, {}, 0.85), 5, 7, 11, 2))
    b = protocols.instance_job(InstanceJob(data, Recognizer("naive_bayes", True, {}, 0.85), 5, 7, 11, 2))
    assert np.array_equal(a.rates, b.rates) and np.array_equal(a.confusion, b.confusion)


def test_fused_rate_after_all_touches_is_not_below_a_single_touch_for_every_classifier():
    rng = np.random.default_rng(5)
    X, y, inst, point = [], [], [], []
    k = 6
    for o in range(3):
        for j in (1, 2, 3):
            img = rng.uniform(0, 1, (k, 16, 16))
            img[:, 4 * o : 4 * o + 4, 4:8] += 0.6  # a weak signal among noise
            X.append(img / 1.6)
            y += [o] * k
            inst += [j] * k
            point += list(range(k))
    test = []
    for o in range(3):
        img = rng.uniform(0, 1, (k, 16, 16))
        img[:, 4 * o : 4 * o + 4, 4:8] += 0.6
        test.append((img / 1.6).astype(np.float32))
    data = InstanceData(
        np.concatenate(X).astype(np.float32), np.array(y), np.array(inst), np.array(point), tuple(test), ("a", "b", "c")
    )
    for name in classify.PAPER_NAMES:  # the place-aware recognizer has no place-free job
        out = protocols.instance_job(InstanceJob(data, Recognizer(name, False, {}, 0.85), k, 20, 0, 0))
        assert out.rates[-1].mean() >= out.rates[0].mean(), name


def test_folds_grouped_by_point_keep_a_points_twins_out_of_its_test_fold():
    # Three identical imprints per point, each point's pattern unrelated to its object: only a twin in training
    # could recognize a test imprint.
    rng = np.random.default_rng(8)
    points = rng.uniform(0, 1, (40, 16, 16)).astype(np.float32)
    y = np.repeat(np.arange(2), 60)
    point = np.repeat(np.arange(40), 3)
    X = points[point]
    rec = Recognizer("knn", False, {}, 0.85)

    def rate(groups):
        splits = protocols.paper_splits(y, groups, folds=5, repeats=1, seed=0)
        return protocols.paper_job(PaperJob(X, y, groups, tuple(splits), (rec,), 2))[0].rates.mean()

    grouped = rate(touches.point_groups(y, point))
    assert 25.0 <= grouped <= 75.0  # chance: no twin ever trains
    assert rate(np.arange(len(y))) > 90.0  # imprints on their own: the twins leak


@pytest.mark.parametrize("drops", [False, True])
def test_a_fold_selection_leaves_whole_is_fitted_once_and_every_outcome_is_its_own(monkeypatch, drops):
    """One classifier without and with selection in one job: the outcomes of each alone, and a training fold
    selection leaves whole is fitted once (four folds: four fits, eight when selection drops imprints)."""
    X, y = _tagged_pool(seed=3)
    groups = np.arange(len(y)) // 2
    splits = protocols.paper_splits(y, groups, 4, 1, 5)
    monkeypatch.setattr(
        tactile,
        "select_by_similarity",
        lambda Xs, ys, threshold=0.85: Xs[:, 0, 0] % 3 != 0 if drops else Xs[:, 0, 0] >= 0,
    )
    real_fit, fits = touches.fit, []

    def counting_fit(*args):
        fits.append(args[2][:, 0].astype(int))
        return real_fit(*args)

    monkeypatch.setattr(touches, "fit", counting_fit)
    pair = tuple(Recognizer("naive_bayes", selection, {}, 0.85) for selection in (False, True))
    both = protocols.paper_job(PaperJob(X, y, groups, splits, pair, 3))
    assert len(fits) == (8 if drops else 4)
    assert both[1].kept == pytest.approx(2 / 3, abs=0.05) if drops else both[1].kept == 1.0
    for rec, together in zip(pair, both):
        (alone,) = protocols.paper_job(PaperJob(X, y, groups, splits, (rec,), 3))
        for name in ("rates", "confusion", "kept"):
            assert np.array_equal(getattr(together, name), getattr(alone, name)), name
