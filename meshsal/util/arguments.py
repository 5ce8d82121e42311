"""What every ``visuotactile`` subcommand's options share: defaults shown in ``--help``, renamed options.

Each package registers its own subcommands (``meshsal.cli``, ``tactile.cli``,
``hw.cli``, ``classify.cli``); they use :class:`HelpFormatter`, and an option
renamed so that one concept has one name everywhere keeps its old spelling
for one release with a warning (:func:`add_renamed`), as scikit-learn
deprecates a parameter.  A subcommand whose options need heavy imports to
describe them adds them only when it is chosen (:func:`defer_options`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from meshsal.util.atomic import check_writable

__all__ = ["HelpFormatter", "Subcommands", "add_renamed", "defer_options", "output_file", "output_folder", "REMOVED_IN"]

#: The release that drops the old spellings.
REMOVED_IN = "0.3"


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """``--help`` with each option's default, unless its help already tells it or there is none to tell.

    Examples
    --------
    >>> p = argparse.ArgumentParser(prog="x", formatter_class=HelpFormatter)
    >>> _ = p.add_argument("--n-points", type=int, default=15, help="points per mesh")
    >>> _ = p.add_argument("--methods", default=("attention", "uniform"), help="point methods")
    >>> _ = p.add_argument("--model", help="touch model file")
    >>> _ = p.add_argument("--quiet", action="store_true", help="no progress bar")
    >>> print(p.format_help().split("options:")[1].strip())  # doctest: +NORMALIZE_WHITESPACE
    -h, --help            show this help message and exit
    --n-points N_POINTS   points per mesh (default: 15)
    --methods METHODS     point methods (default: attention,uniform)
    --model MODEL         touch model file
    --quiet               no progress bar
    """

    def _get_help_string(self, action):
        text = action.help or ""
        default = action.default
        told = "default" in text.lower() or "%(default)" in text
        if told or action.nargs == 0 or default is None or default is argparse.SUPPRESS or default == ():
            return text  # a flag's default is its absence
        if isinstance(default, tuple | list):  # a comma-separated list, as it is typed
            return f"{text} (default: {','.join(map(str, default)).replace('%', '%%')})"
        return super()._get_help_string(action)


class _Renamed(argparse.Action):
    """The old spelling of a renamed option: stores into the new option's destination, with a warning."""

    def __init__(self, option_strings, dest, new_option: str = "", **kwargs):
        self.new_option = new_option
        super().__init__(option_strings, dest, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        print(
            f"{parser.prog}: warning: {option_string} is deprecated and goes in {REMOVED_IN}: "
            f"use {self.new_option} (FutureWarning)",
            file=sys.stderr,
        )
        setattr(namespace, self.dest, values)


def add_renamed(parser: argparse.ArgumentParser, old: str, new: argparse.Action) -> None:
    """Accept ``old``, the former spelling of the option ``new`` (the action ``add_argument`` returned).

    It is hidden from ``--help``; using it stores the value as ``new`` would
    and prints ``PROG: warning: OLD is deprecated and goes in 0.3: use NEW``.

    Examples
    --------
    >>> p = argparse.ArgumentParser(prog="visuotactile points")
    >>> add_renamed(p, "--n", p.add_argument("--n-points", type=int, default=15))
    >>> p.parse_args(["--n", "6"]).n_points   # and a warning on stderr
    6
    """
    parser.add_argument(
        old,
        dest=new.dest,
        type=new.type,
        choices=new.choices,
        metavar=new.metavar,
        action=_Renamed,
        new_option=new.option_strings[-1],
        help=argparse.SUPPRESS,
    )


class Subcommands(argparse._SubParsersAction):
    """``add_subparsers(action=Subcommands)``: subcommands that get their options when they are chosen.

    Describing some options takes heavy imports (the classifiers' registry
    imports scikit-learn: a second).  A subcommand registered through
    :func:`defer_options` gets its options when the command line chooses it,
    or when :meth:`complete` adds every subcommand's (for documentation);
    ``--help`` alone and the other subcommands import none of it.

    Examples
    --------
    >>> p = argparse.ArgumentParser(prog="x")
    >>> sub = p.add_subparsers(dest="command", action=Subcommands)
    >>> added = []
    >>> defer_options(sub, sub.add_parser("heavy"), lambda q: added.append(q.add_argument("--n", type=int)))
    >>> _ = sub.add_parser("light")
    >>> p.parse_args(["light"]).command, added
    ('light', [])
    >>> p.parse_args(["heavy", "--n", "3"]).n, len(added)
    (3, 1)
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._pending = {}

    def defer(self, parser: argparse.ArgumentParser, add_options) -> None:
        """Call ``add_options(parser)`` when ``parser``'s subcommand is chosen, or by :meth:`complete`."""
        self._pending[parser] = add_options

    def complete(self) -> None:
        """Add every deferred subcommand's options now."""
        while self._pending:
            parser, add_options = self._pending.popitem()
            add_options(parser)

    def __call__(self, parser, namespace, values, option_string=None):
        chosen = self._name_parser_map.get(values[0])
        add_options = self._pending.pop(chosen, None)
        if add_options is not None:
            add_options(chosen)
        super().__call__(parser, namespace, values, option_string)


def defer_options(subparsers, parser: argparse.ArgumentParser, add_options) -> None:
    """Add a subcommand's options with ``add_options(parser)`` when it is chosen, where ``subparsers`` defers.

    ``subparsers`` is what ``add_subparsers`` returned and ``parser`` one of
    its subcommands.  Subparsers made with ``action=Subcommands`` wait;
    any others get the options now.
    """
    if isinstance(subparsers, Subcommands):
        subparsers.defer(parser, add_options)
    else:
        add_options(parser)


def output_folder(text: str) -> Path:
    """``type=`` of an option naming a folder to write: refused as the command line is read, before any work,
    when a file is in the way or the folder cannot be written (:func:`meshsal.util.atomic.check_writable`).

    Examples
    --------
    >>> p = argparse.ArgumentParser(prog="x")
    >>> _ = p.add_argument("--out", type=output_folder)
    >>> p.parse_args(["--out", "results"]).out.name
    'results'
    """
    try:
        return check_writable(text, folder=True)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def output_file(text: str) -> Path:
    """``type=`` of an option naming a file to write, checked as :func:`output_folder` checks a folder."""
    try:
        return check_writable(text, folder=False)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
