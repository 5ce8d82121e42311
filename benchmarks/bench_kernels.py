"""Benchmark: what pinning the kernels costs (``meshsal.util.reproducible``), pinned against each CPU's own choice.

The pin is read when the libraries load, so child processes hold the
settings for the whole run: one pinned as the ``visuotactile`` command pins
(OpenBLAS Haswell, OpenCV and NumPy at their baseline, Embree SSE2), one with
``VISUOTACTILE_KERNELS=native``, and on a CPU with AVX one pinned but for
Embree at ``isa=avx`` (8-wide, without the fused multiply-add that moves
AVX2's hits).  Each runs one BLAS thread and one thread of its own.  They
take turns, one call of a stage each per round, so that a busy moment of the
shared machine falls on all, and report the CPU seconds of each call
(``time.process_time``).  Printed: the median CPU seconds of each stage per
setting, and the median (and range) over rounds of the ratio of pinned to
each other setting within a round.  Stages, on the cow toy: its 72 views at
128 px rendered (the Embree scene built in the call), their attention
channels (OpenCV, NumPy), 300 imprints (scene built in the call), and the 15
attention points from nothing (everything above, mesh saliency, touch checks).

Then why Embree stays at SSE2 when AVX is there: each Embree setting traces
the same seeded rays at the cup toy, once as it is and once with every face
twice, the copy turned the other way on vertices of its own, so that a ray
meets two faces at exactly the same distance (as it meets coincident faces
of two parts on one plane; the loader drops exact twins, not those), and
the rays whose face or distance differ from the SSE2 kernels' are counted.

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
#: Rays traced at each cup in the coincident-faces check.
TIE_RAYS = 200_000


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
        request = line.split()
        if request[0] == "ties":
            np.savez(request[1], **_cup_hits())
            print(json.dumps({"saved": request[1]}), flush=True)
            continue
        start = time.process_time()
        stages[request[0]]()
        print(json.dumps({"cpu": time.process_time() - start}), flush=True)


def _cup_hits() -> dict:
    """Face and distance of the first hit of seeded rays at the cup toy, as it is and with coincident faces."""
    import numpy as np

    from meshsal.mesh import Mesh
    from meshsal.mesh.embree import embree_scene
    from meshsal.objects import toys

    cup = toys.make("cup")
    V, F = cup.vertices, cup.faces
    doubled = Mesh(vertices=np.vstack([V, V]), faces=np.vstack([F, F[:, ::-1] + len(V)]))
    rng = np.random.default_rng(0)
    low, high = V.min(axis=0), V.max(axis=0)
    origins = (rng.uniform(low, high, (TIE_RAYS, 3)) + (high - low) * rng.normal(size=(TIE_RAYS, 3))).astype(np.float32)
    directions = ((low + high) / 2 - origins + 10.0 * rng.normal(size=origins.shape)).astype(np.float32)
    out = {}
    for name, mesh in (("cup", cup), ("doubled", doubled)):
        hit = embree_scene(mesh).run(origins, directions, output=1)
        out[name + "_face"], out[name + "_distance"] = hit["primID"], hit["tfar"]
    return out


def start(mode: str) -> subprocess.Popen:
    """A child in ``mode``: "pinned", "native" or "embree-avx" (pinned, but Embree at ``isa=avx``)."""
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
    env.update(
        OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", VISUOTACTILE_KERNELS="native" if mode == "native" else "pinned"
    )
    if mode == "embree-avx":
        env["VISUOTACTILE_EMBREE_CONFIG"] = "isa=avx"  # a user's Embree configuration wins over the pin
    child = subprocess.Popen(
        [sys.executable, __file__, "--serve"], env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    ready = json.loads(child.stdout.readline())
    print(f"{mode}: {ready['kernels']}")
    return child


def ask(child: subprocess.Popen, request: str) -> dict:
    child.stdin.write(request + "\n")
    child.stdin.flush()
    return json.loads(child.stdout.readline())


def _ties(children: dict) -> list[str]:
    """A table's lines: how many of the cups' rays get another face or distance from Embree's AVX kernels than
    from SSE2."""
    import tempfile
    from pathlib import Path

    import numpy as np

    with tempfile.TemporaryDirectory(prefix="bench_kernels_") as folder:
        hits = {}
        for mode in ("pinned", "embree-avx"):
            hits[mode] = dict(np.load(ask(children[mode], f"ties {Path(folder) / mode}.npz")["saved"]))
    lines = [
        "",
        f"Embree's AVX kernels against SSE2 on {TIE_RAYS:,} seeded rays at the cup toy (rays whose first hit differs)",
        "| the cup | another face | another distance |",
        "|---|---:|---:|",
    ]
    for name, label in (("cup", "as it is"), ("doubled", "every face twice, the copy turned over (coincident faces)")):
        sse2, avx = hits["pinned"], hits["embree-avx"]
        faces = int((sse2[name + "_face"] != avx[name + "_face"]).sum())
        distances = int((sse2[name + "_distance"].view(np.uint32) != avx[name + "_distance"].view(np.uint32)).sum())
        lines.append(f"| {label} | {faces:,} | {distances:,} |")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--serve", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.serve:
        serve()
        return
    import numpy as np

    from meshsal.util.reproducible import cpu_flags

    modes = ["pinned", "native"] + (["embree-avx"] if "avx" in (cpu_flags() or ()) else [])
    children = {mode: start(mode) for mode in modes}
    cpu = {(mode, stage): [] for mode in children for stage in STAGES}
    for _ in range(args.repeats):
        for stage in STAGES:
            for mode, child in children.items():
                cpu[mode, stage].append(ask(child, stage)["cpu"])
    no_avx = ["", "This CPU has no AVX: Embree's AVX kernels are not measured."]
    ties = _ties(children) if "embree-avx" in children else no_avx
    for child in children.values():
        child.stdin.close()
        child.wait()
    others = [mode for mode in modes if mode != "pinned"]
    print()
    print(f"CPU seconds per call, median of {args.repeats} rounds (cow, 128 px, one thread)")
    print("| stage | " + " | ".join(modes) + " | " + " | ".join(f"pinned / {m} (median, range)" for m in others) + " |")
    print("|---|" + "---:|" * (len(modes) + len(others)))
    for stage in STAGES:
        pinned = np.array(cpu["pinned", stage])
        cells = [f"{np.median(cpu[mode, stage]):.3f}" for mode in modes]
        for mode in others:
            ratio = pinned / np.array(cpu[mode, stage])
            cells.append(f"{np.median(ratio):.2f} ({ratio.min():.2f}-{ratio.max():.2f})")
        print(f"| {stage} | " + " | ".join(cells) + " |")
    print("\n".join(ties))


if __name__ == "__main__":
    if "--serve" in sys.argv:  # a child: stdout is its replies, and it pins its kernels before NumPy loads
        main()
    else:
        from benchlib import run

        run("bench_kernels", "What the kernel pin costs", main)
