"""The place-aware recognizer in the experiment: every fixed plan and every touch policy, one job per replicate.

In each replicate the recognizer (``classify.recognizers.place.PlaceAware``,
``--classifiers place``) is fitted once on the training instances' touch
codebooks at their candidate places, its bandwidth, mixture and temperature
chosen by leaving training instances out (``classify.policies.fit_place_knowledge``).
Then, with the same fitted model:

* every **fixed plan** (each of ``--methods``) adds the codebooks of its own
  points on the training instances to the banks, locates the points it
  touches on the test instance as the knowledge locates any touch
  (``classify.policies.PlaceKnowledge``), and fuses the touches' place-aware posteriors
  over the same touch sets, tie breaks and stopping rule as the place-free
  recognizers (``classify.experiment.protocols.plan_outcome``);
* every **touch policy** runs its episodes with the place-aware belief and
  the forecast from the codebooks (``classify.experiment.sequential.run_policies``).

Rows of ``results.csv`` carry the classifier ``place``: the fixed plans under
the protocol ``instance``, the policies under ``sequential``.
"""

from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from classify.experiment.config import ExperimentConfig
from classify.experiment.controls import shuffled_imprints, shuffled_places
from classify.experiment.protocols import plan_outcome
from classify.experiment.sequential import policy_measurement, run_policies
from classify.experiment.stages import (
    InstanceStage,
    Measurement,
    ObjectSet,
    Runtime,
    SampleKey,
    recognition_key,
    run_jobs,
)
from classify.policies import fit_place_knowledge, place_touches
from classify.reporting.confusion import ConfusionMatrix, reordered_pairs, summed_pairs

__all__ = ["PlaceJob", "PlaceOutcome", "place_job", "place_jobs", "place_recognition"]


@dataclass(frozen=True, eq=False)
class PlaceJob:
    """One replicate of the place-aware recognizer on one object set: every fixed plan and every policy.

    Attributes
    ----------
    training : dict (object name, instance) -> classify.policies.PlaceSample (packed, or stored on disk:
        ``classify.experiment.spill``) with its codebook, training
        instances
    plans : dict method -> dict (object name, instance) -> TouchSample with its codebook, training instances
    tests : tuple of PlaceSample (packed or stored), the test instances in the order of ``names``
    test_plans : dict method -> tuple of TouchSample, the test instances' plans in the order of ``names``
    names : tuple of str, the objects sorted by name (the classes)
    methods, policies : tuple of str
    touches : int, touches per plan and episode at most
    sets_per_k : int, touch sets per test instance and k
    min_spacing : float, no policy's touch closer than this to an earlier one (mm)
    seed, replicate : int
    stop_levels : tuple of float
    params : dict, classifier parameters (``params["place"]`` for the recognizer)
    """

    training: dict
    plans: dict
    tests: tuple
    test_plans: dict
    names: tuple
    methods: tuple
    policies: tuple
    touches: int
    sets_per_k: int
    min_spacing: float
    seed: int
    replicate: int
    stop_levels: tuple = ()
    params: dict = None


@dataclass(frozen=True)
class PlaceOutcome:
    """A :class:`PlaceJob`'s results.

    ``plan_*``: per method, as :class:`~classify.experiment.protocols.InstanceOutcome`
    (rates (M, K, n), sets (M, K), stop_correct and stop_touches (M, L, n));
    ``plan_confusion`` (k, 4) int64 rows (method, true, predicted, count), each
    method's confusion pairs (:func:`classify.reporting.confusion.confusion_pairs`); ``policy_*``: per policy, as
    :class:`~classify.experiment.sequential.PolicyOutcome`; ``fitted`` the
    recognizer's bandwidth, mixture and temperature.
    """

    plan_rates: np.ndarray
    plan_sets: np.ndarray
    plan_confusion: np.ndarray
    plan_stop_correct: np.ndarray
    plan_stop_touches: np.ndarray
    policy_rates: np.ndarray
    policy_stop_correct: np.ndarray
    policy_stop_touches: np.ndarray
    policy_touched: np.ndarray
    policy_choice_s: np.ndarray
    fitted: np.ndarray


def place_job(job: PlaceJob) -> PlaceOutcome:
    """Fit the place-aware recognizer on the training codebooks, then recognize every plan and run every policy."""
    n, K, L = len(job.names), job.touches, len(job.stop_levels)
    with threadpool_limits(1):
        # Packed training places unpack one at a time, as the knowledge reads them; the tests, read at every
        # touch, unpack once, after the fit (whose peak they would add to).
        knowledge = fit_place_knowledge(job.training, job.params)
        tests = tuple(t.unpacked() for t in job.tests)
        plans = [_plan_outcome(job, m, knowledge, tests) for m in job.methods]
        if job.policies:
            policy = run_policies(
                knowledge,
                tests,
                job.names,
                job.policies,
                K,
                job.min_spacing,
                job.seed,
                job.replicate,
                job.stop_levels,
            )
            policy_arrays = [policy.rates, policy.stop_correct, policy.stop_touches, policy.touched, policy.choice_s]
        else:
            Q = 0
            policy_arrays = [np.zeros((Q, K, n)), np.zeros((Q, L, n)), np.zeros((Q, L, n)), np.zeros((Q, n, K)), []]
    model = knowledge.model
    return PlaceOutcome(
        np.stack([o.rates for o in plans]).reshape(len(plans), K, n),
        np.stack([o.sets for o in plans]).reshape(len(plans), K),
        np.concatenate([np.column_stack([np.full(len(o.confusion), q), o.confusion]) for q, o in enumerate(plans)])
        .reshape(-1, 4)
        .astype(np.int64),
        np.stack([o.stop_correct for o in plans]).reshape(len(plans), L, n),
        np.stack([o.stop_touches for o in plans]).reshape(len(plans), L, n),
        *(np.asarray(a, np.float64) for a in policy_arrays),
        np.array([model.bandwidth_, model.mixture_, model.temperature_]),
    )


def _plan_outcome(job: PlaceJob, method: str, knowledge, tests: tuple):
    """The fixed plan ``method`` recognized by ``knowledge`` with the plan's training points added to its banks.

    The added banks are a copy of the knowledge's; they go when this returns, so one copy at a time lies beside
    the knowledge's own (a thousand objects' banks are hundreds of megabytes).
    """
    X, y, sig, inst, keys = place_touches(job.training, job.names, points=job.plans[method])
    model = knowledge.model.with_places(X, y, signatures=sig, instances=inst, places=keys)
    located = dataclasses.replace(knowledge, model=model)
    proba = [
        located.posterior_at(plan.imprints[0], plan.positions, test.places)
        for plan, test in zip(job.test_plans[method], tests)
    ]
    return plan_outcome(proba, job.names, job.touches, job.sets_per_k, job.seed, job.replicate, job.stop_levels)


def place_jobs(stage: InstanceStage, objects: ObjectSet, n: int, config: ExperimentConfig) -> list:
    """One :class:`PlaceJob` per replicate of the stage, for the first ``n`` objects (with ``config.control`` applied)."""
    settings = config.settings
    order = objects.by_name(n)
    names = tuple(objects.names[i] for i in order)
    jobs = []
    for r in stage.replicates:
        train = [(objects.names[i], i, j) for i in order for j in range(1, settings.train_instances + 1)]
        tests = tuple(stage.places[r, i, 0] for i in order)
        test_plans = {m: tuple(stage.samples[SampleKey(r, m, i, 0)] for i in order) for m in config.methods}
        if config.control is not None:
            tests = shuffled_places(tuple(t.unpacked() for t in tests), names, settings.seed, r, config.control)
            test_plans = {
                m: tuple(
                    dataclasses.replace(t, imprints=imprints[None])
                    for t, imprints in zip(
                        plans,
                        shuffled_imprints(tuple(t.imprints[0] for t in plans), names, settings.seed, r, config.control),
                    )
                )
                for m, plans in test_plans.items()
            }
        jobs.append(
            PlaceJob(
                {(name, j): stage.places[r, i, j] for name, i, j in train},
                {m: {(name, j): stage.samples[SampleKey(r, m, i, j)] for name, i, j in train} for m in config.methods},
                tests,
                test_plans,
                names,
                tuple(config.methods),
                tuple(config.policies),
                settings.n_points,
                config.touch_sets_per_object,
                0.5 * settings.sensor.width_mm,
                settings.seed,
                r,
                config.stop_levels,
                config.params,
            )
        )
    return jobs


def _arrays(job: PlaceJob):
    """Every array a job's outcome depends on, for its cache key, one at a time (packed places unpack to give
    theirs)."""
    plans = [s for m in job.methods for s in (*job.plans[m].values(), *job.test_plans[m])]
    # Places read one at a time: a stored sample reads its file on each use.
    for sample in itertools.chain((s.in_memory() for s in (*job.training.values(), *job.tests)), plans):
        yield from sample.to_arrays().values()
        if sample.codebook is not None:
            yield sample.codebook


def place_recognition(
    n: int, stage: InstanceStage, objects: ObjectSet, config: ExperimentConfig, runtime: Runtime
) -> list[Measurement]:
    """The place-aware recognizer on the first ``n`` objects: one :class:`Measurement` per method (protocol
    ``instance``) and per policy (protocol ``sequential``), classifier ``place``."""
    jobs = place_jobs(stage, objects, n, config)
    back = np.argsort(objects.by_name(n))
    names = objects.names[:n]
    key = recognition_key(
        "place",
        (a for job in jobs for a in _arrays(job)),
        [
            config.settings.key(),
            config.settings.codebook_draws,
            config.params.get("place", {}),
            list(config.methods),
            list(config.policies),
            config.touch_sets_per_object,
            config.stop_levels,
            config.control,
            list(stage.replicates),
        ],
    )
    outcomes = run_jobs(runtime, key, PlaceOutcome, place_job, jobs, f"place-aware, {n} objects")
    out = []
    for q, method in enumerate(config.methods):
        stack = np.stack([o.plan_rates[q] for o in outcomes])[:, :, back]  # (replicates, k, objects)
        K = stack.shape[1]
        confusion = reordered_pairs(
            summed_pairs(o.plan_confusion[o.plan_confusion[:, 0] == q, 1:] for o in outcomes), back
        )
        stopping = (
            np.stack([o.plan_stop_correct[q] for o in outcomes])[:, :, back],
            np.stack([o.plan_stop_touches[q] for o in outcomes])[:, :, back],
        )
        out.append(
            Measurement(
                method,
                "instance",
                "place",
                n,
                False,
                {k: stack[:, k - 1, :] for k in range(1, K + 1)},
                {k: int(min(o.plan_sets[q, k - 1] for o in outcomes)) for k in range(1, K + 1)},
                ConfusionMatrix(method, "instance", "place", n, False, tuple(names), confusion),
                None,
                stopping,
            )
        )
    for q, policy in enumerate(config.policies):
        out.append(
            policy_measurement(
                policy,
                "place",
                n,
                [o.policy_rates[q] for o in outcomes],
                [o.policy_stop_correct[q] for o in outcomes],
                [o.policy_stop_touches[q] for o in outcomes],
                back,
            )
        )
    return out
