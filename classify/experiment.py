"""The recognition experiment behind the paper's Table 1, and its real-data twin (Table 2).

Pipeline, per object and interest-point method: mesh (scaled to ``size_mm``)
-> ``meshsal.interest_points`` (n points) -> tactile imprints -> the five
classifiers.  Every stage is deterministic (seeded), so points and imprints
are cached on disk under a key of the mesh's content, every setting and the
code, and each protocol's recognition rates under a key of its imprints,
settings and code (:mod:`classify.cache`): a second run with the same
settings reads them back instead of recomputing.

Protocols
---------
``paper``
    The paper classifies a pool of simulated imprints by stratified 5-fold
    cross-validation.  Fifteen points give too few imprints per object for
    five folds, so each interest point is touched ``per_point`` times (8 by
    default): ``tactile.acquire`` under a mild perturbation
    (:func:`default_perturbations`, the first one: sub-millimetre placement
    jitter, a few degrees of tilt and in-plane rotation, a little sensor
    noise), drawn from a generator seeded with (``seed``, object).  The pool
    is split by :func:`paper_splits`: stratified k-fold, repeated with seeds
    ``seed + r``.  Similarity selection (``tactile.select_by_similarity``,
    NCC > 0.85 to another object's imprint) is applied to the training fold
    only (:func:`select_training`); the test fold is never filtered, never
    seen in training.  Imprints of one point occur in training and test folds
    alike, as in the paper's pooled cross-validation.
``retouch``
    Train on the clean imprints at the points (``tactile.imprints``) with
    in-plane rotation augmentation (``angles``, every 15 degrees by default:
    the sensor's roll about the normal is not controlled on a real robot),
    optionally filtered by selection; test on imprints re-acquired at the same points by
    ``tactile.acquire`` under a realistic perturbation (the second of
    :func:`default_perturbations`: placement jitter, tilt, any in-plane
    rotation, gain spread, noise, dead taxels, ADC quantization, cover blur)
    from a generator seeded independently of the paper pool's, (``seed``,
    104729, object); one acquisition round per repeat.  Recognition
    after k touches (k = 1 .. n points) multiplies the classifier's
    posteriors over k distinct points of one object (a sum of logs, each
    posterior floored at ``1e-3`` so that one zero cannot veto a class;
    ``touch_sequences_per_object`` random point subsets per object, repeat and k).
    The kNN's posterior is its vote softened by distance (``classify.KNN``),
    so at k = 1 conflicting touches are decided by how firmly each one
    matched, not by the class order.

Statistics: each cell's ``mean`` and ``std`` are over repeats (per repeat, the
rate over all its test imprints or touch sequences), ``ci_low``/``ci_high``
a 95 % Student-t interval of the mean (equal to the mean with one repeat).
Rates are in percent.

Object sets: the first ``min(4, n)`` objects and all ``n`` (the toys are
ordered cow, glasses, cup, hand, plane, dromedary, so these are the paper's
4- and 6-object sets).
"""

from __future__ import annotations

import dataclasses
import json
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import stats
from sklearn.model_selection import StratifiedKFold
from threadpoolctl import threadpool_limits

from classify import cache as cache_mod
from classify import report
from classify.classifiers import NAMES, make
from meshsal.progress import progress

__all__ = ["PROTOCOLS", "METHODS", "Cell", "ConfusionMatrix", "ExperimentResult", "Split", "paper_splits",
           "select_training", "touch_sequences", "combine_touches", "default_perturbations",
           "run_experiment", "run_real", "summarize", "format_tables", "write_outputs"]

PROTOCOLS = ("paper", "retouch")
METHODS = ("attention", "random", "uniform", "mesh_saliency", "curvature")
_FLOOR = 1e-3


@dataclass(frozen=True)
class Cell:
    """One recognition rate of a table (percent), with its spread over repeats."""

    method: str
    protocol: str
    classifier: str
    n_objects: int
    selection: bool
    touches: int
    mean: float
    std: float
    ci_low: float
    ci_high: float
    runs: int


@dataclass(frozen=True)
class ConfusionMatrix:
    """Counts summed over all folds and repeats; rows true object, columns predicted."""

    method: str
    protocol: str
    classifier: str
    n_objects: int
    selection: bool
    object_names: tuple
    counts: np.ndarray


@dataclass(frozen=True)
class ExperimentResult:
    """Everything one experiment measured, and every setting it used.

    ``selection_kept`` maps ``"method/protocol/n_objects"`` to the mean
    fraction of training imprints similarity selection kept.
    """

    cells: tuple
    confusions: tuple
    object_names: tuple
    object_sets: tuple
    classifiers: tuple
    settings: dict = field(default_factory=dict)
    selection_kept: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)

    def cell(self, method, protocol, classifier, n_objects, selection, touches=1) -> Cell:
        """The cell of these coordinates (KeyError when it was not measured)."""
        for c in self.cells:
            if (c.method, c.protocol, c.classifier, c.n_objects, c.selection, c.touches) == (
                    method, protocol, classifier, n_objects, selection, touches):
                return c
        raise KeyError((method, protocol, classifier, n_objects, selection, touches))

    def table(self, method, protocol, touches=1) -> str:
        """The Table 1 layout as Markdown."""
        return report.table_markdown(self.cells, method, protocol, self.classifiers, self.object_sets, touches)

    def to_json(self) -> dict:
        return {
            "settings": self.settings,
            "object_names": list(self.object_names),
            "object_sets": list(self.object_sets),
            "classifiers": list(self.classifiers),
            "cells": [dataclasses.asdict(c) for c in self.cells],
            "confusions": [{**dataclasses.asdict(c), "object_names": list(c.object_names),
                            "counts": c.counts.tolist()} for c in self.confusions],
            "selection_kept": self.selection_kept,
            "timings_s": self.timings,
        }


@dataclass(frozen=True)
class Split:
    """One train/test split of the paper protocol (indices into the imprint pool)."""

    repeat: int
    fold: int
    train: np.ndarray
    test: np.ndarray


def paper_splits(labels, folds=5, repeats=10, seed=0) -> list[Split]:
    """Stratified ``folds``-fold cross-validation repeated ``repeats`` times.

    Repeat r shuffles with seed ``seed + r``.  Within a repeat the test folds
    partition the pool and each split's train and test are disjoint.

    Examples
    --------
    >>> s = paper_splits(np.repeat([0, 1], 5), folds=5, repeats=2)
    >>> len(s), sorted(np.concatenate([x.test for x in s[:5]]).tolist()) == list(range(10))
    (10, True)
    """
    labels = np.asarray(labels)
    counts = np.bincount(np.unique(labels, return_inverse=True)[1])
    if counts.min() < folds:
        raise ValueError(f"paper protocol: {folds}-fold cross-validation needs at least {folds} imprints "
                         f"per object, the smallest object has {counts.min()}")
    out = []
    for r in range(repeats):
        kfold = StratifiedKFold(folds, shuffle=True, random_state=seed + r)
        for f, (train, test) in enumerate(kfold.split(np.zeros(len(labels)), labels)):
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


def touch_sequences(n_points, k, count, rng) -> np.ndarray:
    """``count`` random sets of ``k`` distinct point indices out of ``n_points``, (count, k).

    Examples
    --------
    >>> s = touch_sequences(15, 5, 4, np.random.default_rng(0))
    >>> s.shape, all(len(set(row)) == 5 for row in s.tolist())
    ((4, 5), True)
    """
    if not 1 <= k <= n_points:
        raise ValueError(f"touches must be within 1..{n_points}, got {k}")
    return np.argsort(rng.random((count, n_points)), axis=1)[:, :k]


def combine_touches(proba, sequences) -> np.ndarray:
    """Class index maximizing the product of posteriors over each sequence of touches.

    Parameters
    ----------
    proba : (n_points, n_classes) posteriors of the single touches
    sequences : (s, k) indices into ``proba``

    Returns
    -------
    (s,) int: argmax of sum(log(max(p, 1e-3))) over the sequence.
    """
    logp = np.log(np.maximum(np.asarray(proba, float), _FLOOR))
    return np.argmax(logp[np.asarray(sequences)].sum(axis=1), axis=1)


def summarize(rates) -> tuple[float, float, float, float]:
    """(mean, std, ci_low, ci_high) of per-repeat rates in percent (95 % t interval)."""
    rates = np.asarray(rates, float)
    mean = float(rates.mean())
    if len(rates) < 2:
        return mean, 0.0, mean, mean
    std = float(rates.std(ddof=1))
    half = float(stats.t.ppf(0.975, len(rates) - 1) * std / np.sqrt(len(rates)))
    return mean, std, mean - half, mean + half


def default_perturbations():
    """(paper, retouch) acquisition perturbations.

    paper: 0.5 mm placement jitter, 2 degree tilt, 5 degree roll (standard
    deviations), 2 % gain spread, 1 % noise: repeated touches of one point by
    one careful hand.  retouch: ``tactile.Perturbation.typical()`` (1 mm, 3
    degrees, free roll, 10 % gain spread, 2 % noise, 1 % dead taxels, 8-bit
    ADC, 1 mm cover blur).
    """
    import tactile

    paper = tactile.Perturbation(jitter_mm=0.5, tilt_deg=2.0, rotation_deg=5.0, gain_spread=0.02, noise=0.01)
    retouch = tactile.Perturbation.typical()
    return paper, retouch


# ---------------------------------------------------------------------------
# Data


def _load_objects(objects, size_mm):
    import meshsal
    from meshsal import toys

    if objects is None:
        objects = toys.NAMES
    meshes = []
    for item in objects:
        if isinstance(item, meshsal.Mesh):
            mesh = item
        else:
            mesh = toys.load_object(item)
            if not mesh.name:
                mesh = mesh.replace(name=Path(item).stem)
        meshes.append(meshsal.scale_to(mesh, diagonal_mm=size_mm))
    names = [m.name or f"object{i}" for i, m in enumerate(meshes)]
    if len(set(names)) != len(names):
        raise ValueError(f"objects must have distinct names, got {names}")
    if len(meshes) < 2:
        raise ValueError(f"recognition needs at least two objects, got {len(meshes)}")
    return meshes, tuple(names)


def _mesh_hash(mesh):
    return cache_mod.hash_arrays(mesh.vertices, mesh.faces, mesh.vertex_colors, mesh.uv, mesh.texture)


def _object_data(mesh, index, method, cfg, code, cache_dir):
    """Points and every imprint stack of one object, cached as one entry."""
    import meshsal
    import tactile

    key = cache_mod.cache_key("object", _mesh_hash(mesh), index, method, code, cfg["key"])

    def compute():
        kwargs = {"n": cfg["n_points"], "method": method, "seed": cfg["seed"], "quiet": True}
        if cfg["view_size"] is not None:
            kwargs["size"] = cfg["view_size"]
        pts = meshsal.interest_points(mesh, **kwargs)
        P = np.asarray(pts.positions, np.float64)
        N = np.asarray(pts.normals, np.float64)
        k = len(P)
        sensor = cfg["sensor"]
        # One Embree scene for all stacks, one seeded generator per stack.
        scene = meshsal.embree.embree_scene(mesh)
        reps = cfg["per_point"]
        paper = tactile.acquire(mesh, np.repeat(P, reps, axis=0), np.repeat(N, reps, axis=0), sensor,
                                cfg["paper_perturbation"], np.random.default_rng([cfg["seed"], index]),
                                scene=scene)
        angles = np.asarray(cfg["angles"], np.float64)
        train = tactile.imprints(mesh, np.repeat(P, len(angles), axis=0), np.repeat(N, len(angles), axis=0),
                                 sensor, angles_deg=np.tile(angles, k), scene=scene)
        test = tactile.acquire(mesh, np.tile(P, (cfg["repeats"], 1)), np.tile(N, (cfg["repeats"], 1)), sensor,
                               cfg["retouch_perturbation"], np.random.default_rng([cfg["seed"], 104729, index]),
                               scene=scene)
        return {"vertex_ids": np.asarray(pts.vertex_ids, np.int64), "positions": P, "normals": N,
                "paper": np.asarray(paper, np.float32), "paper_points": np.repeat(np.arange(k), reps),
                "train": np.asarray(train, np.float32), "train_points": np.repeat(np.arange(k), len(angles)),
                "test": np.asarray(test, np.float32).reshape(cfg["repeats"], k, *test.shape[1:])}

    return cache_mod.cached(cache_dir, key, compute)


# ---------------------------------------------------------------------------
# Evaluation


def _fit_predict(name, params, X_train, y_train, X_test):
    model = make(name, **params.get(name, {})).fit(X_train, y_train)
    return model.predict_proba(X_test), model.classes_


def _full_proba(proba, classes, n_classes):
    out = np.zeros((len(proba), n_classes))
    out[:, classes] = proba
    return out


def _cached_rates(cache_dir, key, run):
    """``run()``'s (rates, confusion, kept) through the array cache: dict keys become entry names."""

    def arrays():
        rates, confusion, kept = run()
        out = {"kept": np.asarray(kept, np.float64)}
        out.update({"rate" + json.dumps(list(k)): np.asarray(v) for k, v in rates.items()})
        out.update({"conf" + json.dumps(list(k)): np.asarray(v) for k, v in confusion.items()})
        return out

    stored = cache_mod.cached(cache_dir, key, arrays)

    def decode(prefix):
        return {tuple(json.loads(name[len(prefix):])): value for name, value in stored.items()
                if name.startswith(prefix)}

    return decode("rate"), decode("conf"), float(stored["kept"])


def _run_paper(X, y, n_classes, cfg, classifiers, pool, quiet, desc):
    """Per-repeat rates and confusion counts for each (classifier, selection)."""
    splits = paper_splits(y, cfg["folds"], cfg["repeats"], cfg["seed"])
    hits = {(c, s): np.zeros(cfg["repeats"]) for c in classifiers for s in (False, True)}
    totals = np.zeros(cfg["repeats"])
    confusion = {(c, s): np.zeros((n_classes, n_classes), np.int64) for c in classifiers for s in (False, True)}
    kept = []
    jobs = []
    for split in splits:
        totals[split.repeat] += len(split.test)
        selected = select_training(X, y, split.train, cfg["threshold"])
        kept.append(len(selected) / len(split.train))
        for s, train in ((False, split.train), (True, selected)):
            for c in classifiers:
                jobs.append((split, s, c, train))

    def work(job):
        split, s, c, train = job
        return _fit_predict(c, cfg["params"], X[train], y[train], X[split.test])

    for (split, s, c, _), (proba, classes) in zip(jobs, progress(pool.map(work, jobs), total=len(jobs),
                                                                 desc=desc, quiet=quiet)):
        pred = classes[np.argmax(proba, axis=1)]
        hits[c, s][split.repeat] += np.sum(pred == y[split.test])
        np.add.at(confusion[c, s], (y[split.test], pred), 1)
    rates = {key: 100.0 * h / totals for key, h in hits.items()}
    return rates, confusion, float(np.mean(kept))


def _run_retouch(train_X, train_y, test_X, test_y, n_points, n_classes, cfg, classifiers,
                 pool, quiet, desc):
    """Per-repeat rates for each (classifier, selection, touches) and confusion counts (1 touch)."""
    repeats = cfg["repeats"]
    selected = select_training(train_X, train_y, np.arange(len(train_y)), cfg["threshold"])
    kept = len(selected) / len(train_y)
    jobs = [(c, s, train) for s, train in ((False, np.arange(len(train_y))), (True, selected)) for c in classifiers]
    flat = test_X.reshape(-1, *test_X.shape[2:])

    def work(job):
        c, s, train = job
        return _fit_predict(c, cfg["params"], train_X[train], train_y[train], flat)

    rates, confusion = {}, {}
    ks = range(1, n_points + 1)
    for (c, s, _), (proba, classes) in zip(jobs, progress(pool.map(work, jobs), total=len(jobs),
                                                          desc=desc, quiet=quiet)):
        proba = _full_proba(proba, classes, n_classes).reshape(repeats, -1, n_classes)
        pred = np.argmax(proba, axis=2)
        confusion[c, s] = np.zeros((n_classes, n_classes), np.int64)
        np.add.at(confusion[c, s], (np.broadcast_to(test_y, pred.shape), pred), 1)
        for k in ks:
            per_repeat = np.zeros(repeats)
            for r in range(repeats):
                if k == 1:
                    per_repeat[r] = np.mean(pred[r] == test_y)
                    continue
                rng = np.random.default_rng([cfg["seed"], 15485863, r, k])
                right = 0
                for obj in range(n_classes):
                    rows = np.flatnonzero(test_y == obj)
                    seq = rows[touch_sequences(len(rows), min(k, len(rows)), cfg["touch_sequences"], rng)]
                    right += np.sum(combine_touches(proba[r], seq) == obj)
                per_repeat[r] = right / (n_classes * cfg["touch_sequences"])
            rates[c, s, k] = 100.0 * per_repeat
    return rates, confusion, kept


# ---------------------------------------------------------------------------
# Entry points


def run_experiment(objects=None, size_mm=150.0, methods=("attention",), protocols=PROTOCOLS, n_points=15,
                   folds=5, repeats=10, seed=0, view_size=None, out_dir=None, cache_dir="default",
                   quiet=False, classifiers=NAMES, sensor=None, per_point=8, angles=tuple(range(0, 360, 15)),
                   threshold=0.85, touch_sequences_per_object=50, perturbations=None, params=None,
                   n_jobs=2) -> ExperimentResult:
    """Interest points -> imprints -> recognition, under the paper and retouch protocols.

    Parameters
    ----------
    objects : sequence of mesh paths, toy names or ``meshsal.Mesh``; None for the six toys
    size_mm : float
        Every object is scaled to this bounding-box diagonal.
    methods : interest-point methods (``METHODS``)
    protocols : subset of ``PROTOCOLS``
    n_points : interest points per object
    folds, repeats, seed : cross-validation folds, repeats (both protocols), base seed
    view_size : rendered view size for ``meshsal.interest_points`` (None: its default)
    out_dir : path or None
        Where ``results.json``, ``results.csv``, ``confusion_<classifier>.png``
        and ``touches.png`` go (nothing written when None).
    cache_dir : path, None (no cache) or ``"default"`` (:func:`classify.cache.default_dir`)
    quiet : no progress bars on stderr (``format_tables(result)`` gives the tables)
    classifiers : subset of ``classify.NAMES``
    sensor : ``tactile.Sensor`` (default ``tactile.Sensor()``)
    per_point : imprints per point in the paper protocol's pool
    angles : in-plane rotations (degrees) of the retouch training set
    threshold : NCC threshold of similarity selection
    touch_sequences_per_object : random touch sets per object, repeat and k
    perturbations : (paper, retouch) ``tactile.Perturbation``; None for :func:`default_perturbations`
    params : dict classifier name -> parameters for ``classify.make``
    n_jobs : threads fitting classifiers in parallel

    Returns
    -------
    ExperimentResult

    Examples
    --------
    >>> r = run_experiment(["cow", "cup"], n_points=5, repeats=1, quiet=True)   # doctest: +SKIP
    >>> print(r.table("attention", "paper"))                                     # doctest: +SKIP
    """
    import tactile

    started = time.perf_counter()
    unknown = [m for m in methods if m not in METHODS]
    if unknown or not methods:
        raise ValueError(f"unknown interest-point method(s) {unknown}; choose from {', '.join(METHODS)}")
    bad = [p for p in protocols if p not in PROTOCOLS]
    if bad or not protocols:
        raise ValueError(f"unknown protocol(s) {bad}; choose from {', '.join(PROTOCOLS)}")
    bad = [c for c in classifiers if c not in NAMES]
    if bad or not classifiers:
        raise ValueError(f"unknown classifier(s) {bad}; choose from {', '.join(NAMES)}")
    if folds < 2 or repeats < 1 or n_points < 1 or per_point < 1:
        raise ValueError("folds must be >= 2 and repeats, n_points, per_point >= 1")
    if cache_dir == "default":
        cache_dir = cache_mod.default_dir()
    sensor = tactile.Sensor() if sensor is None else sensor
    paper_p, retouch_p = default_perturbations() if perturbations is None else perturbations
    params = dict(params or {})
    meshes, names = _load_objects(objects, size_mm)
    n_all = len(meshes)
    object_sets = tuple(sorted({min(4, n_all), n_all}))
    cfg = {"n_points": n_points, "seed": seed, "view_size": view_size, "sensor": sensor, "per_point": per_point,
           "angles": tuple(float(a) for a in angles), "repeats": repeats, "folds": folds, "threshold": threshold,
           "paper_perturbation": paper_p, "retouch_perturbation": retouch_p,
           "touch_sequences": touch_sequences_per_object, "params": params}
    cfg["key"] = repr([cfg[k] for k in ("n_points", "seed", "view_size", "sensor", "per_point", "angles",
                                        "repeats", "paper_perturbation", "retouch_perturbation")])
    code = cache_mod.code_fingerprint("meshsal", "tactile")
    settings = {
        "objects": list(names), "size_mm": size_mm, "methods": list(methods), "protocols": list(protocols),
        "n_points": n_points, "folds": folds, "repeats": repeats, "seed": seed, "view_size": view_size,
        "classifiers": list(classifiers), "sensor": repr(sensor), "per_point": per_point,
        "angles_deg": list(cfg["angles"]), "threshold": threshold,
        "touch_sequences_per_object": touch_sequences_per_object,
        "perturbation_paper": repr(paper_p), "perturbation_retouch": repr(retouch_p),
        "classifier_params": {c: make(c, **params.get(c, {})).get_params() for c in classifiers},
        "cache_dir": None if cache_dir is None else str(cache_dir),
    }
    timings = {}

    t0 = time.perf_counter()
    tasks = [(m, i) for m in methods for i in range(n_all)]
    data = {}
    for m, i in progress(tasks, desc="points+imprints", quiet=quiet):
        data[m, i] = _object_data(meshes[i], i, m, cfg, code, cache_dir)
    timings["points_and_imprints"] = time.perf_counter() - t0

    cells, confusions, kept_info = [], [], {}
    t0 = time.perf_counter()
    recognition_code = cache_mod.code_fingerprint("classify", "tactile")
    recognition_cfg = [cfg[k] for k in ("folds", "repeats", "seed", "threshold", "touch_sequences", "params")]

    def recognized(kind, arrays, run):
        """Seeded, hence deterministic: cached under the imprints, settings and code like the imprints."""
        key = cache_mod.cache_key(kind, cache_mod.hash_arrays(*arrays), recognition_cfg, list(classifiers),
                                  n_points, recognition_code)
        return _cached_rates(cache_dir, key, run)

    # One BLAS thread per worker: small matrices, and nested threading thrashes a shared machine.
    with threadpool_limits(1), ThreadPoolExecutor(max(1, int(n_jobs))) as pool:
        for m in methods:
            for n in object_sets:
                if "paper" in protocols:
                    X = np.concatenate([data[m, i]["paper"] for i in range(n)])
                    y = np.concatenate([np.full(len(data[m, i]["paper"]), i) for i in range(n)])
                    rates, conf, kept = recognized("paper", (X, y), lambda: _run_paper(
                        X, y, n, cfg, classifiers, pool, quiet, f"paper {m} {n} objects"))
                    kept_info[f"{m}/paper/{n}"] = kept
                    for (c, s), r in rates.items():
                        cells.append(Cell(m, "paper", c, n, s, 1, *summarize(r), len(r)))
                        confusions.append(ConfusionMatrix(m, "paper", c, n, s, names[:n], conf[c, s]))
                if "retouch" in protocols:
                    train_X = np.concatenate([data[m, i]["train"] for i in range(n)])
                    train_y = np.concatenate([np.full(len(data[m, i]["train"]), i) for i in range(n)])
                    test_X = np.concatenate([data[m, i]["test"] for i in range(n)], axis=1)
                    test_y = np.concatenate([np.full(data[m, i]["test"].shape[1], i) for i in range(n)])
                    rates, conf, kept = recognized("retouch", (train_X, train_y, test_X, test_y), lambda: _run_retouch(
                        train_X, train_y, test_X, test_y, n_points, n, cfg, classifiers, pool, quiet,
                        f"retouch {m} {n} objects"))
                    kept_info[f"{m}/retouch/{n}"] = kept
                    for (c, s, k), r in rates.items():
                        cells.append(Cell(m, "retouch", c, n, s, k, *summarize(r), len(r)))
                    for (c, s), counts in conf.items():
                        confusions.append(ConfusionMatrix(m, "retouch", c, n, s, names[:n], counts))
    timings["recognition"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - started
    result = ExperimentResult(tuple(cells), tuple(confusions), names, object_sets, tuple(classifiers),
                              settings, kept_info, timings)
    if out_dir is not None:
        write_outputs(result, out_dir)
    return result


def run_real(imprint_set, folds=5, repeats=10, seed=0, classifiers=NAMES, threshold=0.85, params=None,
             out_dir=None, quiet=False, n_jobs=2) -> ExperimentResult:
    """Recognition on a measured ``tactile.ImprintSet``, in the paper's Table 2 layout.

    The paper protocol (stratified cross-validation, selection on training
    folds only) over the set's imprints, for the first ``min(4, n)`` objects
    (by label) and all ``n``.  ``imprint_set`` is an ``ImprintSet`` or the
    path of one saved with ``ImprintSet.save``.
    """
    import tactile

    started = time.perf_counter()
    if not isinstance(imprint_set, tactile.ImprintSet):
        imprint_set = tactile.ImprintSet.load(imprint_set)
    X = np.asarray(imprint_set.imprints, np.float32)
    y = np.asarray(imprint_set.labels, np.int64)
    names = tuple(imprint_set.object_names)
    present = np.unique(y)
    if len(present) < 2:
        raise ValueError(f"{imprint_set.source or 'imprint set'}: recognition needs imprints of at least "
                         f"two objects, found {len(present)}")
    n_all = len(names)
    object_sets = tuple(sorted({min(4, n_all), n_all}))
    cfg = {"folds": folds, "repeats": repeats, "seed": seed, "threshold": threshold, "params": dict(params or {})}
    cells, confusions, kept_info = [], [], {}
    with threadpool_limits(1), ThreadPoolExecutor(max(1, int(n_jobs))) as pool:
        for n in object_sets:
            mask = y < n
            rates, conf, kept = _run_paper(X[mask], y[mask], n, cfg, classifiers, pool, quiet, f"real {n} objects")
            kept_info[f"real/paper/{n}"] = kept
            for (c, s), r in rates.items():
                cells.append(Cell("real", "paper", c, n, s, 1, *summarize(r), len(r)))
                confusions.append(ConfusionMatrix("real", "paper", c, n, s, names[:n], conf[c, s]))
    settings = {"real": str(imprint_set.source), "n_imprints": int(len(y)), "folds": folds, "repeats": repeats,
                "seed": seed, "threshold": threshold, "classifiers": list(classifiers),
                "sensor": repr(imprint_set.sensor)}
    result = ExperimentResult(tuple(cells), tuple(confusions), names, object_sets, tuple(classifiers), settings,
                              kept_info, {"total": time.perf_counter() - started})
    if out_dir is not None:
        write_outputs(result, out_dir)
    return result


def format_tables(result: ExperimentResult, title="Table 1 layout") -> str:
    """Every table of a result as Markdown (single touch; retouch also by touches)."""
    blocks = []
    keys = sorted({(c.method, c.protocol) for c in result.cells}, key=lambda mp: (mp[0], PROTOCOLS.index(mp[1])))
    for method, protocol in keys:
        blocks.append(f"### {title}: {method}, {protocol} protocol, recognition rate (%), single touch\n\n"
                      + result.table(method, protocol))
        if protocol == "retouch":
            n = result.object_sets[-1]
            for selection in (False, True):
                blocks.append(f"### {method}, retouch protocol, {n} objects, "
                              f"{'with' if selection else 'no'} selection: recognition (%) after k touches\n\n"
                              + report.touches_markdown(result.cells, method, protocol, result.classifiers,
                                                        n, selection))
    return "\n\n".join(blocks) + "\n"


def write_outputs(result: ExperimentResult, out_dir) -> None:
    """results.json, results.csv, confusion_<classifier>.png and touches.png under ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report.write_json(out / "results.json", result.to_json())
    report.write_csv(out / "results.csv", result.cells)
    n = result.object_sets[-1]
    for name in result.classifiers:
        panels = [(f"{c.method} / {c.protocol} / {'sel' if c.selection else 'no sel'}", c.counts, c.object_names)
                  for c in result.confusions
                  if c.classifier == name and c.n_objects == n and c.selection]
        report.write_confusion_png(out / f"confusion_{name}.png", panels)
    clf = "knn" if "knn" in result.classifiers else result.classifiers[0]
    curves = {}
    for method in dict.fromkeys(c.method for c in result.cells):
        cells = sorted((c for c in result.cells if c.method == method and c.classifier == clf
                        and c.n_objects == n and not c.selection
                        and c.protocol == ("retouch" if any(x.protocol == "retouch" for x in result.cells)
                                           else c.protocol)), key=lambda c: c.touches)
        if cells:
            curves[method] = (np.array([c.touches for c in cells]), np.array([c.mean for c in cells]),
                              np.array([c.std for c in cells]))
    protocol = "retouch" if any(c.protocol == "retouch" for c in result.cells) else result.cells[0].protocol
    report.write_touches_png(out / "touches.png", curves,
                             f"{protocol} protocol, {clf}, {n} objects, no selection: recognition vs touches")
