"""Benchmark: ``meshsal.interest_points`` end to end, time per stage, on a relief and on concave meshes.

Four meshes, each at a 150 mm diagonal: the textured cow (spot), nefertiti
(100k faces, a relief: a pad reaches nearly everywhere), the hand toy (40k
faces, concave: hundreds of candidates between the fingers are refused by
the touch check, and its selection runs on into the fill from every
vertex) and the hand refined to 124k faces (a large scan's size, where a
touch check that asks about candidates one at a time costs seconds).  Stages of the attention method, each timed alone: mesh saliency,
rendering the 72 views, their eight channel maps, combining them, the fusion
on the mesh (best set, peaks, votes, selection) without the touch check, and
what the touch check adds to it; then the whole ``interest_points`` call.
Medians of ``--repeats`` runs, wall and process CPU time (all threads): on a
shared machine the CPU time is the steadier figure.  Targets: every mesh up
to 124k faces <= 2 s end to end on 2 cores.

    python benchmarks/bench_points.py [--meshes-dir ../shared/meshes] [--repeats 3] [--size 128]
"""

from __future__ import annotations

import dataclasses
import statistics
from pathlib import Path

from benchlib import arguments, hand_124k, hand_150mm, run, timed

from meshsal import load_mesh, scale_to
from meshsal.attention import saliency_views
from meshsal.attention.rig import ViewChannels, attention_maps
from meshsal.mesh.curvature import mesh_saliency
from meshsal.points import interest_points
from meshsal.points.attend import attention_points
from meshsal.points.rules import PointOptions
from meshsal.views.cameras import view_rig
from meshsal.views.render import render_views

TARGET_S = 2.0


def meshes(meshes_dir: Path) -> list:
    """(label, mesh) pairs; a public mesh that is missing is skipped, saying so."""
    out = []
    for label, name in (("cow (spot, textured)", "spot/spot.obj"), ("nefertiti (relief)", "nefertiti.obj")):
        path = meshes_dir / name
        if path.exists():
            out.append((label, scale_to(load_mesh(path))))
        else:
            print(f"skipping {label}: {path} not found")
    return out + [("hand toy (concave)", hand_150mm()), ("hand, 124k faces (concave)", hand_124k())]


def stages(mesh, size: int) -> dict:
    """(wall, CPU) seconds of each stage of the attention method, run once."""
    vs, *t_sal = timed(lambda: mesh_saliency(mesh))
    views, *t_render = timed(lambda: render_views(mesh, [c for s in view_rig() for c in s], size=size))
    # As view_channels computes them.
    results, *t_channels = timed(lambda: saliency_views(views, mesh, vertex_saliency=vs, normalize=False))
    seen = ViewChannels(views, results)
    maps, *t_combine = timed(lambda: attention_maps(seen, "equal"))
    rules = PointOptions().rules(mesh)
    free = dataclasses.replace(rules, touch=False)
    _, *t_fuse = timed(lambda: attention_points(mesh, seen.views, maps, vs, free))
    pts, *t_touch = timed(lambda: attention_points(mesh, seen.views, maps, vs, rules))
    _, *t_total = timed(lambda: interest_points(mesh, size=size))
    return {
        "mesh saliency": t_sal,
        "render 72 views": t_render,
        "8 channels x 72": t_channels,
        "combine": t_combine,
        "fusion, no touch check": t_fuse,
        "touch check (added)": [a - b for a, b in zip(t_touch, t_fuse)],
        "interest_points": t_total,
        "untouchable": (pts.untouchable, pts.untouchable),
    }


def main(argv=None) -> int:
    parser = arguments(__doc__, repeats=3)
    parser.add_argument("--size", type=int, default=128, help="view size in pixels (default 128)")
    args = parser.parse_args(argv)
    rows = []
    for label, mesh in meshes(args.meshes_dir):
        stages(mesh, args.size)  # warm-up: imports, thread pools, page faults
        runs = [stages(mesh, args.size) for _ in range(args.repeats)]
        medians = {k: [statistics.median(r[k][i] for r in runs) for i in (0, 1)] for k in runs[0]}
        rows.append((label, mesh.n_faces, medians))

    names = [k for k in rows[0][2] if k != "untouchable"]
    print(
        f"\ninterest_points (attention) at {args.size}x{args.size}, median of {args.repeats}: "
        "wall / CPU seconds (CPU of all threads)\n"
    )
    print("| mesh | faces | refused | " + " | ".join(names) + " |")
    print("|---|---:|---:|" + "---:|" * len(names))
    for label, faces, med in rows:
        cells = " | ".join(f"{med[k][0]:.2f} / {med[k][1]:.2f}" for k in names)
        print(f"| {label} | {faces} | {med['untouchable'][0]:.0f} | {cells} |")
    print()
    for label, _, med in rows:
        wall = med["interest_points"][0]
        verdict = "met" if wall <= TARGET_S else "NOT met (see the load average)"
        print(
            f"{label}: end to end {wall:.2f} s wall, {med['interest_points'][1]:.2f} s CPU "
            f"(target <= {TARGET_S:.0f} s on 2 cores): {verdict}"
        )
    return 0


if __name__ == "__main__":
    run("bench_points", "Interest points end to end, by stage", main)
