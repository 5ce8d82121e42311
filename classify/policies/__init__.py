"""Touch by touch: policies that choose each next touch from what the touches so far have felt.

``knowledge`` (an instance's candidate places, and what touches there feel
like on each object, fitted on training instances; ``place_knowledge`` the
place-aware recognizer's), ``policy`` (the policy
API, the built-in policies and their registry) and ``episodes`` (a policy
touching a test instance, and the stopping rule).
"""

from classify.policies.episodes import (
    Episode,
    Felt,
    available_places,
    decisions,
    episode_steps,
    run_episode,
    run_episodes,
    stopping_curve,
    touched_belief,
)
from classify.policies.knowledge import (
    LANDMARKS,
    Forecast,
    PackedPlaceSample,
    Places,
    PlaceSample,
    TouchKnowledge,
    fit_knowledge,
    signatures,
)
from classify.policies.place_knowledge import PlaceKnowledge, fit_place_knowledge, place_keys, place_touches
from classify.policies.policy import (
    POLICIES,
    Forecasts,
    InfoGainPolicy,
    PlanPolicy,
    RandomPolicy,
    TouchPolicy,
    TouchState,
    expected_entropy,
    hypotheses,
)

__all__ = [
    "available_places",
    "decisions",
    "Episode",
    "expected_entropy",
    "Felt",
    "fit_knowledge",
    "fit_place_knowledge",
    "Forecast",
    "Forecasts",
    "hypotheses",
    "InfoGainPolicy",
    "LANDMARKS",
    "place_keys",
    "place_touches",
    "PlaceKnowledge",
    "PackedPlaceSample",
    "Places",
    "PlaceSample",
    "PlanPolicy",
    "POLICIES",
    "RandomPolicy",
    "run_episode",
    "episode_steps",
    "run_episodes",
    "signatures",
    "stopping_curve",
    "touched_belief",
    "TouchKnowledge",
    "TouchPolicy",
    "TouchState",
]
