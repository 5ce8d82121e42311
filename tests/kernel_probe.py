"""What the kernel pin must keep fixed, computed in this process or, run as a script, in a fresh one.

``python tests/kernel_probe.py OUT_DIR [--points-only]`` pins the kernels as
the ``visuotactile`` command does, then prints :func:`outputs` as JSON, so a
test can compare a process started with another instruction set forced on it.
"""

import json
import sys

from meshsal.util.reproducible import pin_kernels

TOYS = ("cow", "cup")


def points(names=TOYS) -> dict:
    """Each toy's 15 attention points: vertex ids and the SHA-256 of positions, normals and scores."""
    import hashlib

    import numpy as np

    import meshsal

    found = {}
    for name in names:
        p = meshsal.interest_points(meshsal.objects.toys.make(name), threads=1)
        digest = hashlib.sha256(b"".join(np.ascontiguousarray(a).tobytes() for a in (p.positions, p.normals, p.scores)))
        found[name] = {"vertices": [int(v) for v in p.vertex_ids], "sha256": digest.hexdigest()}
    return found


def results_csv(out_dir) -> str:
    """``results.csv`` of a small experiment on the toys: uniform points, 6 each, 2 replicates."""
    from pathlib import Path

    import quick

    config = quick.QUICK.replace(methods=("uniform",), classifiers=("knn", "naive_bayes", "decision_tree"))
    quick.run(list(TOYS), config, n_jobs=1, out_dir=out_dir)
    return (Path(out_dir) / "results.csv").read_text()


def outputs(out_dir, points_only: bool = False) -> dict:
    """The points, and unless ``points_only`` the experiment's table, with the kernels that computed them."""
    from meshsal.util.reproducible import kernels

    found = {"points": points(TOYS[:1] if points_only else TOYS), "kernels": kernels()}
    if not points_only:
        found["results_csv"] = results_csv(out_dir)
    return found


if __name__ == "__main__":
    pin_kernels()
    print(json.dumps(outputs(sys.argv[1], points_only="--points-only" in sys.argv[2:])))
