"""Benchmark: ``meshsal.load_mesh`` (checks, pymeshlab, repairs), CPU time per mesh.

The loader is on the path of every mesh of a batch, so its cost is measured
on the benchmark mesh (nefertiti, 100k faces, OBJ), a YCB scan as shipped
(OBJ, 15,728 faces) and as embedded (binary PLY), and a corpus mesh (about
470 faces).  Figures are the median and the minimum of ``time.process_time``
over repeats (CPU time of this process: steadier than wall time on a shared
machine).

    python benchmarks/bench_load.py [--meshes-dir ../shared/meshes] [--corpus ../shared/corpus/random-objects]
                                    [--repeats 15]
"""

from __future__ import annotations

import statistics
import time
import warnings
from pathlib import Path

from benchlib import arguments, run

from meshsal import load_mesh
from meshsal.objects import ycb

SHARED = Path(__file__).resolve().parents[2] / "shared"


def cpu_times(path: Path, repeats: int) -> list[float]:
    """CPU seconds of ``repeats`` loads of ``path`` (repair warnings silenced)."""
    times = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        load_mesh(path)  # imports and first-touch costs stay out of the figures
        for _ in range(repeats):
            start = time.process_time()
            load_mesh(path)
            times.append(time.process_time() - start)
    return times


def main(argv=None) -> int:
    parser = arguments(__doc__, repeats=15)
    parser.add_argument("--corpus", type=Path, default=SHARED / "corpus" / "random-objects")
    args = parser.parse_args(argv)
    meshes = [
        ("nefertiti (OBJ, 99,938 faces)", args.meshes_dir / "nefertiti.obj"),
        ("power_drill (YCB OBJ, 15,728 faces)", args.meshes_dir / "ycb" / "power_drill.obj"),
        ("power_drill (embedded PLY)", ycb.path("power_drill")),
        ("corpus 000.obj (about 470 faces)", args.corpus / "000.obj"),
    ]
    print("| mesh | median CPU ms | min CPU ms |")
    print("|---|---:|---:|")
    for label, path in meshes:
        if not path.exists():
            print(f"| {label} | missing: {path} | |")
            continue
        times = cpu_times(path, args.repeats)
        print(f"| {label} | {1000 * statistics.median(times):.1f} | {1000 * min(times):.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    run("bench_load", "Loading meshes: checks, pymeshlab, repairs", main)
