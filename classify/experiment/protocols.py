"""The two evaluation protocols: the paper's cross-validation, and fresh object instances.

``paper``
    Faithful to the paper's Table 1: each object's n interest points, one
    clean imprint each, classified by k-fold cross-validation whose folds
    are grouped by point and stratified over objects
    (:func:`paper_splits`), repeated with reshuffled folds.  Similarity
    selection runs on the training folds only (:func:`select_training`).

``instance``
    The main protocol.  Each replicate draws fresh instances of every
    object (:mod:`classify.experiment.samples`): train on several training instances,
    each touched in its own acquisition sessions, and test on a disjoint
    test instance, after k = 1..n touches at distinct points of it.  The
    classifier's posteriors are calibrated on folds that hold out whole
    training instances (:mod:`classify.recognizers.fusion`), then multiplied over the
    touches.  Tuning inside a classifier (kNN's k, the network's early
    stopping) gets folds grouped by (object, instance, point).

A job is one frozen record (:class:`PaperJob`, :class:`InstanceJob`) run
by a pure function in a worker.  Every random choice of a job is seeded by
the base seed, the replicate, the number of touches and the object's name
(:mod:`classify.experiment.streams`), never by a list position or by the
classifier, so every point method and classifier of a replicate sees the
same instances, devices, folds, touch sets and tie breaks.  Each job runs
with one BLAS/OpenMP thread inside its worker, so results do not depend on
how many workers run.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from classify.experiment.streams import Stream, recognition_rng
from classify.policies.episodes import stopping_curve
from classify.recognizers import touches
from classify.recognizers.folds import GroupFolds
from classify.recognizers.fusion import calibrate, fit_calibration, fuse, touch_sets
from classify.recognizers.touches import Recognizer, point_groups
from classify.reporting.confusion import confusion_pairs
from meshsal.util.registry import Registry
from tactile.features import describe

__all__ = [
    "PROTOCOLS",
    "PROTOCOL_REGISTRY",
    "Split",
    "paper_splits",
    "select_training",
    "select_training_sets",
    "PaperJob",
    "PaperOutcome",
    "paper_job",
    "InstanceData",
    "InstanceJob",
    "InstanceOutcome",
    "instance_job",
    "plan_outcome",
]

#: The evaluation protocols (this module's docstring describes them).
PROTOCOL_REGISTRY = Registry(
    "protocol",
    [
        ("paper", None, "the paper's CV, folds grouped by point"),
        ("instance", None, "train and test on distinct fresh instances, k-touch fusion"),
    ],
)
PROTOCOLS = PROTOCOL_REGISTRY.names()


@dataclass(frozen=True)
class Split:
    """One train/test split of the paper protocol (indices into the imprint pool)."""

    repeat: int
    fold: int
    train: np.ndarray
    test: np.ndarray


def paper_splits(labels, groups=None, folds=5, repeats=10, seed=0, names=None) -> list[Split]:
    """``folds``-fold cross-validation grouped by ``groups``, stratified by ``labels``, ``repeats`` times.

    Repeat r shuffles with seed ``seed + r``.  Within a repeat the test folds
    partition the pool, and no group has members on both sides of a split.
    ``names``, one per distinct label in sorted order, name the objects with
    too few groups (points) for the folds in the error.

    Examples
    --------
    >>> s = paper_splits(np.repeat([0, 1], 5), folds=5, repeats=2)     # every imprint its own point
    >>> len(s), sorted(np.concatenate([x.test for x in s[:5]]).tolist()) == list(range(10))
    (10, True)
    """
    labels = np.asarray(labels)
    groups = np.arange(len(labels)) if groups is None else np.asarray(groups)
    classes = np.unique(labels)
    per_class = [len(np.unique(groups[labels == c])) for c in classes]
    if min(per_class) < folds:
        names = [str(c) for c in classes] if names is None else list(names)
        short = ", ".join(f"{name} has {k}" for name, k in zip(names, per_class) if k < folds)
        raise ValueError(
            f"paper protocol: {folds}-fold cross-validation needs at least {folds} points per object; {short} "
            "(fewer --folds, or --protocols instance, which does not fold points)"
        )
    out = []
    for r in range(repeats):
        kfold = GroupFolds(folds, shuffle=True, random_state=seed + r)
        for f, (train, test) in enumerate(kfold.split(np.zeros(len(labels)), labels, groups)):
            out.append(Split(r, f, train, test))
    return out


def select_training(imprints, labels, train, threshold=0.85) -> np.ndarray:
    """The training indices that survive similarity selection.

    Only ``imprints[train]`` is handed to ``tactile.select_by_similarity``:
    the selection never sees a test imprint.
    """
    import tactile

    train = np.asarray(train)
    keep = np.asarray(tactile.select_by_similarity(imprints[train], labels[train], threshold=threshold), bool)
    return train[keep]


def select_training_sets(imprints, labels, instances, threshold=0.85) -> list:
    """:func:`select_training` of the training set with each training instance left out in turn (in increasing
    instance), then of the whole set: (N_i,) int64 indices each, from one pass over the pairs
    (``tactile.select_leaving_out``)."""
    import tactile

    _, keep = tactile.select_leaving_out(imprints, labels, instances, threshold=threshold)
    return [np.flatnonzero(k) for k in keep]


@dataclass(frozen=True, eq=False)
class PaperJob:
    """One repeat of the paper protocol: the pool of imprints, its folds, the ways to recognize.

    ``X`` (N, rows, cols) imprints, ``y`` (N,) object labels, ``groups`` (N,)
    (:func:`point_groups`), ``splits`` the repeat's folds, ``recognizers``
    a tuple of :class:`Recognizer` (e.g. one classifier without and with
    selection), ``n_classes``.
    """

    X: np.ndarray
    y: np.ndarray
    groups: np.ndarray
    splits: tuple
    recognizers: tuple
    n_classes: int


@dataclass(frozen=True)
class PaperOutcome:
    """One repeat of the paper protocol for one classifier and selection setting.

    ``rates`` (n_objects,) percent of each object's imprints recognized;
    ``confusion`` (k, 3) the pairs of true and predicted objects with their counts
    (:func:`classify.reporting.confusion.confusion_pairs`);
    ``kept`` the mean fraction of training imprints selection kept.
    """

    rates: np.ndarray
    confusion: np.ndarray
    kept: float


def paper_job(job: PaperJob) -> tuple[PaperOutcome, ...]:
    """Every fold of one repeat, for each recognizer: fit on the (selected) training fold, predict the test fold.

    A fold that two recognizers train the same model on (one classifier,
    its parameters and features, the same rows: selection kept every
    imprint) is fitted once; the models of one classifier are fitted
    together (:meth:`Recognizer.fit_subsets`).  Returns one outcome per
    recognizer, in order.
    """
    X, y = job.X, job.y
    with threadpool_limits(1):
        # described: features -> F; trains: (classifier, params, features) -> (recognizer, its training row sets);
        # where: (that model, rows) -> the model's number among them.
        described, trains, where, plans = {}, {}, {}, []
        for rec in job.recognizers:
            if rec.features not in described:
                described[rec.features] = describe(X, rec.features)
            model = (rec.classifier, repr(rec.params), rec.features)
            pred, kept, uses = np.full(len(y), -1), [], []
            for split in job.splits:
                train = select_training(X, y, split.train, rec.threshold) if rec.selection else split.train
                kept.append(len(train) / len(split.train))
                if len(np.unique(y[train])) < 2:
                    pred[split.test] = y[train][0] if len(train) else -1
                    continue
                rows = trains.setdefault(model, (rec, []))[1]
                key = (model, np.asarray(train).tobytes())
                if key not in where:
                    where[key] = len(rows)
                    rows.append(train)
                uses.append((split, model, where[key]))
            plans.append((described[rec.features], pred, kept, uses))
        fitted = {
            model: list(rec.fit_subsets(described[model[2]], y, job.groups, rows))
            for model, (rec, rows) in trains.items()
        }
        for F, pred, _, uses in plans:
            for split, model, k in uses:
                scores = touches.posteriors(fitted[model][k], F[split.test], job.n_classes)
                pred[split.test] = np.argmax(scores, axis=1)
    return tuple(_paper_outcome(y, pred, kept, job.n_classes) for _, pred, kept, _ in plans)


def _paper_outcome(y, pred, kept, n_classes) -> PaperOutcome:
    hit = pred >= 0
    confusion = confusion_pairs(y[hit], pred[hit])
    rates = np.array([100.0 * np.mean(pred[y == c] == c) for c in range(n_classes)])
    return PaperOutcome(rates, confusion, float(np.mean(kept)))


@dataclass(frozen=True, eq=False)
class InstanceData:
    """One replicate's imprints for one point method and object set.

    Attributes
    ----------
    train_X : (N, rows, cols) float32
    train_y : (N,) int64, object index
    train_instance : (N,) int64, training instance number (1..)
    train_point : (N,) int64, point index on its instance
    test : tuple of (k_o, rows, cols) float32, the test instance's imprints of each object
    names : tuple of str, the objects' names (seeds of the touch sets)
    """

    train_X: np.ndarray
    train_y: np.ndarray
    train_instance: np.ndarray
    train_point: np.ndarray
    test: tuple
    names: tuple


@dataclass(frozen=True, eq=False)
class InstanceJob:
    """One replicate of the instance protocol for one point method and object set.

    ``data`` the replicate's imprints; recognition after 1..``n_touches``
    touches of ``sets_per_k`` touch sets per object (all when fewer exist),
    drawn from the streams of ``seed`` and ``replicate``; and, touching the
    plan's points in its order, when the stopping rule at each of
    ``stop_levels`` would stop (:func:`classify.policies.stopping_curve`).
    """

    data: InstanceData
    recognizer: Recognizer
    n_touches: int
    sets_per_k: int
    seed: int
    replicate: int
    stop_levels: tuple = ()


@dataclass(frozen=True)
class InstanceOutcome:
    """One replicate of the instance protocol for one classifier and selection setting.

    ``rates`` (n_touches, n_objects) percent of touch sets recognized after
    k = 1..n_touches touches; ``sets`` (n_touches,) the fewest distinct touch
    sets any object had at k (0 where an object had fewer than k points);
    ``confusion`` the single-touch pairs of true and predicted objects with their counts, (k, 3)
    (:func:`classify.reporting.confusion.confusion_pairs`); ``kept`` the
    fraction of training imprints selection kept; ``stop_correct``,
    ``stop_touches`` (len(stop_levels), n_objects): with the plan's points
    touched in order and the stopping rule at each level, 100 where the
    decision at the stop was right (else 0) and the touches used.
    """

    rates: np.ndarray
    sets: np.ndarray
    confusion: np.ndarray
    kept: float
    stop_correct: np.ndarray
    stop_touches: np.ndarray


def _fit_selected(data: InstanceData, F, rec: Recognizer):
    """Models fitted with each training instance held out in turn, then on all of them (after selection), all
    fitted together, and their rows."""
    X, y, inst = data.train_X, data.train_y, data.train_instance
    if rec.selection:
        row_sets = select_training_sets(X, y, inst, rec.threshold)
    else:
        row_sets = [*(np.flatnonzero(inst != held) for held in np.unique(inst)), np.arange(len(y))]
    groups = point_groups(data.train_y, data.train_point, data.train_instance)
    return list(rec.fit_subsets(F, y, groups, row_sets)), row_sets


def _calibration(data: InstanceData, F, models, row_sets, n_classes: int):
    """(eps, T) fitted on each training instance's posteriors under the model of all the others.

    ``models`` and ``row_sets`` are those models and their training rows, in
    the order of the training instances.
    """
    proba, truth = [], []
    for held, model, rows in zip(np.unique(data.train_instance), models, row_sets):
        if len(np.unique(data.train_y[rows])) < 2:
            continue
        out = np.flatnonzero(data.train_instance == held)
        proba.append(touches.posteriors(model, F[out], n_classes))
        truth.append(data.train_y[out])
    if not proba:
        return fit_calibration(np.zeros((0, n_classes)), np.zeros(0, np.int64))
    return fit_calibration(np.concatenate(proba), np.concatenate(truth))


def instance_job(job: InstanceJob) -> InstanceOutcome:
    """Train on the training instances, recognize the test instances after 1..``n_touches`` touches."""
    data, rec = job.data, job.recognizer
    n_classes = len(data.test)
    with threadpool_limits(1):
        F = describe(data.train_X, rec.features)
        # The calibration's models (each training instance held out in turn) and the final one, fitted together.
        models, row_sets = _fit_selected(data, F, rec)
        cal = _calibration(data, F, models[:-1], row_sets[:-1], n_classes)
        model, rows = models[-1], row_sets[-1]
        proba = [
            calibrate(touches.posteriors(model, describe(t, rec.features), n_classes), cal)
            if len(t)
            else np.zeros((0, n_classes))
            for t in data.test
        ]
    return plan_outcome(
        proba,
        data.names,
        job.n_touches,
        job.sets_per_k,
        job.seed,
        job.replicate,
        job.stop_levels,
        len(rows) / len(data.train_y),
    )


def plan_outcome(
    proba: list,
    names: tuple,
    n_touches: int,
    sets_per_k: int,
    seed: int,
    replicate: int,
    stop_levels: tuple,
    kept: float = 1.0,
) -> InstanceOutcome:
    """A fixed plan recognized from its single-touch posteriors: rates after 1..``n_touches`` touches, the
    single-touch confusion and the stopping rule.

    Parameters
    ----------
    proba : list of (k_c, C) float64, each object's test touches' posteriors (calibrated or place-aware), in the
        plan's order
    names : tuple of str, the objects (seeds of the touch sets and tie breaks)
    n_touches, sets_per_k, seed, replicate, stop_levels : as :class:`InstanceJob`
    kept : float, the fraction of training imprints selection kept
    """
    n_classes = len(proba)
    truth = np.concatenate([np.full(len(p), c) for c, p in enumerate(proba)]).astype(np.int64)
    guess = np.concatenate([np.argmax(p, axis=1) for p in proba]).astype(np.int64)
    confusion = confusion_pairs(truth, guess)
    rates = np.zeros((n_touches, n_classes))
    sets = np.full(n_touches, np.iinfo(np.int64).max)
    for k in range(1, n_touches + 1):
        for c, p in enumerate(proba):
            if len(p) == 0:
                sets[k - 1] = 0
                continue
            chosen = touch_sets(
                len(p),
                min(k, len(p)),
                sets_per_k,
                recognition_rng(seed, replicate, k, names[c], Stream.TOUCH_SETS),
            )
            picks = fuse(p, chosen, recognition_rng(seed, replicate, k, names[c], Stream.TIES))
            rates[k - 1, c] = 100.0 * np.mean(picks == c)
            sets[k - 1] = min(sets[k - 1], len(chosen) if len(p) >= k else 0)
    stop_correct, stop_touches = _plan_stops(proba, names, n_touches, seed, replicate, stop_levels)
    return InstanceOutcome(rates, sets, confusion, kept, stop_correct, stop_touches)


def _plan_stops(proba: list, names, n_touches, seed, replicate, stop_levels) -> tuple[np.ndarray, np.ndarray]:
    """The stopping rule on the plan's points in order: 100 where right at the stop, and the touches used."""
    correct = np.zeros((len(stop_levels), len(proba)))
    used = np.zeros((len(stop_levels), len(proba)))
    for c, p in enumerate(proba):
        if len(p) == 0 or not stop_levels:
            continue
        beliefs = np.cumprod(np.maximum(p[:n_touches], 1e-300), axis=0)
        beliefs /= beliefs.sum(axis=1, keepdims=True)
        rng = recognition_rng(seed, replicate, 0, names[c], Stream.EPISODE_TIES)
        right, touches_used = stopping_curve([beliefs], np.array([c]), stop_levels, [rng])
        correct[:, c], used[:, c] = 100.0 * right[:, 0], touches_used[:, 0]
    return correct, used
