"""Benchmark: fast (Embree) imprints against exact plane sections, and batch throughput.

15 imprints at random vertices of nefertiti (scaled to 150 mm) through the
fast path (``tactile.imprints``: pose fit, scene build, one ray batch) and
the exact reference path (``tactile.section.imprints_exact``) in the same
run, median of repeats; then imprints per second of one batch of 1000
points.  Prints a Markdown table.

    .venv/bin/python benchmarks/bench_imprints.py [--meshes-dir DIR] [--repeats 5]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np


def median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--meshes-dir", type=Path, default=Path(__file__).resolve().parents[2] / "shared" / "meshes")
    parser.add_argument("--mesh", default="nefertiti.obj")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--batch", type=int, default=1000)
    parser.add_argument("--supersample", type=int, default=None, help="override the Sensor default")
    args = parser.parse_args(argv)

    import meshsal
    import tactile
    from tactile.raycast import _scene
    from tactile.section import imprints_exact

    path = args.meshes_dir / args.mesh
    if not path.exists():
        print(f"bench_imprints: {path} not found (use --meshes-dir)", file=sys.stderr)
        return 1
    mesh = meshsal.scale_to(meshsal.load_mesh(path), 150.0)
    sensor = tactile.Sensor() if args.supersample is None else tactile.Sensor(supersample=args.supersample)
    rng = np.random.default_rng(0)
    normals = meshsal.vertex_normals(mesh.vertices, mesh.faces)
    ids = rng.choice(mesh.n_vertices, 15, replace=False)
    P, N = mesh.vertices[ids], normals[ids]
    batch = rng.choice(mesh.n_vertices, args.batch, replace=True)
    PB, NB = mesh.vertices[batch], normals[batch]

    tactile.imprints(mesh, P, N, sensor)  # warm up imports and the thread pool
    fast = median_time(lambda: tactile.imprints(mesh, P, N, sensor), args.repeats)
    poses = median_time(lambda: tactile.sensor_poses(mesh, P, N, sensor), args.repeats)
    scene = median_time(lambda: _scene(mesh), args.repeats)
    exact = median_time(lambda: imprints_exact(mesh, P, N, sensor), max(1, args.repeats // 2))
    big = median_time(lambda: tactile.imprints(mesh, PB, NB, sensor), max(1, args.repeats // 2))
    big_poses = median_time(lambda: tactile.sensor_poses(mesh, PB, NB, sensor), max(1, args.repeats // 2))
    rays = (sensor.rows * sensor.supersample) * (sensor.cols * sensor.supersample)

    print(f"nefertiti-like benchmark: {path.name}, {mesh.n_faces} faces, 150 mm; sensor {sensor.rows}x{sensor.cols}, "
          f"pitch {sensor.pitch_mm} mm, supersample {sensor.supersample} ({rays} rays/imprint), mode {sensor.mode}; "
          f"{os.cpu_count()} CPUs, median of {args.repeats}\n")
    print("| measure | seconds | imprints/s | note |")
    print("|---|---|---|---|")
    print(f"| fast, 15 imprints | {fast:.4f} | {15 / fast:.0f} | pose fit + scene build + rays |")
    print(f"| exact, 15 imprints | {exact:.4f} | {15 / exact:.0f} | plane sections + z-buffer |")
    print(f"| **ratio exact / fast (15)** | **{exact / fast:.1f}x** | | target >= 20x |")
    print(f"| of which pose fit (15) | {poses:.4f} | | shared by both paths |")
    print(f"| of which Embree scene build | {scene:.4f} | | once per call |")
    print(f"| **fast, batch of {args.batch}** | {big:.3f} | **{args.batch / big:.0f}** | target >= 1000/s |")
    print(f"| of which pose fit ({args.batch}) | {big_poses:.3f} | | |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
