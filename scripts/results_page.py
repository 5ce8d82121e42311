"""An experiment's own tables as a page of the documentation, from its ``results.json``.

Writes what ``visuotactile experiment`` printed (the paper's Table 1 layout
per method and protocol, the touches tables, the comparisons, the stopping
rule), headed by this command and the experiment's own command, commit,
machine, date and times, which ``results.json`` records.

    .venv/bin/python scripts/results_page.py OUT/results.json --page docs/results/NAME.md --title TITLE
"""

from __future__ import annotations

import argparse
import sys

from classify.reporting.results import ExperimentResult, format_tables
from meshsal.util.jsonfile import read_json
from meshsal.util.pages import write_page

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from compare_methods import experiment_provenance  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("results", help="results.json of a finished experiment")
    parser.add_argument("--page", required=True, help="the Markdown page to write (docs/results/...)")
    parser.add_argument("--title", default="Experiment results")
    args = parser.parse_args()
    document = read_json(args.results, "results file")
    tables = format_tables(ExperimentResult.from_json(document))
    write_page(args.page, args.title, f"{experiment_provenance(document)}\n\n{tables}")
    print(f"wrote {args.page}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
