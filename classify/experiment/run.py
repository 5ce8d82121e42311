"""The recognition experiment behind the paper's Table 1, its real-data twin (Table 2), and beyond.

Two stages.  The per-object stage (:mod:`classify.experiment.samples`) takes each
object's points and imprints, for the paper protocol on the nominal mesh and
for the instance protocol on fresh instances; every result is cached under a
key of its inputs.  The recognition stage (:mod:`classify.experiment.protocols`) runs
the classifiers on them; its outcomes are cached too, so a second run with
the same settings reads everything back.

Rates are summarized over replicates (instance protocol) or repeats (paper
protocol) and objects with a 95 % two-way bootstrap interval, and point
methods are compared with the baseline method by paired differences
(:mod:`classify.reporting.stats`).  Object sets: the first ``min(4, n)`` objects and
all ``n`` (the toys are ordered cow, glasses, cup, hand, plane, dromedary, so
these are the paper's 4- and 6-object sets).
"""

from __future__ import annotations

import dataclasses
import time
from contextlib import nullcontext
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from classify.runtime import cache as cache_mod
from classify.experiment import samples as dataset
from classify.reporting import stats
from classify.runtime.cluster import Inline, worker_pool
from classify.recognizers.classifiers import CLASSIFIERS, NAMES, make
from classify.experiment.survey import fit_replicate_model
from classify.experiment.protocols import (PROTOCOL_REGISTRY, PROTOCOLS, InstanceData, InstanceOutcome, PaperOutcome,
                                instance_job, paper_job, paper_splits)
from classify.reporting.results import Cell, Comparison, ConfusionMatrix, ExperimentResult, format_tables, write_outputs
from meshsal.points import METHODS, MODEL_METHODS, POINT_METHODS
from meshsal.util.progress import progress
from tactile.features import FEATURES

__all__ = ["PROTOCOLS", "METHODS", "DEFAULT_REPLICATES", "FULL_REPLICATES", "load_objects", "instance_stage",
           "run_experiment", "run_real", "format_tables", "write_outputs"]

#: Replicates of the instance protocol in a quick run (the default) and in a full run.
DEFAULT_REPLICATES = 5
FULL_REPLICATES = 20


def load_objects(objects, settings: dataset.Settings):
    """Names and nominal meshes of the objects, all loaded before any work (a bad file stops here).

    ``objects``: None (the toys), strings for ``meshsal.objects.resolve_objects``
    (set names, object names, mesh files, comma-separated or not) or
    ``meshsal.Mesh`` objects with distinct names.
    """
    import meshsal

    items = ["toys"] if objects is None else list(objects)
    meshes = [m for m in items if isinstance(m, meshsal.Mesh)]
    if meshes and len(meshes) != len(items):
        raise ValueError("objects must be all meshes or all names and paths, not a mix")
    if not meshes:
        from meshsal import objects as objects_mod

        refs = objects_mod.resolve_objects(items)
        meshes = [objects_mod.load_ref(ref) for ref in refs]
    names = tuple(m.name for m in meshes)
    if any(not n for n in names) or len(set(names)) != len(names):
        raise ValueError(f"objects must have distinct, non-empty names, got {list(names)}")
    if len(meshes) < 2:
        raise ValueError(f"recognition needs at least two objects, got {len(meshes)}")
    return names, tuple(dataset.nominal_mesh(m, settings) for m in meshes)


def _paper_sample_task(task):
    nominal, name, method, settings, cache_dir, threads = task
    with threadpool_limits(1):
        return dataset.paper_sample(nominal, name, method, settings, cache_dir, threads)


def _instance_samples_task(task):
    nominal, name, methods, settings, r, j, survey, cache_dir, threads, model, surveyed = task
    with threadpool_limits(1):
        return dataset.instance_samples(nominal, name, methods, settings, r, j, survey, cache_dir, threads, model,
                                        surveyed)


def _model_task(surveys):
    with threadpool_limits(1):
        return fit_replicate_model(surveys)


def _paper_task(task):
    X, y, groups, splits, c, s, params, threshold, n, features = task
    return paper_job(X, y, groups, splits, c, s, params, threshold, n, features)


def _instance_task(task):
    data, c, s, params, threshold, n_touches, sets_per_k, seed, r, features = task
    return instance_job(data, c, s, params, threshold, n_touches, sets_per_k, seed, r, features)


def _outcome_arrays(outcomes) -> dict:
    out = {}
    for i, o in enumerate(outcomes):
        for f in dataclasses.fields(o):
            out[f"{i}/{f.name}"] = np.asarray(getattr(o, f.name))
    return out


def _outcomes_from(arrays, cls, count):
    names = [f.name for f in dataclasses.fields(cls)]
    return [cls(**{n: (float(arrays[f"{i}/{n}"]) if n == "kept" else arrays[f"{i}/{n}"]) for n in names})
            for i in range(count)]


def _run_jobs(cache_dir, key, cls, run, tasks, pool, desc, quiet):
    """``run(task)`` for every task, in order, through the cache (one entry for all of them)."""

    def compute():
        return _outcome_arrays(list(progress(pool.map(run, tasks), total=len(tasks), desc=desc, quiet=quiet)))

    return _outcomes_from(cache_mod.cached(cache_dir, key, compute), cls, len(tasks))


def _recognition_key(kind, arrays, parts):
    code = cache_mod.code_fingerprint("classify", "tactile")
    return cache_mod.cache_key(kind, cache_mod.hash_arrays(*arrays), parts, code, cache_mod.library_versions())


def run_experiment(objects=None, methods=("attention",), protocols=PROTOCOLS, classifiers=NAMES, settings=None,
                   replicates=DEFAULT_REPLICATES, folds=5, repeats=10, threshold=0.85, touch_sets_per_object=50,
                   params=None, features="raw", baseline=None, n_jobs=2, executor=None, cache_dir="default",
                   out_dir=None, quiet=False) -> ExperimentResult:
    """Interest points -> imprints -> recognition, under the paper and instance protocols.

    Parameters
    ----------
    objects : None (the six toys), names/paths (see :func:`load_objects`) or meshes
    methods : interest-point methods (``METHODS``)
        The model methods ("learned", "attention_learned") fit a touch
        model per replicate on its training instances
        (:mod:`classify.experiment.survey`) and run in the instance protocol only.
    protocols : subset of ``PROTOCOLS``
    classifiers : subset of ``classify.NAMES``
    settings : classify.experiment.samples.Settings
        Points, sensor, perturbation, instances and seed (default ``Settings()``).
    replicates : int
        Instance-protocol replicates, each with fresh instances
        (``DEFAULT_REPLICATES`` quick, ``FULL_REPLICATES`` for a full run).
    folds, repeats : paper-protocol cross-validation folds and reshuffled repeats
    threshold : NCC threshold of similarity selection
    touch_sets_per_object : distinct touch sets per test instance and k (all of them when fewer exist)
    params : dict classifier name -> parameters for ``classify.make``
    features : str
        What the classifiers see: ``"raw"`` taxels (the paper's) or
        ``"polar"`` roll-invariant descriptors (``tactile.features``).
    baseline : str or None
        The method others are compared with (default ``uniform`` when
        measured, else the first method); no comparison with one method.
    n_jobs : int
        Worker processes (``classify.runtime.cluster.worker_pool``); results do not depend on it.
    executor : optional
        Runs the per-object stage and the recognition jobs instead of a
        pool of ``n_jobs``: anything with an ordered ``map``, e.g. from
        ``classify.runtime.cluster.open_executor`` (a Dask cluster).
    cache_dir : path, None (no cache) or ``"default"`` (:func:`classify.runtime.cache.default_dir`)
    out_dir : path or None
        Where ``results.json``, ``results.csv``, ``confusion_<classifier>.png``,
        ``touches.png`` and, with a learned method, each replicate's touch
        model (``touch_models/replicate_<r>.json``) go (nothing written when None).
    quiet : no progress bars on stderr

    Returns
    -------
    ExperimentResult

    Examples
    --------
    >>> r = run_experiment(["cow", "cup"], replicates=2, quiet=True)     # doctest: +SKIP
    >>> print(format_tables(r))                                          # doctest: +SKIP
    """
    started = time.perf_counter()
    settings = dataset.Settings() if settings is None else settings
    methods, protocols = POINT_METHODS.check(methods), PROTOCOL_REGISTRY.check(protocols)
    classifiers = CLASSIFIERS.check(classifiers)
    if folds < 2 or repeats < 1 or replicates < 1 or touch_sets_per_object < 1:
        raise ValueError("folds must be >= 2 and repeats, replicates, touch_sets_per_object >= 1")
    if baseline is None:
        baseline = "uniform" if "uniform" in methods else methods[0]
    if baseline not in methods:
        raise ValueError(f"baseline {baseline!r} is not among the methods {list(methods)}")
    if features not in FEATURES:
        raise ValueError(f"unknown features {features!r}; choose from {', '.join(FEATURES)}")
    if cache_dir == "default":
        cache_dir = cache_mod.default_dir()
    params = dict(params or {})
    names, nominal = load_objects(objects, settings)
    # A touch model needs training instances: the paper protocol has none.
    paper_methods = [m for m in methods if m not in MODEL_METHODS]
    models = []
    n_all = len(names)
    object_sets = tuple(sorted({min(4, n_all), n_all}))
    timings, rates, confusions, kept = {}, {}, [], {}
    sets = {}

    with threadpool_limits(1), (nullcontext(executor) if executor is not None else worker_pool(n_jobs)) as pool:
        # Workers render with one thread each; alone, the stage renders with every core.
        threads = None if isinstance(pool, Inline) else 1
        if "paper" in protocols and paper_methods:
            t0 = time.perf_counter()
            pairs = [(m, i) for m in paper_methods for i in range(n_all)]
            done = progress(pool.map(_paper_sample_task, [(nominal[i], names[i], m, settings, cache_dir,
                                                          threads) for m, i in pairs]),
                            total=len(pairs), desc="paper: points+imprints", quiet=quiet)
            samples = dict(zip(pairs, done))
            timings["paper_points_and_imprints"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            for m in paper_methods:
                for n in object_sets:
                    order = _by_name(names[:n])
                    X = np.concatenate([samples[m, i]["imprints"] for i in order])
                    y = np.concatenate([np.full(len(samples[m, i]["imprints"]), c) for c, i in enumerate(order)])
                    points = np.concatenate([np.arange(len(samples[m, i]["imprints"])) for i in order])
                    _paper_protocol(m, X, y, y * 100000 + points, names[:n], classifiers, params, threshold, folds,
                                    repeats, settings.seed, features, pool, cache_dir, quiet, (rates, confusions, kept),
                                    order)
            timings["paper_recognition"] = time.perf_counter() - t0

        if "instance" in protocols:
            t0 = time.perf_counter()
            samples, models = instance_stage(nominal, names, methods, settings, replicates, pool, cache_dir, threads,
                                              quiet)
            timings["instance_points_and_imprints"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            for m in methods:
                for n in object_sets:
                    order = _by_name(names[:n])
                    back = np.argsort(order)
                    data = [_instance_data(samples, r, m, order, names, settings) for r in range(replicates)]
                    jobs = [(r, c, s) for r in range(replicates) for c in classifiers for s in (False, True)]
                    tasks = [(data[r], c, s, params, threshold, settings.n_points, touch_sets_per_object,
                              settings.seed, r, features) for r, c, s in jobs]
                    arrays = [a for d in data for a in (d.train_X, d.train_y, d.train_instance, d.train_point,
                                                        *d.test)]
                    key = _recognition_key("instance", arrays, [settings.key(), threshold, params, jobs,
                                                                touch_sets_per_object, sorted(names[:n]), features])
                    outcomes = _run_jobs(cache_dir, key, InstanceOutcome, _instance_task, tasks, pool,
                                         f"instances: {m}, {n} objects", quiet)
                    for c in classifiers:
                        for s in (False, True):
                            mine = [o for (_, cj, sj), o in zip(jobs, outcomes) if (cj, sj) == (c, s)]
                            stack = np.stack([o.rates for o in mine])[:, :, back]   # (replicates, k, objects)
                            for k in range(1, settings.n_points + 1):
                                rates[m, "instance", c, n, s, k] = stack[:, k - 1, :]
                                sets[m, "instance", c, n, s, k] = int(min(o.sets[k - 1] for o in mine))
                            confusions.append(ConfusionMatrix(m, "instance", c, n, s, names[:n],
                                                              sum(o.confusion for o in mine)[np.ix_(back, back)]))
                            if s:
                                kept[f"{m}/instance/{n}"] = float(np.mean([o.kept for o in mine]))
            timings["instance_recognition"] = time.perf_counter() - t0

    cells = tuple(Cell(*key, **dataclasses.asdict(stats.summarize(R, settings.seed)),
                       touch_sets=sets.get(key, 0)) for key, R in rates.items())
    comparisons = []
    if len(methods) > 1:
        for key, R in rates.items():
            # A model method as the baseline has no paper-protocol rates to compare with.
            if key[0] != baseline and (baseline,) + key[1:] in rates:
                d = stats.paired_difference(R, rates[(baseline,) + key[1:]], settings.seed)
                comparisons.append(Comparison(key[0], baseline, *key[1:], d.mean, d.ci_low, d.ci_high, d.p_value,
                                              d.replicates))
    timings["total"] = time.perf_counter() - started
    run_settings = {
        "objects": list(names), "methods": list(methods), "protocols": list(protocols),
        "classifiers": list(classifiers), "baseline": baseline if len(methods) > 1 else None,
        "replicates": replicates, "folds": folds, "repeats": repeats, "threshold": threshold,
        "touch_sets_per_object": touch_sets_per_object, "features": features, "n_points": settings.n_points,
        "size_mm": settings.size_mm, "view_size": settings.view_size, "sensor": repr(settings.sensor),
        "perturbation": repr(settings.perturbation), "train_instances": settings.train_instances,
        "train_sessions": settings.train_sessions, "scale_spread": settings.scale_spread,
        "hue_deg": settings.hue_deg, "brightness_spread": settings.brightness_spread, "seed": settings.seed,
        "classifier_params": {c: {k: repr(v) for k, v in make(c, **params.get(c, {})).get_params().items()}
                              for c in classifiers},
        "libraries": cache_mod.library_versions(),
        "cache_dir": None if cache_dir is None else str(cache_dir),
        "learned_channel_weights": [m.channel_weights for m in models],
    }
    result = ExperimentResult(cells, tuple(comparisons), tuple(confusions), names, object_sets, classifiers,
                              run_settings, kept, timings, rates)
    if out_dir is not None:
        write_outputs(result, out_dir)
        for r, model in enumerate(models):
            model.save(Path(out_dir) / "touch_models" / f"replicate_{r:02d}.json")
    return result


def instance_stage(nominal, names, methods, settings, replicates, pool, cache_dir, threads, quiet):
    """Every instance's points and imprints for every method, and each replicate's touch model.

    One task per instance computes all methods that need no model, sharing
    its rendering, plus its touch survey when a model method is asked for;
    then each replicate's model is fitted on its training instances'
    surveys; then the model methods run on every instance.

    Parameters
    ----------
    nominal, names : the objects' nominal meshes and names (:func:`load_objects`)
    methods : point methods
    settings : classify.experiment.samples.Settings
    replicates : int
    pool : executor with ``map`` (``classify.runtime.cluster``)
    cache_dir : str, Path or None
    threads : rendering and attention threads per task (None: the CPU count); changes nothing
    quiet : bool, no progress bars

    Returns
    -------
    samples : dict (replicate, method, object index, instance index) -> sample (``dataset.instance_samples``)
    models : list of meshsal.points.learned.TouchModel, one per replicate ([] without a model method)
    """
    plain = [m for m in methods if m not in MODEL_METHODS]
    learned = [m for m in methods if m in MODEL_METHODS]
    keys = [(r, i, j) for r in range(replicates) for i in range(len(names))
            for j in range(settings.train_instances + 1)]
    done = progress(pool.map(_instance_samples_task, [(nominal[i], names[i], plain, settings, r, j, bool(learned),
                                                       cache_dir, threads, None, None) for r, i, j in keys]),
                    total=len(keys), desc="instances: points+imprints", quiet=quiet)
    samples, surveys = {}, {}
    for (r, i, j), out in zip(keys, done):
        for m in plain:
            samples[r, m, i, j] = out[m]
        if learned:
            surveys[r, i, j] = out["survey"]
    if not learned:
        return samples, []
    models = list(progress(pool.map(_model_task, [{(names[i], j): surveys[r, i, j] for q, i, j in keys if q == r}
                                                  for r in range(replicates)]),
                           total=replicates, desc="instances: touch models", quiet=quiet))
    done = progress(pool.map(_instance_samples_task, [(nominal[i], names[i], learned, settings, r, j, False,
                                                       cache_dir, threads, models[r], surveys[r, i, j])
                                                      for r, i, j in keys]),
                    total=len(keys), desc="instances: learned points+imprints", quiet=quiet)
    for (r, i, j), out in zip(keys, done):
        for m in learned:
            samples[r, m, i, j] = out[m]
    return samples, models


def _by_name(names) -> np.ndarray:
    """Object positions sorted by name: recognition sees every object set in one order, whatever was given."""
    return np.array(sorted(range(len(names)), key=lambda i: names[i]), dtype=np.int64)


def _paper_protocol(method, X, y, groups, names, classifiers, params, threshold, folds, repeats, seed, features,
                    pool, cache_dir, quiet, into, order):
    """The paper protocol on one pool of imprints; its rates, confusions and kept fractions go ``into``.

    Label c of the pool is object ``order[c]`` of ``names``; what goes ``into`` follows the order of ``names``.
    """
    rates, confusions, kept = into
    n = len(names)
    back = np.argsort(order)
    splits = paper_splits(y, groups, folds, repeats, seed)
    jobs = [(c, s, r) for c in classifiers for s in (False, True) for r in range(repeats)]
    tasks = [(X, y, groups, [x for x in splits if x.repeat == r], c, s, params, threshold, n, features)
             for c, s, r in jobs]
    key = _recognition_key("paper", (X, y, groups), [folds, repeats, seed, threshold, params, jobs, features])
    outcomes = _run_jobs(cache_dir, key, PaperOutcome, _paper_task, tasks, pool, f"paper: {method}, {n} objects",
                         quiet)
    for c in classifiers:
        for s in (False, True):
            mine = [o for (cj, sj, _), o in zip(jobs, outcomes) if (cj, sj) == (c, s)]
            rates[method, "paper", c, n, s, 1] = np.stack([o.rates for o in mine])[:, back]
            confusions.append(ConfusionMatrix(method, "paper", c, n, s, tuple(names),
                                              sum(o.confusion for o in mine)[np.ix_(back, back)]))
            if s:
                kept[f"{method}/paper/{n}"] = float(np.mean([o.kept for o in mine]))


def _instance_data(samples, r, m, order, names, settings) -> InstanceData:
    """Replicate r's imprints of the objects ``order`` (label c is object ``order[c]``)."""
    X, y, inst, point = [], [], [], []
    for c, i in enumerate(order):
        for j in range(1, settings.train_instances + 1):
            imprints = samples[r, m, i, j]["imprints"]                          # (sessions, k, rows, cols)
            sessions, k = imprints.shape[:2]
            X.append(imprints.reshape(-1, *imprints.shape[2:]))
            y.append(np.full(sessions * k, c))
            inst.append(np.full(sessions * k, j))
            point.append(np.tile(np.arange(k), sessions))
    test = tuple(samples[r, m, i, 0]["imprints"][0] for i in order)
    return InstanceData(np.concatenate(X), np.concatenate(y).astype(np.int64), np.concatenate(inst).astype(np.int64),
                        np.concatenate(point).astype(np.int64), test, tuple(names[i] for i in order))


def run_real(imprint_set, folds=5, repeats=10, seed=0, classifiers=NAMES, threshold=0.85, params=None,
             features="raw", out_dir=None, quiet=False, n_jobs=2) -> ExperimentResult:
    """Recognition on a measured ``tactile.ImprintSet``, in the paper's Table 2 layout.

    The paper protocol over the set's imprints, folds grouped by (object,
    point) so repeated presses of one point never sit on both sides, for
    the first ``min(4, n)`` objects (by label) and all ``n``.
    ``imprint_set`` is an ``ImprintSet`` or the path of one saved with
    ``ImprintSet.save``.
    """
    import tactile

    started = time.perf_counter()
    if not isinstance(imprint_set, tactile.ImprintSet):
        imprint_set = tactile.ImprintSet.load(imprint_set)
    X = np.asarray(imprint_set.imprints, np.float32)
    y = np.asarray(imprint_set.labels, np.int64)
    groups = y * 100000 + np.asarray(imprint_set.point_ids, np.int64)
    names = tuple(imprint_set.object_names)
    if len(np.unique(y)) < 2:
        raise ValueError(f"{imprint_set.source or 'imprint set'}: recognition needs imprints of at least "
                         f"two objects, found {len(np.unique(y))}")
    n_all = len(names)
    object_sets = tuple(sorted({min(4, n_all), n_all}))
    params = dict(params or {})
    rates, confusions, kept = {}, [], {}
    with threadpool_limits(1), worker_pool(n_jobs) as pool:
        for n in object_sets:
            mask = y < n
            _paper_protocol("real", X[mask], y[mask], groups[mask], names[:n], classifiers, params, threshold, folds,
                            repeats, seed, features, pool, None, quiet, (rates, confusions, kept), np.arange(n))
    cells = tuple(Cell(*key, **dataclasses.asdict(stats.summarize(R, seed))) for key, R in rates.items())
    settings = {"real": str(imprint_set.source), "n_imprints": int(len(y)), "folds": folds, "repeats": repeats,
                "seed": seed, "threshold": threshold, "classifiers": list(classifiers), "features": features,
                "sensor": repr(imprint_set.sensor)}
    result = ExperimentResult(cells, (), tuple(confusions), names, object_sets, tuple(classifiers), settings, kept,
                              {"total": time.perf_counter() - started}, rates)
    if out_dir is not None:
        write_outputs(result, out_dir)
    return result

