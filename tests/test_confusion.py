"""Confusions kept by their non-zero cells: the dense matrix's counts, sums and reorderings, in space that grows with
the touches recognized; results.json keeps them so, reads the dense matrices of older files, and grows linearly."""

import json

import numpy as np
import pytest
from sklearn.metrics import confusion_matrix

from classify.reporting import report
from classify.reporting.confusion import (
    ConfusionMatrix,
    confusion_pairs,
    counts_pairs,
    dense_counts,
    reordered_pairs,
    summed_pairs,
    top_pairs,
)
from classify.reporting.results import ExperimentResult


def _decisions(n, touches, seed):
    """``touches`` single-touch decisions per class of ``n``: right about half the time, else a random class."""
    rng = np.random.default_rng(seed)
    truth = np.repeat(np.arange(n), touches)
    guess = np.where(rng.random(truth.size) < 0.5, truth, rng.integers(0, n, truth.size))
    return truth, guess


def test_pairs_hold_the_dense_confusion_matrix_cell_for_cell():
    truth, guess = _decisions(7, 9, seed=0)
    pairs = confusion_pairs(truth, guess)
    dense = confusion_matrix(truth, guess, labels=np.arange(7))
    np.testing.assert_array_equal(dense_counts(pairs, 7), dense)
    np.testing.assert_array_equal(counts_pairs(dense), pairs)
    assert (pairs[:, 2] > 0).all() and pairs[:, 2].sum() == truth.size
    assert np.array_equal(np.lexsort((pairs[:, 1], pairs[:, 0])), np.arange(len(pairs)))  # sorted: true, predicted
    assert confusion_pairs([], []).shape == (0, 3)


def test_summed_and_reordered_pairs_are_the_dense_sum_and_reordering():
    parts = [confusion_pairs(*_decisions(6, 5, seed)) for seed in range(4)]
    whole = sum(dense_counts(p, 6) for p in parts)
    np.testing.assert_array_equal(dense_counts(summed_pairs(parts), 6), whole)
    back = np.random.default_rng(1).permutation(6)
    moved = reordered_pairs(summed_pairs(parts), back)
    np.testing.assert_array_equal(dense_counts(moved, 6), whole[np.ix_(back, back)])
    np.testing.assert_array_equal(moved, counts_pairs(whole[np.ix_(back, back)]))  # still sorted
    assert summed_pairs([]).shape == (0, 3)


def test_the_largest_confusions_from_pairs_are_those_of_the_dense_matrix():
    truth, guess = _decisions(30, 12, seed=2)
    names = [f"o{i}" for i in range(30)]
    pairs = confusion_pairs(truth, guess)
    assert top_pairs(pairs, names, k=15) == report.top_confusions(dense_counts(pairs, 30), names, k=15)
    # Ties go to the lower true class, then the lower predicted one.
    tied = counts_pairs(np.array([[5, 0, 2], [2, 5, 0], [0, 2, 5]]))
    assert top_pairs(tied, ["a", "b", "c"]) == [("a", "c", 2, 2 / 7), ("b", "a", 2, 2 / 7), ("c", "b", 2, 2 / 7)]


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: confusion_pairs([0, 1], [0]), "differ in length"),
        (lambda: confusion_pairs([0, 1], [0, -1]), "non-negative"),
        (lambda: reordered_pairs([[0, 1, 1]], [0, 0, 2]), "permutation"),
        (lambda: reordered_pairs([[0, 3, 1]], [0, 1, 2]), "beyond the 3"),
        (lambda: dense_counts([[0, 3, 1]], 3), "beyond the 3"),
        (lambda: dense_counts([[0, 1]], 3), r"\(k, 3\)"),
        (lambda: counts_pairs(np.ones((2, 3))), "square"),
    ],
)
def test_bad_confusions_are_refused_with_what_is_wrong(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def _result(n, touches=5, matrices=4) -> ExperimentResult:
    names = tuple(f"object{i:04d}" for i in range(n))
    confusions = tuple(
        ConfusionMatrix(f"m{q}", "instance", "knn", n, False, names, confusion_pairs(*_decisions(n, touches, q)))
        for q in range(matrices)
    )
    return ExperimentResult(
        cells=(), comparisons=(), confusions=confusions, object_names=names, object_sets=(n,), classifiers=("knn",)
    )


def test_results_json_grows_with_the_objects_not_their_square_and_reads_back():
    small, large = (len(report.json_text(_result(n).to_json())) for n in (250, 1000))
    assert large / small < 4.4  # four times the objects: four times the touches, not sixteen times the cells
    result = _result(300)
    again = ExperimentResult.from_json(json.loads(report.json_text(result.to_json())))
    for read, written in zip(again.confusions, result.confusions, strict=True):
        assert read.object_names == written.object_names and read.n_objects == written.n_objects
        np.testing.assert_array_equal(read.pairs, written.pairs)
        assert read.top(5) == written.top(5)


def test_a_results_json_with_dense_confusion_matrices_still_reads():
    counts = np.array([[3, 1, 0], [0, 4, 0], [2, 0, 2]])
    document = {
        "cells": [],
        "object_names": ["a", "b", "c"],
        "object_sets": [3],
        "classifiers": ["knn"],
        "confusions": [
            {
                "method": "uniform",
                "protocol": "instance",
                "classifier": "knn",
                "n_objects": 3,
                "selection": False,
                "object_names": ["a", "b", "c"],
                "counts": counts.tolist(),
            }
        ],
    }
    (read,) = ExperimentResult.from_json(document).confusions
    np.testing.assert_array_equal(read.counts, counts)
    assert read.top(2) == [("c", "a", 2, 0.5), ("a", "b", 1, 0.25)]


def test_json_text_parses_to_what_json_writes_with_plain_lists_on_one_line():
    payload = {
        "rates": np.arange(6.0).reshape(2, 3),
        "nested": {"empty": [], "none": {}, 3: [{"a": 1}, [1, [2]]], "flag": True},
        "count": np.int64(7),
        "names": ["cup", "cow"],
    }
    text = report.json_text(payload)
    assert json.loads(text) == json.loads(json.dumps(payload, default=lambda o: o.tolist()))
    assert "    [0.0, 1.0, 2.0],\n    [3.0, 4.0, 5.0]\n" in text and '"names": ["cup", "cow"]' in text
