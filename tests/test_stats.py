"""Bootstrap intervals, paired differences, calibration and touch fusion, kNN's ties."""

import numpy as np
import pytest

import classify
from classify.recognizers import fusion
from classify.reporting import stats


def test_bootstrap_interval_covers_the_true_mean_about_95_percent_of_the_time():
    rng = np.random.default_rng(0)
    hits = 0
    trials = 200
    for t in range(trials):
        R = 70.0 + 5.0 * rng.standard_normal((20, 1))  # replicates only: a plain mean
        s = stats.summarize(R, seed=t)
        hits += s.ci_low <= 70.0 <= s.ci_high
    assert 0.88 <= hits / trials <= 0.99


def test_interval_widens_with_object_spread_and_is_a_point_when_nothing_varies():
    flat = stats.summarize(np.full((6, 4), 80.0))
    assert (flat.mean, flat.ci_low, flat.ci_high, flat.std) == (80.0, 80.0, 80.0, 0.0)
    spread = stats.summarize(np.tile([60.0, 70.0, 90.0, 100.0], (6, 1)))
    assert spread.std == 0.0 and spread.ci_low < 75.0 < 80.0 < spread.ci_high


def test_paired_difference_finds_a_planted_gap_that_unpaired_noise_would_hide():
    rng = np.random.default_rng(1)
    base = rng.uniform(40, 100, (20, 6))  # replicate/object difficulty varies a lot
    better = base + 3.0 + rng.normal(0, 1.0, base.shape)
    d = stats.paired_difference(better, base)
    assert 2.0 < d.ci_low < 3.0 < d.ci_high < 4.0 and d.p_value < 1e-3
    same = stats.paired_difference(base, base)
    assert (same.mean, same.ci_low, same.ci_high, same.p_value) == (0.0, 0.0, 0.0, 1.0)
    with pytest.raises(ValueError, match="equal shapes"):
        stats.paired_difference(base, base[:3])


def test_calibration_never_changes_a_single_decision_but_softens_certainty():
    rng = np.random.default_rng(2)
    P = rng.dirichlet(np.ones(4) * 0.1, 50)
    cal = fusion.Calibration(eps=0.1, temperature=3.0)
    Q = fusion.calibrate(P, cal)
    assert np.array_equal(np.argmax(P, axis=1), np.argmax(Q, axis=1))
    assert np.allclose(Q.sum(axis=1), 1.0) and Q.max() < P.max()


def test_calibration_fitted_on_one_hot_wrong_answers_stops_a_single_zero_from_vetoing():
    y = np.repeat([0, 1], 20)
    P = np.eye(2)[y]
    P[:4] = [0.0, 1.0]  # 4 of 20 "certain" answers are wrong
    cal = fusion.fit_calibration(P, y)
    fused = fusion.fuse(
        fusion.calibrate([[1.0, 0.0], [1.0, 0.0], [0.0, 1.0]], cal), [[0, 1, 2]], np.random.default_rng(0)
    )
    assert fused.tolist() == [0]  # two firm votes beat one


def test_calibration_scored_on_a_spread_sample_fits_what_the_whole_set_does():
    # Overconfident posteriors: the labels are drawn from the square root of what they say.
    rng = np.random.default_rng(4)
    truth = rng.dirichlet(np.ones(6) * 0.5, 3000)
    y = np.array([rng.choice(6, p=row) for row in truth])
    P = truth**2 / (truth**2).sum(axis=1, keepdims=True)

    def nll(cal):
        return -np.mean(np.log(fusion.calibrate(P, cal)[np.arange(len(y)), y]))

    whole, some = fusion.fit_calibration(P, y), fusion.fit_calibration(P, y, rows=600)
    assert whole.temperature > 1.5 and some.temperature > 1.5  # both soften the overconfidence
    assert nll(some) < 1.02 * nll(whole) < nll(fusion.Calibration())


def test_calibration_fitted_a_block_of_rows_at_a_time_matches_the_whole_grid_scored_at_once(monkeypatch):
    rng = np.random.default_rng(5)
    truth = rng.dirichlet(np.ones(40) * 0.2, 500)
    y = np.array([rng.choice(40, p=row) for row in truth])
    P = truth**3 / (truth**3).sum(axis=1, keepdims=True)
    # The reference: every grid point scored on all rows at once.
    grid = [fusion.Calibration(e, t) for e in fusion._EPS_GRID for t in fusion._T_GRID]
    nll = [-np.mean(np.log(np.maximum(fusion.calibrate(P, c)[np.arange(len(y)), y], 1e-12))) for c in grid]
    whole = grid[int(np.argmin(nll))]
    assert 0.1 < whole.temperature < 20.0  # an inner optimum, not the grid's edge
    monkeypatch.setattr(fusion, "_CELLS", 7 * 40)  # blocks of 7 rows
    assert fusion.fit_calibration(P, y) == whole


def test_calibration_grid_scores_are_calibrate_bit_for_bit():
    rng = np.random.default_rng(6)
    P = rng.dirichlet(np.ones(30) * 0.1, 200) ** 2
    P /= P.sum(axis=1, keepdims=True)
    P[:40] = np.round(P[:40], 1)  # exact zeros and ties as well
    y = rng.integers(0, 30, 200)
    grid = [fusion.Calibration(e, t) for e in fusion._EPS_GRID for t in fusion._T_GRID]
    reference = np.stack([fusion.calibrate(P, c)[np.arange(len(y)), y] for c in grid])
    scored = np.empty_like(reference)
    fusion._score_block(P, y, scored)
    assert np.array_equal(scored, reference)


def test_calibration_scores_fewer_rows_as_objects_grow_so_its_cost_stays_linear(monkeypatch):
    assert fusion.calibration_rows(16) == fusion.CALIBRATION_ROWS
    assert fusion.calibration_rows(2 * fusion.CALIBRATION_CELLS // fusion.CALIBRATION_ROWS) < fusion.CALIBRATION_ROWS
    assert all(fusion.calibration_rows(c) * c <= fusion.CALIBRATION_CELLS for c in (1000, 2000, 4000))
    assert fusion.calibration_rows(10**9) == fusion._MIN_ROWS
    monkeypatch.setattr(fusion, "CALIBRATION_CELLS", 50 * 20)  # 50 rows of 20 objects
    monkeypatch.setattr(fusion, "_MIN_ROWS", 10)
    rng = np.random.default_rng(7)
    truth = rng.dirichlet(np.ones(20) * 0.3, 400)
    y = np.array([rng.choice(20, p=row) for row in truth])
    P = truth**2 / (truth**2).sum(axis=1, keepdims=True)
    from classify.recognizers.shortlist import spread

    pick = spread(len(y), 50)
    scored, score = [], fusion._score_block
    monkeypatch.setattr(fusion, "_score_block", lambda P, y, out: scored.append(len(y)) or score(P, y, out))
    assert fusion.fit_calibration(P, y) == fusion.fit_calibration(P[pick], y[pick], rows=len(y))
    assert scored == [50, 50]


def test_touch_sets_are_distinct_exhaustive_when_few_and_seeded():
    rng = np.random.default_rng(0)
    assert len(fusion.touch_sets(15, 14, 50, rng)) == 15  # C(15, 14) = 15 < 50: all of them
    a = fusion.touch_sets(15, 4, 50, np.random.default_rng(3))
    b = fusion.touch_sets(15, 4, 50, np.random.default_rng(3))
    assert np.array_equal(a, b) and len({tuple(r) for r in a.tolist()}) == 50
    assert all(len(set(r)) == 4 for r in a.tolist())
    with pytest.raises(ValueError, match="within 1..15"):
        fusion.touch_sets(15, 16, 5, rng)


def test_fused_ties_go_either_way_with_the_seed_never_to_index_zero():
    P = np.full((3, 3), 1 / 3)
    picks = fusion.fuse(P, np.zeros((300, 1), int), np.random.default_rng(0))
    assert set(picks.tolist()) == {0, 1, 2} and 60 < np.sum(picks == 0) < 140
    again = fusion.fuse(P, np.zeros((300, 1), int), np.random.default_rng(0))
    assert np.array_equal(picks, again)


def test_knn_k_ties_are_drawn_with_the_seed_not_taken_by_order():
    X = np.r_[np.zeros((8, 2)), np.ones((8, 2))]
    y = np.repeat([0, 1], 8)
    chosen = {classify.make("knn", random_state=s).fit(X, y).k_ for s in range(12)}
    assert len(chosen) > 1  # every k scores 100 %: the draw decides


def test_knn_tuning_with_groups_does_not_reward_memorizing_a_point():
    # Each point touched 4 times with tiny noise; points of the two objects interleave along a line.
    rng = np.random.default_rng(4)
    centers = np.arange(40, dtype=float)
    labels = (rng.random(40) < 0.5).astype(int)
    labels[::7] = 1 - labels[::7]
    X = np.repeat(centers, 4)[:, None] + 0.01 * rng.standard_normal((160, 1))
    y = np.repeat(labels, 4)
    groups = np.repeat(np.arange(40), 4)
    leaky = classify.make("knn", ks=(1, 9)).fit(X, y)
    grouped = classify.make("knn", ks=(1, 9)).fit(X, y, groups=groups)
    assert leaky.cv_scores_[1] > 0.95  # re-touches of the same point: memorized
    assert grouped.cv_scores_[1] < 0.9  # held-out points: no such luck


def test_knn_is_invariant_to_the_order_of_its_training_set():
    rng = np.random.default_rng(6)
    X = np.round(rng.uniform(0, 1, (60, 16)) * 255) / 255  # ADC codes: exact distances
    X[10] = X[40]  # exact ties between classes
    y = np.repeat([0, 1, 2], 20)
    queries = np.r_[X[:5], X[40:41], rng.uniform(0, 1, (10, 16))]
    perm = rng.permutation(60)
    a = classify.make("knn", ks=(1, 3)).fit(X, y).predict_proba(queries)
    b = classify.make("knn", ks=(1, 3)).fit(X[perm], y[perm]).predict_proba(queries)
    assert np.array_equal(a, b)


def test_intervals_follow_the_objects_names_not_their_order():
    rng = np.random.default_rng(3)
    R, B = rng.uniform(0, 100, (6, 5)), rng.uniform(0, 100, (6, 5))
    names = ["cow", "cup", "hand", "plane", "glasses"]
    turn = [3, 0, 4, 1, 2]
    a, b = stats.summarize(R, 7, names), stats.summarize(R[:, turn], 7, [names[i] for i in turn])
    assert (a.ci_low, a.ci_high) == (b.ci_low, b.ci_high)
    d, e = (
        stats.paired_difference(R, B, 7, names),
        stats.paired_difference(R[:, turn], B[:, turn], 7, [names[i] for i in turn]),
    )
    assert (d.ci_low, d.ci_high) == (e.ci_low, e.ci_high)
    # By position, the same resamples draw other objects: the interval moves.
    assert stats.summarize(R[:, turn], 7).ci_low != a.ci_low
    with pytest.raises(ValueError, match="distinct object names"):
        stats.summarize(R, 7, names[:4])


def test_a_missing_comparison_names_what_was_asked_and_what_exists():
    from classify.reporting.results import Comparison, ExperimentResult, MissingCell

    def comparison(method, classifier):
        return Comparison(method, "uniform", "instance", classifier, 6, False, 1, 1.0, 0.0, 2.0, 0.5, 10)

    result = ExperimentResult(
        cells=(),
        comparisons=(comparison("attention", "knn"), comparison("attention", "svm")),
        confusions=(),
        object_names=(),
        object_sets=(),
        classifiers=("knn", "svm"),
    )
    assert result.comparison("attention", "instance", "svm", 6, False).classifier == "svm"
    with pytest.raises(KeyError) as caught:
        result.comparison("learned", "instance", "knn", 16, False)
    assert isinstance(caught.value, MissingCell)
    assert str(caught.value) == (
        "no comparison at method='learned', protocol='instance', classifier='knn', n_objects=16, selection=False, "
        "touches=1; measured: method 'attention' (not 'learned'); protocol 'instance'; classifier 'knn', 'svm'; "
        "n_objects 6 (not 16); selection False; touches 1"
    )
    with pytest.raises(MissingCell, match="no cell at method='attention'.*: this result has none$"):
        result.cell("attention", "instance", "knn", 6, False)
