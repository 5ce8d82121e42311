"""Benchmark: what the place-aware recognizer's shortlist costs past 16 objects, screened by touch or by place.

Past its ``shortlist`` (16 objects) the place-aware recognizer scores a
touch in full only under some objects (``PlaceAware(screening=...)``):

* ``touch`` (the default): the 16 objects whose place-free samples come
  nearest the touch; every other object gets a lower bound;
* ``place``: every object, the touch's place located by laying each
  object's landmarks onto the touched instance through the two surface
  frames (by default nothing more, ``exact_places=0``), and with
  ``exact_places=8`` the 8 most likely objects again, the place located by
  registration.

For the first ``--objects`` corpus objects (``../shared/corpus/random-objects``,
sorted by name, a file that does not load left out), the settings of
``bench_scaling.py`` (2 replicates of the instance protocol, uniform and
mesh-saliency points, kNN and the place-aware recognizer, ``info_gain``, 5
points per instance, 64 px views, seed 0) run under each of the three, each
with both controls beside it: each test instance given another object's
imprints, place for place (``shuffled``) or in a random order
(``scrambled``, which keeps nothing of where they were taken); chance is
1 / objects.  ``--mismatch decimated`` (any of
``classify.experiment.config.MISMATCHES``) makes the test instances differ
from the training ones as that mismatch arm does (``decimated``: another
tessellation, which can reorder the instance's own landmarks) and writes
``bench_screening_MISMATCH.md`` instead.  The nine runs share one cache,
so the instances are computed once, by the first run; each run is a fresh
process.  The table gives the
recognition rate after 1 to 5 touches with its interval, and the
place-aware stage's wall time, CPU time and peak memory (all processes);
kNN does not depend on the screening and is given once per control.

    python -m meshsal.util.reproducible .venv/bin/python benchmarks/bench_screening.py [--objects 256] [--mismatch decimated]
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

from benchlib import CORPUS, arguments, corpus_files, run

_ONE = """
import json, sys, warnings
files, params, control, mismatch, cache, here = json.loads(sys.argv[1])
sys.path.insert(0, here)
from benchlib import scaling_config
from classify.experiment import run_experiment
config = scaling_config({"place": params}, control, mismatch)
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    result = run_experiment(files, config, cache_dir=cache, quiet=True, skip_bad=True)
n = len(result.object_names)
rates = {}
for method, protocol, clf in (("mesh_saliency", "instance", "knn"), ("mesh_saliency", "instance", "place"),
                              ("info_gain", "sequential", "place")):
    rates[f"{method}/{clf}"] = [
        [c.mean, c.ci_low, c.ci_high] for c in (result.cell(method, protocol, clf, n, False, k) for k in range(1, 6))
    ]
print(json.dumps({"objects": n, "usage": result.usage, "rates": rates}))
"""


#: The screenings compared: a label and the place-aware recognizer's parameters.
ARMS = (
    ("touch", {"screening": "touch"}),
    ("place, 8 registered", {"screening": "place", "exact_places": 8}),
    ("place, none registered", {"screening": "place"}),
)
#: Each screening's controls: none, then the donor's imprints place for place, then in a random order.
CONTROLS = (None, "shuffled", "scrambled")


def _arm(files: list, label: str, params: dict, control, mismatch: list, cache: str) -> dict:
    """One run in a fresh process: its JSON row (SystemExit naming the arm when it fails)."""
    done = subprocess.run(
        [sys.executable, "-c", _ONE, json.dumps([files, params, control, mismatch, cache, str(Path(__file__).parent)])],
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        raise SystemExit(f"bench_screening: screening {label}, control {control} failed:\n{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def _rates(values) -> str:
    return " | ".join(f"{m:.1f} [{lo:.1f}, {hi:.1f}]" for m, lo, hi in values)


def _page(mismatch: list) -> str:
    """The page's name: ``bench_screening``, with the mismatch arm's names when there is one."""
    return "_".join(["bench_screening", *mismatch])


def parser():
    from classify.experiment.config import MISMATCHES

    parser = arguments(__doc__, 1, meshes_dir=False)
    parser.add_argument("--objects", type=int, default=256, help="the first N corpus files (default 256)")
    parser.add_argument(
        "--mismatch",
        choices=MISMATCHES,
        action="append",
        default=[],
        help="a mismatch arm of the test instances (repeat for several); writes bench_screening_MISMATCH.md",
    )
    return parser


def main(args) -> int:
    if not CORPUS.is_dir():
        print(f"bench_screening: error: {CORPUS} not found", file=sys.stderr)
        return 1
    files = corpus_files(args.objects)
    rows = {}
    with tempfile.TemporaryDirectory(prefix="bench_screening-") as cache:
        for label, params in ARMS:
            for control in CONTROLS:
                rows[label, control] = _arm(files, label, params, control, args.mismatch, cache)
                print(f"screening {label}, control {control}: done", file=sys.stderr)
    first = ARMS[0][0]
    n = rows[first, None]["objects"]
    tested = f"; test instances {', '.join(args.mismatch)}" if args.mismatch else ""
    print(f"{n} corpus objects, 2 replicates, seed 0{tested}; chance {100 / n:.1f} %\n")
    print("| recognizer | touches: 1 | 2 | 3 | 4 | 5 |")
    print("|---|:---:|:---:|:---:|:---:|:---:|")
    for control in CONTROLS:
        arm = f", {control} control" if control else ""
        print(f"| kNN, mesh saliency's plan{arm} | {_rates(rows[first, control]['rates']['mesh_saliency/knn'])} |")
    for label, _ in ARMS:
        for control in CONTROLS:
            r = rows[label, control]["rates"]
            arm = f"screening {label}" + (f", {control} control" if control else "")
            print(f"| place-aware, mesh saliency's plan, {arm} | {_rates(r['mesh_saliency/place'])} |")
            print(f"| place-aware, `info_gain`, {arm} | {_rates(r['info_gain/place'])} |")
    print("\n| screening | control | place-aware stage wall (s) | CPU (s) | peak memory, all processes (MB) |")
    print("|---|---|---:|---:|---:|")
    for (label, control), row in rows.items():
        u = row["usage"]["place"]
        print(f"| {label} | {control or 'none'} | {u['wall_s']:.1f} | {u['cpu_s']:.1f} | {u['peak_mb']:.0f} |")
    return 0


if __name__ == "__main__":
    args = parser().parse_args()
    title = "The place-aware recognizer past its shortlist: screened by touch or by place"
    run(_page(args.mismatch), title + "".join(f", {m} test instances" for m in args.mismatch), lambda: main(args))
