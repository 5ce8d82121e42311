"""Batch throughput: meshes per second on a Dask LocalCluster of 1 and of 2 workers, side by side.

For each worker count, a fresh store receives the attention and uniform
points and 15 imprints of the first ``--meshes`` meshes of the corpus
(``../shared/corpus/random-objects``, about 470 faces each).  Printed: wall
time with the cluster already up, meshes/s, the speed-up of 2 workers over
1, the scheduling overhead (the share of the workers' time not spent inside
a task) and the peak memory of a worker.  Then the median time of each stage
per mesh, for the corpus and for the ten embedded YCB scans (15,728 faces),
and what 1,000 such objects would take on N workers at the measured
efficiency.

    .venv/bin/python benchmarks/bench_batch.py [--meshes 120] [--corpus DIR]
"""

from __future__ import annotations

import argparse
import resource
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from benchlib import run

from classify.batch import STAGES, BatchSettings, find_meshes, process_mesh, run_batch
from classify.runtime.cluster import open_executor

SHARED = Path(__file__).resolve().parents[2] / "shared" / "corpus" / "random-objects"


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _subset(corpus: Path, count: int, into: Path) -> Path:
    into.mkdir(parents=True, exist_ok=True)
    for _, path in find_meshes(corpus)[:count]:
        shutil.copy(path, into / path.name)
    return into


def _run(folder: Path, workers: int, settings: BatchSettings, scratch: Path) -> dict:
    store = scratch / f"store{workers}"
    with open_executor(workers=workers) as executor:
        client = executor._client if hasattr(executor, "_client") else None
        started = time.perf_counter()
        summary = run_batch(folder, store, settings, executor, quiet=True)
        wall = time.perf_counter() - started
        peak = max(client.run(_peak_rss_mb).values()) if client is not None else float("nan")
    busy = 0.0
    from classify.batch import load_store

    for entry in load_store(store).values():
        busy += sum(entry.timings.values())
    return {
        "workers": workers,
        "wall": wall,
        "done": summary.done,
        "rate": summary.done / wall,
        "overhead": 1.0 - busy / (workers * wall),
        "peak_mb": peak,
        "stages": summary.stage_median_s,
    }


def _ycb_stages(settings: BatchSettings, scratch: Path) -> dict:
    from meshsal.objects import ycb

    times = {k: [] for k in STAGES}
    for name in ycb.NAMES:
        result = process_mesh(ycb.path(name), name, scratch / "ycb", settings)
        for k in STAGES:
            times[k].append(result["timings"][k])
    return {k: float(np.median(v)) for k, v in times.items()}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--meshes", type=int, default=120)
    parser.add_argument("--corpus", type=Path, default=SHARED)
    args = parser.parse_args()
    if not args.corpus.is_dir():
        print(f"corpus not found at {args.corpus}", file=sys.stderr)
        return 1
    settings = BatchSettings(methods=("attention", "uniform"), n_points=15)
    scratch = Path(tempfile.mkdtemp(prefix="bench_batch_"))
    try:
        folder = _subset(args.corpus, args.meshes, scratch / "meshes")
        runs = [_run(folder, w, settings, scratch) for w in (1, 2)]
        print(f"### {args.meshes} corpus meshes, attention + uniform points, 15 imprints each\n")
        print("| workers | wall (cluster up) | meshes/s | scheduling overhead | peak memory per worker |")
        print("|---:|---:|---:|---:|---:|")
        for r in runs:
            print(
                f"| {r['workers']} | {r['wall']:.1f} s | {r['rate']:.2f} | {100 * r['overhead']:.1f} % "
                f"| {r['peak_mb']:.0f} MB |"
            )
        print(
            f"\n2 workers / 1 worker: {runs[1]['rate'] / runs[0]['rate']:.2f}x; the 1,000-mesh corpus on 2 workers "
            f"at this rate: {1000 / runs[1]['rate'] / 60:.1f} min\n"
        )
        ycb = _ycb_stages(settings, scratch)
        print("| stage, median per mesh | corpus (~470 faces, 1 worker) | YCB scan (15,728 faces, in process) |")
        print("|---|---:|---:|")
        for k in STAGES:
            print(f"| {k} | {1000 * runs[0]['stages'].get(k, float('nan')):.1f} ms | {1000 * ycb[k]:.1f} ms |")
        per_mesh = sum(ycb.values())
        efficiency = 1.0 - runs[1]["overhead"]
        print(
            f"\n1,000 YCB-sized objects: {per_mesh:.2f} s each; on N workers about "
            + ", ".join(f"N={n}: {1000 * per_mesh / (n * efficiency) / 60:.1f} min" for n in (2, 8, 32))
        )
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    return 0


if __name__ == "__main__":
    run("bench_batch", "Corpus batch on Dask workers", main)
