"""Pages written at every build from what is there: the API reference, the commands' help, the measurement pages.

And the gallery's output is started afresh when an example it holds no longer exists.

The API reference has one page per public module of ``meshsal``, ``tactile``, ``classify`` and
``hw``: its docstring, a table of its public names (``__all__``, or what it
defines when it has none) and the full documentation of the names whose home
it is.  A function or class lives at its shortest public path (the
``meshsal.interest_points`` a user types, not the module that defines it); a
constant lives where it is defined, since its ``#:`` comment is there.  So
each object is documented once, and every table links to it.  Names exported
lazily (``meshsal.util.lazy``) are found through the package's ``__all__``,
which loads them.
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import os
import pkgutil
import shutil
import types
from pathlib import Path

PACKAGES = ("meshsal", "tactile", "classify", "hw")
TITLES = {
    "meshsal": "meshes, views, visual attention and interest points",
    "tactile": "simulated tactile imprints",
    "classify": "recognition, the experiment, batches",
    "hw": "real sensors",
}


def _modules(package: str) -> list[types.ModuleType]:
    """The package and every public module under it, imported, in dotted order."""
    root = importlib.import_module(package)
    names = [package]
    for info in pkgutil.walk_packages(root.__path__, prefix=package + "."):
        if not any(part.startswith("_") for part in info.name.split(".")):
            names.append(info.name)
    return [importlib.import_module(name) for name in sorted(names)]


def _public(module: types.ModuleType) -> dict[str, object]:
    """Public name -> object: ``__all__`` (submodules left out), or the functions and classes it defines."""
    if hasattr(module, "__all__"):
        named = {name: getattr(module, name) for name in module.__all__}
    else:
        named = {
            name: value
            for name, value in vars(module).items()
            if not name.startswith("_")
            and (inspect.isfunction(value) or inspect.isclass(value))
            and value.__module__ == module.__name__
        }
    return {name: value for name, value in named.items() if not isinstance(value, types.ModuleType)}


def _kind(value) -> str:
    if inspect.isclass(value):
        return "class" if not issubclass(value, BaseException) else "exception"
    if callable(value) and hasattr(value, "__module__") and hasattr(value, "__qualname__"):
        return "function"
    return "data"


def homes(modules) -> dict[tuple[str, int], str]:
    """(name, id of the object) -> the module whose page documents it.

    Callables and classes: the shallowest module that lists them, unless a
    module has that very dotted name (``meshsal.attention.dkl`` is a function
    and a module: the function moves down to where it is defined).
    Constants: the deepest module that lists them.
    """
    module_names = {m.__name__ for m in modules}
    listed: dict[tuple[str, int], list[str]] = {}
    kinds = {}
    for module in modules:
        for name, value in _public(module).items():
            listed.setdefault((name, id(value)), []).append(module.__name__)
            kinds[name, id(value)] = _kind(value)
    chosen = {}
    for key, where in listed.items():
        where = sorted(where, key=lambda m: (m.count("."), m), reverse=kinds[key] == "data")
        free = [m for m in where if f"{m}.{key[0]}" not in module_names]
        chosen[key] = (free or where)[0]
    return chosen


def _underline(title: str, char: str = "=") -> str:
    return f"{title}\n{char * len(title)}\n"


def _relative(target: str, module: str) -> str:
    """``target`` as autosummary takes it on ``module``'s page: under the current module, without its prefix."""
    return target.removeprefix(module + ".")


def module_page(module, public, home, children) -> str:
    name = module.__name__
    lines = [_underline(f"``{name}``"), f".. automodule:: {name}", "   :no-members:", ""]
    if children:
        lines += [".. rubric:: Modules", "", ".. autosummary::", ""]
        lines += [f"   {_relative(child, name)}" for child in children]
        lines += ["", ".. toctree::", "   :hidden:", ""]
        lines += [f"   {child}" for child in children]
        lines.append("")
    if public:
        lines += [".. rubric:: Public names", "", ".. autosummary::", "   :nosignatures:", ""]
        for attr, value in public.items():
            lines.append(f"   ~{_relative(home[attr, id(value)] + '.' + attr, name)}")
        lines.append("")
    own = [(attr, value) for attr, value in public.items() if home[attr, id(value)] == name]
    if own:
        lines += [f".. currentmodule:: {name}", ""]
    for attr, value in own:
        kind = _kind(value)
        directive = {"class": "autoclass", "exception": "autoexception", "function": "autofunction"}.get(kind)
        if directive is None:
            lines += [f".. autodata:: {attr}", "   :no-value:", ""]
        elif kind in ("class", "exception"):
            lines += [f".. {directive}:: {attr}", "   :members:", "   :show-inheritance:", ""]
        else:
            lines += [f".. {directive}:: {attr}", ""]
    return "\n".join(lines)


def _write(path: Path, text: str) -> None:
    """Write only what changed, so that an unchanged page is not read again."""
    if not path.exists() or path.read_text() != text:
        path.write_text(text)


def api_reference(out: Path) -> list[str]:
    """Write ``out/index.rst`` and one page per module; returns the modules' names."""
    out.mkdir(parents=True, exist_ok=True)
    modules = [m for package in PACKAGES for m in _modules(package)]
    home = homes(modules)
    names = [m.__name__ for m in modules]
    for module in modules:
        name = module.__name__
        children = [n for n in names if n.rpartition(".")[0] == name]
        _write(out / f"{name}.rst", module_page(module, _public(module), home, children))
    index = [
        _underline("API reference"),
        "Every public name of the four packages, from their docstrings.  Each object is documented",
        "once, at the path a user imports it from; the pages of the modules that define it link there.",
        "",
        ".. toctree::",
        "   :maxdepth: 1",
        "",
    ]
    index += [f"   {package}" for package in PACKAGES]
    index.append("   commands")
    index += ["", ".. list-table::", "   :widths: 20 80", ""]
    for package in PACKAGES:
        index += [f"   * - :mod:`{package}`", f"     - {TITLES[package]}"]
    index += ["   * - :doc:`commands`", "     - the ``visuotactile`` command: every subcommand's ``--help``"]
    _write(out / "index.rst", "\n".join(index) + "\n")
    _write(out / "commands.rst", commands_page())
    for stale in set(out.glob("*.rst")) - {out / f"{n}.rst" for n in [*names, "index", "commands"]}:
        stale.unlink()
    return names


def _help(parser: argparse.ArgumentParser) -> str:
    """``--help`` as a terminal 100 columns wide shows it, whatever terminal the build runs in."""
    columns = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "100"
    try:
        return parser.format_help()
    finally:
        if columns is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = columns


def commands_page() -> str:
    """Every subcommand's ``--help``, from the parser the command itself builds (``classify.cli``)."""
    from classify.cli import build_parser

    parser = build_parser()
    lines = [
        _underline("The ``visuotactile`` command"),
        "What ``visuotactile --help`` and ``visuotactile COMMAND --help`` print.",
        "",
        ".. code-block:: text",
        "",
    ]
    lines += [f"   {line}".rstrip() for line in _help(parser).splitlines()]
    lines.append("")
    subcommands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name, sub in subcommands.choices.items():
        lines += [_underline(name, "-"), ".. code-block:: text", ""]
        lines += [f"   {line}".rstrip() for line in _help(sub).splitlines()]
        lines.append("")
    return "\n".join(lines)


MEASUREMENTS = {
    "results": "Results",
    "benchmarks": "Benchmarks",
}


def measurements(docs: Path) -> None:
    """Write ``docs/measurements.rst``: the Markdown pages commands wrote to ``docs/results`` and ``docs/benchmarks``.

    The pages are listed as they are found, so a page appears once its command has written it.
    """
    lines = [
        _underline("Measurements"),
        "Pages written by the commands that measured them (``meshsal.util.pages``): each names its",
        "command, the commit it ran at, the machine and the date in its header.  Rerun the command to",
        "bring a page up to date.",
        "",
    ]
    for folder, title in MEASUREMENTS.items():
        pages = sorted(path.stem for path in (docs / folder).glob("*.md"))
        lines += [_underline(title, "-")]
        if pages:
            lines += [".. toctree::", "   :maxdepth: 1", ""] + [f"   {folder}/{page}" for page in pages] + [""]
        else:
            lines += [f"No page in ``docs/{folder}`` yet.", ""]
    _write(docs / "measurements.rst", "\n".join(lines))


def prune_gallery(examples: Path, gallery: Path) -> None:
    """Remove ``gallery`` (sphinx-gallery's output) when it holds an example no longer in ``examples``.

    Sphinx-gallery reruns the examples that changed, but leaves the pages of removed or renamed ones,
    which then belong to no table of contents.
    """
    present = {path.stem for path in examples.glob("*.py")}
    held = {path.stem for path in gallery.glob("*.rst") if path.stem not in ("index", "sg_execution_times")}
    if held - present:
        shutil.rmtree(gallery)
