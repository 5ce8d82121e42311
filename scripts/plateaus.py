"""Peaks or plateaus? The share of the silhouette above half the map's maximum, per object.

For every object (default: the ten embedded YCB scans), render the 72 views
at 128 px, compute their saliency maps with the paper's equal weights and
with Itti's N(.) on each channel, and print the median over views of
``meshsal.attention.plateau_fraction`` as a Markdown table: near 0 a map
singles out a few spots, near 1 it is high over the whole object.

    .venv/bin/python scripts/plateaus.py [--objects ycb] [--size 128]
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from meshsal.attention import plateau_fraction
from meshsal.mesh.curvature import mesh_saliency
from meshsal.mesh.transform import scale_to_principal
from meshsal.objects import load_ref, resolve_objects
from meshsal.points import saliency_maps

#: The fixed combinations ("learned" needs a fitted touch model, which this script does not have).
COMBINATIONS = ("equal", "itti")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--objects", default="ycb")
    parser.add_argument("--size", type=int, default=128)
    args = parser.parse_args()
    print("| object | " + " | ".join(f"{c}: silhouette above half max" for c in COMBINATIONS) + " |")
    print("|---|" + ":---:|" * len(COMBINATIONS))
    totals = {c: [] for c in COMBINATIONS}
    for ref in resolve_objects([args.objects]):
        mesh = scale_to_principal(load_ref(ref), 150.0)
        field = mesh_saliency(mesh)
        row = []
        for combination in COMBINATIONS:
            views, maps = saliency_maps(mesh, size=args.size, vertex_saliency=field, combination=combination)
            share = float(np.median([plateau_fraction(m, v.mask) for m, v in zip(maps, views)]))
            totals[combination].append(share)
            row.append(f"{100 * share:.0f} %")
        print(f"| {mesh.name} | " + " | ".join(row) + " |", flush=True)
    print("| median | " + " | ".join(f"{100 * np.median(totals[c]):.0f} %" for c in COMBINATIONS) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
