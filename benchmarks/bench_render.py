"""Benchmark: the 72 views at 256x256 of nefertiti (100k faces), end to end, against Open3D.

Prints pixels (primary rays) per second of ``meshsal.render.render_views``
(everything a View holds: ray generation, Embree tracing, shading, the
pixel-to-surface maps), with the Embree scene built in the call and prebuilt,
and of its Embree tracer alone.  In the same run it casts a ray for every
pixel of the same 72 images through Open3D's ``RaycastingScene`` (tracing
only; scene prebuilt, and built in the call), and our own candidate rays too,
when Open3D is installed (``pip install -e '.[bench]'``; it needs
``apt-get install libusb-1.0-0``).  The renderer casts rays only inside the
image of the mesh's convex hull, as no other ray can hit.  Figures are medians
of repeats; the ratios are the ones to quote, as the machine is shared and
noisy.

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
from meshsal.render import _candidates, _hull_points, _pixel_grid, _rays, render_views, view_rig

DEFAULT_MESHES = Path(__file__).resolve().parents[2] / "shared" / "meshes"


def median_seconds(fn, repeats: int) -> float:
    fn()  # warm-up: thread pools, page faults, BVH caches
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def every_pixel_rays(mesh, cameras, size):
    """(k, 6) float32 origins and directions of a ray through every pixel centre, as Open3D takes them."""
    center, radius = bounding_sphere(mesh.vertices)
    grid = _pixel_grid(size)
    rays = []
    for c in cameras:
        origins, directions, _ = _rays(c, center, radius, grid.xy1)
        rays.append(np.hstack([origins, np.broadcast_to(directions, origins.shape)]))
    return np.vstack(rays)


def candidate_rays(mesh, cameras, size):
    """One (origins, direction) pair per view: the rays the renderer casts."""
    center, radius = bounding_sphere(mesh.vertices)
    hull, grid = _hull_points(mesh.vertices), _pixel_grid(size)
    return [_rays(c, center, radius, grid.xy1[_candidates(c, center, radius, grid, hull)])[:2] for c in cameras]


def embree_trace_seconds(scene, rays, repeats):
    """The renderer's tracer alone: the same Embree queries in the same thread pool, no shading."""
    with ThreadPoolExecutor(max_workers=os.cpu_count()) as pool:
        return median_seconds(lambda: list(pool.map(lambda r: scene.run(*r, dists=np.inf, output=1), rays)),
                              repeats)


def open3d_seconds(mesh, rays, repeats, build: bool):
    """Open3D casting the (k, 6) rays; with ``build``, its scene is made and built in the timed call."""
    try:
        import open3d as o3d
    except ImportError:
        return None
    vertices = o3d.core.Tensor(mesh.vertices.astype(np.float32))
    faces = o3d.core.Tensor(mesh.faces.astype(np.uint32))
    batch = o3d.core.Tensor(np.ascontiguousarray(rays))

    def new_scene():
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(vertices, faces)
        return scene

    if build:
        return median_seconds(lambda: new_scene().cast_rays(batch), repeats)
    scene = new_scene()
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
    scene = embree_scene(mesh)
    ours = {"prebuilt": median_seconds(lambda: render_views(mesh, cameras, size=args.size, scene=scene), args.repeats),
            "built": median_seconds(lambda: render_views(mesh, cameras, size=args.size), args.repeats)}
    candidates = candidate_rays(mesh, cameras, args.size)
    cast = sum(len(o) for o, _ in candidates)
    trace = embree_trace_seconds(scene, candidates, args.repeats)
    every = every_pixel_rays(mesh, cameras, args.size)
    same = np.vstack([np.hstack([o, np.broadcast_to(d, o.shape)]) for o, d in candidates])
    peers = {"prebuilt": open3d_seconds(mesh, every, args.repeats, build=False),
             "built": open3d_seconds(mesh, every, args.repeats, build=True),
             "same": open3d_seconds(mesh, same, args.repeats, build=False)}

    print(f"nefertiti: {mesh.n_faces} faces, {len(cameras)} views at {args.size}^2 = {n_rays} pixels; "
          f"the renderer casts {cast} rays ({cast / n_rays:.0%}), median of {args.repeats}\n")
    print("| renderer | seconds (72 views) | Mpixels/s |")
    print("|---|---:|---:|")
    rows = [("meshsal.render_views (Embree, shaded), scene prebuilt", ours["prebuilt"]),
            ("meshsal.render_views, scene built in the call", ours["built"]),
            ("its tracer alone (embreex, its rays, no shading)", trace)]
    if peers["prebuilt"] is not None:
        rows += [("Open3D RaycastingScene, trace only, a ray per pixel, scene prebuilt", peers["prebuilt"]),
                 ("Open3D, scene built in the call, a ray per pixel", peers["built"]),
                 ("Open3D, trace only, the renderer's rays", peers["same"])]
    for label, seconds in rows:
        print(f"| {label} | {seconds:.3f} | {n_rays / seconds / 1e6:.2f} |")
    if peers["prebuilt"] is None:
        print("\nOpen3D is not installed: no ratio.")
    else:
        print(f"\nthroughput ratio meshsal.render_views / Open3D: {peers['prebuilt'] / ours['prebuilt']:.2f}x "
              f"(both scenes prebuilt), {peers['built'] / ours['built']:.2f}x (both built in the call)")
        print(f"tracer alone / Open3D on the same rays: {peers['same'] / trace:.2f}x")
    print(f"target: 72 views <= 0.5 s -> {'met' if ours['built'] <= 0.5 else 'missed'} "
          f"({ours['built']:.3f} s with the scene built in the call)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
