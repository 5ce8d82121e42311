"""Do a method's points come back? Test-instance points against the training instances' points.

Under the instance protocol every instance is turned, resized and repainted,
and each point method runs on the instance's own rendering.  A test touch is
easy to recognize when training touched the same place.  For each object,
replicate and method this script takes the experiment's own instances
(``classify.dataset.instance_samples``, the same seeds), maps every point
back to the object's nominal frame, and measures how far each test-instance
point lies from the nearest point of that replicate's training instances.
It prints, per object set, the median of that distance and the share of test
points within ``--near`` mm of a training point, as a Markdown table.

    .venv/bin/python scripts/repeatability.py [--objects toys,ycb] [--replicates 5] [--near 5]
        [--methods attention,attention_itti,attention_learned,learned,random,uniform,mesh_saliency]
        [--cache-dir DIR]

The learned methods use each replicate's touch model, fitted as the
experiment fits it: on the training instances' surveys of every object given.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
from scipy.spatial import cKDTree

from classify import dataset
from classify.experiment import load_objects
from classify.learned import fit_replicate_model
from meshsal import toys, ycb
from meshsal.mesh import Similarity
from meshsal.points import MODEL_METHODS, POINT_METHODS
from meshsal.progress import progress

METHODS = ("attention", "attention_itti", "attention_learned", "learned", "random", "uniform", "mesh_saliency")


def nominal_positions(settings: dataset.Settings, name: str, replicate: int, index: int, positions) -> np.ndarray:
    """(k, 3) float64: an instance's points in its object's nominal frame (mm)."""
    spec = dataset.instance_spec(settings, name, replicate, index)
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
    plain = [m for m in methods if m not in MODEL_METHODS]
    learned = [m for m in methods if m in MODEL_METHODS]
    settings = dataset.Settings()
    names, nominal = load_objects([args.objects], settings)
    instances = range(settings.train_instances + 1)
    groups = [_group(n) for n in names]
    sets = list(dict.fromkeys(groups))
    distances = {(s, m): [] for s in sets for m in methods}
    for r in progress(range(args.replicates), total=args.replicates, desc="replicates", quiet=False):
        samples = {(i, j): dataset.instance_samples(nominal[i], names[i], plain, settings, r, j, survey=bool(learned),
                                                    cache_dir=args.cache_dir)
                   for i in range(len(names)) for j in instances}
        if learned:
            model = fit_replicate_model({(names[i], j): out["survey"] for (i, j), out in samples.items()})
            for (i, j), out in samples.items():
                out.update(dataset.instance_samples(nominal[i], names[i], learned, settings, r, j,
                                                    cache_dir=args.cache_dir, model=model, surveyed=out["survey"]))
        for i, name in enumerate(names):
            for m in methods:
                test, *training = (nominal_positions(settings, name, r, j, samples[i, j][m]["positions"])
                                   for j in instances)
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
