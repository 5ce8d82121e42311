"""Benchmark: how long a touch policy takes to choose the next touch (target <= 20 ms: 300 places, 16 objects).

A policy chooses from a :class:`classify.policies.TouchState`: the test
instance's places, the belief after the touches so far, and the forecast of
every place under every object (``TouchKnowledge.forecast``, made once per
episode).  The cost depends on the counts only, so the knowledge here is
built from random posteriors at the experiment's sizes: 16 objects, 330
places each (the pool of 300 and 30 mesh-saliency peaks for 15 points),
3 training touches per place.  Every policy chooses from the same states (a
belief drawn from a Dirichlet, several touches already made) in interleaved
rounds, with one BLAS thread as in the experiment's workers; the table gives
the median wall and CPU time per choice (CPU time is what a busy machine
does not inflate), and the per-episode cost of the forecast.

    .venv/bin/python benchmarks/bench_policies.py [--objects 16] [--places 330] [--repeats 30]
"""

from __future__ import annotations

import argparse
import statistics
from functools import partial

import numpy as np
from benchlib import page, timed
from threadpoolctl import threadpool_limits


def synthetic(objects: int, places: int, touches: int, seed: int = 0):
    """A TouchKnowledge of random calibrated posteriors, and a test instance's Places, at the given sizes."""
    from classify.policies import Places, TouchKnowledge, signatures
    from classify.recognizers.fusion import Calibration
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
        posteriors.append(rng.dirichlet(np.full(objects, 0.3), size=(places, touches)))
        weights.append(np.full((places, touches), 1.0 / touches))
    knowledge = TouchKnowledge(
        names, tuple(place_ids), tuple(located), tuple(posteriors), tuple(weights), None, Calibration(), "polar"
    )
    return knowledge, test


def main(argv=None) -> int:
    from classify.policies import POLICIES, TouchState

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--objects", type=int, default=16)
    parser.add_argument("--places", type=int, default=330)
    parser.add_argument("--touches", type=int, default=3, help="training touches per place and object")
    parser.add_argument("--repeats", type=int, default=30, help="states each policy chooses from")
    args = parser.parse_args(argv)
    knowledge, places = synthetic(args.objects, args.places, args.touches)
    rng = np.random.default_rng(1)
    with threadpool_limits(1):
        forecast = knowledge.forecast(places)  # warm: imports, first allocations
        forecast_s = [timed(partial(knowledge.forecast, places))[1:] for _ in range(5)]
        states = []
        for r in range(args.repeats):
            touched = tuple(int(t) for t in rng.choice(args.places, r % 4, replace=False))
            available = np.ones(args.places, bool)
            available[list(touched)] = False
            states.append(
                TouchState(
                    places,
                    touched,
                    np.zeros((len(touched), 16, 16), np.float32),
                    rng.dirichlet(np.full(args.objects, 1.0 if r % 2 else 5.0)),
                    available,
                    forecast,
                    knowledge,
                )
            )
        policies = {name: POLICIES.get(name)() for name in POLICIES.names()}
        times = {name: [] for name in policies}
        for state in states:
            for name, policy in policies.items():
                times[name].append(timed(partial(policy.choose, state, np.random.default_rng(0)))[1:])
    print(
        f"| what ({args.objects} objects, {args.places} places, {args.touches} training touches each) "
        f"| median wall | median CPU | target |"
    )
    print("|---|---:|---:|---:|")
    rows = {"forecast of every place under every object, once per episode": forecast_s}
    rows.update({f"choose: {name}": t for name, t in times.items()})
    for what, t in rows.items():
        target = "<= 20 ms" if what == "choose: info_gain" else ""
        print(
            f"| {what} | {statistics.median(w for w, _ in t) * 1e3:.2f} ms "
            f"| {statistics.median(c for _, c in t) * 1e3:.2f} ms | {target} |"
        )
    return 0


if __name__ == "__main__":
    with page("bench_policies", "Choosing the next touch"):
        status = main()
    raise SystemExit(status)
