"""Benchmark: the 72 views at 256x256 of nefertiti (100k faces), end to end, against Open3D.

Prints pixels (primary rays) per second of ``meshsal.render.render_views``
(ray generation, Embree tracing, shading, colour lookup: everything a View
holds; rays outside the bounding sphere's image disk are culled, as they
cannot hit), of its Embree tracer alone, and, in the same run, of the same 72
images through Open3D's ``RaycastingScene`` (tracing only), once with a ray
for every pixel and once with the same culled rays, when Open3D is installed
(``pip install -e '.[bench]'``; it needs ``apt-get install libusb-1.0-0``).  Figures are medians of repeats; the
ratio is the one to quote, as the machine is shared and noisy.

    python benchmarks/bench_render.py [--meshes-dir ../shared/meshes] [--repeats 7]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from meshsal import load_mesh
from meshsal.embree import embree_scene
from meshsal.mesh import bounding_sphere
from meshsal.render import _pixel_grid, _rays, render_views, view_rig

DEFAULT_MESHES = Path(__file__).resolve().parents[2] / "shared" / "meshes"


def median_seconds(fn, repeats: int) -> float:
    fn()  # warm-up: thread pools, page faults, BVH caches
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def view_rays(mesh, cameras, size, cull):
    """One (origins, directions) pair of (k, 3) float32 arrays per view, as the renderer casts them."""
    center, radius = bounding_sphere(mesh.vertices)
    return [_rays(c, center, radius, _pixel_grid(c, size, cull)[1])[:2] for c in cameras]


def embree_trace_seconds(mesh, rays, repeats):
    """The renderer's tracer alone: the same Embree queries in the same thread pool, no shading."""
    scene = embree_scene(mesh)
    with ThreadPoolExecutor(max_workers=os.cpu_count()) as pool:
        return median_seconds(lambda: list(pool.map(lambda r: scene.run(*r, output=1), rays)), repeats)


def open3d_seconds(mesh, rays, repeats):
    try:
        import open3d as o3d
    except ImportError:
        return None
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(mesh.vertices.astype(np.float32)),
                        o3d.core.Tensor(mesh.faces.astype(np.uint32)))
    batch = o3d.core.Tensor(np.vstack([np.hstack(r) for r in rays]))
    return median_seconds(lambda: scene.cast_rays(batch), repeats)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--meshes-dir", type=Path, default=DEFAULT_MESHES)
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args(argv)

    mesh = load_mesh(args.meshes_dir / "nefertiti.obj")
    cameras = [c for s in view_rig() for c in s]
    n_rays = len(cameras) * args.size**2
    ours = median_seconds(lambda: render_views(mesh, cameras, size=args.size), args.repeats)
    rays = {cull: view_rays(mesh, cameras, args.size, cull) for cull in (False, True)}
    trace = embree_trace_seconds(mesh, rays[True], args.repeats)
    peers = {cull: open3d_seconds(mesh, rays[cull], args.repeats) for cull in (False, True)}

    print(f"nefertiti: {mesh.n_faces} faces, {len(cameras)} views at {args.size}^2 = {n_rays} rays, "
          f"median of {args.repeats}\n")
    print("| renderer | seconds (72 views) | Mrays/s |")
    print("|---|---:|---:|")
    print(f"| meshsal.render (Embree, shaded) | {ours:.3f} | {n_rays / ours / 1e6:.2f} |")
    print(f"| its tracer alone (embreex, culled rays, no shading) | {trace:.3f} | {n_rays / trace / 1e6:.2f} |")
    if peers[False] is None:
        print("| Open3D RaycastingScene | not installed | |")
    else:
        for cull, label in ((False, "every pixel"), (True, "same culled rays")):
            print(f"| Open3D RaycastingScene, trace only, {label} | {peers[cull]:.3f} | "
                  f"{n_rays / peers[cull] / 1e6:.2f} |")
        print(f"\nthroughput ratio meshsal.render / Open3D: {peers[False] / ours:.2f}x (every pixel), "
              f"{peers[True] / ours:.2f}x (same culled rays)")
        print(f"tracer alone / Open3D on the same culled rays: {peers[True] / trace:.2f}x")
    print(f"target: 72 views <= 0.5 s -> {'met' if ours <= 0.5 else 'missed'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
