"""Benchmark: ``meshsal.interest_points`` end to end, time per stage.

On the textured cow (spot) and on nefertiti (100k faces), each scaled to a
150 mm diagonal: mesh saliency, rendering the 72 views, their saliency maps,
and the fusion on the mesh (best set, peaks, votes, suppression), then the
whole ``interest_points`` call.  Figures are medians of repeats on a shared
machine; the target is <= 3 s for nefertiti end to end.

    python benchmarks/bench_points.py [--meshes-dir ../shared/meshes] [--repeats 3] [--size 128]
"""

from __future__ import annotations

import argparse
import statistics
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from meshsal import load_mesh, scale_to
from meshsal.attention import saliency
from meshsal.mesh.curvature import mesh_saliency
from meshsal.points import attention_points, interest_points
from meshsal.views.cameras import view_rig
from meshsal.views.render import render_views

DEFAULT_MESHES = Path(__file__).resolve().parents[2] / "shared" / "meshes"
MESHES = (("cow (spot, textured)", "spot/spot.obj"), ("nefertiti", "nefertiti.obj"))


def timed(fn):
    start = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - start


def stages(mesh, size: int) -> dict:
    """Seconds of each stage of the attention pipeline, run once."""
    cameras = [c for s in view_rig() for c in s]
    vs, t_sal = timed(lambda: mesh_saliency(mesh))
    views, t_render = timed(lambda: render_views(mesh, cameras, size=size))

    def maps():
        with ThreadPoolExecutor() as pool:
            return list(pool.map(lambda v: saliency(v, mesh, vertex_saliency=vs).map, views))

    m, t_maps = timed(maps)
    _, t_fuse = timed(lambda: attention_points(mesh, views, m, vs))
    _, t_total = timed(lambda: interest_points(mesh, size=size))
    return {"mesh saliency": t_sal, "render 72 views": t_render, "72 saliency maps": t_maps,
            "fusion on the mesh": t_fuse, "interest_points (end to end)": t_total}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--meshes-dir", type=Path, default=DEFAULT_MESHES)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--size", type=int, default=128, help="view size in pixels (default 128)")
    args = parser.parse_args(argv)

    rows = []
    for label, name in MESHES:
        path = args.meshes_dir / name
        if not path.exists():
            print(f"skipping {label}: {path} not found")
            continue
        mesh = scale_to(load_mesh(path))
        stages(mesh, args.size)  # warm-up: imports, thread pools, page faults
        runs = [stages(mesh, args.size) for _ in range(args.repeats)]
        medians = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
        rows.append((label, mesh.n_vertices, mesh.n_faces, medians))

    if not rows:
        return 1
    names = list(rows[0][3])
    print(f"interest_points at {args.size}x{args.size}, median of {args.repeats} (seconds)\n")
    print("| mesh | vertices | faces | " + " | ".join(names) + " |")
    print("|---|---:|---:|" + "---:|" * len(names))
    for label, nv, nf, med in rows:
        print(f"| {label} | {nv} | {nf} | " + " | ".join(f"{med[k]:.2f}" for k in names) + " |")
    for label, _, _, med in rows:
        if label == "nefertiti":
            total = med["interest_points (end to end)"]
            print(f"\nnefertiti end to end: {total:.2f} s (target <= 3 s): {'met' if total <= 3.0 else 'NOT met'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
