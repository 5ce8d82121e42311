"""Benchmark: the recognizers' hot loops at the experiment's sizes, each beside a scikit-learn peer.

* Group folds: :class:`classify.recognizers.folds.GroupFolds` against
  scikit-learn's ``StratifiedGroupKFold``, which it must match split for
  split (checked here too): the deep network's validation split in the demo
  (10 folds, a few hundred imprints grouped by point) and the kNN's inner
  folds over a touch knowledge (3 folds, 16 objects, every place of three
  training instances).
* kNN fit at the touch knowledge's size (16 objects x 3 instances x 330
  places, 42 polar features): k chosen on grouped inner folds, and the
  distance scale; the peer is ``GridSearchCV`` over ``KNeighborsClassifier``
  with grouped folds, what one would write with scikit-learn.
* The evolutionary SVM at the demo's size (6 toys, 15 points, 3 training
  instances x 2 sessions); the peer is ``SVC`` (LIBSVM's SMO on the same dual).
* The evolutionary SVM on the training sets the protocols fit together
  (``fit_each``: a repeat's five folds, an instance job's four fits); the
  peer is the same fits one by one, which must give the same models.

One BLAS thread, as in the experiment's workers.  Medians over ``--repeats``
runs, wall and CPU time; ratios are peer / ours.

    .venv/bin/python benchmarks/bench_recognition.py [--repeats 5]
"""

from __future__ import annotations

import statistics
import sys
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

sys.path.insert(0, str(Path(__file__).resolve().parent))
from benchlib import arguments, run, timed  # noqa: E402


def grouped(objects: int, groups_per_object: int, per_group: int, features: int, seed: int = 0):
    """Imprint-like rows: ``per_group`` re-touches of each point, points grouped, objects apart by a little."""
    rng = np.random.default_rng(seed)
    y = np.repeat(np.arange(objects), groups_per_object * per_group)
    groups = np.repeat(np.arange(objects * groups_per_object), per_group)
    centre = rng.normal(size=(objects * groups_per_object, features))
    X = centre[groups] + 0.3 * rng.normal(size=(len(y), features)) + 0.2 * y[:, None] / objects
    order = rng.permutation(len(y))
    return X[order], y[order], groups[order]


def median_times(fn, repeats: int):
    runs = [timed(fn) for _ in range(repeats)]
    return runs[-1][0], statistics.median(r[1] for r in runs), statistics.median(r[2] for r in runs)


def row(task, ours, peer, note=""):
    ratio = peer[1] / ours[1] if ours[1] > 0 else float("inf")
    return (
        f"| {task} | {ours[1] * 1e3:.1f} ms ({ours[2] * 1e3:.1f} CPU) | {peer[1] * 1e3:.1f} ms "
        f"({peer[2] * 1e3:.1f} CPU) | {ratio:.2g}x | {note} |"
    )


def main(argv=None) -> int:
    from sklearn.model_selection import GridSearchCV, GroupKFold, StratifiedGroupKFold
    from sklearn.neighbors import KNeighborsClassifier
    from sklearn.svm import SVC

    from classify.recognizers.classifiers import KNN, EvolutionarySVM
    from classify.recognizers.folds import GroupFolds

    parser = arguments(__doc__, repeats=5, meshes_dir=False)
    args = parser.parse_args(argv)
    print("| task | ours | scikit-learn peer | peer / ours | |")
    print("|---|---|---|---|---|")
    with threadpool_limits(1):
        for task, (objects, per_object, per_group, folds) in {
            "group folds, deep network's validation split (6 objects, 540 imprints, 10 folds)": (6, 45, 2, 10),
            "group folds, kNN inner folds of a touch knowledge (16 objects, 15,840 rows, 3 folds)": (16, 990, 1, 3),
        }.items():
            X, y, groups = grouped(objects, per_object, per_group, 4)

            def split(kind, folds=folds, X=X, y=y, groups=groups):
                return [test.tolist() for _, test in kind(folds, shuffle=True, random_state=0).split(X, y, groups)]

            ours = median_times(lambda split=split: split(GroupFolds), args.repeats)
            peer = median_times(lambda split=split: split(StratifiedGroupKFold), args.repeats)
            print(row(task, ours, peer, "same splits" if ours[0] == peer[0] else "SPLITS DIFFER"))

        X, y, groups = grouped(16, 990, 1, 42)
        ks = (1, 3, 5, 7, 9)
        ours = median_times(lambda: KNN(ks=ks).fit(X, y, groups), max(1, args.repeats // 2))
        peer = median_times(
            lambda: GridSearchCV(KNeighborsClassifier(), {"n_neighbors": ks}, cv=GroupKFold(3)).fit(
                X, y, groups=groups
            ),
            max(1, args.repeats // 2),
        )
        print(
            row("kNN fit, k from grouped inner folds (16 objects, 15,840 rows x 42)", ours, peer, f"k = {ours[0].k_}")
        )

        X, y, _ = grouped(6, 45, 1, 256)
        ours = median_times(lambda: EvolutionarySVM().fit(X, y), args.repeats)
        peer = median_times(lambda: SVC().fit(X, y), args.repeats)
        print(row("evolutionary SVM fit (6 objects, 270 imprints x 256)", ours, peer, f"{ours[0].n_generations_} gen."))

        # The protocols fit the evolutionary SVM on several training sets at once; the peer fits them one by one.
        print("\n| evolutionary SVM, several fits | together (fit_each) | one by one | one by one / together | |")
        print("|---|---|---|---|---|")
        X, y, groups = grouped(6, 15, 1, 256)
        paper = [(X[groups % 5 != k], y[groups % 5 != k]) for k in range(5)]
        X, y, groups = grouped(6, 45, 1, 256)
        instance = [(X[groups % 3 != k], y[groups % 3 != k]) for k in range(3)] + [(X, y)]
        for task, sets in {
            "paper protocol: the 5 training folds of a repeat (6 objects x 15 points)": paper,
            "instance protocol: 3 calibration fits and the final one (6 objects, 270 imprints)": instance,
        }.items():
            ours = median_times(lambda sets=sets: EvolutionarySVM().fit_each(sets), args.repeats)
            peer = median_times(lambda sets=sets: [EvolutionarySVM().fit(X, y) for X, y in sets], args.repeats)
            same = all(np.array_equal(a.dual_coef_, b.dual_coef_) for a, b in zip(ours[0], peer[0]))
            print(row(task, ours, peer, "same models" if same else "MODELS DIFFER"))
    return 0


if __name__ == "__main__":
    run("bench_recognition", "Recognition: folds, kNN fit, evolutionary SVM beside scikit-learn", main)
