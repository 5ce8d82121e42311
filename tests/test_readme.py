"""The README as a user meets it: every Python block runs as written and prints what the text after it says.

A block's expected output is the ``text`` block that follows it (before the
next Python block).  Each runs as a script of its own in a fresh folder,
pinned as the ``visuotactile`` command is (``python -m meshsal.util.reproducible``),
so that the figures it prints are the ones on every x86-64 machine.
"""

import re
import subprocess
import sys
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.M | re.S)


def _blocks():
    """(python source, expected output or None), in the README's order."""
    fences = FENCE.findall(README.read_text())
    out = []
    for i, (lang, body) in enumerate(fences):
        if lang == "python":
            after = fences[i + 1] if i + 1 < len(fences) else ("", "")
            out.append((body, after[1] if after[0] == "text" else None))
    return out


BLOCKS = _blocks()


def test_the_readme_has_python_blocks_and_each_says_what_it_prints():
    assert len(BLOCKS) >= 3
    assert all(expected for _, expected in BLOCKS)


@pytest.mark.parametrize("number", range(len(BLOCKS)))
def test_a_readme_block_runs_as_written_and_prints_what_the_readme_says(number, tmp_path):
    source, expected = BLOCKS[number]
    (tmp_path / "script.py").write_text(source)
    done = subprocess.run(
        [sys.executable, "-m", "meshsal.util.reproducible", sys.executable, "script.py"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip() == expected.strip(), done.stdout
