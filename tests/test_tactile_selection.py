"""Similarity-based selection: drops exactly the imprints that look alike across objects."""

import numpy as np
import pytest

from tactile import select_by_similarity, select_leaving_out
from tactile.selection import normalized_rows


def planted_set(seed=0):
    """Three objects with ten random imprints each; object 1's #3 and object 2's #5 are near copies."""
    rng = np.random.default_rng(seed)
    X = rng.random((30, 16, 16)).astype(np.float32)
    y = np.repeat([0, 1, 2], 10)
    X[25] = X[13] + 0.02 * rng.standard_normal((16, 16))
    # Within one object, near copies are fine.
    X[4] = X[2] + 0.02 * rng.standard_normal((16, 16))
    return X, y


def test_planted_cross_object_duplicates_are_dropped_and_nothing_else():
    X, y = planted_set()
    keep = select_by_similarity(X, y)
    assert keep.dtype == bool and keep.shape == (30,)
    assert np.flatnonzero(~keep).tolist() == [13, 25]


def test_ncc_ignores_brightness_and_contrast():
    X, y = planted_set()
    X[25] = 0.3 * X[13] + 0.5
    assert np.flatnonzero(~select_by_similarity(X, y)).tolist() == [13, 25]


def test_threshold_is_configurable():
    X, y = planted_set()
    assert select_by_similarity(X, y, threshold=1.0).all()
    assert not select_by_similarity(X, y, threshold=-1.0).any()
    # Random 16x16 images correlate around 0 +- 0.06.
    assert (~select_by_similarity(X, y, threshold=0.3)).sum() == 2


def test_flat_imprints_of_two_objects_count_as_alike():
    X, y = planted_set()
    X[0], X[15] = 0.0, 0.7
    assert np.flatnonzero(~select_by_similarity(X, y)).tolist() == [0, 13, 15, 25]


def test_flat_vectors_and_unit_rows():
    Z, flat = normalized_rows(np.array([[1.0, 2.0, 3.0], [5.0, 5.0, 5.0]]))
    np.testing.assert_allclose(np.linalg.norm(Z[0]), 1.0)
    assert flat.tolist() == [False, True] and not Z[1].any()


def test_blocks_give_the_same_answer(monkeypatch):
    import tactile.selection as selection

    X, y = planted_set()
    expected = select_by_similarity(X, y)
    monkeypatch.setattr(selection, "_CELLS", 7 * len(y))  # blocks of 7 rows
    np.testing.assert_array_equal(select_by_similarity(X, y), expected)


@pytest.mark.parametrize("threshold", [0.85, 0.1])
def test_leaving_a_group_out_is_the_selection_of_the_rest(monkeypatch, threshold):
    import tactile.selection as selection

    # Near copies of two objects in two groups (7, 21) and in one (13, 25); flat imprints of two objects (0, 15).
    X, y = planted_set()
    X[7] = X[21] + 0.02 * np.random.default_rng(1).standard_normal((16, 16))
    X[0], X[15] = 0.0, 0.7
    groups = np.tile([1, 2, 3], 10)
    monkeypatch.setattr(selection, "_CELLS", 5 * len(y))  # blocks of 5 rows
    ids, keep = select_leaving_out(X, y, groups, threshold=threshold)
    assert ids.tolist() == [1, 2, 3] and keep.shape == (4, 30)
    for g, left_out in enumerate(ids):
        rest = groups != left_out
        expected = np.zeros(30, bool)
        expected[rest] = select_by_similarity(X[rest], y[rest], threshold=threshold)
        np.testing.assert_array_equal(keep[g], expected)
    np.testing.assert_array_equal(keep[-1], select_by_similarity(X, y, threshold=threshold))
    assert not keep[[0, 2, 3]][:, [13, 25]].any()  # the planted pair goes unless its group 2 is left out
    with pytest.raises(ValueError, match="groups must have one entry per imprint"):
        select_leaving_out(X, y, groups[:-1])


@pytest.mark.parametrize(
    "X,y,match",
    [
        (np.zeros((3, 4)), [0, 1], "labels"),
        (np.zeros(3), [0, 1, 2], "shape"),
        (np.full((2, 4), np.nan), [0, 1], "finite"),
    ],
)
def test_bad_input(X, y, match):
    with pytest.raises(ValueError, match=match):
        select_by_similarity(X, y)


def test_bad_threshold():
    with pytest.raises(ValueError, match="threshold"):
        select_by_similarity(np.random.default_rng(0).random((4, 9)), [0, 0, 1, 1], threshold=1.5)
