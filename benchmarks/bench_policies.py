"""Benchmark: how long a touch policy takes to choose the next touch (target <= 20 ms: 330 places, 16 objects).

A policy chooses from a :class:`classify.policies.TouchState`: the test
instance's places, the belief after the touches so far, and the forecast of
every place under every object (made once per episode).  The cost depends on
the counts only, so both knowledges are built from synthetic data at the
experiment's sizes: 16 objects, 330 places each (the pool of 300 and 30
mesh-saliency peaks for 15 points).

* place-aware (``PlaceKnowledge``, the default belief): a codebook of 8
  touches per place on each of 3 training instances (42-dimensional
  descriptors), fitted as the experiment fits it; its forecast holds 16
  touches per place and object (the 2 nearest places' 8 each);
* place-free (``TouchKnowledge``): random calibrated posteriors, 3 training
  touches per place.

Every policy chooses from the same states (a belief drawn from a Dirichlet,
several touches already made) in interleaved rounds, with one BLAS thread as
in the experiment's workers; the table gives the median wall and CPU time
per choice (CPU time is what a busy machine does not inflate), the
per-episode cost of the forecast and of the belief of every place (for the
place-aware belief, each on a new instance: laying its places onto every
object's included), and the place-aware model's fit, once per replicate.

    python -m meshsal.util.reproducible .venv/bin/python benchmarks/bench_policies.py [--objects 16] [--places 330]
"""

from __future__ import annotations

import copy
import statistics
from functools import partial

import numpy as np
from benchlib import arguments, run, timed
from threadpoolctl import threadpool_limits


def synthetic(objects: int, places: int, touches: int, seed: int = 0):
    """A TouchKnowledge of random calibrated posteriors, and a test instance's Places, at the given sizes."""
    from classify.policies import Places, TouchKnowledge, signatures
    from classify.recognizers.fusion import Calibration
    from classify.recognizers.shortlist import SparseRows
    from meshsal.points.learned import FEATURES

    rng = np.random.default_rng(seed)
    names = tuple(f"object{j:02d}" for j in range(objects))
    test = Places(
        np.arange(places),
        rng.normal(size=(places, 3)) * 50.0,
        rng.normal(size=(places, 3)),
        rng.random((places, len(FEATURES))),
        np.ones(places, bool),
    )
    place_ids, located, posteriors, weights = [], [], [], []
    for _ in range(objects):
        place_ids.append(np.sort(rng.choice(4 * places, places, replace=False)))
        located.append(signatures(test)[rng.permutation(places)])  # every object's places, in another order
        post = rng.dirichlet(np.full(objects, 0.3), size=(places, touches))
        posteriors.append(
            SparseRows(post, np.tile(np.arange(objects), (places, touches, 1)), np.zeros((places, touches)), objects)
        )
        weights.append(np.full((places, touches), 1.0 / touches))
    knowledge = TouchKnowledge(
        names, tuple(place_ids), tuple(located), tuple(posteriors), tuple(weights), None, Calibration(), "polar"
    )
    return knowledge, test


def synthetic_place(objects: int, places: int, instances: int = 3, draws: int = 8, seed: int = 0):
    """A PlaceKnowledge fitted on synthetic codebooks (each object's places in another order), its fit's time, and
    a test instance's Places and session imprints."""
    from classify.policies import Places, PlaceSample, fit_place_knowledge
    from meshsal.points.learned import FEATURES

    rng = np.random.default_rng(seed)
    positions = rng.normal(size=(places, 3)) * 50.0
    training = {}
    for j in range(objects):
        order = np.r_[np.arange(8), 8 + rng.permutation(places - 8)]  # the landmarks first, as on a real pool
        feel = rng.normal(size=(places, 42))
        for i in range(1, instances + 1):
            where = Places(
                np.arange(places),
                positions[order],
                rng.normal(size=(places, 3)),
                np.zeros((places, len(FEATURES))),
                np.ones(places, bool),
            )
            book = (feel[order][:, None] + 0.5 * rng.normal(size=(places, draws, 42))).astype(np.float32)
            imprints = rng.random((1, places, 16, 16)).astype(np.float32)
            training[f"object{j:02d}", i] = PlaceSample(where, imprints, book)
    knowledge, fit_wall, fit_cpu = timed(partial(fit_place_knowledge, training))
    test = training["object00", 1]
    return knowledge, test.places, test.imprints[0], (fit_wall, fit_cpu)


def _states(places, knowledge, forecasts, objects, repeats, rng):
    """Policy states: a belief drawn from a Dirichlet, up to three touches already made."""
    from classify.policies import TouchState, hypotheses

    P = len(places)
    states = []
    for r in range(repeats):
        touched = tuple(int(t) for t in rng.choice(P, r % 4, replace=False))
        available = np.ones(P, bool)
        available[list(touched)] = False
        belief = rng.dirichlet(np.full(objects, 1.0 if r % 2 else 5.0))
        states.append(
            TouchState(
                places,
                touched,
                np.zeros((len(touched), 16, 16), np.float32),
                belief,
                available,
                forecasts,
                knowledge,
                hypotheses(belief, knowledge.hypotheses, rng),
            )
        )
    return states


def _median_ms(times) -> str:
    return (
        f"{statistics.median(w for w, _ in times) * 1e3:.2f} ms | {statistics.median(c for _, c in times) * 1e3:.2f} ms"
    )


def main(argv=None) -> int:
    parser = arguments(__doc__, repeats=30, meshes_dir=False, repeats_help="states each policy chooses from")
    parser.add_argument("--objects", type=int, default=16)
    parser.add_argument("--places", type=int, default=330)
    parser.add_argument("--touches", type=int, default=3, help="place-free: training touches per place and object")
    _measure(parser.parse_args(argv))
    return 0


def _measure(args) -> None:
    from classify.policies import POLICIES, Forecasts

    rng = np.random.default_rng(1)
    rows = []
    with threadpool_limits(1):
        place, place_places, imprints, fit = synthetic_place(args.objects, args.places)
        free, free_places = synthetic(args.objects, args.places, args.touches)
        rows.append(
            ("place-aware: fit on the codebooks (3 instances x 8 touches per place), once per replicate", [fit])
        )
        for label, knowledge, places in (("place-aware", place, place_places), ("place-free", free, free_places)):
            knowledge.forecast(places)  # warm: imports, first allocations
            rows.append(
                (
                    f"{label}: forecast of every place under every object, once per episode",
                    [timed(partial(knowledge.forecast, copy.copy(places)))[1:] for _ in range(5)],
                )
            )
            if label == "place-aware":
                rows.append(
                    (
                        f"{label}: the belief of a touch at every place, once per episode",
                        [timed(partial(knowledge.posterior, imprints, copy.copy(places)))[1:] for _ in range(5)],
                    )
                )
            forecasts = Forecasts(knowledge, places)
            states = _states(places, knowledge, forecasts, args.objects, args.repeats, rng)
            for state in states:
                forecasts.over(state.hypotheses)  # made before the choices are timed, as a first touch makes it
            policies = {name: POLICIES.get(name)() for name in POLICIES.names()}
            times = {name: [] for name in policies}
            for state in states:
                for name, policy in policies.items():
                    times[name].append(timed(partial(policy.choose, state, np.random.default_rng(0)))[1:])
            rows += [(f"{label}: choose, {name}", t) for name, t in times.items()]
    lines = [
        f"| what ({args.objects} objects, {args.places} places) | median wall | median CPU | target |",
        "|---|---:|---:|---:|",
    ]
    for what, t in rows:
        target = "<= 20 ms" if what.endswith("choose, info_gain") else ""
        lines.append(f"| {what} | {_median_ms(t)} | {target} |")
    print("\n".join(lines))


if __name__ == "__main__":
    run("bench_policies", "Choosing the next touch", main)
