"""scripts/other_rounding.py: its comparison of each run's results.csv with the plain run's, its table, and its
refusals (the runs themselves: the stand-in's tests in test_embree.py)."""

import json
import subprocess
from pathlib import Path

import pytest

import scripts


@pytest.fixture(scope="module")
def script():
    return scripts.load("other_rounding")


def test_rows_are_compared_place_for_place_and_missing_rows_count(script, tmp_path):
    ours, theirs = tmp_path / "a.csv", tmp_path / "b.csv"
    ours.write_text("head\n1\n2\n3\n")
    theirs.write_text("head\n1\n9\n3\n")
    assert script.differing_rows(ours, theirs) == (1, 4)
    theirs.write_text("head\n1\n")
    assert script.differing_rows(ours, theirs) == (2, 4)
    assert script.differing_rows(ours, ours) == (0, 4)


def _fake_runs(monkeypatch, script, csv_of, exit_code=0):
    """subprocess.run writing, for each arm, the results.csv ``csv_of(where)`` and the arm's counts."""

    real = subprocess.run

    def run(command, **kwargs):
        if "--arm" not in command:  # git, for the page's provenance
            return real(command, **kwargs)
        out = Path(command[command.index("--out") + 1])
        where = command[command.index("--arm") + 1]
        (out / "results.csv").write_text(csv_of(where))
        counts = {"moved": 0 if where == "none" else 1200, "turned": 0 if where == "none" else 7}
        scenes = 0 if where == "none" else 3
        (out / "rounding.json").write_text(json.dumps({**counts, "scenes": scenes, "exit_code": exit_code}))
        return subprocess.CompletedProcess(command, 0)

    monkeypatch.setattr(script.subprocess, "run", run)


def test_the_table_counts_what_moved_and_the_rows_that_differ(script, monkeypatch, tmp_path, capsys):
    _fake_runs(monkeypatch, script, lambda where: "h\n1\n2\n" if where != "settled" else "h\n1\n3\n")
    page = tmp_path / "page.md"
    assert script.main(["--page", str(page), "--", "--objects", "cow,cup"]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| ")][1:]
    assert rows[0].startswith("| as it is | 0 | 0 | 0 | 0 of 3 |")
    assert rows[1].startswith("| rounded otherwise inside the settling | 3 | 1,200 | 7 | 0 of 3 |")
    assert rows[2].startswith("| the same, around the settled hits | 3 | 1,200 | 7 | 1 of 3 |")
    text = page.read_text()
    assert text.startswith("# The tables when Embree's hits") and "`visuotactile experiment --objects cow,cup`" in text


def test_a_failed_run_stops_it_with_a_non_zero_status_and_no_page(script, monkeypatch, tmp_path, capsys):
    _fake_runs(monkeypatch, script, lambda where: "h\n", exit_code=2)
    page = tmp_path / "page.md"
    assert script.main(["--page", str(page)]) == 1
    assert "the experiment failed" in capsys.readouterr().err and not page.exists()


def test_a_share_outside_zero_to_one_is_refused(script, capsys):
    with pytest.raises(SystemExit) as stop:
        script.main(["--share", "1.5"])
    assert stop.value.code == 2 and "--share must lie in [0, 1]" in capsys.readouterr().err
