"""The documentation: the user's guide runs as written, and the API reference documents every public name once.

``scripts/test`` builds the whole site with warnings as errors (``scripts/docs``); these tests check
what a build cannot see: that the guide's Python prints what the page says, and that no public
name is missing from the reference or documented twice.
"""

import importlib
import importlib.util
import inspect
import re
import subprocess
import sys
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[1] / "docs"
GUIDE_PAGES = sorted(p.name for p in (DOCS / "guide").glob("*.rst") if ">>>" in p.read_text())
DIRECTIVE = re.compile(r"^\.\. auto(?:function|class|exception|data):: (\S+)$", re.M)


def _generate():
    spec = importlib.util.spec_from_file_location("docs_generate", DOCS / "generate.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def generate():
    return _generate()


@pytest.fixture(scope="module")
def reference(generate, tmp_path_factory):
    """The API reference as a build writes it: page name -> text."""
    out = tmp_path_factory.mktemp("api")
    names = generate.api_reference(out)
    return {name: (out / f"{name}.rst").read_text() for name in names}


def _resolve(dotted: str):
    """The object at a dotted path: the longest importable module, then attributes."""
    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        for attr in parts[cut:]:
            obj = getattr(obj, attr)
        return obj
    raise ImportError(dotted)


def _documented(reference) -> dict[str, str]:
    """Full dotted name -> the page documenting it (each directive names an object of the page's module)."""
    found = {}
    for page, text in reference.items():
        for name in DIRECTIVE.findall(text):
            full = f"{page}.{name}"
            assert full not in found, f"{full} documented on {found[full]} and {page}"
            found[full] = page
    return found


def test_the_guide_pages_with_python_are_found():
    assert {"tour.rst", "policy.rst"} <= set(GUIDE_PAGES)


@pytest.mark.parametrize("page", GUIDE_PAGES)
def test_a_guide_page_runs_as_written_and_prints_what_it_says(page):
    # In a process of its own, pinned as the command line is: as a reader would paste it, and a page's
    # registrations (a policy of one's own) stay out of the other tests.
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "meshsal.util.reproducible",
            sys.executable,
            "-m",
            "doctest",
            str(DOCS / "guide" / page),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]


def test_every_public_name_of_every_package_is_documented_at_the_path_a_user_types(reference):
    documented = _documented(reference)
    for package in ("meshsal", "tactile", "classify"):
        exported = {n: _resolve(f"{package}.{n}") for n in importlib.import_module(package).__all__}
        callables = [n for n, obj in exported.items() if inspect.isclass(obj) or inspect.isfunction(obj)]
        assert len(callables) >= 10, package
        for name in callables:
            assert f"{package}.{name}" in documented, f"{package}.{name} is not documented"
        # A constant lives where it is defined, with its comment; the package's table links there.
        for name, obj in exported.items():
            if not (inspect.ismodule(obj) or name in callables):
                homes = [full for full in documented if full.rpartition(".")[2] == name and _resolve(full) is obj]
                assert len(homes) == 1, f"{package}.{name}: documented at {homes}"


def test_every_object_is_documented_once_and_every_table_entry_leads_to_it(reference, generate):
    documented = _documented(reference)
    seen = {}
    for full in documented:
        obj = _resolve(full)
        if inspect.isclass(obj) or inspect.isfunction(obj):
            assert id(obj) not in seen, f"{full} and {seen[id(obj)]} document the same object"
            seen[id(obj)] = full
    for page, text in reference.items():
        module = importlib.import_module(page)
        entries = [line.strip()[1:] for line in text.splitlines() if line.startswith("   ~")]
        if hasattr(module, "__all__"):
            expected = [n for n in module.__all__ if not inspect.ismodule(getattr(module, n))]
            assert sorted(e.rpartition(".")[2] for e in entries) == sorted(expected), page
        for entry in entries:
            full = entry if entry.split(".")[0] in generate.PACKAGES else f"{page}.{entry}"
            assert full in documented, f"{page} lists {entry}, documented nowhere"
            assert _resolve(full) is getattr(module, full.rpartition(".")[2]), f"{page}: {entry} is another object"


def test_a_function_named_like_a_module_is_documented_where_it_is_defined(reference):
    # meshsal.attention.dkl is both a module and the function the package exports under that name.
    documented = _documented(reference)
    assert "meshsal.attention.dkl" in reference and "meshsal.attention.dkl" not in documented
    assert "meshsal.attention.dkl.dkl" in documented
    assert "meshsal.attention.intensity" in documented  # its neighbours stay at the package


def test_the_commands_page_holds_every_subcommands_help(generate):
    from classify.cli import build_parser

    page = generate.commands_page()
    for name in ("toys", "points", "imprints", "experiment", "batch", "capture", "export", "plan"):
        assert f"\n{name}\n{'-' * len(name)}\n" in page
        assert f"usage: visuotactile {name} [-h]" in page
    assert "usage: visuotactile [-h] COMMAND" in page
    assert build_parser().format_usage().startswith("usage: visuotactile")


def test_the_measurements_page_lists_the_pages_commands_wrote(generate, tmp_path):
    (tmp_path / "benchmarks").mkdir()
    (tmp_path / "benchmarks" / "bench_render.md").write_text("# Rendering\n")
    (tmp_path / "benchmarks" / "bench_load.md").write_text("# Loading\n")
    generate.measurements(tmp_path)
    text = (tmp_path / "measurements.rst").read_text()
    assert "   benchmarks/bench_load\n   benchmarks/bench_render\n" in text
    assert "No page in ``docs/results`` yet." in text
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "methods.md").write_text("# Methods\n")
    generate.measurements(tmp_path)
    text = (tmp_path / "measurements.rst").read_text()
    assert "   results/methods\n" in text and "No page" not in text


def test_a_page_names_its_commit_and_changes_to_the_code_but_not_to_the_pages_it_writes(tmp_path):
    from meshsal.util.pages import commit

    def git(*args) -> str:
        done = subprocess.run(["git", "-C", str(tmp_path), *args], check=True, capture_output=True, text=True)
        return done.stdout.strip()

    git("init", "-q")
    (tmp_path / "code.py").write_text("x = 1\n")
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "page.md").write_text("# A page\n")
    git("add", ".")
    git("-c", "user.name=t", "-c", "user.email=t@t", "-c", "commit.gpgsign=false", "commit", "-qm", "first")
    head = git("rev-parse", "--short=10", "HEAD")
    assert commit(tmp_path) == head
    (tmp_path / "docs" / "page.md").write_text("# A page, measured again\n")
    assert commit(tmp_path) == head
    assert commit(tmp_path / "docs") == head  # asked from inside docs/ too
    (tmp_path / "code.py").write_text("x = 2\n")
    assert commit(tmp_path) == head + " +changes"
    assert commit(tmp_path / "docs") == head + " +changes"
