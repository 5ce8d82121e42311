"""The sequential protocol: touch policies on the instance protocol's instances, touch by touch.

In each replicate the policies meet the very instances, devices and seeds
the fixed plans meet (:mod:`classify.experiment.samples`).  The training
instances are touched once at every candidate place (session 0, the same
device as the fixed plans' first session); the touch knowledge is fitted on
them (:func:`classify.policies.fit_knowledge`); then every policy touches
every object's test instance up to ``n_points`` times
(:func:`classify.policies.run_episode`), feeling what the test session's
device reads there.  The rate after k touches is the share of test
instances whose most probable object after the first k touches is right;
the stopping rule gives accuracy against touches used.  Rows of
``results.csv`` carry the protocol ``sequential`` and the policy's name as
the method.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from classify.experiment.config import ExperimentConfig
from classify.experiment.controls import shuffled_places
from classify.experiment.stages import InstanceStage, Measurement, ObjectSet, Runtime, recognition_key, run_jobs
from classify.experiment.streams import Stream, name_seed, recognition_rng
from classify.policies import POLICIES, Felt, decisions, episode_steps, fit_knowledge, run_episodes, stopping_curve
from classify.recognizers.touches import Recognizer

__all__ = ["PolicyJob", "PolicyOutcome", "policy_job", "run_policies", "policy_recognition", "policy_measurement"]

#: Episodes stepped together under a place-free knowledge: each round's touches are felt in one batch (one pass
#: over the training touches for this many), and few episodes' forecasts are held at once.
TOGETHER = 32


@dataclass(frozen=True, eq=False)
class PolicyJob:
    """One replicate of the sequential protocol for one classifier, every policy.

    Attributes
    ----------
    training : dict (object name, instance) -> classify.policies.PlaceSample, training instances only
    tests : tuple of PlaceSample (packed or stored), the test instances in the order of ``names``
    names : tuple of str, the objects sorted by name (the classes)
    recognizer : Recognizer
    policies : tuple of str, names in ``classify.policies.POLICIES``
    touches : int, touches per episode at most
    min_spacing : float, no touch closer than this to an earlier one (mm)
    seed, replicate : int, the streams of the episodes' draws
    stop_levels : tuple of float, the stopping rule's thresholds
    """

    training: dict
    tests: tuple
    names: tuple
    recognizer: Recognizer
    policies: tuple
    touches: int
    min_spacing: float
    seed: int
    replicate: int
    stop_levels: tuple = ()


@dataclass(frozen=True)
class PolicyOutcome:
    """Every policy of one :class:`PolicyJob`.

    ``rates`` (policies, touches, objects) 100 where the decision after k
    touches was right, else 0; ``stop_correct``, ``stop_touches`` (policies,
    levels, objects) the same at the stopping rule's stop and the touches it
    used; ``touched`` (policies, objects, touches) the vertices touched (-1
    after an episode that ran out of places); ``choice_s`` (policies,) the
    median seconds a choice took.
    """

    rates: np.ndarray
    stop_correct: np.ndarray
    stop_touches: np.ndarray
    touched: np.ndarray
    choice_s: np.ndarray


def policy_job(job: PolicyJob) -> PolicyOutcome:
    """Fit the touch knowledge on the training instances, then run every policy on every test instance."""
    with threadpool_limits(1):
        # Packed training places unpack one at a time, as the knowledge reads them.
        knowledge = fit_knowledge(job.training, job.recognizer)
        return run_policies(
            knowledge,
            tuple(s.unpacked() for s in job.tests),
            job.names,
            job.policies,
            job.touches,
            job.min_spacing,
            job.seed,
            job.replicate,
            job.stop_levels,
        )


def run_policies(
    knowledge,
    tests: tuple,
    names: tuple,
    policies: tuple,
    touches: int,
    min_spacing: float,
    seed: int,
    replicate: int,
    stop_levels: tuple,
) -> PolicyOutcome:
    """Every policy on every test instance (``tests`` in the order of ``names``), with ``knowledge``'s belief.

    The episodes' draws come from the streams of ``seed``, ``replicate``, the
    object's name and the policy's, never from the knowledge: every belief
    meets the same episodes.
    """
    n, K, L = len(names), touches, len(stop_levels)
    rates = np.zeros((len(policies), K, n))
    stop_correct, stop_touches = np.zeros((len(policies), L, n)), np.zeros((len(policies), L, n))
    touched = np.full((len(policies), n, K), -1, np.int64)
    choice_s = np.zeros(len(policies))
    felt = [Felt(knowledge, test.imprints[0], test.places) for test in tests]
    # A few episodes at a time in step, where their touches are felt in one batch; a place-aware knowledge's
    # episodes one at a time, since stepping together would only hold more of its (larger) forecasts at once.
    together = TOGETHER if getattr(knowledge, "place_free", False) else 1
    for q, name in enumerate(policies):
        seconds = []
        episodes = []
        for a in range(0, n, together):
            steps = [
                episode_steps(
                    POLICIES.get(name)(),
                    tests[c],
                    knowledge,
                    K,
                    min_spacing,
                    recognition_rng(seed, replicate, 0, names[c], Stream.EPISODE, name_seed(name)),
                )
                for c in range(a, min(a + together, n))
            ]
            episodes += run_episodes(steps, felt[a : a + together])
        for c, episode in enumerate(episodes):
            ties = recognition_rng(seed, replicate, 0, names[c], Stream.EPISODE_TIES)
            picks = decisions(episode.beliefs, ties)
            last = np.minimum(np.arange(K), len(picks) - 1)
            rates[q, :, c] = 100.0 * (picks[last] == c)
            ties = recognition_rng(seed, replicate, 0, names[c], Stream.EPISODE_TIES)
            right, used = stopping_curve([episode.beliefs], np.array([c]), stop_levels, [ties])
            stop_correct[q, :, c], stop_touches[q, :, c] = 100.0 * right[:, 0], used[:, 0]
            touched[q, c, : len(episode.vertex_ids)] = episode.vertex_ids
            seconds.extend(episode.choice_s)
        choice_s[q] = float(np.median(seconds)) if seconds else 0.0
    return PolicyOutcome(rates, stop_correct, stop_touches, touched, choice_s)


def policy_jobs(stage, objects, n: int, config: ExperimentConfig) -> list:
    """One :class:`PolicyJob` per replicate of the stage and classifier, for the first ``n`` objects."""
    settings = config.settings
    order = objects.by_name(n)
    names = tuple(objects.names[i] for i in order)
    jobs = []
    for r in stage.replicates:
        # The place-free knowledge reads imprints only: the codebooks (the place-aware recognizer's) stay behind.
        training = {
            (objects.names[i], j): stage.places[r, i, j].without_codebook()
            for i in order
            for j in range(1, settings.train_instances + 1)
        }
        tests = tuple(stage.places[r, i, 0] for i in order)
        if config.control is not None:
            tests = shuffled_places(tuple(t.unpacked() for t in tests), names, settings.seed, r, config.control)
        # The place-aware recognizer's policies run in its own job (classify.experiment.place).
        for c in (c for c in config.classifiers if c != "place"):
            jobs.append(
                PolicyJob(
                    training,
                    tests,
                    names,
                    Recognizer(c, False, config.params, config.threshold, config.features),
                    config.policies,
                    settings.n_points,
                    0.5 * settings.sensor.width_mm,
                    settings.seed,
                    r,
                    config.stop_levels,
                )
            )
    return jobs


def policy_recognition(
    n: int, stage: InstanceStage, objects: ObjectSet, config: ExperimentConfig, runtime: Runtime
) -> list[Measurement]:
    """The sequential protocol on the first ``n`` objects: one :class:`Measurement` per policy and classifier."""
    free = [c for c in config.classifiers if c != "place"]
    if not free:
        return []
    jobs = policy_jobs(stage, objects, n, config)
    back = np.argsort(objects.by_name(n))
    arrays = (
        a
        for job in jobs[:: len(free)]
        for sample in (*job.training.values(), *job.tests)
        for a in sample.to_arrays().values()
    )
    key = recognition_key(
        "sequential",
        arrays,
        [
            config.settings.key(),
            config.params,
            config.features,
            list(config.policies),
            free,
            config.stop_levels,
            list(stage.replicates),
            config.control,
        ],
    )
    outcomes = run_jobs(runtime, key, PolicyOutcome, policy_job, jobs, f"policies, {n} objects")
    out = []
    for q, policy in enumerate(config.policies):
        for c in free:
            mine = [o for job, o in zip(jobs, outcomes) if job.recognizer.classifier == c]
            out.append(
                policy_measurement(
                    policy,
                    c,
                    n,
                    [o.rates[q] for o in mine],
                    [o.stop_correct[q] for o in mine],
                    [o.stop_touches[q] for o in mine],
                    back,
                )
            )
    return out


def policy_measurement(policy: str, classifier: str, n: int, rates, stop_correct, stop_touches, back) -> Measurement:
    """One policy's :class:`Measurement` from its replicates' (k, objects) rates and (levels, objects) stops,
    objects by name (``back`` puts them back in the order given)."""
    stack = np.stack(rates)[:, :, back]  # (replicates, k, objects)
    K = stack.shape[1]
    stopping = (np.stack(stop_correct)[:, :, back], np.stack(stop_touches)[:, :, back])
    return Measurement(
        policy,
        "sequential",
        classifier,
        n,
        False,
        {k: stack[:, k - 1, :] for k in range(1, K + 1)},
        dict.fromkeys(range(1, K + 1), 1),
        None,
        None,
        stopping,
    )
