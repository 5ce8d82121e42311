"""Sphinx configuration: the user's guide, the API reference from the docstrings and the gallery.

``scripts/docs`` builds it with warnings as errors into ``docs/_build/html``.
"""

from __future__ import annotations

import importlib.metadata
import re
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import generate  # noqa: E402

import meshsal.util.reproducible  # noqa: E402

# The gallery runs in this process: its numbers and pictures are the pinned ones the command line gives.
meshsal.util.reproducible.pin_kernels()

project = "visuotactile"
author = "the visuotactile authors"
copyright = "the visuotactile authors, MIT License"
release = version = importlib.metadata.version("visuotactile")

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
    "myst_parser",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "examples/README.rst", "**/README.md"]
templates_path = []

# The API reference (one page per module) and the list of measurement pages, written at every build.
generate.api_reference(HERE / "api")
generate.measurements(HERE)
autosummary_generate = False
autodoc_default_options = {"member-order": "bysource"}
autodoc_typehints = "none"
autodoc_inherit_docstrings = False
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
# Of numpydoc's checks, the one a reader would see as a wrong page: a documented parameter the function does not
# take.  The others (a summary per section, an example per function...) flag style, over a thousand times.
numpydoc_validation_checks = {"PR02"}

# The measurement pages are written by commands (meshsal.util.pages): their headings start at "#".
myst_heading_anchors = 2
# Measurement pages are written by the commands that measured them, headings at whatever level their tables take.
suppress_warnings = ["myst.header"]

generate.prune_gallery(HERE / "examples", HERE / "auto_examples")
sphinx_gallery_conf = {
    "examples_dirs": str(HERE / "examples"),
    "gallery_dirs": str(HERE / "auto_examples"),
    "filename_pattern": r"/plot_",
    "within_subsection_order": "FileNameSortKey",
    "download_all_examples": False,
    "remove_config_comments": True,
    "show_memory": False,
    "min_reported_time": 1,
}

OURS = tuple(generate.PACKAGES)
# |x| is an absolute value in the docstrings' formulas, a substitution to reStructuredText: shown as code.
ABSOLUTE = re.compile(r"(?<![|`\w])\|([^|`\n]*[^|`\s])\|(?![|`\w])")


def skip_foreign(app, what, name, obj, skip, options):
    """Leave out members a class gets from elsewhere (scikit-learn's generated ``set_*_request``)."""
    module = getattr(obj, "__module__", None) or ""
    if callable(obj) and module and module.split(".")[0] not in OURS:
        return True
    return None


def absolute_values(app, what, name, obj, options, lines):
    for i, line in enumerate(lines):
        if not line.lstrip().startswith((">>>", "...", "|", "+")):
            lines[i] = ABSOLUTE.sub(r"``|\1|``", line)


def setup(app):
    app.connect("autodoc-skip-member", skip_foreign)
    app.connect("autodoc-process-docstring", absolute_values)


html_theme = "pydata_sphinx_theme"
html_title = "visuotactile"
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "secondary_sidebar_items": ["page-toc"],
}
html_static_path = []
html_show_sourcelink = False
