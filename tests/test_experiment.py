"""The recognition experiment: fold generation, no leakage, touch fusion, outputs, the CLI."""

import csv
import json
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

import classify
import tactile
from classify import experiment
from classify.cli import main
from classify.report import CSV_COLUMNS


def _tagged_pool(n_objects=3, per_object=20, seed=0):
    """Imprints whose first taxel holds their own index, so any row can be traced back."""
    rng = np.random.default_rng(seed)
    y = np.repeat(np.arange(n_objects), per_object)
    X = rng.uniform(0, 1, (len(y), 16, 16)).astype(np.float32)
    X[np.arange(len(y)), 4, 4] += 3 * y                 # a class signal
    X[:, 0, 0] = np.arange(len(y))
    return X, y


def test_paper_splits_partition_each_repeat_and_keep_train_and_test_apart():
    y = np.repeat([0, 1, 2], [10, 12, 15])
    splits = experiment.paper_splits(y, folds=5, repeats=3, seed=7)
    assert len(splits) == 15
    for r in range(3):
        mine = [s for s in splits if s.repeat == r]
        tests = np.concatenate([s.test for s in mine])
        assert sorted(tests.tolist()) == list(range(len(y)))          # each imprint tested once per repeat
        for s in mine:
            assert not set(s.train.tolist()) & set(s.test.tolist())
            assert len(s.train) + len(s.test) == len(y)
            assert np.all(np.bincount(y[s.test], minlength=3) >= 2)   # stratified
    first = [s.test.tolist() for s in splits if s.repeat == 0]
    second = [s.test.tolist() for s in splits if s.repeat == 1]
    assert first != second                                            # repeats reshuffle
    again = experiment.paper_splits(y, folds=5, repeats=3, seed=7)
    assert all(np.array_equal(a.test, b.test) for a, b in zip(splits, again))


def test_paper_splits_refuse_too_few_imprints_per_object():
    with pytest.raises(ValueError, match="at least 5 imprints per object"):
        experiment.paper_splits(np.repeat([0, 1], [3, 10]), folds=5)


def test_paper_protocol_never_trains_or_selects_on_a_test_imprint(monkeypatch):
    X, y = _tagged_pool()
    selected_rows, fits = [], []

    def spy_select(Xs, ys, threshold=0.85):
        selected_rows.append(Xs[:, 0, 0].astype(int))
        return Xs[:, 0, 0].astype(int) % 3 != 0           # drop some training imprints

    def spy_fit(name, params, X_train, y_train, X_test):
        fits.append((X_train[:, 0, 0].astype(int), X_test[:, 0, 0].astype(int)))
        classes = np.unique(y_train)
        return np.full((len(X_test), len(classes)), 1.0 / len(classes)), classes

    monkeypatch.setattr(tactile, "select_by_similarity", spy_select, raising=False)
    monkeypatch.setattr(experiment, "_fit_predict", spy_fit)
    cfg = {"folds": 5, "repeats": 2, "seed": 3, "threshold": 0.85, "params": {}}
    with ThreadPoolExecutor(2) as pool:
        experiment._run_paper(X, y, 3, cfg, ("knn", "deep"), pool, True, "")
    splits = experiment.paper_splits(y, 5, 2, 3)
    assert len(selected_rows) == len(splits)
    for rows, split in zip(selected_rows, splits):
        assert sorted(rows.tolist()) == sorted(split.train.tolist())  # selection saw the training fold only
    assert len(fits) == len(splits) * 2 * 2
    for train_ids, test_ids in fits:
        assert not set(train_ids.tolist()) & set(test_ids.tolist())
    kept = [t for t, _ in fits if np.all(t % 3 != 0)]
    assert len(kept) == len(splits) * 2                               # the selected runs used the filtered fold


def test_retouch_protocol_trains_on_clean_imprints_and_tests_only_reacquisitions(monkeypatch):
    train_X, train_y = _tagged_pool(n_objects=2, per_object=12)
    repeats, n_points = 3, 4
    test_X = np.random.default_rng(1).uniform(0, 1, (repeats, 2 * n_points, 16, 16)).astype(np.float32)
    test_X[:, :, 0, 0] = 1000 + np.arange(repeats * 2 * n_points).reshape(repeats, -1)
    test_y = np.repeat([0, 1], n_points)
    fits = []

    def spy_fit(name, params, X_train, y_train, X_test):
        fits.append((X_train[:, 0, 0].astype(int), X_test[:, 0, 0].astype(int)))
        return np.tile([[0.7, 0.3]], (len(X_test), 1)), np.array([0, 1])

    monkeypatch.setattr(tactile, "select_by_similarity", lambda X, y, threshold=0.85: np.ones(len(X), bool),
                        raising=False)
    monkeypatch.setattr(experiment, "_fit_predict", spy_fit)
    cfg = {"repeats": repeats, "seed": 0, "threshold": 0.85, "params": {}, "touch_sequences": 5}
    with ThreadPoolExecutor(2) as pool:
        rates, confusion, kept = experiment._run_retouch(train_X, train_y, test_X, test_y, n_points, 2, cfg,
                                                         ("knn",), pool, True, "")
    for train_ids, test_ids in fits:
        assert set(train_ids.tolist()) <= set(range(len(train_y)))
        assert sorted(test_ids.tolist()) == list(range(1000, 1000 + test_X[:, :, 0, 0].size))
    # every test imprint says "object 0": half right for any number of touches
    assert set(rates) == {("knn", s, k) for s in (False, True) for k in range(1, n_points + 1)}
    assert all(np.allclose(r, 50.0) for r in rates.values())
    assert confusion["knn", False].tolist() == [[repeats * n_points, 0], [repeats * n_points, 0]]


def test_paper_protocol_rates_and_confusion_on_an_easy_pool():
    X, y = _tagged_pool(per_object=15)
    X[:, 0, 0] = 0.0                                                  # the tag would be a feature here
    cfg = {"folds": 5, "repeats": 2, "seed": 0, "threshold": 0.99, "params": {}}
    with ThreadPoolExecutor(2) as pool:
        rates, confusion, kept = experiment._run_paper(X, y, 3, cfg, ("knn", "naive_bayes"), pool, True, "")
    assert kept == 1.0                                                # random images never match at 0.99
    for key, r in rates.items():
        assert r.shape == (2,) and np.all(r >= 95.0), key
        assert confusion[key].sum() == 2 * len(y)                     # every imprint tested once per repeat


def test_touch_fusion_multiplies_posteriors():
    proba = np.array([[0.6, 0.4], [0.6, 0.4], [0.3, 0.7], [0.0, 1.0], [0.99, 0.01], [0.99, 0.01], [0.99, 0.01]])
    assert experiment.combine_touches(proba, [[0, 1]]).tolist() == [0]
    assert experiment.combine_touches(proba, [[0, 1, 2]]).tolist() == [1]   # 0.108 < 0.112
    assert experiment.combine_touches(proba, [[3, 4, 5, 6]]).tolist() == [0]  # a zero is floored, not a veto
    seq = experiment.touch_sequences(6, 6, 3, np.random.default_rng(0))
    assert all(sorted(row) == list(range(6)) for row in seq.tolist())


def test_two_one_nearest_neighbour_touches_agree_or_let_the_firmer_one_decide():
    # 1-NN on a line: object 0 at 0, object 1 at 10.  A touch at 4.9 is (barely) object 0, one at 9
    # firmly object 1, one at 0.5 firmly object 0.  One-hot posteriors would tie the conflicting pair
    # and hand it to the lowest index, 0.
    model = classify.make("knn", ks=(1,)).fit([[0.0], [0.2], [10.0], [10.2]], [0, 0, 1, 1])
    proba = model.predict_proba([[4.9], [9.0], [0.5]])
    assert model.k_ == 1 and model.predict([[4.9], [9.0], [0.5]]).tolist() == [0, 1, 0]
    assert 0.0 < proba[0, 1] < proba[0, 0] < 1.0                   # the ambiguous touch keeps some doubt
    assert experiment.combine_touches(proba, [[0, 1], [1, 0]]).tolist() == [1, 1]   # conflict: the firmer touch
    assert experiment.combine_touches(proba, [[0, 2], [2, 0]]).tolist() == [0, 0]   # agreement
    assert experiment.combine_touches(proba, [[0], [1]]).tolist() == [0, 1]         # single touches: predictions


def test_summary_is_a_student_t_interval():
    mean, std, lo, hi = experiment.summarize([80.0, 90.0])
    assert mean == 85.0 and std == pytest.approx(np.sqrt(50))
    assert hi - mean == pytest.approx(12.706 * np.sqrt(50) / np.sqrt(2), rel=1e-3)
    assert experiment.summarize([70.0]) == (70.0, 0.0, 70.0, 70.0)


def test_tiny_experiment_through_the_cli_writes_every_file(tmp_path, capsys):
    out, cache = tmp_path / "out", tmp_path / "cache"

    def argv(out_dir):
        return ["experiment", "--objects", "cow", "cup", "--n-points", "5", "--repeats", "1", "--folds", "2",
                "--view-size", "64",
                "--methods", "attention,random", "--out", str(out_dir), "--cache-dir", str(cache), "--quiet"]

    assert main(argv(out)) == 0
    printed = capsys.readouterr().out
    assert "| classifier | 2 objects, no selection | 2 objects, selection |" in printed
    assert "attention, paper protocol" in printed and "random, retouch protocol" in printed
    names = {p.name for p in out.iterdir()}
    assert {"results.json", "results.csv", "touches.png"} <= names
    assert {f"confusion_{c}.png" for c in ("knn", "naive_bayes", "decision_tree", "evolutionary_svm",
                                            "deep")} <= names
    with open(out / "results.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert tuple(rows[0].keys()) == CSV_COLUMNS
    assert {r["selection"] for r in rows} == {"true", "false"}
    touches = {int(r["touches"]) for r in rows if r["protocol"] == "retouch"}
    assert touches == set(range(1, 6))
    assert {int(r["touches"]) for r in rows if r["protocol"] == "paper"} == {1}
    assert all(0.0 <= float(r["mean"]) <= 100.0 for r in rows)
    settings = json.loads((out / "results.json").read_text())["settings"]
    assert settings["objects"] == ["cow", "cup"] and settings["n_points"] == 5
    # the second run reads points, imprints and rates from the cache and gives the same numbers
    entries = sorted(p.name for p in cache.iterdir())
    assert sum(e.startswith("object-") for e in entries) == 4         # 2 objects x 2 methods
    assert sum(e.startswith(("paper-", "retouch-")) for e in entries) == 4   # 2 methods x 2 protocols
    assert main(argv(tmp_path / "out2")) == 0
    assert sorted(p.name for p in cache.iterdir()) == entries
    assert (tmp_path / "out2" / "results.csv").read_text() == (out / "results.csv").read_text()


def test_bad_mesh_exits_non_zero_with_the_loaders_message(tmp_path, capsys):
    bad = tmp_path / "broken.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nf 1 2 9\n")
    code = main(["experiment", "--objects", str(bad), "cow", "--out", str(tmp_path / "o"), "--quiet"])
    err = capsys.readouterr().err
    assert code != 0
    assert "visuotactile experiment: error:" in err and "broken.obj" in err


def test_real_imprint_set_gives_table_2(tmp_path, capsys):
    rng = np.random.default_rng(4)
    labels = np.repeat(np.arange(3), 10)
    imprints = rng.uniform(0, 0.2, (30, 16, 16)).astype(np.float32)
    for i, c in enumerate(labels):
        imprints[i, 4 * c:4 * c + 4, 4:8] = 0.9                      # each object presses its own patch
    sset = tactile.ImprintSet(imprints=imprints, labels=labels.astype(np.int64),
                              object_names=("mug", "ball", "box"), point_ids=np.tile(np.arange(10), 3),
                              positions=np.zeros((30, 3)), normals=np.tile([0.0, 0.0, 1.0], (30, 1)),
                              sensor=tactile.Sensor(), perturbation=None, seed=None, source="test")
    path = tmp_path / "real.npz"
    sset.save(path)
    out = tmp_path / "real_out"
    assert main(["experiment", "--real", str(path), "--repeats", "2", "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "Table 2" in printed and "| classifier | 3 objects, no selection | 3 objects, selection |" in printed
    with open(out / "results.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 5 * 2 and all(r["method"] == "real" for r in rows)
    knn = [r for r in rows if r["classifier"] == "knn" and r["selection"] == "false"][0]
    assert float(knn["mean"]) == 100.0
