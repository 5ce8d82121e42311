"""How many candidates each point method loses because the pad could not touch them first.

For every object (default: the toys and the ten YCB scans) at its nominal
150 mm size, run each point method with the touch check (32 mm pad, 1 mm
tolerance) and print, as a Markdown table, how many candidates it skipped
before it had its 15 points (``InterestPoints.untouchable``).

    .venv/bin/python scripts/touchable.py [--objects toys,ycb] [--methods attention,random,uniform,mesh_saliency]
"""

from __future__ import annotations

import argparse
import sys

import meshsal
from meshsal.mesh.transform import scale_to_principal
from meshsal.objects import load_ref, resolve_objects


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--objects", default="toys,ycb")
    parser.add_argument("--methods", default="attention,random,uniform,mesh_saliency")
    args = parser.parse_args()
    methods = meshsal.points.POINT_METHODS.check(args.methods.split(","))
    print("| object | " + " | ".join(methods) + " |")
    print("|---|" + ":---:|" * len(methods))
    totals = dict.fromkeys(methods, 0)
    refs = resolve_objects([args.objects])
    for ref in refs:
        mesh = scale_to_principal(load_ref(ref), 150.0)
        row = []
        for method in methods:
            lost = meshsal.interest_points(mesh, n=15, method=method, pad_width=32.0).untouchable
            totals[method] += lost
            row.append(str(lost))
        print(f"| {mesh.name} | " + " | ".join(row) + " |", flush=True)
    print(f"| all {len(refs)} | " + " | ".join(str(totals[m]) for m in methods) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
