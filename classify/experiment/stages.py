"""The stages of the experiment, each a function from frozen records to frozen records.

objects (:class:`ObjectSet`, :func:`load_objects`) -> samples per method and
instance (:func:`paper_stage`, :func:`instance_stage`, with each replicate's
touch model) -> recognition (:func:`paper_recognition`,
:func:`instance_recognition`) -> :class:`Measurement` records, which
:mod:`classify.experiment.run` turns into cells, comparisons and files.
Work runs through :class:`Runtime`'s pool (local processes or a Dask
cluster); every stage reads and writes the content-keyed cache.
"""

from __future__ import annotations

import dataclasses
import functools
import warnings
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from threadpoolctl import threadpool_limits

from classify.experiment.config import ExperimentConfig, Settings
from classify.experiment.controls import shuffled_imprints
from classify.experiment.protocols import (
    InstanceData,
    InstanceJob,
    InstanceOutcome,
    PaperJob,
    PaperOutcome,
    Recognizer,
    instance_job,
    paper_job,
    paper_splits,
    point_groups,
)
from classify.experiment.samples import (
    PaperSampleTask,
    SampleTask,
    TouchSample,
    instance_samples,
    nominal_mesh,
    paper_sample,
)
from classify.experiment.spill import stored
from classify.experiment.survey import fit_replicate_model
from classify.reporting.confusion import ConfusionMatrix, reordered_pairs, summed_pairs
from classify.runtime import cache as cache_mod
from meshsal.points import MODEL_METHODS
from meshsal.util.errors import naming
from meshsal.util.progress import progress

__all__ = [
    "ObjectSet",
    "load_objects",
    "Runtime",
    "SampleKey",
    "InstanceStage",
    "paper_stage",
    "instance_stage",
    "Measurement",
    "join_replicates",
    "paper_recognition",
    "instance_recognition",
    "run_jobs",
    "recognition_key",
]


@dataclass(frozen=True, eq=False)
class ObjectSet:
    """The objects of an experiment: distinct ``names`` and their ``nominal`` meshes, in the order given."""

    names: tuple
    nominal: tuple

    def __len__(self) -> int:
        return len(self.names)

    def by_name(self, n: int | None = None) -> np.ndarray:
        """Positions of the first ``n`` objects sorted by name: recognition sees every object set in one order."""
        names = self.names[:n]
        return np.array(sorted(range(len(names)), key=lambda i: names[i]), dtype=np.int64)


def load_objects(objects, settings: Settings, pool=None, skip_bad: bool = False) -> ObjectSet:
    """The objects' names and nominal meshes, all loaded before any work (a bad file stops here).

    ``objects``: None (the toys), strings for ``meshsal.objects.resolve_objects``
    (set names, object names, mesh files, folders, list files, comma-separated
    or not) or ``meshsal.Mesh`` objects with distinct names (repaired as the
    loader repairs files: ``meshsal.repair_mesh``).  With ``settings.size_mm``
    None the objects keep their real sizes (named objects only: the units of
    a file or an in-memory mesh are not known).  ``pool`` (local worker
    processes with this process's kernel pin, anything with an ordered
    ``map``) builds the toys, a second of CPU each, while this process loads
    the rest: the same meshes.

    Files with the same bytes are one object (a warning names both).  Files
    that do not load are all listed in one error before any work; with
    ``skip_bad`` they are listed in a warning instead and the run goes on
    without them.
    """
    import meshsal
    from meshsal import objects as objects_mod

    items = ["toys"] if objects is None else list(objects)
    meshes = [m for m in items if isinstance(m, meshsal.Mesh)]
    if meshes and len(meshes) != len(items):
        raise ValueError("objects must be all meshes or all names and paths, not a mix")
    units = [None] * len(meshes)
    if meshes:
        # Meshes built in memory did not pass the loader's repairs: they get them here.
        meshes = [_repaired(m) for m in meshes]
    else:
        refs, same = objects_mod.distinct_files(objects_mod.resolve_objects(items))
        if same:
            warnings.warn(
                "files with the same bytes are one object: "
                + ", ".join(f"{name} (= {first})" for name, first in same.items()),
                stacklevel=2,
            )
        built_elsewhere = [ref for ref in refs if ref.kind == "toy"] if pool is not None else []
        pending = pool.map(objects_mod.load_ref, built_elsewhere) if built_elsewhere else ()
        loaded, bad = {}, {}
        for ref in refs:
            if ref not in built_elsewhere:
                try:
                    loaded[ref.name] = objects_mod.load_ref(ref)
                except (ValueError, OSError) as exc:
                    bad[ref.name] = f"{exc}"
        loaded.update(zip((ref.name for ref in built_elsewhere), pending))
        if bad:
            listed = "; ".join(bad.values())
            if not skip_bad:
                raise ValueError(
                    f"{len(bad)} of {len(refs)} objects do not load (--skip-bad runs on the rest): {listed}"
                )
            warnings.warn(f"left out {len(bad)} of {len(refs)} objects that do not load: {listed}", stacklevel=2)
            refs = tuple(ref for ref in refs if ref.name not in bad)
        meshes = [loaded[ref.name] for ref in refs]
        units = [ref.units_mm for ref in refs]
    names = tuple(m.name for m in meshes)
    if any(not n for n in names) or len(set(names)) != len(names):
        raise ValueError(f"objects must have distinct, non-empty names, got {list(names)}")
    if len(meshes) < 2:
        raise ValueError(f"recognition needs at least two objects, got {len(meshes)}")
    return ObjectSet(names, tuple(nominal_mesh(m, settings, u) for m, u in zip(meshes, units)))


def check_landmarks(objects: ObjectSet) -> None:
    """Refuse, before any work, objects with fewer places a pad can press than the landmarks that locate a touch.

    The place-aware recognizer and the touch policies locate each place by its
    distances to an instance's first :data:`meshsal.points.places.LANDMARKS`
    candidate places (vertices with a normal); a mesh with fewer has no such
    signature.

    Raises
    ------
    ValueError
        Naming every such object and its count of places.
    """
    from meshsal.mesh.geometry import normal_defined
    from meshsal.points.places import LANDMARKS

    pressable = (np.count_nonzero(normal_defined(m.vertices, m.faces)) for m in objects.nominal)
    few = {name: int(k) for name, k in zip(objects.names, pressable) if k < LANDMARKS}
    if few:
        raise ValueError(
            f"the place-aware recognizer and the touch policies locate a touch by {LANDMARKS} landmarks, places a "
            "pad can press (vertices with a normal); "
            + ", ".join(f"{name} has {k}" for name, k in few.items())
            + ": give a finer mesh (subdivided), or leave out --classifiers place and --policies"
        )


def _repaired(mesh):
    from meshsal.mesh.io import MeshRepairWarning
    from meshsal.mesh.repair import repair_mesh

    fixed, report = repair_mesh(mesh)
    if report.noteworthy:
        warnings.warn(report.message(), MeshRepairWarning, stacklevel=3)
    return fixed


@dataclass(frozen=True)
class Runtime:
    """Where a stage's work runs and what it keeps.

    ``pool`` anything with an ordered ``map`` (``classify.runtime.cluster``);
    ``cache_dir`` the cache (None: none); ``threads`` rendering and attention
    threads per task (None: the CPU count; changes nothing); ``quiet`` no
    progress bars; ``label`` what every progress bar's description starts with
    (e.g. the block of replicates it works on); ``places_dir`` a folder this
    process and the pool's workers share, where the instances' places wait on
    disk for their jobs (``classify.experiment.spill``; None: in memory).
    """

    pool: object
    cache_dir: object = None
    threads: int | None = None
    quiet: bool = True
    label: str = ""
    places_dir: object = None

    def map(self, fn, tasks: list, desc: str):
        return list(progress(self.pool.map(fn, tasks), total=len(tasks), desc=self.label + desc, quiet=self.quiet))


class SampleKey(NamedTuple):
    """Where a :class:`~classify.experiment.samples.TouchSample` belongs: replicate, method, object, instance."""

    replicate: int
    method: str
    obj: int
    instance: int


@dataclass(frozen=True, eq=False)
class InstanceStage:
    """The instances of some replicates: every instance's sample for every method (by :class:`SampleKey`), each
    replicate's touch model (in the order of ``replicates``), and with touch policies every instance's places
    (``classify.policies.PlaceSample`` by (replicate, object, instance), packed: ``PlaceSample.packed``; with
    ``Runtime.places_dir``, ``classify.experiment.spill.StoredPlaceSample``)."""

    samples: dict
    models: tuple = ()
    places: dict = None
    replicates: tuple = ()


def _paper_sample(task: PaperSampleTask) -> TouchSample:
    with threadpool_limits(1), naming(task.name):
        return paper_sample(task)


def _instance_samples(task: SampleTask, folder=None):
    with threadpool_limits(1), naming(task.name):
        out = instance_samples(task)
    if out.places is None:
        return out
    # The block holds every instance's places until its last stage: packed, a third of the bytes, and with a
    # folder on disk (classify.experiment.spill), only their path.
    places = out.places.packed()
    return dataclasses.replace(out, places=places if folder is None else stored(places, folder))


def _fit_model(surveys: dict, view_size: int):
    with threadpool_limits(1):
        return fit_replicate_model(surveys, view_size=view_size)


def paper_stage(objects: ObjectSet, methods, settings: Settings, runtime: Runtime) -> dict:
    """Each object's paper-protocol sample per method: ``{(method, object index): TouchSample}``."""
    pairs = [(m, i) for m in methods for i in range(len(objects))]
    tasks = [
        PaperSampleTask(objects.nominal[i], objects.names[i], m, settings, runtime.cache_dir, runtime.threads)
        for m, i in pairs
    ]
    return dict(zip(pairs, runtime.map(_paper_sample, tasks, "paper: points+imprints")))


def instance_stage(
    objects: ObjectSet,
    methods,
    settings: Settings,
    replicates,
    runtime: Runtime,
    places: bool = False,
    codebook: bool = False,
) -> InstanceStage:
    """Every instance's points and imprints for every method, and each replicate's touch model.

    ``replicates``: how many (replicates 0 to n - 1), or which ones.  A
    replicate's instances, model and recognition depend on no other
    replicate, so a run may take its replicates a few at a time.

    One task per instance computes all methods that need no model, sharing
    its rendering, plus its touch survey when a model method is asked for,
    its places when ``places`` (touch policies, the place-aware recognizer)
    and, on a training instance, its touch codebooks when ``codebook`` (the
    place-aware recognizer); then each replicate's model is fitted on its
    training instances' surveys; then the model methods run on every
    instance (with their codebooks).
    """
    plain = tuple(m for m in methods if m not in MODEL_METHODS)
    learned = tuple(m for m in methods if m in MODEL_METHODS)
    replicates = (
        tuple(range(replicates)) if isinstance(replicates, int | np.integer) else tuple(int(r) for r in replicates)
    )
    where = [(r, i, j) for r in replicates for i in range(len(objects)) for j in range(settings.train_instances + 1)]

    def task(r, i, j, methods, **more):
        return SampleTask(
            objects.nominal[i],
            objects.names[i],
            methods,
            settings,
            r,
            j,
            cache_dir=runtime.cache_dir,
            threads=runtime.threads,
            **more,
        )

    done = runtime.map(
        functools.partial(_instance_samples, folder=runtime.places_dir if places else None),
        [task(r, i, j, plain, survey=bool(learned), places=places, codebook=codebook) for r, i, j in where],
        "instances: points+imprints",
    )
    samples = {SampleKey(r, m, i, j): out.by_method[m] for (r, i, j), out in zip(where, done) for m in plain}
    found = {(r, i, j): out.places for (r, i, j), out in zip(where, done)} if places else None
    if not learned:
        return InstanceStage(samples, (), found, replicates)
    surveys = {(r, i, j): out.survey for (r, i, j), out in zip(where, done)}
    models = runtime.map(
        functools.partial(_fit_model, view_size=settings.rendered_view_size),
        [{(objects.names[i], j): surveys[r, i, j] for q, i, j in where if q == r} for r in replicates],
        "instances: touch models",
    )
    model_of = dict(zip(replicates, models))
    done = runtime.map(
        _instance_samples,
        [task(r, i, j, learned, model=model_of[r], surveyed=surveys[r, i, j], codebook=codebook) for r, i, j in where],
        "instances: learned points+imprints",
    )
    samples.update({SampleKey(r, m, i, j): out.by_method[m] for (r, i, j), out in zip(where, done) for m in learned})
    return InstanceStage(samples, tuple(models), found, replicates)


@dataclass(frozen=True, eq=False)
class Measurement:
    """One method, protocol, object set, classifier and selection setting, measured.

    ``rates`` maps a number of touches to its (replicates or repeats,
    objects) rate matrix in percent, objects in the order given;
    ``touch_sets`` the fewest distinct touch sets any object offered at that
    many touches (0 for the paper protocol); ``confusion`` the single-touch
    counts; ``kept`` the fraction of training imprints selection kept, one
    per replicate or repeat (with selection only); ``stopping`` (correct,
    touches), each (replicates, levels, objects): the stopping rule at each of
    the config's ``stop_levels``, 100 where right at the stop and the touches
    used.
    """

    method: str
    protocol: str
    classifier: str
    n_objects: int
    selection: bool
    rates: dict
    touch_sets: dict
    confusion: ConfusionMatrix | None = None
    kept: tuple | None = None
    stopping: tuple | None = None


def join_replicates(blocks) -> list[Measurement]:
    """The measurements of blocks of replicates, joined: each as if all the replicates had been measured at once.

    Parameters
    ----------
    blocks : list of lists of Measurement
        One list per block of replicates, in replicate order; every block
        measured the same things in the same order.

    Returns
    -------
    list of Measurement
        Rates, stopping and selection's ``kept`` have the blocks' replicates
        one after the other, confusion counts are summed and touch sets are
        the fewest of any block: the same values, bit for bit, as one block of
        all the replicates gives.

    Raises
    ------
    ValueError
        If the blocks did not measure the same things.
    """
    blocks = [list(b) for b in blocks]
    if len(blocks) <= 1:
        return blocks[0] if blocks else []
    what = [[(m.method, m.protocol, m.classifier, m.n_objects, m.selection) for m in b] for b in blocks]
    if any(w != what[0] for w in what[1:]):
        raise ValueError("blocks of replicates measured different things; they cannot be joined")
    joined = []
    for ms in zip(*blocks):
        first = ms[0]
        touches = list(first.rates)
        rates = _as_measured([np.stack([m.rates[k] for k in touches], axis=1) for m in ms])
        confusion = first.confusion
        if confusion is not None:
            confusion = dataclasses.replace(confusion, pairs=summed_pairs(m.confusion.pairs for m in ms))
        joined.append(
            dataclasses.replace(
                first,
                rates={k: rates[:, t, :] for t, k in enumerate(touches)},
                touch_sets={k: min(m.touch_sets[k] for m in ms) for k in first.touch_sets},
                confusion=confusion,
                kept=None if first.kept is None else tuple(v for m in ms for v in m.kept),
                stopping=None
                if first.stopping is None
                else tuple(_as_measured([m.stopping[a] for m in ms]) for a in range(len(first.stopping))),
            )
        )
    return joined


def _as_measured(parts) -> np.ndarray:
    """(replicates, k, objects) arrays of consecutive replicates, joined in the memory layout a measurement's
    ``np.stack(...)[:, :, back]`` gives: numpy sums an array in an order that follows its layout, and the intervals
    are sums."""
    joined = np.concatenate(parts)
    return joined[:, :, np.arange(joined.shape[2])]


def _outcome_arrays(outcomes) -> dict:
    return {
        f"{i}/{f.name}": np.asarray(getattr(o, f.name)) for i, o in enumerate(outcomes) for f in dataclasses.fields(o)
    }


def _outcomes_from(arrays, cls, count):
    names = [f.name for f in dataclasses.fields(cls)]
    return [
        cls(**{n: (float(arrays[f"{i}/{n}"]) if n == "kept" else arrays[f"{i}/{n}"]) for n in names})
        for i in range(count)
    ]


def run_jobs(runtime: Runtime, key: str, cls, run, jobs: list, desc: str, outcomes=None) -> list:
    """``run(job)`` for every job, in order, through the cache (one entry for all of them).

    ``outcomes`` (given a job per several outcomes) turns the jobs' results into the list of outcomes.
    """
    spread = outcomes or (lambda done: done)
    found = cache_mod.cached(runtime.cache_dir, key, lambda: _outcome_arrays(spread(runtime.map(run, jobs, desc))))
    # Every outcome stores each of its fields.
    return _outcomes_from(found, cls, len(found) // len(dataclasses.fields(cls)))


def recognition_key(kind, arrays, parts):
    """The cache key of a recognition stage: its kind, the arrays (any iterable, read one at a time), the
    parts, the code and the libraries."""
    code = cache_mod.code_fingerprint("classify", "tactile")
    return cache_mod.cache_key(kind, cache_mod.hash_array_stream(arrays), parts, code, cache_mod.library_versions())


def _recognizers(config: ExperimentConfig):
    """Every (classifier, selection) of the place-free classifiers, in the order the tables list them (the
    place-aware recognizer has its own job: ``classify.experiment.place``)."""
    return [(c, s) for c in config.classifiers if c != "place" for s in (False, True)]


def paper_recognition(
    method: str, X, y, points, names, config: ExperimentConfig, runtime: Runtime, order=None
) -> list[Measurement]:
    """The paper protocol on one pool of imprints: one :class:`Measurement` per classifier and selection.

    Label c of the pool is object ``order[c]`` of ``names`` (default: the
    given order); the measurements follow the order of ``names``.
    """
    n = len(names)
    order = np.arange(n) if order is None else np.asarray(order)
    back = np.argsort(order)
    groups = point_groups(y, points)
    seed = config.settings.seed
    splits = paper_splits(y, groups, config.folds, config.repeats, seed, [names[order[c]] for c in np.unique(y)])
    jobs = [(c, s, r) for c, s in _recognizers(config) for r in range(config.repeats)]
    # One job per classifier and repeat, with and without selection: a fold selection leaves whole is fitted once.
    shared = [(c, r) for c in config.classifiers if c != "place" for r in range(config.repeats)]
    work = [
        PaperJob(
            X,
            y,
            groups,
            tuple(x for x in splits if x.repeat == r),
            tuple(Recognizer(c, s, config.params, config.threshold, config.features) for s in (False, True)),
            n,
        )
        for c, r in shared
    ]
    key = recognition_key(
        "paper",
        (X, y, groups),
        [config.folds, config.repeats, seed, config.threshold, config.params, jobs, config.features],
    )

    def in_job_order(done):
        by_job = {(c, s, r): o for (c, r), pair in zip(shared, done) for s, o in zip((False, True), pair)}
        return [by_job[j] for j in jobs]

    outcomes = run_jobs(runtime, key, PaperOutcome, paper_job, work, f"paper: {method}, {n} objects", in_job_order)
    out = []
    for c, s in _recognizers(config):
        mine = [o for (cj, sj, _), o in zip(jobs, outcomes) if (cj, sj) == (c, s)]
        confusion = ConfusionMatrix(
            method, "paper", c, n, s, tuple(names), reordered_pairs(summed_pairs(o.confusion for o in mine), back)
        )
        out.append(
            Measurement(
                method,
                "paper",
                c,
                n,
                s,
                {1: np.stack([o.rates for o in mine])[:, back]},
                {1: 0},
                confusion,
                tuple(o.kept for o in mine) if s else None,
            )
        )
    return out


def instance_data(
    stage: InstanceStage, replicate: int, method: str, objects: ObjectSet, order, settings: Settings, control=None
) -> InstanceData:
    """Replicate ``replicate``'s imprints of the objects ``order`` (label c is object ``order[c]``); with
    ``control`` (``classify.experiment.controls``), each test instance's imprints are another object's."""
    X, y, inst, point = [], [], [], []
    for c, i in enumerate(order):
        for j in range(1, settings.train_instances + 1):
            imprints = stage.samples[SampleKey(replicate, method, i, j)].imprints  # (sessions, k, rows, cols)
            sessions, k = imprints.shape[:2]
            X.append(imprints.reshape(-1, *imprints.shape[2:]))
            y.append(np.full(sessions * k, c))
            inst.append(np.full(sessions * k, j))
            point.append(np.tile(np.arange(k), sessions))
    test = tuple(stage.samples[SampleKey(replicate, method, i, 0)].imprints[0] for i in order)
    names = tuple(objects.names[i] for i in order)
    if control is not None:
        test = shuffled_imprints(test, names, settings.seed, replicate, control)
    return InstanceData(
        np.concatenate(X),
        np.concatenate(y).astype(np.int64),
        np.concatenate(inst).astype(np.int64),
        np.concatenate(point).astype(np.int64),
        test,
        names,
    )


def instance_recognition(
    method: str, n: int, stage: InstanceStage, objects: ObjectSet, config: ExperimentConfig, runtime: Runtime
) -> list[Measurement]:
    """The instance protocol for one method on the first ``n`` objects: one :class:`Measurement` per
    classifier and selection."""
    settings = config.settings
    names = objects.names[:n]
    order = objects.by_name(n)
    back = np.argsort(order)
    data = {r: instance_data(stage, r, method, objects, order, settings, config.control) for r in stage.replicates}
    jobs = [(r, c, s) for r in stage.replicates for c, s in _recognizers(config)]
    work = [
        InstanceJob(
            data[r],
            Recognizer(c, s, config.params, config.threshold, config.features),
            settings.n_points,
            config.touch_sets_per_object,
            settings.seed,
            r,
            config.stop_levels,
        )
        for r, c, s in jobs
    ]
    arrays = [a for d in data.values() for a in (d.train_X, d.train_y, d.train_instance, d.train_point, *d.test)]
    key = recognition_key(
        "instance",
        arrays,
        [
            settings.key(),
            config.threshold,
            config.params,
            jobs,
            config.touch_sets_per_object,
            sorted(names),
            config.features,
            config.stop_levels,
        ],
    )
    outcomes = run_jobs(runtime, key, InstanceOutcome, instance_job, work, f"instances: {method}, {n} objects")
    out = []
    for c, s in _recognizers(config):
        mine = [o for (_, cj, sj), o in zip(jobs, outcomes) if (cj, sj) == (c, s)]
        stack = np.stack([o.rates for o in mine])[:, :, back]  # (replicates, k, objects)
        rates = {k: stack[:, k - 1, :] for k in range(1, settings.n_points + 1)}
        sets = {k: int(min(o.sets[k - 1] for o in mine)) for k in range(1, settings.n_points + 1)}
        confusion = ConfusionMatrix(
            method, "instance", c, n, s, names, reordered_pairs(summed_pairs(o.confusion for o in mine), back)
        )
        stopping = (
            np.stack([o.stop_correct for o in mine])[:, :, back],
            np.stack([o.stop_touches for o in mine])[:, :, back],
        )
        out.append(
            Measurement(
                method,
                "instance",
                c,
                n,
                s,
                rates,
                sets,
                confusion,
                tuple(o.kept for o in mine) if s else None,
                stopping,
            )
        )
    return out
