"""Do a method's points come back? Test-instance points against the training instances' points.

Under the instance protocol every instance is turned, resized and repainted,
and each point method runs on the instance's own rendering.  A test touch is
easy to recognize when training touched the same place.  For each object,
replicate and method this script takes the experiment's own instances (the
same seeds), maps every point back to the object's nominal frame, and
measures how far each test-instance point lies from the nearest point of
that replicate's training instances.
It prints, per object set, the median of that distance and the share of test
points within ``--near`` mm of a training point, as a Markdown table.

    .venv/bin/python scripts/repeatability.py [--objects toys,ycb] [--replicates 5] [--near 5]
        [--methods attention,attention_itti,attention_learned,learned,random,uniform,mesh_saliency]
        [--cache-dir DIR]

The points come from the experiment's own instance stage
(``classify.experiment.instance_stage``): the learned methods use each
replicate's touch model, fitted on the training instances of every object given.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
from scipy.spatial import cKDTree

from classify.experiment import samples
from classify.experiment.stages import Runtime, SampleKey, instance_stage, load_objects
from classify.runtime.cluster import Inline
from meshsal.mesh import Similarity
from meshsal.objects import toys, ycb
from meshsal.points import POINT_METHODS

METHODS = ("attention", "attention_itti", "attention_learned", "learned", "random", "uniform", "mesh_saliency")


def nominal_positions(settings: samples.Settings, name: str, replicate: int, index: int, positions) -> np.ndarray:
    """(k, 3) float64: an instance's points in its object's nominal frame (mm)."""
    spec = samples.instance_spec(settings, name, replicate, index)
    return Similarity(spec.scale, np.zeros(3), spec.rotation).inverse().apply(positions)


def nearest_training_distances(test: np.ndarray, training: list[np.ndarray]) -> np.ndarray:
    """(k,) float64: each test point's distance to the nearest training point."""
    return cKDTree(np.concatenate(training)).query(test)[0]


def _group(name: str) -> str:
    return "toys" if name in toys.NAMES else "YCB" if name in ycb.NAMES else "other"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--objects", default="toys,ycb")
    parser.add_argument("--replicates", type=int, default=5)
    parser.add_argument("--methods", default=",".join(METHODS))
    parser.add_argument("--near", type=float, default=5.0, help="mm (default 5)")
    parser.add_argument("--cache-dir", default=None)
    args = parser.parse_args()
    methods = POINT_METHODS.check(args.methods.split(","))
    settings = samples.Settings()
    objects = load_objects([args.objects], settings)
    names = objects.names
    stage = instance_stage(objects, methods, settings, args.replicates, Runtime(Inline(), args.cache_dir, quiet=False))
    groups = [_group(n) for n in names]
    sets = list(dict.fromkeys(groups))
    distances = {(s, m): [] for s in sets for m in methods}
    for r in range(args.replicates):
        for i, name in enumerate(names):
            for m in methods:
                test, *training = (
                    nominal_positions(settings, name, r, j, stage.samples[SampleKey(r, m, i, j)].positions)
                    for j in range(settings.train_instances + 1)
                )
                distances[groups[i], m].append(nearest_training_distances(test, training))
    print("| method | " + " | ".join(f"{s}: median distance (mm) | {s}: within {args.near:g} mm" for s in sets) + " |")
    print("|---|" + ":---:|:---:|" * len(sets))
    for m in methods:
        cells = []
        for s in sets:
            d = np.concatenate(distances[s, m])
            cells += [f"{np.median(d):.1f}", f"{100 * np.mean(d <= args.near):.0f} %"]
        print(f"| {m} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
