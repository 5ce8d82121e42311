"""Benchmark: fast (Embree) imprints against exact plane sections, and batch throughput.

15 imprints at random vertices of nefertiti (scaled to 150 mm) through the
fast path (``tactile.imprints``: pose fit and one ray batch, with the Embree
scene built in the call or prebuilt and passed as ``scene``) and through the
exact reference path (``tactile.section.imprints_exact``), in the same run;
then the imprints per second of one batch of 1000 points.  The variants are
timed in interleaved rounds (each round runs every variant once) so that a
change in the machine's load hits them alike; the table gives medians, and
the load average before and after.

The >= 20x target is judged on the fast path with a prebuilt scene: a robot
or an experiment takes many imprints on each mesh (15 per object per
acquisition, repeated with perturbations), so it builds the scene once per
mesh and passes it to every call; the build (a BVH of the whole mesh) is a
per-mesh cost, reported on its own row and in the other ratio.

    .venv/bin/python benchmarks/bench_imprints.py [--meshes-dir DIR] [--repeats 5]
"""

from __future__ import annotations

import os
import statistics
import sys
import time

import numpy as np
from benchlib import arguments, run


def interleaved_medians(cases: dict, repeats: int, warm: bool = False) -> dict:
    """Median wall time of each ``name -> fn`` over ``repeats`` rounds that run every case once.

    With ``warm``, each case runs once untimed right before its timed run,
    so that it is timed with its own data in cache, as in a loop of calls,
    and not right after another case evicted it.
    """
    times = {name: [] for name in cases}
    for _ in range(repeats):
        for name, fn in cases.items():
            if warm:
                fn()
            start = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - start)
    return {name: statistics.median(t) for name, t in times.items()}


def load_average() -> str:
    return " / ".join(f"{x:.2f}" for x in os.getloadavg())


def main(argv=None) -> int:
    parser = arguments(__doc__, repeats=5, repeats_help="rounds for the 15-imprint cases")
    parser.add_argument("--mesh", default="nefertiti.obj")
    parser.add_argument("--batch-repeats", type=int, default=3, help="rounds for the batch cases")
    parser.add_argument("--batch", type=int, default=1000)
    parser.add_argument("--supersample", type=int, default=None, help="override the Sensor default")
    args = parser.parse_args(argv)

    import meshsal
    import tactile
    from meshsal.mesh.embree import embree_scene
    from tactile.section import imprints_exact

    path = args.meshes_dir / args.mesh
    if not path.exists():
        print(f"bench_imprints: {path} not found (use --meshes-dir)", file=sys.stderr)
        return 1
    mesh = meshsal.scale_to(meshsal.load_mesh(path), 150.0)
    sensor = tactile.Sensor() if args.supersample is None else tactile.Sensor(supersample=args.supersample)
    coarse = tactile.Sensor(supersample=2)
    rng = np.random.default_rng(0)
    normals = meshsal.vertex_normals(mesh.vertices, mesh.faces)
    ids = rng.choice(mesh.n_vertices, 15, replace=False)
    P, N = mesh.vertices[ids], normals[ids]
    batch = rng.choice(mesh.n_vertices, args.batch, replace=True)
    PB, NB = mesh.vertices[batch], normals[batch]

    load_before = load_average()
    scene = embree_scene(mesh)
    # Warm up imports and the thread pool; check that the prebuilt scene changes nothing.
    if not np.array_equal(tactile.imprints(mesh, P, N, sensor), tactile.imprints(mesh, P, N, sensor, scene=scene)):
        print("bench_imprints: a prebuilt scene changed the imprints", file=sys.stderr)
        return 1
    small = interleaved_medians(
        {
            "scene": lambda: embree_scene(mesh),
            "poses": lambda: tactile.sensor_poses(mesh, P, N, sensor),
            "fast": lambda: tactile.imprints(mesh, P, N, sensor),
            "fast_scene": lambda: tactile.imprints(mesh, P, N, sensor, scene=scene),
            "exact": lambda: imprints_exact(mesh, P, N, sensor),
        },
        args.repeats,
        warm=True,
    )
    big = interleaved_medians(
        {
            "batch": lambda: tactile.imprints(mesh, PB, NB, sensor),
            "batch_scene": lambda: tactile.imprints(mesh, PB, NB, sensor, scene=scene),
            "batch_poses": lambda: tactile.sensor_poses(mesh, PB, NB, sensor),
            "batch_coarse": lambda: tactile.imprints(mesh, PB, NB, coarse, scene=scene),
        },
        args.batch_repeats,
    )
    load_after = load_average()

    def rays(s):
        return (s.rows * s.supersample) * (s.cols * s.supersample)

    k = args.batch
    print(
        f"imprint benchmark: {path.name}, {mesh.n_faces} faces, 150 mm; sensor {sensor.rows}x{sensor.cols}, "
        f"pitch {sensor.pitch_mm} mm, supersample {sensor.supersample} ({rays(sensor)} rays/imprint), mode "
        f"{sensor.mode}, plane {sensor.plane}; {os.cpu_count()} CPUs; medians of {args.repeats} interleaved warm "
        f"rounds ({args.batch_repeats} rounds for the batches)"
    )
    print(f"load average (1/5/15 min): {load_before} before, {load_after} after\n")
    print("| measure | seconds | imprints/s | note |")
    print("|---|---|---|---|")
    print(f"| Embree scene build | {small['scene']:.4f} | | once per mesh (`meshsal.mesh.embree.embree_scene`) |")
    print(f"| pose fit, 15 points | {small['poses']:.4f} | | shared by both paths, included in both |")
    print(
        f"| fast, 15 imprints, scene built in the call | {small['fast']:.4f} | {15 / small['fast']:.0f} | "
        "`imprints(mesh, P, N, sensor)` |"
    )
    print(
        f"| fast, 15 imprints, prebuilt scene | {small['fast_scene']:.4f} | {15 / small['fast_scene']:.0f} | "
        "`imprints(..., scene=scene)` |"
    )
    print(f"| exact, 15 imprints | {small['exact']:.4f} | {15 / small['exact']:.0f} | plane sections + z-buffer |")
    print(
        f"| **ratio exact / fast, prebuilt scene** | **{small['exact'] / small['fast_scene']:.1f}x** | | "
        "target >= 20x is judged here: many imprints per mesh, scene built once |"
    )
    print(
        f"| ratio exact / fast, scene built in the call | {small['exact'] / small['fast']:.1f}x | | "
        "one-off call on a new mesh |"
    )
    print(
        f"| **fast, batch of {k}, scene built in the call** | {big['batch']:.3f} | **{k / big['batch']:.0f}** | "
        "target >= 1000/s |"
    )
    print(f"| fast, batch of {k}, prebuilt scene | {big['batch_scene']:.3f} | {k / big['batch_scene']:.0f} | |")
    print(f"| pose fit, {k} points | {big['batch_poses']:.3f} | | included above |")
    print(
        f"| fast, batch of {k}, prebuilt scene, supersample 2 | {big['batch_coarse']:.3f} | "
        f"{k / big['batch_coarse']:.0f} | {rays(coarse)} rays/imprint; not the default |"
    )
    return 0


if __name__ == "__main__":
    run("bench_imprints", "Tactile imprints: fast against exact, and batch throughput", main)
