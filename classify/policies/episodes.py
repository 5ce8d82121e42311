"""Episodes: a policy touches a test instance, touch by touch; what it decided, and when it could have stopped.

The runner (:func:`run_episode`) holds the test instance's imprints at every
place and the label; the policy sees only a
:class:`~classify.policies.policy.TouchState`.  After each touch the belief
is the product of the single-touch posteriors of the touches so far: the
calibrated posteriors of a place-free classifier, as the fusion multiplies
them (``classify.recognizers.fusion``), or the tempered place-aware
likelihoods of ``PlaceKnowledge``; the decision after
k touches is its most probable class, ties broken by the episode's tie
stream.  :func:`stopping_curve` applies a stopping rule afterwards: stop when
the top class's belief reaches p, or after the last touch.  Many episodes can
step together (:func:`episode_steps`, :func:`run_episodes`), their touches of
each round felt in one batch.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from classify.policies.knowledge import Places, PlaceSample, TouchKnowledge
from classify.policies.policy import Forecasts, TouchPolicy, TouchState, hypotheses

__all__ = [
    "Episode",
    "Felt",
    "available_places",
    "touched_belief",
    "run_episode",
    "episode_steps",
    "run_episodes",
    "decisions",
    "stopping_curve",
]


@dataclass(frozen=True, eq=False)
class Episode:
    """One test instance touched by one policy.

    ``touched`` (k,) int64 place indices in order; ``vertex_ids`` (k,) their
    vertices; ``beliefs`` (k, C) float64, the belief after each touch
    (classes as the knowledge's names); ``choice_s`` (k,) seconds each choice took.
    """

    touched: np.ndarray
    vertex_ids: np.ndarray
    beliefs: np.ndarray
    choice_s: np.ndarray


class Felt:
    """What a touch at each place of an instance gives, ``knowledge.posterior`` of its imprint there, computed
    when the place is first touched: ``felt[p]`` is (C,) float64.

    Up to ``knowledge.hypotheses`` objects the posteriors of every place are
    computed at once, in one batch; past it only the touched places', since
    each costs a registration per shortlisted object.
    """

    def __init__(self, knowledge, imprints: np.ndarray, places: Places):
        self.knowledge, self.imprints, self.places = knowledge, imprints, places
        self._all = None
        self._one = {}
        if knowledge.n_classes <= knowledge.hypotheses:
            self._all = knowledge.posterior(imprints, places)

    def __getitem__(self, p: int) -> np.ndarray:
        if self._all is not None:
            return self._all[p]
        if p not in self._one:
            at = self.places.positions[[p]]
            self._one[p] = self.knowledge.posterior_at(self.imprints[[p]], at, self.places)[0]
        return self._one[p]

    @staticmethod
    def feel(wanted: list) -> None:
        """Compute what the touches ``wanted``, (Felt, place) pairs, give where not computed yet.

        Under a place-free knowledge (``knowledge.place_free``: its posterior
        reads the imprints only) the touches of every instance are scored in one
        batch per knowledge: one pass over the training touches instead of one
        per touch.  A place-aware knowledge locates each instance's touches on
        its own, when read.
        """
        batches = {}
        for felt, p in wanted:
            if felt._all is None and p not in felt._one and getattr(felt.knowledge, "place_free", False):
                batches.setdefault(id(felt.knowledge), {})[id(felt), p] = (felt, p)
        for batch in batches.values():
            todo = list(batch.values())
            knowledge = todo[0][0].knowledge
            rows = knowledge.posterior(np.stack([felt.imprints[p] for felt, p in todo]))
            for (felt, p), row in zip(todo, rows):
                felt._one[p] = row


def available_places(places: Places, touched, min_spacing: float) -> np.ndarray:
    """The places that may be touched next, (P,) bool: touchable, untouched, ``min_spacing`` from every touched one.

    Examples
    --------
    >>> line = Places(np.arange(4), np.array([[0.0, 0, 0], [5, 0, 0], [20, 0, 0], [40, 0, 0]]),
    ...               np.tile([0.0, 0, 1], (4, 1)), np.zeros((4, 1)), np.array([True, True, True, False]))
    >>> available_places(line, [], 10.0).tolist()
    [True, True, True, False]
    >>> available_places(line, [1], 10.0).tolist()          # place 0 is 5 away from the touch, place 2 is 15
    [False, False, True, False]
    """
    ok = places.touchable.copy()
    touched = list(touched)
    if touched:
        P = places.positions
        near = np.linalg.norm(P[:, None, :] - P[touched][None, :, :], axis=2).min(axis=1)
        ok &= near >= min_spacing
        ok[touched] = False
    return ok


def touched_belief(belief: np.ndarray, felt: np.ndarray) -> np.ndarray:
    """The belief after one more touch: ``belief`` times that touch's single-touch posterior ``felt``, normalized.

    Examples
    --------
    >>> touched_belief(np.array([0.5, 0.5]), np.array([0.9, 0.1])).round(2).tolist()
    [0.9, 0.1]
    """
    belief = belief * np.maximum(felt, 1e-300)
    return belief / belief.sum()


def run_episode(
    policy: TouchPolicy,
    sample: PlaceSample,
    knowledge: TouchKnowledge,
    touches: int,
    min_spacing: float,
    rng: np.random.Generator,
    session: int = 0,
    felt: np.ndarray | None = None,
) -> Episode:
    """Let ``policy`` touch the test instance ``sample`` up to ``touches`` times.

    Parameters
    ----------
    policy : TouchPolicy
    sample : PlaceSample
        The test instance: its places and the imprints of ``session`` at each.
    knowledge : TouchKnowledge or PlaceKnowledge
        Fitted on training instances only.
    touches : int
        At most this many touches (fewer when no place is left).
    min_spacing : float
        No touch closer than this to an earlier one (mesh units), as for fixed plans.
    rng : numpy Generator
        The policy's own draws.
    session : int
        Which of the sample's acquisition sessions the touches feel.
    felt : (P, C) float64 or :class:`Felt`, optional
        ``knowledge.posterior`` of that session's imprint at every place, when
        already computed (it does not depend on the policy); by default each
        touched place's, when touched.

    Returns
    -------
    Episode
    """
    if felt is None:
        felt = Felt(knowledge, sample.imprints[session], sample.places)  # never seen by the policy
    steps = episode_steps(policy, sample, knowledge, touches, min_spacing, rng, session)
    return run_episodes([steps], [felt])[0]


def episode_steps(
    policy: TouchPolicy,
    sample: PlaceSample,
    knowledge: TouchKnowledge,
    touches: int,
    min_spacing: float,
    rng: np.random.Generator,
    session: int = 0,
):
    """:func:`run_episode` one touch at a time: a generator that yields each place it touches, is sent back what
    the touch there felt ((C,) float64, ``knowledge.posterior`` of the imprint), and returns the :class:`Episode`.

    Many episodes stepped together (:func:`run_episodes`) have each round's
    touches felt in one batch.
    """
    import time

    places = sample.places
    forecasts = Forecasts(knowledge, places)
    C = knowledge.n_classes
    # Objects of equal belief are drawn from a stream of their own, so the policy's draws stay its own.
    ties = rng.spawn(1)[0] if C > knowledge.hypotheses else None
    belief = np.full(C, 1.0 / C)
    touched, beliefs, seconds = [], [], []
    for _ in range(touches):
        available = available_places(places, touched, min_spacing)
        if not available.any():
            break
        state = TouchState(
            places,
            tuple(touched),
            sample.imprints[session, touched],
            belief,
            available,
            forecasts,
            knowledge,
            hypotheses(belief, knowledge.hypotheses, ties),
        )
        started = time.perf_counter()
        p = int(policy.choose(state, rng))
        seconds.append(time.perf_counter() - started)
        if not (0 <= p < len(places) and available[p]):
            raise ValueError(f"policy {type(policy).__name__} chose place {p}, which is not available")
        touched.append(p)
        belief = touched_belief(belief, (yield p))
        beliefs.append(belief)
    return Episode(
        np.asarray(touched, np.int64),
        places.vertex_ids[touched].astype(np.int64),
        np.asarray(beliefs, np.float64).reshape(-1, C),
        np.asarray(seconds),
    )


def run_episodes(episodes: list, felts: list) -> list:
    """Step episodes together, touch by touch: a list of :class:`Episode`, one per generator of :func:`episode_steps`.

    ``felts`` holds each episode's :class:`Felt` (or (P, C) array).  Each
    round's touches of every episode are felt together (:meth:`Felt.feel`),
    then each episode takes its next step; an episode's draws and belief are
    its own, so it ends as it would alone.
    """
    out = [None] * len(episodes)
    running, sent = range(len(episodes)), [None] * len(episodes)  # nothing is sent before the first touch
    while running:
        asked = {}
        for e in running:
            try:
                asked[e] = episodes[e].send(sent[e])
            except StopIteration as done:
                out[e] = done.value
        Felt.feel([(felts[e], p) for e, p in asked.items() if isinstance(felts[e], Felt)])
        for e, p in asked.items():
            sent[e] = felts[e][p]
        running = list(asked)
    return out


def decisions(beliefs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The most probable class after each touch, (k,) int64; equal beliefs (within 1e-9) drawn at random.

    Examples
    --------
    >>> decisions(np.array([[0.2, 0.8], [0.6, 0.4]]), np.random.default_rng(0)).tolist()
    [1, 0]
    """
    B = np.asarray(beliefs, dtype=np.float64)
    top = B.max(axis=1, keepdims=True)
    keys = np.where(B >= top - 1e-9 * np.maximum(1.0, top), rng.random(B.shape), -1.0)
    return np.argmax(keys, axis=1).astype(np.int64)


def stopping_curve(beliefs: list, truth: np.ndarray, levels, rngs: list) -> tuple[np.ndarray, np.ndarray]:
    """Accuracy and touches used when stopping as soon as the top belief reaches each level.

    Parameters
    ----------
    beliefs : list of (k_e, C) arrays, one episode each (k_e >= 1)
    truth : (E,) int, each episode's class
    levels : (L,) float, the stopping thresholds p
    rngs : list of Generators, each episode's tie breaks

    Returns
    -------
    correct : (L, E) float64, 1 where the decision at the stop was right
    touches : (L, E) float64, touches used
    """
    levels = np.asarray(levels, dtype=np.float64)
    correct = np.zeros((levels.size, len(beliefs)))
    used = np.zeros((levels.size, len(beliefs)))
    for e, B in enumerate(beliefs):
        picks = decisions(B, rngs[e])
        reached = B.max(axis=1)[None, :] >= levels[:, None]  # (L, k)
        stop = np.where(reached.any(axis=1), np.argmax(reached, axis=1), len(B) - 1)
        correct[:, e] = picks[stop] == truth[e]
        used[:, e] = stop + 1
    return correct, used
