"""The recognition experiment behind the paper's Table 1, its real-data twin (Table 2), and beyond.

:func:`run_experiment` composes the stages of :mod:`classify.experiment.stages`:
objects -> each object's samples (paper protocol: the nominal mesh;
instance protocol: fresh instances, with each replicate's touch model) ->
recognition -> measurements, summarized here into rate cells with 95 %
two-way bootstrap intervals over replicates (or repeats) and objects, and
paired comparisons of every point method with the baseline method
(:mod:`classify.reporting.stats`).  Object sets: the first ``min(4, n)``
objects and all ``n`` (the toys are ordered cow, glasses, cup, hand, plane,
dromedary, so these are the paper's 4- and 6-object sets).
"""

from __future__ import annotations

import dataclasses
import tempfile
import time
from contextlib import nullcontext
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from classify.experiment.config import DEFAULT_REPLICATES, FULL_REPLICATES, ExperimentConfig, Settings
from classify.experiment.place import place_recognition
from classify.experiment.protocols import PROTOCOLS
from classify.experiment.sequential import policy_recognition
from classify.experiment.stages import (
    InstanceStage,
    ObjectSet,
    Runtime,
    check_landmarks,
    instance_recognition,
    instance_stage,
    join_replicates,
    load_objects,
    paper_recognition,
    paper_stage,
)
from classify.reporting import stats
from classify.reporting.results import (
    Cell,
    CellKey,
    Comparison,
    ExperimentResult,
    StoppingCell,
    format_tables,
    write_outputs,
)
from classify.runtime import cache as cache_mod
from classify.runtime.cluster import Inline, runs_pinned_here, shares_disk, worker_pool
from classify.runtime.usage import StageUsage, cpu_seconds, measured, resident_mb
from meshsal.points import METHODS, MODEL_METHODS
from meshsal.util.atomic import check_writable

__all__ = [
    "PROTOCOLS",
    "METHODS",
    "DEFAULT_REPLICATES",
    "FULL_REPLICATES",
    "REPLICATES_AT_ONCE",
    "ExperimentConfig",
    "Settings",
    "ObjectSet",
    "InstanceStage",
    "Runtime",
    "load_objects",
    "instance_stage",
    "run_experiment",
    "run_real",
    "format_tables",
    "write_outputs",
]

#: What a worker process of the experiment imports as it starts, while the objects load (``worker_pool``'s
#: ``preload``): the stages, scikit-learn, OpenCV, the mesh libraries (2-3 s).
WORKER_MODULES = (__name__, "meshsal.points", "meshsal.attention.rig", "meshsal.objects.instances", "tactile")


def _provenance() -> dict:
    """Where and when this run measured: its command line, the commit, the machine, the date (UTC)."""
    import datetime
    import shlex
    import sys

    from meshsal.util import pages

    return {
        "command": shlex.join(sys.argv),
        "commit": pages.commit(),
        "machine": pages.machine(),
        "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
    }


#: Replicates whose instances a run holds at once, by default: its memory is that of two replicates however many it
#: measures, and a block gives each of two workers a recognition job.
REPLICATES_AT_ONCE = 2


def _object_sets(n_all: int) -> tuple:
    return tuple(sorted({min(4, n_all), n_all}))


def _paper_measurements(objects: ObjectSet, methods, config: ExperimentConfig, runtime: Runtime) -> list:
    samples = paper_stage(objects, methods, config.settings, runtime)
    out = []
    for m in methods:
        for n in _object_sets(len(objects)):
            order = objects.by_name(n)
            imprints = [samples[m, i].imprints for i in order]
            X = np.concatenate(imprints)
            y = np.concatenate([np.full(len(a), c) for c, a in enumerate(imprints)])
            points = np.concatenate([np.arange(len(a)) for a in imprints])
            out += paper_recognition(m, X, y, points, objects.names[:n], config, runtime, order)
    return out


def _summarize(measurements: list, config: ExperimentConfig, names) -> dict:
    """The measured fields of an :class:`ExperimentResult`: cells, paired comparisons with the baseline,
    confusions, selection kept, stopping cells and the rate and stopping matrices.

    ``names`` are the objects in the order of the rate matrices' columns.  A
    touch policy (protocol "sequential") is compared with the baseline
    method's fixed plan (protocol "instance").
    """
    seed = config.settings.seed
    rates, sets, kept, stopping, stopping_rates = {}, {}, {}, [], {}
    for m in measurements:
        for k, R in m.rates.items():
            key = CellKey(m.method, m.protocol, m.classifier, m.n_objects, m.selection, k)
            rates[key], sets[key] = R, m.touch_sets[k]
        if m.kept is not None:
            kept[f"{m.method}/{m.protocol}/{m.n_objects}"] = float(np.mean(m.kept))
        if m.stopping is not None and not m.selection:
            correct, used = m.stopping
            stopping_rates[m.method, m.protocol, m.classifier, m.n_objects] = m.stopping
            for level_index, level in enumerate(config.stop_levels):
                who = names[: m.n_objects]
                a = stats.summarize(correct[:, level_index], seed, who)
                u = stats.summarize(used[:, level_index], seed, who)
                stopping.append(
                    StoppingCell(
                        m.method,
                        m.protocol,
                        m.classifier,
                        m.n_objects,
                        level,
                        a.mean,
                        a.ci_low,
                        a.ci_high,
                        u.mean,
                        u.ci_low,
                        u.ci_high,
                        a.replicates,
                    )
                )
    cells = tuple(
        Cell(*key, **dataclasses.asdict(stats.summarize(R, seed, names[: key.n_objects])), touch_sets=sets[key])
        for key, R in rates.items()
    )
    comparisons = []
    if len(config.methods) > 1 or config.policies:
        for key, R in rates.items():
            # A model method as the baseline has no paper-protocol rates to compare with.
            other = key._replace(
                method=config.baseline, protocol="instance" if key.protocol == "sequential" else key.protocol
            )
            if key != other and other in rates:
                d = stats.paired_difference(R, rates[other], seed, names[: key.n_objects])
                comparisons.append(
                    Comparison(
                        key.method, config.baseline, *key[1:], d.mean, d.ci_low, d.ci_high, d.p_value, d.replicates
                    )
                )
    confusions = tuple(m.confusion for m in measurements if m.confusion is not None)
    return {
        "cells": cells,
        "comparisons": tuple(comparisons),
        "confusions": confusions,
        "selection_kept": kept,
        "stopping": tuple(stopping),
        "rates": rates,
        "stopping_rates": stopping_rates,
    }


def _replicate_blocks(replicates: int, at_once: int) -> list[tuple]:
    """Replicates 0 to ``replicates - 1`` in consecutive blocks of at most ``at_once``.

    Examples
    --------
    >>> _replicate_blocks(5, 2)
    [(0, 1), (2, 3), (4,)]
    """
    return [tuple(range(a, min(a + at_once, replicates))) for a in range(0, replicates, at_once)]


def _report_block(block, replicates: int, elapsed: float) -> None:
    """A line on stderr as a block of replicates ends: the time so far and, at that pace, the time left."""
    import sys

    from meshsal.util.progress import duration

    done = block[-1] + 1
    left = f", about {duration(elapsed / done * (replicates - done))} left" if done < replicates else ""
    print(f"replicates 1-{done} of {replicates} measured in {duration(elapsed)}{left}", file=sys.stderr)


def _timed(usage: dict, name: str, work):
    """``work()``, its :class:`~classify.runtime.usage.StageUsage` added to ``usage[name]``."""
    out, cost = measured(work)
    usage[name] = usage[name] + cost if name in usage else cost
    return out


def _measure_block(objects: ObjectSet, config: ExperimentConfig, runtime: Runtime, block, usage) -> tuple:
    """A block of replicates measured under the instance protocol: (its touch models, its measurements).

    Its instances (:func:`instance_stage`) live only in this call, so the next block's take their place; with
    ``runtime.places_dir`` their places wait in a folder of the block, removed with it.
    """
    with tempfile.TemporaryDirectory(dir=runtime.places_dir) if runtime.places_dir else nullcontext() as folder:
        return _measure_in(objects, config, dataclasses.replace(runtime, places_dir=folder), block, usage)


def _measure_in(objects: ObjectSet, config: ExperimentConfig, runtime: Runtime, block, usage) -> tuple:
    place = "place" in config.classifiers
    sets = _object_sets(len(objects))
    stage = _timed(
        usage,
        "instance_points_and_imprints",
        lambda: instance_stage(
            objects,
            config.methods,
            config.settings,
            block,
            runtime,
            places=bool(config.policies) or place,
            codebook=place,
        ),
    )
    out = _timed(
        usage,
        "instance_recognition",
        lambda: [
            x for m in config.methods for n in sets for x in instance_recognition(m, n, stage, objects, config, runtime)
        ],
    )
    if config.policies:
        out += _timed(
            usage,
            "sequential",
            lambda: [x for n in sets for x in policy_recognition(n, stage, objects, config, runtime)],
        )
    if place:
        out += _timed(
            usage,
            "place",
            lambda: [x for n in sets for x in place_recognition(n, stage, objects, config, runtime)],
        )
    return stage.models, out


def run_experiment(
    objects=None,
    config: ExperimentConfig | None = None,
    *,
    executor=None,
    n_jobs: int = 2,
    cache_dir="default",
    out_dir=None,
    quiet: bool = False,
    skip_bad: bool = False,
    replicates_at_once: int = REPLICATES_AT_ONCE,
    **changes,
) -> ExperimentResult:
    """Interest points -> imprints -> recognition, under the paper and instance protocols.

    Parameters
    ----------
    objects : None (the six toys), names/paths (see :func:`load_objects`) or meshes
    config : ExperimentConfig, optional
        What to measure (default ``ExperimentConfig()``), changed by any
        ``**changes`` named as its fields (``methods=``, ``replicates=``,
        ``settings=``...).
    executor : optional
        Runs the per-object stage and the recognition jobs: anything with an
        ordered ``map``, e.g. from ``classify.runtime.cluster.open_executor``
        (a Dask cluster).  Default: a pool of ``n_jobs`` worker processes
        (``classify.runtime.cluster.worker_pool``); results do not depend on it.
    n_jobs : int
    cache_dir : path, None (no cache) or ``"default"`` (:func:`classify.runtime.cache.default_dir`)
    out_dir : path or None
        Where ``results.json``, ``results.csv``, ``confusion_<classifier>.png``,
        ``touches.png`` and, with a learned method, each replicate's touch
        model (``touch_models/replicate_<r>.json``) go (nothing written when None).
    quiet : bool
        No progress bars on stderr.
    skip_bad : bool
        Run on the objects that load when some do not (they are listed in a
        warning); by default they are listed in an error before any work.
    replicates_at_once : int
        The instance protocol's replicates are measured in blocks of this
        many, one block's instances in memory at a time (its samples, places
        and codebooks; the memory then grows with the objects, not with the
        replicates).  Results do not depend on it; each block's jobs give the
        workers one recognition job per replicate.

    Returns
    -------
    ExperimentResult

    Examples
    --------
    >>> r = run_experiment(["cow", "cup"], replicates=2, quiet=True)     # doctest: +SKIP
    >>> print(format_tables(r))                                          # doctest: +SKIP
    """
    from meshsal.util.reproducible import warn_if_unpinned

    started, cpu_started = time.perf_counter(), cpu_seconds()
    config = (config or ExperimentConfig()).replace(**changes).checked()
    if int(replicates_at_once) < 1:
        raise ValueError(f"replicates_at_once must be at least 1, got {replicates_at_once}")
    warn_if_unpinned("run_experiment")
    settings = config.settings
    if cache_dir == "default":
        cache_dir = cache_mod.default_dir()
    # A results or cache folder that cannot be written stops the run here, not after hours of work.
    for folder in (out_dir, cache_dir):
        if folder is not None:
            check_writable(folder, folder=True)
    # A touch model needs training instances: the paper protocol has none.
    paper_methods = [m for m in config.methods if m not in MODEL_METHODS]
    usage, measurements, models = {}, [], []
    workers = nullcontext(executor) if executor is not None else worker_pool(n_jobs, preload=WORKER_MODULES)
    # Workers with this process's kernel pin build the toys this process would.
    local = runs_pinned_here(executor)
    # The instances' places wait for their jobs on this machine's disk when the workers share it.
    on_disk = shares_disk(executor)
    places_dir = tempfile.TemporaryDirectory(prefix="visuotactile-places-") if on_disk else nullcontext()
    with threadpool_limits(1), workers as pool, places_dir as folder:
        # Local workers start while the objects load, and build the toys; a bad file still stops the run before any work.
        objects = load_objects(objects, settings, pool if local else None, skip_bad=skip_bad)
        if "instance" in config.protocols and ("place" in config.classifiers or config.policies):
            check_landmarks(objects)
        # Workers render with one thread each; alone, the stage renders with every core.
        runtime = Runtime(pool, cache_dir, None if isinstance(pool, Inline) else 1, quiet, places_dir=folder)
        if "paper" in config.protocols and paper_methods:
            measurements += _timed(usage, "paper", lambda: _paper_measurements(objects, paper_methods, config, runtime))
        if "instance" in config.protocols:
            blocks, instance_started = [], time.perf_counter()
            by_block = _replicate_blocks(config.replicates, int(replicates_at_once))
            for block in by_block:
                here = runtime
                if len(block) < config.replicates:
                    which = f"{block[0] + 1}-{block[-1] + 1}" if len(block) > 1 else f"{block[0] + 1}"
                    here = dataclasses.replace(runtime, label=f"replicates {which} of {config.replicates}: ")
                fitted, taken = _measure_block(objects, config, here, block, usage)
                models += fitted
                blocks.append(taken)
                if not quiet and len(by_block) > 1:
                    _report_block(block, config.replicates, time.perf_counter() - instance_started)
            measurements += join_replicates(blocks)

    summary = _summarize(measurements, config, objects.names)
    timings = {name: u.wall_s for name, u in usage.items()}
    timings["total"] = time.perf_counter() - started
    # CPU time of this process and of its finished local workers: what a busy machine does not inflate.
    timings["cpu_total"] = cpu_seconds() - cpu_started
    peak = max([u.peak_mb for u in usage.values()] + [resident_mb()])
    usage["total"] = StageUsage(timings["total"], timings["cpu_total"], peak)
    run_settings = {
        "objects": list(objects.names),
        **config.to_json(),
        "libraries": cache_mod.library_versions(),
        "cache_dir": None if cache_dir is None else str(cache_dir),
        "learned_channel_weights": [m.channel_weights for m in models],
        "provenance": _provenance(),
    }
    result = ExperimentResult(
        object_names=objects.names,
        object_sets=_object_sets(len(objects)),
        classifiers=config.classifiers,
        settings=run_settings,
        timings=timings,
        usage={name: dataclasses.asdict(u) for name, u in usage.items()},
        **summary,
    )
    if out_dir is not None:
        write_outputs(result, out_dir)
        for r, model in enumerate(models):
            model.save(Path(out_dir) / "touch_models" / f"replicate_{r:02d}.json")
    return result


def run_real(
    imprint_set,
    config: ExperimentConfig | None = None,
    *,
    out_dir=None,
    quiet: bool = False,
    n_jobs: int = 2,
    **changes,
) -> ExperimentResult:
    """Recognition on a measured ``tactile.ImprintSet``, in the paper's Table 2 layout.

    The paper protocol over the set's imprints, folds grouped by (object,
    point) so repeated presses of one point never sit on both sides, for
    the first ``min(4, n)`` objects (by label) and all ``n``; ``config``'s
    classifiers, folds, repeats, threshold, parameters, features and seed.
    ``imprint_set`` is an ``ImprintSet`` or the path of one saved with
    ``ImprintSet.save``.
    """
    import tactile

    started = time.perf_counter()
    config = (config or ExperimentConfig()).replace(**changes).checked()
    if out_dir is not None:
        check_writable(out_dir, folder=True)
    if not isinstance(imprint_set, tactile.ImprintSet):
        imprint_set = tactile.ImprintSet.load(imprint_set)
    X = np.asarray(imprint_set.imprints, np.float32)
    y = np.asarray(imprint_set.labels, np.int64)
    points = np.asarray(imprint_set.point_ids, np.int64)
    names = tuple(imprint_set.object_names)
    if len(np.unique(y)) < 2:
        raise ValueError(
            f"{imprint_set.source or 'imprint set'}: recognition needs imprints of at least "
            f"two objects, found {len(np.unique(y))}"
        )
    measurements = []
    with threadpool_limits(1), worker_pool(n_jobs) as pool:
        runtime = Runtime(pool, None, None, quiet)
        for n in _object_sets(len(names)):
            mask = y < n
            measurements += paper_recognition("real", X[mask], y[mask], points[mask], names[:n], config, runtime)
    summary = _summarize(measurements, config.replace(methods=("real",)), names)
    settings = {
        "real": str(imprint_set.source),
        "n_imprints": int(len(y)),
        "folds": config.folds,
        "repeats": config.repeats,
        "seed": config.settings.seed,
        "threshold": config.threshold,
        "classifiers": list(config.classifiers),
        "features": config.features,
        "sensor": repr(imprint_set.sensor),
    }
    result = ExperimentResult(
        object_names=names,
        object_sets=_object_sets(len(names)),
        classifiers=config.classifiers,
        settings=settings,
        timings={"total": time.perf_counter() - started},
        **summary,
    )
    if out_dir is not None:
        write_outputs(result, out_dir)
    return result
