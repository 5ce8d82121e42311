"""Benchmark: what pinning the kernels costs (``meshsal.util.reproducible``), pinned against each CPU's own choice.

The pin is read when the libraries load, so two child processes hold the two
settings for the whole run: one pinned as the ``visuotactile`` command pins
(OpenBLAS Haswell, OpenCV and NumPy at their baseline, Embree SSE2), one with
``VISUOTACTILE_KERNELS=native``.  Both run one BLAS thread and one thread of
their own.  They take turns, one call of a stage each per round, so that a
busy moment of the shared machine falls on both, and report the CPU seconds
of each call (``time.process_time``).  Printed: the median CPU seconds of each
stage per setting, and the median (and range) over rounds of the ratio of
pinned to native within a round.  Stages, on the cow toy: its 72 views at
128 px rendered (the Embree scene built in the call), their attention
channels (OpenCV, NumPy), 300 imprints (scene built in the call), and the 15
attention points from nothing (everything above, mesh saliency, touch checks).

    python benchmarks/bench_kernels.py [--repeats 7]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

# NumPy is imported inside the functions: a child must pin its kernels before it loads.
STAGES = ("render72", "attention72", "imprints300", "points")


def serve() -> None:
    """Child: set up the cow's inputs, then run each stage named on stdin, replying its CPU seconds."""
    from meshsal.util.reproducible import kernels, pin_kernels

    pin_kernels()
    import time

    import numpy as np

    import meshsal
    import tactile
    from meshsal import render_views, view_rig
    from meshsal.attention import saliency_views

    cow = meshsal.objects.toys.make("cow")
    saliency = meshsal.mesh_saliency(cow)
    cameras = [c for s in view_rig() for c in s]
    views = render_views(cow, cameras, size=128, threads=1)
    spots = meshsal.interest_points(cow, method="uniform", n=15, touch=False)
    positions, normals = np.repeat(spots.positions, 20, axis=0), np.repeat(spots.normals, 20, axis=0)
    angles = np.tile(np.linspace(0.0, 342.0, 20), len(spots.positions))
    stages = {
        "render72": lambda: render_views(cow, cameras, size=128, threads=1),
        "attention72": lambda: saliency_views(views, cow, vertex_saliency=saliency, threads=1, quiet=True),
        "imprints300": lambda: tactile.imprints(cow, positions, normals, angles_deg=angles, workers=1),
        "points": lambda: meshsal.interest_points(cow, threads=1),
    }
    for stage in stages.values():
        stage()  # warm-up: page faults, the Embree device, OpenCV's buffers
    print(json.dumps({"kernels": kernels()}), flush=True)
    for line in sys.stdin:
        start = time.process_time()
        stages[line.strip()]()
        print(json.dumps({"cpu": time.process_time() - start}), flush=True)


def start(native: bool) -> subprocess.Popen:
    env = {
        k: v
        for k, v in os.environ.items()
        if k
        not in (
            "OPENBLAS_CORETYPE",
            "OPENCV_CPU_DISABLE",
            "OPENCV_IPP",
            "NPY_DISABLE_CPU_FEATURES",
            "VISUOTACTILE_EMBREE_CONFIG",
        )
    }
    env.update(OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", VISUOTACTILE_KERNELS="native" if native else "pinned")
    child = subprocess.Popen(
        [sys.executable, __file__, "--serve"], env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    ready = json.loads(child.stdout.readline())
    print(f"{'native' if native else 'pinned'}: {ready['kernels']}")
    return child


def ask(child: subprocess.Popen, stage: str) -> float:
    child.stdin.write(stage + "\n")
    child.stdin.flush()
    return json.loads(child.stdout.readline())["cpu"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--serve", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.serve:
        serve()
        return
    import numpy as np

    children = {"pinned": start(native=False), "native": start(native=True)}
    cpu = {(mode, stage): [] for mode in children for stage in STAGES}
    for _ in range(args.repeats):
        for stage in STAGES:
            for mode, child in children.items():
                cpu[mode, stage].append(ask(child, stage))
    for child in children.values():
        child.stdin.close()
        child.wait()
    print(f"CPU seconds per call, median of {args.repeats} rounds (cow, 128 px, one thread)")
    print("| stage | native | pinned | pinned / native (median, range) |")
    print("|---|---:|---:|---:|")
    for stage in STAGES:
        native, pinned = np.array(cpu["native", stage]), np.array(cpu["pinned", stage])
        ratio = pinned / native
        print(
            f"| {stage} | {np.median(native):.3f} | {np.median(pinned):.3f} | "
            f"{np.median(ratio):.2f} ({ratio.min():.2f}-{ratio.max():.2f}) |"
        )


if __name__ == "__main__":
    if "--serve" in sys.argv:  # a child: stdout is its replies, and it pins its kernels before NumPy loads
        main()
    else:
        from benchlib import run

        run("bench_kernels", "What the kernel pin costs", main)
