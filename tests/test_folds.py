"""GroupFolds gives scikit-learn's StratifiedGroupKFold splits, split for split."""

import numpy as np
import pytest
from sklearn.model_selection import StratifiedGroupKFold

from classify.recognizers.folds import GroupFolds


def _splits(kind, y, groups, n_splits, seed):
    return [
        (train.tolist(), test.tolist())
        for train, test in kind(n_splits, shuffle=True, random_state=seed).split(np.zeros(len(y)), y, groups)
    ]


@pytest.mark.parametrize("trial", range(40))
def test_the_same_splits_as_scikit_learn(trial):
    rng = np.random.default_rng(trial)
    n_classes = int(rng.integers(2, 17))
    n_splits = int(rng.integers(2, 11))
    # Groups of one class each (an instance's point) with 1-4 re-touches, as the protocols make them;
    # every third trial mixes classes inside groups.
    per_class = int(rng.integers(n_splits, 3 * n_splits + 2))
    sizes = rng.integers(1, 5, size=n_classes * per_class)
    y = np.repeat(np.repeat(np.arange(n_classes), per_class), sizes)
    groups = np.repeat(rng.permutation(len(sizes)), sizes)
    if trial % 3 == 0:
        y = rng.permutation(y)
    order = rng.permutation(len(y))
    y, groups = y[order], groups[order]
    assert _splits(GroupFolds, y, groups, n_splits, trial) == _splits(StratifiedGroupKFold, y, groups, n_splits, trial)


def test_ties_between_equally_even_folds_go_to_the_emptier_fold():
    # Equal groups of one class: every fold scores alike until it is filled, so only the tie rule decides.
    y = np.zeros(12, int)
    y[6:] = 1
    groups = np.arange(12)
    ours = _splits(GroupFolds, y, groups, 3, 4)
    assert ours == _splits(StratifiedGroupKFold, y, groups, 3, 4)
    assert [len(test) for _, test in ours] == [4, 4, 4]


def test_the_same_splits_when_the_groups_spreads_are_computed_a_few_rows_at_a_time(monkeypatch):
    import classify.recognizers.folds as folds

    rng = np.random.default_rng(7)
    y = np.repeat(np.arange(40), 9)
    groups = rng.permutation(len(y)) // 2  # pairs of rows, some of two classes
    monkeypatch.setattr(folds, "_CELLS", 3 * 40)  # three groups' rows of the table at a time
    assert _splits(GroupFolds, y, groups, 4, 1) == _splits(StratifiedGroupKFold, y, groups, 4, 1)


@pytest.mark.parametrize("n_classes, n_splits", [(129, 3), (300, 5), (1000, 4)])
def test_the_same_splits_as_scikit_learn_with_hundreds_of_classes(n_classes, n_splits):
    # Past 128 classes NumPy sums a row of the table in halves: the kept sums of that tree are exercised.
    rng = np.random.default_rng(n_classes)
    sizes = rng.integers(1, 4, size=n_classes * n_splits)
    y = np.repeat(np.repeat(np.arange(n_classes), n_splits), sizes)
    groups = np.repeat(rng.permutation(len(sizes)), sizes)
    assert _splits(GroupFolds, y, groups, n_splits, 3) == _splits(StratifiedGroupKFold, y, groups, n_splits, 3)


def test_a_row_mean_with_one_value_changed_is_numpys_bit_for_bit():
    from classify.recognizers.folds import _ChangedMean

    rng = np.random.default_rng(0)
    for size in [*range(1, 40), 127, 128, 129, 130, 255, 256, 257, 1000, 1001, 4099]:
        row = rng.random(size) * rng.choice([1e-6, 1.0, 1e6], size=size)
        mean = _ChangedMean(row)
        assert mean.with_value(0, row[0]) == np.mean(row)
        for _ in range(6):
            j, v = int(rng.integers(size)), float(rng.random() * 10.0 ** rng.integers(-6, 7))
            changed = row.copy()
            changed[j] = v
            assert mean.with_value(j, v) == np.mean(changed)
            if rng.random() < 0.5:
                row = changed
                mean.set(j, v)
                assert mean.with_value(j, v) == np.mean(row)


def test_the_spreads_of_one_class_over_the_folds_are_numpys_bit_for_bit():
    from classify.recognizers.folds import _fold_spreads

    rng = np.random.default_rng(1)
    for k in (2, 3, 5, 8, 10, 13):
        column, n, total = rng.integers(0, 50, k).astype(float), float(rng.integers(1, 5)), float(rng.integers(60, 99))
        trial = np.repeat(np.c_[column, column][None], k, axis=0)  # (k trials, k folds, 2 equal columns)
        trial[np.arange(k), np.arange(k)] += n
        assert _fold_spreads(column.tolist(), n, total) == np.std(trial / total, axis=1)[:, 0].tolist()
