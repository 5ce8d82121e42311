"""Pictures of results stay readable: a confusion grid for a few classes, the largest confusions for many."""

import numpy as np

from classify.reporting.report import GRID_CLASSES, confusion_image, top_confusions


def _confused(n, seed=0):
    rng = np.random.default_rng(seed)
    M = np.diag(rng.integers(5, 20, n))
    for _ in range(4 * n):
        M[rng.integers(n), rng.integers(n)] += 1
    return M


def test_a_few_classes_get_a_grid_and_many_a_list_of_the_largest_confusions():
    few = confusion_image([("few", _confused(6), [f"o{i}" for i in range(6)])])
    many = confusion_image([("many", _confused(1000), [f"object{i:04d}" for i in range(1000)])])
    more = confusion_image([("more", _confused(2000), [f"object{i:04d}" for i in range(2000)])])
    assert few.shape[0] > 6 * 40  # a cell per pair
    assert many.shape == more.shape and many.shape[0] < 1000  # a list, whatever the number of classes
    assert GRID_CLASSES < 1000


def test_top_confusions_are_the_largest_off_diagonal_cells_with_their_share():
    M = np.array([[8, 2, 0], [1, 9, 0], [0, 5, 5]])
    assert top_confusions(M, ["a", "b", "c"], k=3) == [("c", "b", 5, 0.5), ("a", "b", 2, 0.2), ("b", "a", 1, 0.1)]
    assert top_confusions(np.eye(3, dtype=int), ["a", "b", "c"]) == []  # no confusion, nothing listed
