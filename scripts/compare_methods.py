"""The methods comparison of a finished experiment, split by object set, as Markdown tables.

Reads ``results.json`` of ``visuotactile experiment`` (several ``--methods``)
and, for each object set among the run's objects (the toys, the YCB scans;
rates from the run's all-object recognition, so the classes are all of the
run's objects), prints each method's rate after 1, 5 and 15 touches with
its 95 % bootstrap interval, its paired difference against the baseline
with interval and Wilcoxon p, and the fewest touches whose mean reaches
95 %.  Statistics are those of the experiment (:mod:`classify.reporting.stats`), on
the set's columns of each replicate-by-object rate matrix.

    .venv/bin/python scripts/compare_methods.py OUT/results.json [--classifier knn] [--selection]
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from classify.reporting import stats
from classify.reporting.report import format_diff, format_rate
from meshsal.objects import toys, ycb
from meshsal.util.jsonfile import read_json

SETS = {"Toys": toys.NAMES, "YCB": ycb.NAMES}
SHOWN = (1, 5, 15)


def _touches_to(rates: dict, k_max: int, level: float = 95.0) -> str:
    for k in range(1, k_max + 1):
        if np.mean(rates[k]) >= level:
            return str(k)
    return f"not within {k_max}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("results", help="results.json of a finished experiment")
    parser.add_argument("--classifier", default="knn")
    parser.add_argument("--selection", action="store_true", help="the rates with similarity selection")
    args = parser.parse_args()
    document = read_json(args.results, "results file")
    names = document["object_names"]
    seed = int(document["settings"]["seed"])
    methods = document["settings"]["methods"]
    baseline = document["settings"].get("baseline") or methods[0]
    cells = {}
    for cell in document["rates"]:
        if (cell["protocol"], cell["classifier"], cell["n_objects"], cell["selection"]) == \
                ("instance", args.classifier, len(names), args.selection):
            cells.setdefault(cell["method"], {})[cell["touches"]] = np.asarray(cell["replicate_by_object"])
    k_max = max(max(v) for v in cells.values())
    groups = {title: [names.index(n) for n in members if n in names] for title, members in SETS.items()}
    groups["All objects"] = list(range(len(names)))
    for title, columns in groups.items():
        if not columns:
            continue
        print(f"\n{title} ({len(columns)} of {len(names)} classes), instance protocol, {args.classifier}, "
              f"{'with' if args.selection else 'no'} selection:\n")
        head = "| points | " + " | ".join(f"{k} touch{'es' if k > 1 else ''} | diff at {k}" for k in SHOWN)
        print(head + " | touches to 95 % |")
        print("|---|" + ":---:|" * (2 * len(SHOWN) + 1))
        for method in [baseline] + [m for m in methods if m != baseline and m in cells]:
            rates = {k: R[:, columns] for k, R in cells[method].items()}
            row = [method]
            for k in SHOWN:
                s = stats.summarize(rates[k], seed, [names[c] for c in columns])
                row.append(format_rate(s.mean, s.ci_low, s.ci_high))
                if method == baseline:
                    row.append("baseline")
                else:
                    d = stats.paired_difference(rates[k], cells[baseline][k][:, columns], seed,
                                                [names[c] for c in columns])
                    row.append(format_diff(d.mean, d.ci_low, d.ci_high, d.p_value))
            row.append(_touches_to(rates, k_max))
            print("| " + " | ".join(row) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
