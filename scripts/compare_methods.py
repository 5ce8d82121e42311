"""The methods and policies comparison of a finished experiment, split by object set, as Markdown tables.

Reads ``results.json`` of ``visuotactile experiment`` (several ``--methods``,
any ``--policies``) and, for each object set among the run's objects (the
toys, the YCB scans; rates from the run's all-object recognition, so the
classes are all of the run's objects), prints each fixed plan's and each
policy's rate after the ``--touches`` shown with its 95 % bootstrap
interval, its paired difference against the baseline's fixed plan with
interval and Wilcoxon p, and the fewest touches whose mean reaches 95 %.
With policies it also prints the stopping rule per set: at the lowest
posterior threshold whose mean accuracy reaches 95 %, the mean touches used
with its interval.  Statistics are those of the experiment
(:mod:`classify.reporting.stats`), on the set's columns of each
replicate-by-object matrix.

    .venv/bin/python scripts/compare_methods.py OUT/results.json [--classifier knn] [--selection] [--touches 1,3,5,15]
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
ROWS = {"instance": "{}", "sequential": "policy {}"}


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
    parser.add_argument("--touches", default="1,5,15", help="comma-separated touch counts shown")
    args = parser.parse_args()
    shown = tuple(int(k) for k in args.touches.split(","))
    document = read_json(args.results, "results file")
    names = document["object_names"]
    seed = int(document["settings"]["seed"])
    methods = document["settings"]["methods"]
    baseline = document["settings"].get("baseline") or methods[0]
    cells = {}
    for cell in document["rates"]:
        if cell["protocol"] in ROWS and (cell["classifier"], cell["n_objects"], cell["selection"]) == (
            args.classifier,
            len(names),
            args.selection,
        ):
            row = ROWS[cell["protocol"]].format(cell["method"])
            cells.setdefault(row, {})[cell["touches"]] = np.asarray(cell["replicate_by_object"])
    k_max = max(max(v) for v in cells.values())
    groups = {title: [names.index(n) for n in members if n in names] for title, members in SETS.items()}
    groups["All objects"] = list(range(len(names)))
    for title, columns in groups.items():
        if not columns:
            continue
        print(
            f"\n{title} ({len(columns)} of {len(names)} classes), instance protocol, {args.classifier}, "
            f"{'with' if args.selection else 'no'} selection:\n"
        )
        head = "| points or policy | " + " | ".join(f"{k} touch{'es' if k > 1 else ''} | diff at {k}" for k in shown)
        print(head + " | touches to 95 % |")
        print("|---|" + ":---:|" * (2 * len(shown) + 1))
        for method in [baseline] + [m for m in cells if m != baseline]:
            rates = {k: R[:, columns] for k, R in cells[method].items()}
            row = [method]
            for k in shown:
                s = stats.summarize(rates[k], seed, [names[c] for c in columns])
                row.append(format_rate(s.mean, s.ci_low, s.ci_high))
                if method == baseline:
                    row.append("baseline")
                else:
                    d = stats.paired_difference(
                        rates[k], cells[baseline][k][:, columns], seed, [names[c] for c in columns]
                    )
                    row.append(format_diff(d.mean, d.ci_low, d.ci_high, d.p_value))
            row.append(_touches_to(rates, k_max))
            print("| " + " | ".join(row) + " |")
        _stopping(document, args.classifier, len(names), columns, seed, [names[c] for c in columns])
    return 0


def _stopping(document, classifier, n_objects, columns, seed, who) -> None:
    """Per fixed plan and policy: the touches used at the lowest threshold whose mean accuracy reaches 95 %."""
    levels = document["settings"].get("stop_levels", [])
    found = [
        s
        for s in document.get("stopping_by_object", [])
        if (s["classifier"], s["n_objects"]) == (classifier, n_objects)
    ]
    if not found:
        return
    print(
        "\nStopping rule (stop when the top class's posterior reaches p, or after every point): "
        "mean touches used [95 % interval] at the lowest p whose mean accuracy reaches 95 %\n"
    )
    print("| points or policy | p | accuracy | touches used |")
    print("|---|:---:|:---:|:---:|")
    for s in found:
        correct = np.asarray(s["correct"])[:, :, columns]
        used = np.asarray(s["touches"])[:, :, columns]
        name = ROWS[s["protocol"]].format(s["method"])
        reached = [i for i in range(len(levels)) if correct[:, i].mean() >= 95.0]
        if not reached:
            best = int(np.argmax(correct.mean(axis=(0, 2))))
            print(f"| {name} | - | at most {correct[:, best].mean():.1f} % (p = {levels[best]:g}) | not reached |")
            continue
        i = reached[0]
        a, u = stats.summarize(correct[:, i], seed, who), stats.summarize(used[:, i], seed, who)
        print(
            f"| {name} | {levels[i]:g} | {format_rate(a.mean, a.ci_low, a.ci_high)} | "
            f"{u.mean:.2f} [{u.ci_low:.2f}, {u.ci_high:.2f}] |"
        )


if __name__ == "__main__":
    sys.exit(main())
