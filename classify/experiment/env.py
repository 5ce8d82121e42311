"""Touch by touch as a Gymnasium environment: touch a test instance place by place, then name the object.

:class:`TouchEnv` is the sequential protocol (:mod:`classify.experiment.sequential`)
behind Gymnasium's standard API, so that a policy of one's own (learned by
reinforcement or written by hand) meets ours on the same instances,
devices and touch knowledge.

The training side is built once, at construction: the objects' training
instances (instances 1..``train_instances`` of replicate 0, as in the
instance protocol), touched once at every candidate place with a codebook
of simulated touches there, and the touch knowledge fitted on them
(:func:`classify.policies.fit_knowledge`: by default the place-aware
recognizer, whose belief knows where each touch was taken).  Each
episode (:meth:`TouchEnv.reset`) draws an object uniformly and one of the
test instances: instance 0 (the instance protocol's test instance) of one of
``test_replicates``, an instance training never saw (a different pose, size,
paint and device).  Replicate 0's test instance is the one the sequential
protocol's replicate 0 touches, so with the same settings and recognizer
(``--classifiers place``) the env reproduces its episodes.

Observation (a ``spaces.Dict``, places padded to ``P_max = (POOL_FACTOR +
PEAK_FACTOR) * n_points`` candidates, ``k_max = n_points`` touches):

==============  ======================  =========================================================
key             shape, dtype            what
==============  ======================  =========================================================
``features``    (P_max, F) float32      what the 72 views see at each place (``meshsal.points.learned.FEATURES``)
``positions``   (P_max, 3) float32      each place in the instance's frame (mm), as vision finds it
``normals``     (P_max, 3) float32      unit outward normals
``valid``       (P_max,) int8           1 for a real place, 0 for padding
``available``   (P_max,) int8           1 where a touch may go next: touchable, untouched and at
                                        least half a pad from every touched place
``touched``     (P_max,) int16          0 untouched, else which touch (1, 2...) touched the place
``imprints``    (k_max, rows, cols)     what touch i felt (zeros for a touch not yet made, or one
                float32                 that touched nothing)
``belief``      (C,) float64            the single-touch posteriors of the touches so far multiplied
                                        and normalized, classes as ``names`` (uniform at first)
``touches``     Discrete(k_max + 1)     touches used so far
==============  ======================  =========================================================

It never holds the label, nor an imprint of a place not touched.

Actions (``Discrete(P_max + 1)``): a place index touches that place; ``P_max``
stops and answers the belief's most probable object (equal beliefs drawn
from the env's ``np_random``).  A place that is not available (padding,
untouchable, touched, or too near a touched one) costs a touch and feels
nothing.

Reward: ``-touch_cost`` for every touch, and at the answer ``1`` if it names
the object, else ``0``; so an episode's return is its correctness less the
cost of its touches.  The episode terminates at the answer, which is given
automatically after the ``k_max``-th touch or when no place is left; it is
never truncated.  ``info`` holds ``touches`` (and at reset ``replicate``, the
test instance), and only once the episode has ended ``object`` (the truth),
``answer`` and ``correct``.

The agent decides where to touch and when to stop, never what to answer:
the answer is the touch belief's, so vision (the places, their positions
and features) can guide the touches but cannot name the object.  Every
episode draws alike from the env's ``np_random`` whatever the agent does
(the object, the test instance, one tie break at the answer), so agents run
from the same seed meet the same episodes: their comparison is paired.

Our policies (``classify.policies.POLICIES``) run through the env with
:func:`run_policy`, which builds the :class:`~classify.policies.TouchState`
they see from the env's knowledge and the observation (:func:`touch_state`)::

    from classify import TouchEnv
    from classify.experiment.env import run_policy

    env = TouchEnv(["cow", "cup"])
    run = run_policy(env, "info_gain", episodes=10, seed=1)
    print(run.rewards.mean(), run.correct.mean(), run.touches.mean())

``gymnasium.make(ENV_ID, objects=[...])`` makes one too, once this module is
imported (``gymnasium.make("classify.experiment.env:visuotactile/Touch-v0")``
imports it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import gymnasium
import numpy as np
from gymnasium import spaces

from classify.experiment.config import FULL_REPLICATES, Settings
from classify.experiment.samples import SampleTask, instance_samples
from classify.experiment.stages import load_objects
from classify.policies import (
    POLICIES,
    Felt,
    Forecasts,
    TouchPolicy,
    TouchState,
    available_places,
    decisions,
    fit_knowledge,
    hypotheses,
    touched_belief,
)
from classify.recognizers.touches import Recognizer
from meshsal.points.places import PEAK_FACTOR, POOL_FACTOR

__all__ = ["ENV_ID", "TouchEnv", "PolicyRun", "touch_state", "run_policy"]

#: The env's Gymnasium id (``gymnasium.make(ENV_ID, objects=[...])``).
ENV_ID = "visuotactile/Touch-v0"


class TouchEnv(gymnasium.Env):
    """Touch a test instance place by place, then name the object; our touch knowledge behind the standard API.

    Parameters
    ----------
    objects : sequence
        Objects as ``visuotactile experiment --objects`` names them (set names
        such as ``"toys"``, object names, mesh files) or ``meshsal.Mesh``
        objects with distinct names; at least two.
    settings : Settings, optional
        Points (``n_points`` is ``k_max``, the candidates scale with it),
        sensor, perturbation, training instances, instance variation and the
        base seed of every instance and device (default ``Settings()``).
    classifier : str or Recognizer
        What the belief is made of: ``"place"`` (default), the place-aware
        likelihood of touch codebooks simulated on the training instances
        (``classify.recognizers.place``), or a place-free single-touch
        classifier (``classify.NAMES``) on roll-invariant polar descriptors,
        or a :class:`~classify.recognizers.touches.Recognizer`.
    touch_cost : float
        Reward lost per touch (>= 0), against 1 for a right answer.
    test_replicates : iterable of int
        The test instances episodes draw from: instance 0 of each of these
        replicates (default the 20 of a full run).  Train an agent on some
        and evaluate it on others.
    seed : int
        Seeds the episodes when the first ``reset`` is given no seed.
    cache_dir : path, None or "default"
        Where instances' places and imprints are kept (``classify.runtime.cache``;
        "default": :func:`~classify.runtime.cache.default_dir`, shared with
        ``visuotactile experiment``; None: nothing kept, every reset renders).

    Attributes
    ----------
    names : tuple of str
        The objects (classes), sorted.
    knowledge : classify.policies.PlaceKnowledge or classify.policies.TouchKnowledge
        Fitted on the training instances only.
    settings : Settings
    touch_cost : float
    test_replicates : tuple of int
    max_places, max_touches : int
        ``P_max`` and ``k_max``.
    min_spacing : float
        No touch nearer than this to an earlier one (half the pad, mm).
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        objects=("cow", "cup"),
        settings: Settings | None = None,
        classifier="place",
        touch_cost: float = 0.01,
        test_replicates=range(FULL_REPLICATES),
        seed: int = 0,
        cache_dir="default",
    ):
        from classify.recognizers.classifiers import CLASSIFIERS
        from classify.runtime import cache as cache_mod
        from meshsal.points.learned import FEATURES
        from meshsal.util.reproducible import warn_if_unpinned

        warn_if_unpinned("TouchEnv")
        self.settings = Settings() if settings is None else settings
        if not (math.isfinite(touch_cost) and touch_cost >= 0):
            raise ValueError(f"touch_cost must be finite and >= 0, got {touch_cost!r}")
        self.touch_cost = float(touch_cost)
        self.test_replicates = tuple(int(r) for r in test_replicates)
        if (
            not self.test_replicates
            or min(self.test_replicates) < 0
            or len(set(self.test_replicates)) != len(self.test_replicates)
        ):
            raise ValueError(
                f"test_replicates must be distinct replicates >= 0, at least one, got {list(self.test_replicates)}"
            )
        recognizer = (
            classifier
            if isinstance(classifier, Recognizer)
            else Recognizer(CLASSIFIERS.check((classifier,))[0], features="polar")
        )
        self._recognizer = recognizer
        self._first_seed = int(seed)
        self.cache_dir = cache_mod.default_dir() if cache_dir == "default" else cache_dir
        loaded = load_objects(objects, self.settings)
        order = loaded.by_name()
        self.names = tuple(loaded.names[i] for i in order)
        self._nominal = {loaded.names[i]: loaded.nominal[i] for i in order}
        n = self.settings.n_points
        training = {
            (name, j): self._place_sample(name, 0, j)
            for name in self.names
            for j in range(1, self.settings.train_instances + 1)
        }
        self.knowledge = fit_knowledge(training, recognizer)
        self.max_places, self.max_touches = (POOL_FACTOR + PEAK_FACTOR) * n, n
        self.min_spacing = 0.5 * self.settings.sensor.width_mm
        shape = next(iter(training.values())).imprints.shape[2:]
        # An instance is its nominal mesh turned about the origin and resized by at most 1 + scale_spread.
        reach = math.ceil(
            max(np.linalg.norm(m.vertices, axis=1).max() for m in self._nominal.values())
            * (1.0 + self.settings.scale_spread)
        )
        P, K, big = self.max_places, self.max_touches, np.finfo(np.float32).max
        self.observation_space = spaces.Dict(
            {
                "features": spaces.Box(0.0, big, (P, len(FEATURES)), np.float32),
                "positions": spaces.Box(-reach, reach, (P, 3), np.float32),
                "normals": spaces.Box(-1.0, 1.0, (P, 3), np.float32),
                "valid": spaces.MultiBinary(P),
                "available": spaces.MultiBinary(P),
                "touched": spaces.Box(0, K, (P,), np.int16),
                "imprints": spaces.Box(0.0, 1.0, (K, *shape), np.float32),
                "belief": spaces.Box(0.0, 1.0, (len(self.names),), np.float64),
                "touches": spaces.Discrete(K + 1),
            }
        )
        self.action_space = spaces.Discrete(P + 1)
        self._episode = None

    def _place_sample(self, name: str, replicate: int, index: int):
        task = SampleTask(
            self._nominal[name],
            name,
            (),
            self.settings,
            replicate,
            index,
            places=True,
            codebook=self._recognizer.classifier == "place",
            cache_dir=self.cache_dir,
        )
        return instance_samples(task).places

    @property
    def places(self):
        """The current test instance's :class:`~classify.policies.Places` (what vision gives of it)."""
        self._check_reset()
        return self._episode.sample.places

    @property
    def forecast(self):
        """``knowledge.forecast`` of the current test instance's places, under every object."""
        self._check_reset()
        return self._episode.forecasts.over(None)

    def _check_reset(self):
        if self._episode is None:
            raise gymnasium.error.ResetNeeded("TouchEnv: call reset() before step() or reading the episode")

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Draw an object and a test instance of it; the observation before the first touch.

        With ``seed`` None the episode continues the env's ``np_random`` (the
        first one is seeded by the env's ``seed``).  ``options`` is unused.
        """
        super().reset(seed=self._first_seed if seed is None and self._np_random is None else seed)
        truth = int(self.np_random.integers(len(self.names)))
        replicate = self.test_replicates[int(self.np_random.integers(len(self.test_replicates)))]
        sample = self._place_sample(self.names[truth], replicate, 0)
        if len(sample.places) > self.max_places:
            raise ValueError(
                f"TouchEnv: {self.names[truth]!r} replicate {replicate} offers {len(sample.places)} "
                f"places, more than the {self.max_places} the observation holds"
            )
        self._episode = _Episode(
            sample,
            Forecasts(self.knowledge, sample.places),
            Felt(self.knowledge, sample.imprints[0], sample.places),
            truth,
            replicate,
            np.full(len(self.names), 1.0 / len(self.names)),
        )
        return self._observation(), {"touches": 0, "replicate": replicate}

    def step(self, action):
        """Touch a place (``action < P_max``) or answer (``action == P_max``).

        Returns
        -------
        observation, reward, terminated, truncated (always False), info
        """
        self._check_reset()
        e = self._episode
        if e.over:
            raise RuntimeError("TouchEnv: the episode has ended; call reset()")
        if not self.action_space.contains(action):
            raise ValueError(f"TouchEnv: action {action!r} is not in {self.action_space}")
        action, reward = int(action), 0.0
        if action < self.max_places:
            reward -= self.touch_cost
            places = e.sample.places
            felt = action < len(places) and bool(available_places(places, e.touched, self.min_spacing)[action])
            e.steps.append(action if felt else -1)
            if felt:
                e.belief = touched_belief(e.belief, e.felt[action])
            e.over = len(e.steps) == self.max_touches or not available_places(places, e.touched, self.min_spacing).any()
        else:
            e.over = True
        info = {"touches": len(e.steps)}
        if e.over:
            answer = int(decisions(e.belief[None], self.np_random)[0])
            reward += float(answer == e.truth)
            info.update(object=self.names[e.truth], answer=self.names[answer], correct=answer == e.truth)
        return self._observation(), reward, e.over, False, info

    def _observation(self) -> dict:
        e, P = self._episode, self.max_places
        places = e.sample.places
        p = len(places)

        def padded(a, dtype):
            out = np.zeros((P, *np.shape(a)[1:]), dtype)
            out[:p] = a
            return out

        touched = np.zeros(P, np.int16)
        imprints = np.zeros(self.observation_space["imprints"].shape, np.float32)
        for i, place in enumerate(e.steps):
            if place >= 0:
                touched[place] = i + 1
                imprints[i] = e.sample.imprints[0, place]
        return {
            "features": padded(places.features, np.float32),
            "positions": padded(places.positions, np.float32),
            "normals": padded(places.normals, np.float32),
            "valid": padded(np.ones(p), np.int8),
            "available": padded(available_places(places, e.touched, self.min_spacing), np.int8),
            "touched": touched,
            "imprints": imprints,
            "belief": e.belief.copy(),
            "touches": np.int64(len(e.steps)),
        }


@dataclass(eq=False)
class _Episode:
    """What the env holds of the current episode; ``felt[p]`` (C,) the posterior a touch at place p would give,
    ``steps`` each touch's place (-1: it touched nothing)."""

    sample: object
    forecasts: object
    felt: object
    truth: int
    replicate: int
    belief: np.ndarray
    over: bool = False
    steps: list = field(default_factory=list)

    @property
    def touched(self) -> list:
        return [p for p in self.steps if p >= 0]


def touch_state(env, observation: dict) -> TouchState:
    """The :class:`~classify.policies.TouchState` a policy of ``classify.policies`` sees, from ``env``'s
    knowledge and places and an observation of it (the places touched, their imprints, the belief)."""
    env = env.unwrapped
    places = env.places
    p = len(places)
    touched = np.asarray(observation["touched"][:p], np.int64)
    order = np.flatnonzero(touched)
    order = order[np.argsort(touched[order], kind="stable")]
    belief = np.asarray(observation["belief"], np.float64)
    return TouchState(
        places,
        tuple(int(i) for i in order),
        np.asarray(observation["imprints"])[touched[order] - 1],
        belief,
        np.asarray(observation["available"][:p], bool),
        env._episode.forecasts,
        env.knowledge,
        hypotheses(belief, env.knowledge.hypotheses, np.random.default_rng([env._episode.replicate, order.size])),
    )


@dataclass(frozen=True, eq=False)
class PolicyRun:
    """Episodes of one policy through a :class:`TouchEnv`.

    ``rewards`` (E,) float64 returns; ``correct`` (E,) bool; ``touches``
    (E,) int64 touches used; ``objects`` (E,) str the truths; ``replicates``
    (E,) int64 the test instances; ``beliefs`` (E, C) float64 the belief at
    the answer; ``touched`` tuple of (k_e,) int64, each episode's places in
    order.
    """

    rewards: np.ndarray
    correct: np.ndarray
    touches: np.ndarray
    objects: np.ndarray
    replicates: np.ndarray
    beliefs: np.ndarray
    touched: tuple


def run_policy(env, policy, episodes: int, seed: int = 0, stop: float | None = None) -> PolicyRun:
    """Play ``episodes`` episodes of a touch policy through ``env``'s API.

    Parameters
    ----------
    env : TouchEnv, or a wrapper of one (``gymnasium.make``)
    policy : str or classify.policies.TouchPolicy
        A name in ``classify.policies.POLICIES`` (``random``, ``info_gain``...) or a policy.
    episodes : int
    seed : int
        The first reset's seed (then the env's draws continue) and, through
        another stream, the policy's own draws.
    stop : float, optional
        The stopping rule: answer as soon as, after a touch, the top belief
        reaches ``stop``; None touches until ``k_max`` or no place is left.

    Returns
    -------
    PolicyRun
    """
    policy = POLICIES.get(policy)() if isinstance(policy, str) else policy
    if not isinstance(policy, TouchPolicy):
        raise TypeError(f"policy must be a name in {POLICIES.names()} or a TouchPolicy, got {type(policy).__name__}")
    rng = np.random.default_rng([int(seed), 1])
    answer = env.action_space.n - 1
    rewards, correct, touches, objects, replicates, beliefs, touched = [], [], [], [], [], [], []
    for e in range(int(episodes)):
        observation, info = env.reset(seed=int(seed) if e == 0 else None)
        replicates.append(info["replicate"])
        total, over = 0.0, False
        while not over:
            if not observation["available"].any() or (
                stop is not None and observation["touches"] > 0 and observation["belief"].max() >= stop
            ):
                action = answer
            else:
                action = int(policy.choose(touch_state(env, observation), rng))
            observation, reward, over, _, info = env.step(action)
            total += reward
        state = touch_state(env, observation)
        rewards.append(total)
        correct.append(info["correct"])
        touches.append(info["touches"])
        objects.append(info["object"])
        beliefs.append(observation["belief"])
        touched.append(np.asarray(state.touched, np.int64))
    return PolicyRun(
        np.asarray(rewards, np.float64),
        np.asarray(correct, bool),
        np.asarray(touches, np.int64),
        np.asarray(objects, str),
        np.asarray(replicates, np.int64),
        np.asarray(beliefs, np.float64).reshape(-1, len(env.unwrapped.names)),
        tuple(touched),
    )


gymnasium.register(ENV_ID, entry_point="classify.experiment.env:TouchEnv")
