"""The five classifiers: separable data, the evolutionary SVM against SVC, the estimator contract (scikit-learn's
estimator checks included)."""

import numpy as np
import pytest
from sklearn.base import clone
from sklearn.datasets import load_digits
from sklearn.model_selection import train_test_split
from sklearn.svm import SVC
from sklearn.utils.estimator_checks import parametrize_with_checks

import classify
from classify.recognizers.classifiers import KNN, DecisionTree, DeepNet, NaiveBayes
from classify.recognizers.evolution_strategy import solve_dual, solve_duals
from classify.recognizers.evolutionary_svm import EvolutionarySVM


def _separable_imprints(n_per_class=30, n_classes=4, seed=0):
    """Each class lights its own 4x4 block of a 16x16 image; noise elsewhere stays well below."""
    rng = np.random.default_rng(seed)
    X, y = [], []
    for c in range(n_classes):
        img = rng.uniform(0, 0.2, (n_per_class, 16, 16))
        r, q = divmod(c, 4)
        img[:, 4 * r : 4 * r + 4, 4 * q : 4 * q + 4] += rng.uniform(0.6, 0.8, (n_per_class, 4, 4))
        X.append(img)
        y.append(np.full(n_per_class, c))
    return np.concatenate(X).astype(np.float32), np.concatenate(y)


@pytest.mark.parametrize("name", classify.PAPER_NAMES)
def test_each_classifier_separates_planted_classes(name):
    X, y = _separable_imprints(seed=1)
    Xt, yt = _separable_imprints(n_per_class=20, seed=2)
    model = classify.make(name).fit(X, y)  # (N, 16, 16) accepted as is
    assert model.score(Xt.reshape(len(Xt), -1), yt) >= 0.99
    proba = model.predict_proba(Xt)
    assert proba.shape == (len(Xt), 4)
    np.testing.assert_allclose(proba.sum(axis=1), 1.0, atol=1e-9)
    np.testing.assert_array_equal(model.classes_[np.argmax(proba, axis=1)], model.predict(Xt))


@pytest.mark.parametrize("name", classify.PAPER_NAMES)
def test_estimator_contract_clone_and_params(name):
    model = classify.make(name)
    params = model.get_params()
    twin = clone(model)
    assert twin.get_params() == params
    X, y = _separable_imprints(n_per_class=12, n_classes=3, seed=3)
    a = clone(model).fit(X, y).predict(X)
    b = clone(model).fit(X, y).predict(X)
    np.testing.assert_array_equal(a, b)  # seeded: same input, same output


# Each with its class defaults, as check_estimator asks (the network trains for fewer epochs).
@parametrize_with_checks([KNN(), NaiveBayes(), DecisionTree(), EvolutionarySVM(), DeepNet(max_iter=100)])
def test_each_classifier_passes_scikit_learn_s_estimator_checks(estimator, check):
    check(estimator)


def test_make_rejects_unknown_names_and_parameters():
    with pytest.raises(ValueError, match="knn, naive_bayes, decision_tree, evolutionary_svm, deep"):
        classify.make("svm")
    with pytest.raises(ValueError, match="no parameter n_neighbours"):
        classify.make("knn", n_neighbours=3)


def test_deep_is_a_network_with_two_hidden_layers_and_early_stopping():
    params = classify.make("deep").get_params()
    assert len(params["hidden_layer_sizes"]) >= 2 and params["early_stopping"] is True


def test_knn_inner_cv_picks_larger_k_on_label_noise():
    # Two Gaussian clouds with 20 % flipped labels: 1-NN copies the noise, larger k averages it out.
    rng = np.random.default_rng(0)
    X = np.r_[rng.normal(0, 1, (100, 2)), rng.normal(2.5, 1, (100, 2))]
    y = np.repeat([0, 1], 100)
    flip = rng.random(200) < 0.2
    y = np.where(flip, 1 - y, y)
    model = classify.make("knn").fit(X, y)
    assert model.k_ > 1
    assert model.cv_scores_[model.k_] >= model.cv_scores_[1]


def test_knn_scores_at_most_cv_rows_and_still_finds_the_larger_k():
    # The same noisy clouds, ten times over: 300 scored rows choose as the 2,000 do, and the scale is theirs.
    rng = np.random.default_rng(0)
    X = np.r_[rng.normal(0, 1, (1000, 2)), rng.normal(2.5, 1, (1000, 2))]
    y = np.where(rng.random(2000) < 0.2, 1 - np.repeat([0, 1], 1000), np.repeat([0, 1], 1000))
    whole = classify.make("knn", cv_rows=10**6).fit(X, y)
    some = classify.make("knn", cv_rows=300).fit(X, y)
    assert some.k_ > 1 and whole.k_ > 1
    assert abs(some.scale_ - whole.scale_) < 0.5 * whole.scale_
    # The sample is the rows of least content hash: the same whatever the rows' order.
    order = rng.permutation(2000)
    again = classify.make("knn", cv_rows=300).fit(X[order], y[order])
    assert again.k_ == some.k_ and again.scale_ == some.scale_ and again.cv_scores_ == some.cv_scores_


def test_knn_scores_fewer_rows_of_a_larger_set_so_the_search_grows_linearly(monkeypatch):
    from classify.recognizers import classifiers as module

    monkeypatch.setattr(module, "_SCAN_PAIRS", 400 * 400)  # scored whole up to 400 rows
    monkeypatch.setattr(module, "_MIN_CV_ROWS", 50)
    rng = np.random.default_rng(3)

    def fitted(n, cv_rows="auto"):
        X = np.r_[rng.normal(0, 1, (n // 2, 2)), rng.normal(2.5, 1, (n // 2, 2))]
        y = np.repeat([0, 1], n // 2)
        return classify.make("knn", cv_rows=cv_rows).fit(X, y)

    for n, scored in ((300, 300), (400, 400), (800, 200), (4000, 50)):
        state = rng.bit_generator.state
        auto = fitted(n)
        rng.bit_generator.state = state
        fixed = fitted(n, scored)
        assert (auto.k_, auto.scale_, auto.cv_scores_) == (fixed.k_, fixed.scale_, fixed.cv_scores_)
        assert min(n, auto._scored_rows(n)) * n <= max(400 * 400, 50 * n)  # pairs the search compares
    with pytest.raises(ValueError, match="cv_rows"):
        classify.make("knn", cv_rows=0).fit(np.zeros((4, 2)), [0, 0, 1, 1])
    with pytest.raises(ValueError, match="cv_rows"):
        classify.make("knn", cv_rows="all").fit(np.zeros((4, 2)), [0, 0, 1, 1])


def test_knn_predicts_a_block_at_a_time_as_it_would_row_by_row():
    rng = np.random.default_rng(1)
    X, y = rng.normal(size=(300, 4)), rng.integers(0, 3, 300)
    model = classify.make("knn").fit(X, y)
    Q = rng.normal(size=(1100, 4))  # more rows than a block
    whole = model.predict_proba(Q)
    np.testing.assert_array_equal(
        np.concatenate([model.predict_proba(Q[i : i + 1]) for i in (0, 700, 1099)]), whole[[0, 700, 1099]]
    )


def test_knn_without_enough_samples_for_inner_cv_uses_smallest_k():
    model = classify.make("knn", ks=(3, 1)).fit([[0.0], [1.0]], [0, 1])
    assert model.k_ == 1
    assert model.predict([[0.9]])[0] == 1


def test_knn_posterior_keeps_the_majority_and_breaks_a_tied_vote_by_distance():
    X = [[0.0], [0.1], [1.0], [1.1]]
    y = ["a", "a", "b", "b"]
    two = classify.make("knn", ks=(2,)).fit(X, y)
    # 0.6 has one neighbour of each object; b's imprint (0.4 away) is nearer than a's (0.5 away).
    assert two.k_ == 2 and list(two.predict([[0.6], [0.4]])) == ["b", "a"]
    three = classify.make("knn", ks=(3,)).fit(X, y)
    # Neighbours of 0.9: 1.0, 1.1 (b) and 0.1 (a): the majority b wins, and b's vote share stays on top.
    proba = three.predict_proba([[0.9]])[0]
    assert list(three.predict([[0.9]])) == ["b"] and proba[1] > 0.5 > proba[0] > 0
    np.testing.assert_allclose(proba.sum(), 1.0)


def test_knn_with_every_k_larger_than_the_inner_folds_still_fits():
    # 2 inner folds of 2 training samples each: k = 3 cannot be scored there, so it is the only choice.
    model = classify.make("knn", ks=(3,)).fit([[0.0], [0.1], [1.0], [1.1]], [0, 0, 1, 1])
    assert model.k_ == 3 and model.predict([[1.05]])[0] == 1


def test_bad_inputs_have_clear_messages():
    with pytest.raises(ValueError, match="shape"):
        classify.make("knn").fit(np.zeros(5), np.zeros(5))
    with pytest.raises(ValueError, match="NaN"):
        classify.make("evolutionary_svm").fit(np.full((4, 2), np.nan), [0, 0, 1, 1])
    with pytest.raises(ValueError, match="C must be"):
        classify.make("evolutionary_svm", C=-1.0).fit(np.zeros((4, 2)), [0, 0, 1, 1])
    with pytest.raises(ValueError, match="two classes"):
        classify.make("evolutionary_svm").fit(np.zeros((4, 2)), [0, 0, 0, 0])


def test_evolutionary_svm_matches_svc_on_digits():
    digits = load_digits()
    idx = np.random.default_rng(0).permutation(len(digits.target))[:500]
    Xtr, Xte, ytr, yte = train_test_split(
        digits.data[idx], digits.target[idx], test_size=0.4, random_state=0, stratify=digits.target[idx]
    )
    svc = SVC(kernel="rbf", C=1.0, gamma="scale").fit(Xtr, ytr).score(Xte, yte)
    es = classify.make("evolutionary_svm", C=1.0, gamma="scale").fit(Xtr, ytr).score(Xte, yte)
    assert abs(es - svc) <= 0.02, (es, svc)


def test_evolution_strategy_reaches_the_dual_optimum_of_svc():
    rng = np.random.default_rng(5)
    X = np.r_[rng.normal(0, 1, (60, 3)), rng.normal(1.5, 1, (60, 3))]
    y = np.repeat([-1.0, 1.0], 60)
    C, gamma = 2.0, 0.3
    K = np.exp(-gamma * ((X[:, None] - X[None]) ** 2).sum(-1))
    svc = SVC(C=C, gamma=gamma).fit(X, y)
    a_svc = np.zeros(len(X))
    a_svc[svc.support_] = np.abs(svc.dual_coef_[0])
    w_svc = a_svc.sum() - 0.5 * (a_svc * y) @ K @ (a_svc * y)
    alpha, w, _ = solve_dual(K, y[None], C=C, max_generations=4000, patience=400)
    assert np.all(alpha >= 0) and np.all(alpha <= C)
    assert abs(alpha[0] @ y) < 1e-9
    w_check = alpha[0].sum() - 0.5 * (alpha[0] * y) @ K @ (alpha[0] * y)
    assert w[0] == pytest.approx(w_check, rel=1e-9)  # incremental fitness stays exact
    assert w[0] >= 0.995 * w_svc
    assert w[0] <= w_svc + 1e-6  # SVC's optimum bounds every feasible point


@pytest.mark.parametrize("block", [1, 7])
@pytest.mark.parametrize(
    "n, problems, lam, generations, patience, stops_at",
    [(30, 3, 64, 173, 60, 173), (12, 2, 4, 500, 5, 180)],  # the generation cap; a stall, mid-block
)
def test_evolution_strategy_run_does_not_depend_on_its_draw_blocks(
    monkeypatch, block, n, problems, lam, generations, patience, stops_at
):
    """The draws are prepared a block of generations at a time: any block size gives the same run, bit for bit."""
    from classify.recognizers import evolution_strategy

    rng = np.random.default_rng(3)
    X = rng.normal(size=(n, 4))
    K = np.exp(-0.5 * ((X[:, None] - X[None]) ** 2).sum(-1))
    Y = np.where(rng.random((problems, n)) < 0.4, 1.0, -1.0)
    runs = []
    for size in (evolution_strategy._BLOCK, block):
        monkeypatch.setattr(evolution_strategy, "_BLOCK", size)
        runs.append(solve_dual(K, Y, C=1.0, pairs=2, lam=lam, max_generations=generations, patience=patience))
    (a0, w0, g0), (a1, w1, g1) = runs
    assert g0 == g1 == stops_at
    assert a0.tobytes() == a1.tobytes() and w0.tobytes() == w1.tobytes()
    assert np.all(a0 >= 0) and np.all(a0 <= 1.0) and np.allclose(np.einsum("pn,pn->p", a0, Y), 0, atol=1e-12)


def test_duals_solved_together_give_each_run_what_it_gives_alone():
    """Runs of different sizes, problem counts and stopping generations share one loop; each keeps its own run."""
    rng = np.random.default_rng(11)
    problems = []
    for n, p in [(12, 1), (30, 4), (7, 3), (25, 2)]:
        X = rng.normal(size=(n, 3))
        K = np.exp(-0.5 * ((X[:, None] - X[None]) ** 2).sum(-1))
        problems.append((K, np.where(rng.random((p, n)) < 0.4, 1.0, -1.0)))
    settings = dict(C=2.0, lam=6, pairs=2, max_generations=300, patience=8)
    together = solve_duals(problems, **settings)
    alone = [solve_dual(K, Y, **settings) for K, Y in problems]
    assert len({g for _, _, g in alone}) > 2  # the runs stop at different generations, mid-block
    for (a0, w0, g0), (a1, w1, g1), (_, Y) in zip(alone, together, problems):
        assert g0 == g1 and a1.shape == Y.shape
        assert a0.tobytes() == a1.tobytes() and w0.tobytes() == w1.tobytes()
    assert solve_duals([]) == []


def test_evolutionary_svms_fitted_together_are_the_models_fitted_one_by_one():
    X, y = _separable_imprints(n_per_class=8, n_classes=3, seed=4)
    sets = [(X[i::2], y[i::2]) for i in range(2)] + [(X[y < 2], y[y < 2])]  # a two-class set too
    template = classify.make("evolutionary_svm", max_generations=120)
    for together, (Xs, ys) in zip(template.fit_each(sets), sets):
        alone = clone(template).fit(Xs, ys)
        assert together is not template and together.get_params() == template.get_params()
        for name in ("dual_coef_", "intercept_", "support_", "classes_", "fitness_"):
            assert np.array_equal(getattr(together, name), getattr(alone, name)), name
        assert np.array_equal(together.predict_proba(X), alone.predict_proba(X))
    assert not hasattr(template, "dual_coef_")  # the template stays unfitted


def test_evolutionary_svm_two_classes_decision_sign_follows_classes():
    X = np.array([[0.0], [0.2], [3.0], [3.2]])
    model = classify.make("evolutionary_svm", C=10.0).fit(X, ["a", "a", "b", "b"])
    f = model.decision_function(np.array([[0.1], [3.1]]))
    assert f.shape == (2,) and f[0] < 0 < f[1]
    assert list(model.predict([[0.1], [3.1]])) == ["a", "b"]


def test_knn_neighbours_are_the_first_k_of_the_full_sort_ties_included():
    from classify.recognizers.distances import ranked

    rng = np.random.default_rng(0)
    for trial in range(60):
        n, m = int(rng.integers(1, 700)), int(rng.integers(1, 200))
        levels = int(rng.integers(1, 5)) if trial % 2 else 10**6  # few levels: many ties at the k-th distance
        d2 = rng.integers(0, levels, size=(n, m)).astype(float)
        if trial % 7 == 0:
            d2[:] = 0.0  # every training row equally near (empty imprints)
        tiebreak = rng.permutation(m).astype(np.uint64)
        full = np.lexsort((np.broadcast_to(tiebreak, d2.shape), d2), axis=1)
        for k in (1, 3, 9, m):
            np.testing.assert_array_equal(ranked(d2, tiebreak, k), full[:, : min(k, m)])


def test_knn_neighbours_screened_by_runs_of_columns_are_the_first_k_of_the_full_sort():
    """Past a few hundred columns per neighbour, ranked screens runs of columns: the same neighbours, with ties at
    the k-th distance, rows with few finite distances, a column count that leaves columns over, and row keys."""
    from classify.recognizers.distances import ranked

    rng = np.random.default_rng(1)
    for trial in range(24):
        n, m = int(rng.integers(1, 60)), int(rng.integers(600, 6000))
        levels = int(rng.integers(2, 6)) if trial % 2 else 10**9
        d2 = rng.integers(0, levels, size=(n, m)).astype(float)
        if trial % 3 == 0:
            d2[rng.random(d2.shape) < 0.995] = np.inf  # a few rows keep fewer than k finite distances
        if trial % 4 == 1:
            tiebreak = rng.permutation(n * m).reshape(n, m).astype(np.uint64)
            full = np.lexsort((tiebreak, d2), axis=1)
        else:
            tiebreak = rng.permutation(m).astype(np.uint64)
            full = np.lexsort((np.broadcast_to(tiebreak, d2.shape), d2), axis=1)
        for k in (1, 5, 9):
            np.testing.assert_array_equal(ranked(d2, tiebreak, k), full[:, :k])


def test_knn_fitted_on_subsets_together_are_the_models_fitted_one_by_one():
    """One pass over the distances serves every subset: each model is its own fit's, to the bit."""
    rng = np.random.default_rng(4)
    for grid in (True, False):
        X = rng.normal(size=(300, 6))
        if grid:
            X = np.round(rng.random((300, 6)) * 6) / 255  # on the ADC's grid: many equal distances
        y = np.repeat(np.arange(5), 60)
        groups = np.arange(300) // 3
        inst = np.tile([1, 2, 3], 100)
        subsets = [inst != 1, np.flatnonzero(inst != 2), np.flatnonzero(inst != 3), np.arange(300), np.arange(40, 130)]
        subsets += [inst == 1, np.flatnonzero(inst == 2)]  # sets that share no row read none of each other's
        template = classify.make("knn", cv_rows=70)  # fewer rows scored than a subset holds
        together = list(template.fit_subsets(X, y, groups, subsets))
        queries = rng.normal(size=(25, 6)) if not grid else np.round(rng.random((25, 6)) * 6) / 255
        for model, rows in zip(together, subsets):
            alone = classify.make("knn", cv_rows=70).fit(X[rows], y[rows], groups[rows])
            assert model.k_ == alone.k_ and model.scale_ == alone.scale_ and model.cv_scores_ == alone.cv_scores_
            np.testing.assert_array_equal(model.classes_, alone.classes_)
            np.testing.assert_array_equal(model.X_, alone.X_)
            np.testing.assert_array_equal(model.predict_proba(queries), alone.predict_proba(queries))
        assert len({m.scale_ for m in together}) > 1  # the subsets' models differ


@pytest.mark.parametrize("name", ["knn", "naive_bayes", "decision_tree"])
def test_a_recognizer_fitted_on_subsets_predicts_as_fitted_on_each_subset_alone(name):
    from classify.recognizers.touches import Recognizer

    rng = np.random.default_rng(8)
    X, y = rng.normal(size=(90, 4)), np.repeat([0, 1, 2], 30)
    X[:, 0] += y
    groups = np.arange(90) // 2
    rec = Recognizer(name)
    subsets = [np.arange(0, 90, 2), y != 1, np.arange(20, 90)]
    for model, rows in zip(rec.fit_subsets(X, y, groups, subsets), subsets):
        alone = rec.fit(X[rows], y[rows], groups[rows])
        np.testing.assert_array_equal(model.classes_, alone.classes_)
        np.testing.assert_array_equal(model.predict_proba(X), alone.predict_proba(X))


def test_knn_class_distances_are_each_class_nearest_sample_in_any_order_of_codes():
    from classify.recognizers.distances import class_distances

    rng = np.random.default_rng(3)
    for sort in (True, False):
        d2 = rng.random((9, 40))
        codes = rng.integers(0, 5, 40)
        codes[codes == 3] = 4  # class 3 has no sample: infinitely far
        if sort:
            codes = np.sort(codes)
        expected = np.array(
            [[np.sqrt(row[codes == c].min()) if (codes == c).any() else np.inf for c in range(6)] for row in d2]
        )
        np.testing.assert_array_equal(class_distances(d2, codes, 6), expected)


def test_knn_posteriors_from_prepared_training_rows_are_those_from_the_raw_rows():
    from classify.recognizers.classifiers import _posterior
    from classify.recognizers.distances import class_distances, ranked, sq_distances

    rng = np.random.default_rng(4)
    for grid in (True, False):
        X, Q = rng.random((60, 7)), rng.random((11, 7))
        if grid:
            X, Q = np.round(X * 255) / 255, np.round(Q * 255) / 255
        model = classify.make("knn").fit(X, np.arange(60) % 3)
        assert (model.grid_rows_ is not None) == grid
        d2 = sq_distances(Q, model.X_)
        assert np.allclose(d2, ((Q[:, None] - model.X_[None]) ** 2).sum(axis=2), atol=1e-9)
        order = ranked(d2, model.tiebreak_, model.k_)
        expected = _posterior(model.codes_[order], class_distances(d2, model.codes_, 3), model.scale_)
        np.testing.assert_array_equal(model.predict_proba(Q), expected)


def test_knn_blocks_of_queries_shrink_with_the_training_set_and_change_no_result(monkeypatch):
    from classify.recognizers import classifiers, distances

    rng = np.random.default_rng(5)
    X, Q = np.round(rng.random((300, 6)) * 255) / 255, np.round(rng.random((40, 6)) * 255) / 255
    y = np.arange(300) % 4
    wide = classify.make("knn").fit(X, y, groups=np.arange(300) % 12)
    expected = wide.predict_proba(Q)
    seen = []
    real = distances.distances_to

    def spy(A, rows):
        seen.append(len(A) * len(rows.values))
        return real(A, rows)

    # 1,000 distances a block: 3 queries against 300 rows, where the default takes all 40 at once.
    monkeypatch.setattr(distances, "CELLS", 1000)
    assert distances.block_rows(300) == 3 and distances.block_rows(10**9) == 1
    monkeypatch.setattr(classifiers, "distances_to", spy)
    narrow = classify.make("knn").fit(X, y, groups=np.arange(300) % 12)
    assert (narrow.k_, narrow.scale_, narrow.cv_scores_) == (wide.k_, wide.scale_, wide.cv_scores_)
    np.testing.assert_array_equal(narrow.predict_proba(Q), expected)
    assert seen and max(seen) <= 1000


def test_the_evolution_strategy_is_importable_beside_its_estimator():
    from classify.recognizers import evolution_strategy, evolutionary_svm

    for name in ("Strategy", "solve_dual", "solve_duals"):
        assert getattr(evolutionary_svm, name) is getattr(evolution_strategy, name)
