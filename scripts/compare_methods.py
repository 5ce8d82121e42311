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
with its interval.  With ``--versus OTHER`` it adds, per fixed plan and
policy, the paired difference between ``--classifier`` and ``OTHER`` on the
same instances (``--classifier place --versus knn``: what knowing where the
pad pressed buys).  Statistics are those of the experiment
(:mod:`classify.reporting.stats`), on the set's columns of each
replicate-by-object matrix.

``--page docs/results/NAME.md`` also writes the tables as a page of the
documentation, headed by this command and the experiment's own command,
commit, machine and date (``results.json`` records them).

    .venv/bin/python scripts/compare_methods.py OUT/results.json [--classifier knn] [--versus knn] [--selection]
        [--touches 1,3,5,15] [--page docs/results/touch-by-touch.md --title TITLE]
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


def _cells(document, classifier: str, n_objects: int, selection: bool) -> dict:
    """row name -> touches -> (replicates, objects) rates of one recognizer."""
    cells = {}
    for cell in document["rates"]:
        if cell["protocol"] in ROWS and (cell["classifier"], cell["n_objects"], cell["selection"]) == (
            classifier,
            n_objects,
            selection,
        ):
            row = ROWS[cell["protocol"]].format(cell["method"])
            cells.setdefault(row, {})[cell["touches"]] = np.asarray(cell["replicate_by_object"])
    return cells


def comparison(document, classifier: str, selection: bool, shown, baseline: str, columns) -> str:
    """Rates and paired differences against the baseline's fixed plan on the objects ``columns``."""
    names = document["object_names"]
    seed = int(document["settings"]["seed"])
    cells = _cells(document, classifier, len(names), selection)
    if baseline not in cells:
        return ""
    who = [names[c] for c in columns]
    k_max = max(max(v) for v in cells.values())
    lines = [
        "| points or policy | "
        + " | ".join(f"{k} touch{'es' if k > 1 else ''} | diff at {k}" for k in shown)
        + " | touches to 95 % |",
        "|---|" + ":---:|" * (2 * len(shown) + 1),
    ]
    for method in [baseline] + [m for m in cells if m != baseline]:
        rates = {k: R[:, columns] for k, R in cells[method].items()}
        row = [method]
        for k in shown:
            s = stats.summarize(rates[k], seed, who)
            row.append(format_rate(s.mean, s.ci_low, s.ci_high))
            if method == baseline:
                row.append("baseline")
            else:
                d = stats.paired_difference(rates[k], cells[baseline][k][:, columns], seed, who)
                row.append(format_diff(d.mean, d.ci_low, d.ci_high, d.p_value))
        row.append(_touches_to(rates, k_max))
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def versus(document, classifier: str, other: str, selection: bool, shown, columns) -> str:
    """Per fixed plan and policy: ``classifier`` minus ``other`` on the same instances, paired."""
    names = document["object_names"]
    seed = int(document["settings"]["seed"])
    mine = _cells(document, classifier, len(names), selection)
    theirs = _cells(document, other, len(names), selection)
    rows = [m for m in mine if m in theirs]
    if not rows:
        return ""
    who = [names[c] for c in columns]
    lines = [
        "| points or policy | "
        + " | ".join(f"{other} at {k} | {classifier} at {k} | diff at {k}" for k in shown)
        + " |",
        "|---|" + ":---:|" * (3 * len(shown)),
    ]
    for m in rows:
        row = [m]
        for k in shown:
            a, b = mine[m][k][:, columns], theirs[m][k][:, columns]
            sa, sb = stats.summarize(a, seed, who), stats.summarize(b, seed, who)
            d = stats.paired_difference(a, b, seed, who)
            row += [
                format_rate(sb.mean, sb.ci_low, sb.ci_high),
                format_rate(sa.mean, sa.ci_low, sa.ci_high),
                format_diff(d.mean, d.ci_low, d.ci_high, d.p_value),
            ]
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def stopping(document, classifier, n_objects, columns) -> str:
    """Per fixed plan and policy: the touches used at the lowest threshold whose mean accuracy reaches 95 %."""
    names = document["object_names"]
    seed = int(document["settings"]["seed"])
    who = [names[c] for c in columns]
    levels = document["settings"].get("stop_levels", [])
    found = [
        s
        for s in document.get("stopping_by_object", [])
        if (s["classifier"], s["n_objects"]) == (classifier, n_objects)
    ]
    if not found:
        return ""
    lines = ["| points or policy | p | accuracy | touches used |", "|---|:---:|:---:|:---:|"]
    for s in found:
        correct = np.asarray(s["correct"])[:, :, columns]
        used = np.asarray(s["touches"])[:, :, columns]
        name = ROWS[s["protocol"]].format(s["method"])
        reached = [i for i in range(len(levels)) if correct[:, i].mean() >= 95.0]
        if not reached:
            best = int(np.argmax(correct.mean(axis=(0, 2))))
            lines.append(
                f"| {name} | - | at most {correct[:, best].mean():.1f} % (p = {levels[best]:g}) | not reached |"
            )
            continue
        i = reached[0]
        a, u = stats.summarize(correct[:, i], seed, who), stats.summarize(used[:, i], seed, who)
        lines.append(
            f"| {name} | {levels[i]:g} | {format_rate(a.mean, a.ci_low, a.ci_high)} | "
            f"{u.mean:.2f} [{u.ci_low:.2f}, {u.ci_high:.2f}] |"
        )
    return "\n".join(lines)


def report(document, classifier: str, other: str | None, selection: bool, shown) -> str:
    """Every table of the comparison, per object set, as Markdown."""
    names = document["object_names"]
    methods = document["settings"]["methods"]
    baseline = document["settings"].get("baseline") or methods[0]
    groups = {title: [names.index(n) for n in members if n in names] for title, members in SETS.items()}
    groups["All objects"] = list(range(len(names)))
    blocks = []
    for title, columns in groups.items():
        if not columns:
            continue
        head = f"### {title} ({len(columns)} of {len(names)} classes)"
        what = f"{classifier}, {'with' if selection else 'no'} selection"
        table = comparison(document, classifier, selection, shown, baseline, columns)
        if table:
            blocks.append(f"{head}: {what}, against {baseline}'s fixed plan\n\n{table}")
        if other:
            table = versus(document, classifier, other, selection, shown, columns)
            if table:
                blocks.append(f"{head}: {classifier} against {other} on the same touches\n\n{table}")
        table = stopping(document, classifier, len(names), columns)
        if table:
            blocks.append(
                f"{head}: stopping rule, {classifier} (stop when the top object's posterior reaches p, or after "
                f"every point): mean touches used [95 % interval] at the lowest p whose mean accuracy reaches "
                f"95 %\n\n{table}"
            )
    return "\n\n".join(blocks)


def experiment_provenance(document) -> str:
    """What ``results.json`` says of the run that measured it."""
    run = document["settings"].get("provenance") or {}
    times = document.get("timings_s", {})
    if not run:
        return "The experiment's command, commit and machine are not recorded in this results.json."
    return "\n".join(
        [
            "The experiment:",
            "",
            f"- command: `{run.get('command', '?')}`",
            f"- commit: {run.get('commit', '?')}",
            f"- machine: {run.get('machine', '?')}",
            f"- date: {run.get('date', '?')}",
            f"- wall time: {times.get('total', float('nan')):.0f} s"
            + (f"; CPU time: {times['cpu_total']:.0f} s" if "cpu_total" in times else ""),
        ]
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("results", help="results.json of a finished experiment")
    parser.add_argument("--classifier", default="knn")
    parser.add_argument("--versus", default=None, metavar="CLASSIFIER", help="also the paired difference with it")
    parser.add_argument("--selection", action="store_true", help="the rates with similarity selection")
    parser.add_argument("--touches", default="1,5,15", help="comma-separated touch counts shown")
    parser.add_argument("--page", default=None, help="also write the tables as this Markdown page (docs/...)")
    parser.add_argument("--title", default="Methods and policies compared", help="the page's title")
    args = parser.parse_args()
    shown = tuple(int(k) for k in args.touches.split(","))
    document = read_json(args.results, "results file")
    text = report(document, args.classifier, args.versus, args.selection, shown)
    print(text)
    if args.page:
        from meshsal.util.pages import write_page

        write_page(args.page, args.title, f"{experiment_provenance(document)}\n\n{text}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
