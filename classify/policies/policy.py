"""Touch policies: where to touch next, from what vision gives and what the touches so far have felt.

A policy sees a :class:`TouchState`: the test instance's candidate places
(vision), the places touched so far and the imprints they gave, the belief
(the single-touch posteriors of those touches multiplied, as the fusion
multiplies them), which places may still be touched, the forecast of every
place under every hypothesis, and the touch knowledge fitted on training
instances.  It never sees the label, or an imprint of a place it has not
touched: the episode runner (:mod:`classify.policies.episodes`) holds those.

To add a policy, subclass :class:`TouchPolicy`, implement
:meth:`~TouchPolicy.choose` and register a factory in :data:`POLICIES`::

    class Greediest(TouchPolicy):
        def choose(self, state, rng):
            return int(np.flatnonzero(state.available)[0])

    POLICIES.register("greediest", Greediest, "the first place in line")

Built in: ``random``; ``info_gain``, the greedy expected information gain
over the belief; and fixed plans over the same places (``plan_uniform``: the
farthest-point order of the pool; ``plan_mesh_saliency``: the places by
mesh saliency), which never look at what they felt.  A two-step lookahead
(the first touch of the pair with the most expected information) was tried
on development seeds and did not pay (README, "Touch by touch").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from classify.policies.knowledge import Forecast, Places, TouchKnowledge
from meshsal.util.registry import Registry

__all__ = [
    "TouchState",
    "TouchPolicy",
    "RandomPolicy",
    "InfoGainPolicy",
    "PlanPolicy",
    "POLICIES",
    "Forecasts",
    "hypotheses",
    "expected_entropy",
]


@dataclass(frozen=True, eq=False)
class TouchState:
    """What a policy may see before choosing the next touch.

    Attributes
    ----------
    places : Places
        The test instance's candidate places and what vision says of each.
    touched : tuple of int
        Indices into ``places`` touched so far, in order.
    imprints : (k, rows, cols) float32
        What those touches felt.
    belief : (C,) float64
        Single-touch posteriors of those touches (place-aware or calibrated)
        multiplied and normalized (uniform before the first touch), classes as
        ``knowledge.names``.
    available : (P,) bool
        Places that may be touched next: touchable, untouched and at least
        the minimum spacing from every touched place.
    forecasts : Forecasts
        The forecasts of ``places`` (``knowledge.forecast``), made when asked for.
    knowledge : PlaceKnowledge or TouchKnowledge
        Fitted on training instances only.
    hypotheses : (H,) int64 or None
        The objects :attr:`forecast` is over: the most probable ones when there
        are more than ``knowledge.hypotheses`` (:func:`hypotheses`), else None (every object).
    """

    places: Places
    touched: tuple
    imprints: np.ndarray
    belief: np.ndarray
    available: np.ndarray
    forecasts: Forecasts
    knowledge: TouchKnowledge
    hypotheses: np.ndarray | None = None

    @property
    def forecast(self) -> Forecast:
        """The forecast of every place under :attr:`hypotheses`."""
        return self.forecasts.over(self.hypotheses)


class Forecasts:
    """An instance's forecasts under sets of hypotheses, each made once, when first asked for.

    Examples
    --------
    >>> class Knows:
    ...     def forecast(self, places, classes=None):
    ...         print("made")
    ...         return classes
    >>> made = Forecasts(Knows(), None)
    >>> made.over(None); made.over(None)
    made
    """

    def __init__(self, knowledge, places: Places):
        self.knowledge, self.places = knowledge, places
        self._made = {}

    def over(self, classes=None) -> Forecast:
        """``knowledge.forecast(places, classes)``; ``classes`` None for every object."""
        key = None if classes is None else tuple(int(c) for c in classes)
        if key not in self._made:
            if len(self._made) > 8:
                self._made.clear()
            self._made[key] = self.knowledge.forecast(self.places, classes)
        return self._made[key]


def hypotheses(belief: np.ndarray, H: int, rng: np.random.Generator | None) -> np.ndarray | None:
    """The ``H`` most probable objects of ``belief``, in increasing order, or None when there are no more.

    A forecast over every object costs the square of their number per place;
    over the most probable ``H`` it costs the same for 16 objects or 1,000.
    Objects of equal belief (all of them before the first touch) are drawn
    with ``rng``, so a flat belief gives a random sample, not the first names.

    Examples
    --------
    >>> hypotheses(np.array([0.1, 0.5, 0.3, 0.1]), 2, None).tolist()
    [1, 2]
    >>> print(hypotheses(np.array([0.5, 0.5]), 2, None))
    None
    """
    C = len(belief)
    if C <= H:
        return None
    draws = np.zeros(C) if rng is None else rng.random(C)
    return np.sort(np.lexsort((draws, -np.asarray(belief)))[:H])


class TouchPolicy:
    """Chooses the next place to touch.  Subclasses implement :meth:`choose`."""

    def choose(self, state: TouchState, rng: np.random.Generator) -> int:
        """The index into ``state.places`` of the next touch; one of ``state.available``."""
        raise NotImplementedError


class RandomPolicy(TouchPolicy):
    """Any available place, uniformly at random."""

    def choose(self, state: TouchState, rng: np.random.Generator) -> int:
        return int(rng.choice(np.flatnonzero(state.available)))


@dataclass(frozen=True)
class PlanPolicy(TouchPolicy):
    """A fixed plan over the places: the best available place by a ranking made before the first touch.

    ``order`` is "pool" (the candidate pool's farthest-point order, then the
    peaks) or the name of a visual feature (``meshsal.points.learned.FEATURES``),
    highest first.
    """

    order: str = "pool"

    def choose(self, state: TouchState, rng: np.random.Generator) -> int:
        from meshsal.points.learned import FEATURES

        if self.order == "pool":
            score = -np.arange(len(state.places), dtype=np.float64)
        else:
            score = state.places.features[:, FEATURES.index(self.order)]
        ranked = np.lexsort((np.arange(score.size), -score))
        return int(ranked[state.available[ranked]][0])


def _entropy(P: np.ndarray) -> np.ndarray:
    return -np.sum(P * np.log(np.maximum(P, 1e-300)), axis=-1)


def expected_entropy(belief: np.ndarray, forecast: Forecast, places: np.ndarray | None = None) -> np.ndarray:
    """Expected entropy of the belief after one more touch at each place.

    Under hypothesis j (probability ``belief[j]``) a touch at place p feels
    like one of object j's training touches there, s with weight
    ``forecast.weights[j, p, s]``, whose calibrated posterior q multiplies
    the belief b.  The entropy of ``b q / Z`` (``Z = b . q``) is
    ``log Z - (b . (q log q) + q . (b log b)) / Z``, so one pass over the
    forecast per belief does.  Where a hypothesis has no forecast for a
    place, the touch says nothing under it.

    Parameters
    ----------
    belief : (C,) or (B, C) float64, normalized (several beliefs at once); over the forecast's
        ``classes`` only (renormalized) when it has them
    forecast : Forecast
    places : (m,) int, optional
        Only these places (default all).

    Returns
    -------
    (m,) or (B, m) float64 nats

    Examples
    --------
    >>> from classify.policies.knowledge import Forecast
    >>> sure = np.array([[[[0.9, 0.1]], [[0.5, 0.5]]], [[[0.1, 0.9]], [[0.5, 0.5]]]])   # (J=2, P=2, S=1, C=2)
    >>> h = expected_entropy(np.array([0.5, 0.5]), Forecast(sure, np.ones((2, 2, 1))))
    >>> bool(h[0] < h[1]), round(float(h[1]), 4)           # place 0 tells the objects apart, place 1 does not
    (True, 0.6931)
    """
    b = np.atleast_2d(np.asarray(belief, dtype=np.float64))  # (B, C)
    if forecast.classes is not None:
        b = b[:, forecast.classes]
        b = b / b.sum(axis=1, keepdims=True)
    P, Q, W = forecast.posteriors, forecast.plogp, forecast.weights
    if places is not None:
        P, Q, W = P[:, places], Q[:, places], W[:, places]
    J, m, S, C = P.shape
    blogb = np.where(b > 0, b * np.log(np.where(b > 0, b, 1.0)), 0.0)
    P2, Q2 = P.reshape(-1, C), Q.reshape(-1, C)
    Z = P2 @ b.T  # (J m S, B)
    with np.errstate(divide="ignore", invalid="ignore"):
        h = np.log(Z) - (Q2 @ b.T + P2 @ blogb.T) / Z
    # A touch whose posterior shares no object with the belief (both rounded to zero elsewhere) leaves it as it is.
    h = np.where(Z > 0, h, -blogb.sum(axis=1)[None, :])
    h = (W.reshape(-1, 1) * h).reshape(J, m, S, -1).sum(axis=2)  # (J, m, B)
    h += (1.0 - W.sum(axis=2))[:, :, None] * (-blogb.sum(axis=1))[None, None, :]
    out = np.einsum("bj,jmb->bm", b, h)
    return out[0] if np.ndim(belief) == 1 else out


class InfoGainPolicy(TouchPolicy):
    """Greedy expected information gain: the available place whose touch is expected to leave the least entropy.

    Ties go to the earlier place.  The forecast is the per-object touch models
    of :class:`~classify.policies.place_knowledge.PlaceKnowledge` (the codebooks of
    the matched places) or :class:`~classify.policies.knowledge.TouchKnowledge`,
    scored with the single-touch posteriors the belief multiplies.
    """

    def choose(self, state: TouchState, rng: np.random.Generator) -> int:
        candidates = np.flatnonzero(state.available)
        return int(candidates[np.argmin(expected_entropy(state.belief, state.forecast)[candidates])])


#: The touch policies, each a factory of a :class:`TouchPolicy`.
POLICIES = Registry("touch policy")
POLICIES.register("random", RandomPolicy, "any available place, uniformly at random")
POLICIES.register("info_gain", InfoGainPolicy, "greedy expected information gain over the objects' posterior")
POLICIES.register("plan_uniform", PlanPolicy, "fixed plan: the places in farthest-point order")
POLICIES.register("plan_mesh_saliency", lambda: PlanPolicy("mesh_saliency"), "fixed plan: the places by mesh saliency")
