"""Benchmark the attention model: the eight channel maps over the 72 views, and mesh saliency.

Prints Markdown tables: time per channel for all 72 views at 256 x 256 of
the textured cow and of the hand toy at 150 mm (concave, painted per
vertex), stacks of views in a thread pool as ``saliency_views`` takes them;
the full ``saliency_views`` (all channels + combination), beside it with one
view per stack (the per-view calls on small maps that stacks avoid), and
on one thread (``saliency_views`` caps OpenCV's own pool at one thread
while its views' pool runs: the two would fight for the cores); and mesh
saliency on nefertiti (a relief), on a subdivided nefertiti of about 200k
vertices and on the hand refined to 124k faces.  Times are medians of
``--repeats`` runs, wall and process CPU time (all threads); the machine
(CPU model, cores, load average) is printed with them, as another 2-core
machine can be twice as slow.

Targets (2 cores): ``saliency_views`` of all 72 views of the cow <= 0.5 s
on an AVX-512 host and <= 0.8 s on an AVX2 one, pinned (issue 32); mesh
saliency of 100k vertices <= 1 s.  Run it pinned, as the pipeline runs:
``python -m meshsal.util.reproducible python benchmarks/bench_attention.py``.
Prints the machine line and the kernels, and writes its tables to
``docs/benchmarks/bench_attention.md``.

    .venv/bin/python benchmarks/bench_attention.py [--meshes-dir DIR] [--repeats 3]
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import cv2
import numpy as np
from benchlib import arguments, hand_124k, hand_150mm, run

import meshsal
from meshsal import attention
from meshsal.attention import combine
from meshsal.attention.combine import image_channels_stack
from meshsal.mesh.curvature import mesh_saliency
from meshsal.util.threads import opencv_threads
from meshsal.views import cameras as cameras_mod
from meshsal.views import render


def median_time(fn, repeats: int) -> tuple[float, float]:
    """Median wall time and median process CPU time (all threads) of ``fn()``, seconds.

    On a shared machine the wall time grows with other people's load; the CPU
    time does much less, and CPU / cores is what an idle machine would take
    if the threads scale.
    """
    walls, cpus = [], []
    for _ in range(repeats):
        start, cpu = time.perf_counter(), time.process_time()
        fn()
        walls.append(time.perf_counter() - start)
        cpus.append(time.process_time() - cpu)
    return statistics.median(walls), statistics.median(cpus)


def median_times_alternating(fns, repeats: int) -> list[tuple[float, float]]:
    """:func:`median_time` of several functions run in turn, so a drift of the machine's speed hits them alike."""
    walls, cpus = [[] for _ in fns], [[] for _ in fns]
    for _ in range(repeats):
        for k, fn in enumerate(fns):
            start, cpu = time.perf_counter(), time.process_time()
            fn()
            walls[k].append(time.perf_counter() - start)
            cpus[k].append(time.process_time() - cpu)
    return [(statistics.median(w), statistics.median(c)) for w, c in zip(walls, cpus)]


def channel_over_views(name, views, vertex_saliency, pool):
    if name == "curvature":
        return list(pool.map(lambda v: attention.curvature(v, vertex_saliency), views))
    stacks = [views[k : k + combine._VIEWS_PER_STACK] for k in range(0, len(views), combine._VIEWS_PER_STACK)]
    return list(pool.map(lambda stack: image_channels_stack([v.rgb for v in stack], [name]), stacks))


def one_view_per_stack(fn):
    def run():
        per_stack = combine._VIEWS_PER_STACK
        combine._VIEWS_PER_STACK = 1
        try:
            return fn()
        finally:
            combine._VIEWS_PER_STACK = per_stack

    return run


def bench_channels(mesh, label: str, size: int, repeats: int, threads: int) -> None:
    cameras = [c for s in cameras_mod.view_rig() for c in s]
    start = time.perf_counter()
    views = render.render_views(mesh, cameras, size=size)
    render_s = time.perf_counter() - start
    vertex_saliency = mesh_saliency(mesh)

    def whole(workers):
        return lambda: attention.saliency_views(views, mesh, vertex_saliency=vertex_saliency, threads=workers)

    rows = []
    with ThreadPoolExecutor(max_workers=threads) as pool:
        for name in attention.CHANNELS:
            rows.append(
                (name, *median_time(lambda name=name: channel_over_views(name, views, vertex_saliency, pool), repeats))
            )
    rows.append(("sum of channels", sum(r[1] for r in rows), sum(r[2] for r in rows)))
    stacked, single = median_times_alternating([whole(threads), one_view_per_stack(whole(threads))], repeats)
    rows.append(("saliency_views (8 channels + combination)", *stacked))
    rows.append(("saliency_views, one view per stack", *single))
    default = cv2.getNumThreads()
    with opencv_threads(1):
        rows.append(("saliency_views on one thread", *median_time(whole(1), repeats)))

    n = len(views)
    print(
        f"\n### Channel maps: {label}, {n} views at {size}x{size}, "
        f"{threads} threads (OpenCV: {default}), median of {repeats}\n"
    )
    print("| channel | wall, all views (s) | CPU, all views (s) | CPU per view (ms) |")
    print("|---|---:|---:|---:|")
    for name, wall, cpu in rows:
        print(f"| {name} | {wall:.3f} | {cpu:.3f} | {1000 * cpu / n:.2f} |")
    wall, cpu = stacked
    print(
        f"\nTarget: saliency_views of all views <= 0.5 s on 2 cores (AVX-512), pinned; measured {wall:.2f} s wall, "
        f"{cpu:.2f} s CPU (load average at the end: {os.getloadavg()[0]:.1f}). "
        f"Rendering the views, not included: {render_s:.2f} s. Stacks of {combine._VIEWS_PER_STACK} views "
        f"against one view per stack, run in turn: {single[0] / stacked[0]:.2f}x the speed."
    )


def subdivided(mesh, target_vertices: int):
    import igl

    V = np.ascontiguousarray(mesh.vertices, np.float64)
    F = np.ascontiguousarray(mesh.faces, np.int64)
    while V.shape[0] < target_vertices:
        V, F = igl.upsample(V, F)
    return meshsal.Mesh(vertices=V, faces=F.astype(np.int32), name=f"{mesh.name} subdivided")


def bench_mesh_saliency(meshes_dir: Path, repeats: int) -> None:
    path = meshes_dir / "nefertiti.obj"
    base = meshsal.load_mesh(path)
    cases = [
        ("nefertiti", base),
        ("nefertiti, 1:4 midpoint upsample (igl.upsample)", subdivided(base, 150_000)),
        ("hand toy, Loop-subdivided and decimated to 124k faces (concave)", hand_124k()),
    ]
    print(f"\n### Mesh saliency (Lee et al. 2005), median of {repeats}\n")
    print("| mesh | vertices | faces | wall (s) | CPU (s) | wall per 100k vertices (s) |")
    print("|---|---:|---:|---:|---:|---:|")
    for label, mesh in cases:
        wall, cpu = median_time(lambda mesh=mesh: mesh_saliency(mesh), repeats)
        n = mesh.vertices.shape[0]
        print(f"| {label} | {n} | {mesh.faces.shape[0]} | {wall:.3f} | {cpu:.3f} | {wall * 1e5 / n:.3f} |")
    print(f"\nTarget: 100k vertices <= 1 s (load average at the end: {os.getloadavg()[0]:.1f}).")


def main(argv=None) -> int:
    parser = arguments(__doc__, repeats=3)
    parser.add_argument("--size", type=int, default=256, help="view size in pixels (default 256)")
    parser.add_argument(
        "--threads", type=int, default=os.cpu_count() or 1, help="worker threads over views (default: CPU count)"
    )
    parser.add_argument("--skip-mesh-saliency", action="store_true", help="only time the channel maps")
    args = parser.parse_args(argv)
    spot = args.meshes_dir / "spot" / "spot.obj"
    if not spot.exists():
        print(f"bench_attention: error: {spot} not found (use --meshes-dir)", file=sys.stderr)
        return 1
    from meshsal.util.reproducible import kernels

    print(f"kernels: {kernels()}")
    bench_channels(meshsal.load_mesh(spot), "the textured cow (spot)", args.size, args.repeats, args.threads)
    bench_channels(
        hand_150mm(), "the hand toy at 150 mm (concave, painted per vertex)", args.size, args.repeats, args.threads
    )
    if not args.skip_mesh_saliency:
        bench_mesh_saliency(args.meshes_dir, args.repeats)
    return 0


if __name__ == "__main__":
    run("bench_attention", "Attention: eight channels on 72 views, and mesh saliency", main)
