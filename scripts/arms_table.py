"""Matched run, controls and mismatch arms side by side: what each recognizer keeps when the test departs from training.

Reads the ``results.json`` of several ``visuotactile experiment`` runs on the
same objects and seed (the matched run, ``--control shuffled``, each
``--mismatch`` arm) and prints, for each fixed plan and policy, the rate of
each recognizer after the ``--touches`` shown, one row per run, with its 95 %
interval, and the paired difference from the matched run (the first file):
what the arm costs.  Chance is 100 / (number of objects).

    .venv/bin/python scripts/arms_table.py matched/results.json shuffled/results.json decimated/results.json ...
        [--classifiers place,knn] [--rows mesh_saliency,info_gain] [--touches 1,2,3,5] [--page docs/results/arms.md]
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from classify.reporting import stats
from classify.reporting.report import format_diff, format_rate
from meshsal.util.jsonfile import read_json

PROTOCOLS = {"instance": "{}", "sequential": "policy {}"}


def _arm(document) -> str:
    s = document["settings"]
    parts = ([f"control {s['control']}"] if s.get("control") else []) + [
        f"mismatch {m}" for m in s.get("mismatch") or []
    ]
    return ", ".join(parts) or "matched"


def _rates(document, classifier: str) -> dict:
    n = len(document["object_names"])
    out = {}
    for cell in document["rates"]:
        if cell["protocol"] in PROTOCOLS and (cell["classifier"], cell["n_objects"], cell["selection"]) == (
            classifier,
            n,
            False,
        ):
            row = PROTOCOLS[cell["protocol"]].format(cell["method"])
            out.setdefault(row, {})[cell["touches"]] = np.asarray(cell["replicate_by_object"])
    return out


def table(documents, classifier: str, rows, shown) -> str:
    """One Markdown table: a row per (plan or policy, run), rates and differences from the first run."""
    names = documents[0]["object_names"]
    seed = int(documents[0]["settings"]["seed"])
    base = _rates(documents[0], classifier)
    lines = [
        "| points or policy | run | "
        + " | ".join(f"{k} touch{'es' if k > 1 else ''} | cost at {k}" for k in shown)
        + " |",
        "|---|---|" + ":---:|" * (2 * len(shown)),
    ]
    for row in rows or list(base):
        for d, document in enumerate(documents):
            mine = _rates(document, classifier).get(row)
            if mine is None or document["object_names"] != names:
                continue
            cells = [row, _arm(document)]
            for k in shown:
                s = stats.summarize(mine[k], seed, names)
                cells.append(format_rate(s.mean, s.ci_low, s.ci_high))
                if d == 0 or row not in base:
                    cells.append("-")
                else:
                    diff = stats.paired_difference(mine[k], base[row][k], seed, names)
                    cells.append(format_diff(diff.mean, diff.ci_low, diff.ci_high, diff.p_value))
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("results", nargs="+", help="results.json files; the first is the matched run")
    parser.add_argument("--classifiers", default="place,knn")
    parser.add_argument("--rows", default=None, help="comma-separated plans and policies (as 'policy NAME')")
    parser.add_argument("--touches", default="1,2,3,5")
    parser.add_argument("--page", default=None, help="also write the tables as this Markdown page (docs/...)")
    parser.add_argument("--title", default="Controls and mismatch arms")
    args = parser.parse_args()
    documents = [read_json(path, "results file") for path in args.results]
    shown = tuple(int(k) for k in args.touches.split(","))
    rows = args.rows.split(",") if args.rows else None
    chance = 100.0 / len(documents[0]["object_names"])
    blocks = []
    for classifier in args.classifiers.split(","):
        blocks.append(
            f"### {classifier}, {len(documents[0]['object_names'])} objects (chance {chance:.1f} %): rate (%) [95 % "
            f"interval], and the paired difference from the matched run (points) [95 % interval], Wilcoxon p\n\n"
            + table(documents, classifier, rows, shown)
        )
    text = "\n\n".join(blocks)
    print(text)
    if args.page:
        from meshsal.util.pages import write_page

        runs = "\n".join(
            f"- {_arm(d)}: `{(d['settings'].get('provenance') or {}).get('command', '?')}` at "
            f"{(d['settings'].get('provenance') or {}).get('commit', '?')}, "
            f"{d.get('timings_s', {}).get('total', float('nan')):.0f} s"
            for d in documents
        )
        write_page(args.page, args.title, f"The runs:\n\n{runs}\n\n{text}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
