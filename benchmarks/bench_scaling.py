"""Benchmark: how the experiment's cost grows with the number of objects (target: time per object flat within 1.5x).

For each count of corpus objects (``../shared/corpus/random-objects``, the
first N files that load, sorted by name), one run of ``run_experiment`` with
fixed settings: 2 replicates of the instance protocol, uniform and
mesh-saliency points, kNN and the place-aware recognizer, polar features,
``info_gain``, 5 points per instance, 64 px views, nothing cached.  Each run
is a fresh process (so peak memory is its own), with two local workers.
A count whose run takes under 5 minutes runs ``--repeats`` times (default
3) and its row is the run of median wall time: the smallest count's time
per object is the ratio's denominator, and a short run is the one a busy
machine moves most.
The first table gives, per count, each stage's wall time, the whole run's
wall and CPU time, the time per object, its peak memory (of its largest
process, and of all its processes together) and the recognition rate after
1 and 5 touches with its interval; the second, each stage's wall time, CPU
time and peak memory (all processes, sampled every 0.1 s:
``classify.runtime.usage``); a PNG plots time per object against the
number of objects.
Stages whose time per object grows with the objects are the ones to fix.
Past 16 objects ``info_gain`` forecasts under the belief's 16 most likely
objects, and screened by touch the place-aware recognizer scores a touch in
full under 16 (``classify.recognizers.shortlist``): their rates there are
the shortlisted model's, below what the full model gives.
The page is named by the screening it ran (``--screening``, default the
recognizer's own, ``place``: every touch scored under every object):
``bench_scaling_place.md`` or ``bench_scaling_touch.md``, with its PNG, so
a page keeps its name when the default changes.

    python -m meshsal.util.reproducible .venv/bin/python benchmarks/bench_scaling.py [--counts 16,64,256,1000] [--repeats 3] [--keep DIR] [--screening place|touch]
"""

from __future__ import annotations

import datetime
import hashlib
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
from benchlib import CORPUS, arguments, corpus_files, run

from classify.recognizers.place import SCREENINGS, PlaceAware
from classify.runtime.cache import code_fingerprint, file_fingerprint
from meshsal.util.atomic import atomic_path
from meshsal.util.pages import machine

#: Counts whose first run takes less than this run ``--repeats`` times.
_REPEAT_UNDER_S = 300
BENCHMARKS = Path(__file__).resolve().parent
PAGES = BENCHMARKS.parent / "docs" / "benchmarks"

_ONE = """
import json, resource, sys, time, warnings
sys.path.insert(0, sys.argv[3])
from benchlib import scaling_config
from classify.experiment import run_experiment
files = json.loads(sys.argv[1])
config = scaling_config(json.loads(sys.argv[2]))
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    result = run_experiment(files, config, cache_dir=None, quiet=True, skip_bad=True)
n = len(result.object_names)
rates = {}
for method, protocol, clf in (("mesh_saliency", "instance", "knn"), ("mesh_saliency", "instance", "place"),
                              ("info_gain", "sequential", "place")):
    for k in (1, 5):
        c = result.cell(method, protocol, clf, n, False, k)
        rates[f"{method}/{clf}@{k}"] = [c.mean, c.ci_low, c.ci_high]
peak = max(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
print(json.dumps({"objects": n, "timings": result.timings, "usage": result.usage, "peak_mb": peak / 1024, "rates": rates}))
"""


def _screening(asked: str | None) -> str:
    """The screening a run uses: the one asked for, else the place-aware recognizer's default."""
    return asked or PlaceAware().screening


def _page(screening: str | None) -> str:
    """The page's name, after the screening it runs (None: the place-aware recognizer's default)."""
    return f"bench_scaling_{_screening(screening)}"


def _measure(count: int, params: dict) -> dict | None:
    """One run on the first ``count`` corpus objects, in a fresh process: its JSON row (None when it fails)."""
    done = subprocess.run(
        [sys.executable, "-c", _ONE, json.dumps(corpus_files(count)), json.dumps(params), str(BENCHMARKS)],
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        print(f"bench_scaling: {count} objects failed:\n{done.stderr[-2000:]}", file=sys.stderr)
        return None
    return json.loads(done.stdout.strip().splitlines()[-1])


def parser():
    parser = arguments(
        __doc__,
        3,
        meshes_dir=False,
        repeats_help=f"runs of each count whose first run takes under {_REPEAT_UNDER_S} s; its row is the run of "
        "median wall time",
    )
    parser.add_argument("--counts", default="16,64,256,1000", help="comma-separated object counts")
    parser.add_argument(
        "--keep",
        metavar="DIR",
        help="keep each count's row in DIR as it is measured; a row kept for the same code is read back "
        "instead of measured again, so a long run resumes where it stopped",
    )
    parser.add_argument(
        "--screening",
        choices=SCREENINGS,
        help="the place-aware recognizer's screening past its shortlist (default: the recognizer's own); "
        "the page is bench_scaling_SCREENING.md",
    )
    return parser


def main(args) -> int:
    params = {} if args.screening is None else {"place": {"screening": args.screening}}
    counts = [int(c) for c in args.counts.split(",")]
    if not CORPUS.is_dir():
        print(f"bench_scaling: error: {CORPUS} not found", file=sys.stderr)
        return 1
    # Rows are kept under the code they measured: the toolkit's sources, this script and the settings' helper.
    code = code_fingerprint("meshsal", "tactile", "classify") + json.dumps(params)
    code += file_fingerprint(__file__) + file_fingerprint(BENCHMARKS / "benchlib.py")
    code = hashlib.sha256(code.encode()).hexdigest()[:16]
    rows = []
    for count in counts:
        kept = Path(args.keep) / f"{count}-{code}.json" if args.keep else None
        if kept is not None and kept.is_file():
            rows.append(json.loads(kept.read_text()))
            print(f"{count} objects: kept from {rows[-1]['measured']}", file=sys.stderr)
            continue
        runs = [_measure(count, params)]
        if runs[0] is not None and runs[0]["timings"]["total"] < _REPEAT_UNDER_S:
            runs += [_measure(count, params) for _ in range(args.repeats - 1)]
        if None in runs:
            return 1
        walls = sorted(r["timings"]["total"] for r in runs)
        rows.append(sorted(runs, key=lambda r: r["timings"]["total"])[(len(runs) - 1) // 2])
        rows[-1]["runs_s"] = walls
        rows[-1]["measured"] = f"{datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC, {machine()}"
        if kept is not None:
            kept.parent.mkdir(parents=True, exist_ok=True)
            with atomic_path(kept) as tmp:
                Path(tmp).write_text(json.dumps(rows[-1]))
        print(f"{count} objects: {rows[-1]['timings']['total']:.0f} s", file=sys.stderr)
    stages = [s for s in rows[0]["timings"] if s not in ("total", "cpu_total")]
    print(
        "| objects | "
        + " | ".join(f"{s} (s)" for s in stages)
        + " | wall (s) | CPU (s) | wall per object (s) | largest process (MB) | all processes (MB) | "
        + " | ".join(rows[0]["rates"])
        + " |"
    )
    print("|---:|" + "---:|" * (len(stages) + 5) + ":---:|" * len(rows[0]["rates"]))
    for r in rows:
        t = r["timings"]
        print(
            f"| {r['objects']} | "
            + " | ".join(f"{t.get(s, float('nan')):.1f}" for s in stages)
            + f" | {t['total']:.0f} | {t.get('cpu_total', float('nan')):.0f} | {t['total'] / r['objects']:.2f} | "
            f"{r['peak_mb']:.0f} | {r['usage']['total']['peak_mb']:.0f} | "
            + " | ".join(f"{m:.1f} [{lo:.1f}, {hi:.1f}]" for m, lo, hi in r["rates"].values())
            + " |"
        )
    print("\n| objects | stage | wall (s) | CPU (s) | CPU / wall | wall per object (s) | peak memory (MB) |")
    print("|---:|---|---:|---:|---:|---:|---:|")
    for r in rows:
        for s in stages:
            u = r["usage"][s]
            print(
                f"| {r['objects']} | {s} | {u['wall_s']:.1f} | {u['cpu_s']:.1f} | {u['cpu_s'] / u['wall_s']:.2f} | "
                f"{u['wall_s'] / r['objects']:.3f} | {u['peak_mb']:.0f} |"
            )
    print()
    for r in rows:
        runs = r.get("runs_s", [r["timings"]["total"]])
        which = f", the median of {len(runs)} runs ({', '.join(f'{w:.0f}' for w in runs)} s)" if len(runs) > 1 else ""
        print(f"- {r['objects']} objects measured {r['measured']}{which}")
    per = [r["timings"]["total"] / r["objects"] for r in rows]
    print(f"\ntime per object, largest over smallest: {max(per) / min(per):.2f}x (target <= 1.5x)")
    png = PAGES / f"{_page(args.screening)}.png"
    _plot(rows, stages, png)
    print(f"\n![time per object]({png.name})")
    return 0


def _plot(rows, stages, png: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = np.array([r["objects"] for r in rows])
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(n, [r["timings"]["total"] / r["objects"] for r in rows], "o-", label="whole run")
    for s in stages:
        ax.plot(n, [r["timings"].get(s, np.nan) / r["objects"] for r in rows], ".--", label=s)
    ax.set_xscale("log")
    ax.set_xlabel("objects")
    ax.set_ylabel("wall seconds per object")
    ax.legend(fontsize=7)
    fig.tight_layout()
    with atomic_path(png) as tmp:
        fig.savefig(tmp, dpi=120)


if __name__ == "__main__":
    args = parser().parse_args()
    title = "How the experiment's cost grows with the number of objects"
    run(_page(args.screening), f"{title}, screened by {_screening(args.screening)}", lambda: main(args))
