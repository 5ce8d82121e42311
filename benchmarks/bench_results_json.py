"""Benchmark: how ``results.json`` grows with the number of objects (target: linearly, as every stage's cost).

For each count of corpus objects (``../shared/corpus/random-objects``, the
first N files that load, sorted by name), one run of ``run_experiment``
with the settings of ``bench_scaling.py`` (``benchlib.scaling_config``),
all runs sharing one cache, so that each object's instances are computed
once.  Each run writes its outputs; the table gives ``results.json``'s
size, its confusions' part, the bytes per object, and the time to read it
back (``json.loads`` and ``ExperimentResult.from_json``, median of
``--repeats``); beside it, the same result written with dense confusion
matrices (n x n counts) and every number on its own line
(``json.dumps(..., indent=2)``), whose confusions grow with the square of
the objects.

    python -m meshsal.util.reproducible .venv/bin/python benchmarks/bench_results_json.py [--counts 16,64,256]
"""

from __future__ import annotations

import json
import statistics
import sys
import tempfile
import time
import warnings
from pathlib import Path

from benchlib import CORPUS, arguments, corpus_files, run, scaling_config

from classify.experiment import run_experiment
from classify.reporting import report
from classify.reporting.results import ExperimentResult

MB = 1e6


def _dense(result: ExperimentResult) -> tuple[int, int]:
    """The bytes of the result written with dense confusion matrices, one number a line: all, and the confusions'."""
    document = result.to_json()
    for written, confusion in zip(document["confusions"], result.confusions):
        del written["pairs"]
        written["counts"] = confusion.counts.tolist()
    every = len(json.dumps(document, indent=2, default=lambda o: o.tolist()).encode())
    confusions = len(json.dumps(document["confusions"], indent=2).encode())
    return every, confusions


def _row(count: int, cache: Path, out: Path, repeats: int) -> dict:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = run_experiment(
            corpus_files(count), scaling_config(), cache_dir=cache, out_dir=out, quiet=True, skip_bad=True
        )
    text = (out / "results.json").read_text()
    reads = []
    for _ in range(repeats):
        started = time.perf_counter()
        ExperimentResult.from_json(document := json.loads(text))
        reads.append(time.perf_counter() - started)
    dense, dense_confusions = _dense(result)
    return {
        "objects": len(result.object_names),
        "confusions": len(result.confusions),
        "bytes": len(text.encode()),
        "confusion_bytes": len(report.json_text(document["confusions"]).encode()),
        "read_s": statistics.median(reads),
        "dense": dense,
        "dense_confusions": dense_confusions,
    }


def main(args) -> int:
    if not CORPUS.is_dir():
        print(f"bench_results_json: error: {CORPUS} not found", file=sys.stderr)
        return 1
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_results_json-") as tmp:
        for count in (int(c) for c in args.counts.split(",")):
            rows.append(_row(count, Path(tmp) / "cache", Path(tmp) / f"out-{count}", args.repeats))
            print(f"{count} objects: {rows[-1]['bytes'] / MB:.2f} MB", file=sys.stderr)
    print(
        "| objects | confusion matrices | results.json (MB) | its confusions (MB) | bytes per object | read back (s) "
        "| dense, one number a line (MB) | its confusions (MB) | bytes per object |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        n = r["objects"]
        print(
            f"| {n} | {r['confusions']} | {r['bytes'] / MB:.2f} | {r['confusion_bytes'] / MB:.2f} | {r['bytes'] / n:,.0f} "
            f"| {r['read_s']:.2f} | {r['dense'] / MB:.2f} | {r['dense_confusions'] / MB:.2f} | {r['dense'] / n:,.0f} |"
        )
    first, last = rows[0], rows[-1]
    for label, key in (("results.json", "bytes"), ("dense, one number a line", "dense")):
        growth = (last[key] / last["objects"]) / (first[key] / first["objects"])
        print(f"\n{label}: bytes per object, {last['objects']} objects over {first['objects']}: {growth:.2f}x")
    return 0


if __name__ == "__main__":
    parser = arguments(
        __doc__, 5, meshes_dir=False, repeats_help="reads of each results.json; the figure is their median"
    )
    parser.add_argument("--counts", default="16,64,256", help="comma-separated object counts")
    run("bench_results_json", "How results.json grows with the number of objects", lambda: main(parser.parse_args()))
