"""What an experiment measured: rate cells, paired comparisons, their tables and files.

A cell is one recognition rate (method, protocol, classifier, object set,
selection, touches) summarized over replicates and objects
(:func:`classify.reporting.stats.summarize`).  A comparison is the paired difference
of a method's rates and the baseline method's on the same replicates and
objects (:func:`classify.reporting.stats.paired_difference`).  ``results.csv`` holds
both: one row per cell, the comparison columns filled for every method but
the baseline.  ``results.json`` adds every setting and the raw
(replicate, object) rate matrices, so any other statistic can be computed
from it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from classify.reporting import report
from classify.reporting.confusion import ConfusionMatrix, counts_pairs

__all__ = [
    "CellKey",
    "Cell",
    "Comparison",
    "ConfusionMatrix",
    "StoppingCell",
    "ExperimentResult",
    "MissingCell",
    "format_tables",
    "write_outputs",
]


class CellKey(NamedTuple):
    """Where a rate belongs: the coordinates of a cell (equal to the plain tuple of its fields)."""

    method: str
    protocol: str
    classifier: str
    n_objects: int
    selection: bool
    touches: int


@dataclass(frozen=True)
class Cell:
    """One recognition rate (percent) with its 95 % interval over replicates and objects.

    ``touch_sets`` is the fewest distinct touch sets any object's test
    instance offered at this many touches (0 for the paper protocol, which
    has no touch fusion).
    """

    method: str
    protocol: str
    classifier: str
    n_objects: int
    selection: bool
    touches: int
    mean: float
    std: float
    ci_low: float
    ci_high: float
    replicates: int
    touch_sets: int = 0


@dataclass(frozen=True)
class Comparison:
    """A method's rate minus the baseline method's, paired (percentage points).

    A touch policy (protocol "sequential") is compared with the baseline
    method's fixed plan on the same instances (protocol "instance").
    """

    method: str
    baseline: str
    protocol: str
    classifier: str
    n_objects: int
    selection: bool
    touches: int
    diff: float
    ci_low: float
    ci_high: float
    p_value: float
    replicates: int


@dataclass(frozen=True)
class StoppingCell:
    """The stopping rule at one level: stop when the top class's calibrated posterior reaches ``level``.

    ``accuracy`` (percent) and ``touches`` used, each mean and 95 % interval
    over replicates and objects; fixed plans touch their points in order.
    """

    method: str
    protocol: str
    classifier: str
    n_objects: int
    level: float
    accuracy: float
    accuracy_low: float
    accuracy_high: float
    touches: float
    touches_low: float
    touches_high: float
    replicates: int


@dataclass(frozen=True)
class ExperimentResult:
    """Everything one experiment measured, and every setting it used.

    ``rates`` maps a cell's coordinates (a :class:`CellKey`: ``(method, protocol,
    classifier, n_objects, selection, touches)``) to its (replicates, objects) matrix of
    rates in percent.  ``selection_kept`` maps ``"method/protocol/n_objects"``
    to the mean fraction of training imprints similarity selection kept.
    ``stopping`` holds the stopping rule's :class:`StoppingCell` records, and
    ``stopping_rates`` maps ``(method, protocol, classifier, n_objects)`` to the
    (correct, touches used) matrices behind them, each (replicates, levels,
    objects), so that a subset of the objects can be summarized afterwards.
    ``timings`` maps each stage, ``"total"`` and ``"cpu_total"`` to seconds;
    ``usage`` maps each stage and ``"total"`` to its ``wall_s``, ``cpu_s``
    and ``peak_mb`` (``classify.runtime.usage.StageUsage``: this process and
    its local workers).
    """

    cells: tuple
    comparisons: tuple
    confusions: tuple
    object_names: tuple
    object_sets: tuple
    classifiers: tuple
    settings: dict = field(default_factory=dict)
    selection_kept: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    usage: dict = field(default_factory=dict)
    rates: dict = field(default_factory=dict)
    stopping: tuple = ()
    stopping_rates: dict = field(default_factory=dict)

    def cell(self, method, protocol, classifier, n_objects, selection, touches=1) -> Cell:
        """The cell of these coordinates (:class:`MissingCell`, a KeyError listing what was measured, if none)."""
        return _find(self.cells, (method, protocol, classifier, n_objects, selection, touches), "cell")

    def comparison(self, method, protocol, classifier, n_objects, selection, touches=1) -> Comparison:
        """The paired comparison of ``method`` with the baseline at these coordinates.

        Raises
        ------
        MissingCell
            A KeyError naming the coordinates asked for and listing, for each, the values measured.
        """
        return _find(self.comparisons, (method, protocol, classifier, n_objects, selection, touches), "comparison")

    def table(self, method, protocol, touches=1) -> str:
        """The Table 1 layout as Markdown."""
        return report.table_markdown(self.cells, method, protocol, self.classifiers, self.object_sets, touches)

    @classmethod
    def from_json(cls, document: dict) -> ExperimentResult:
        """The result a ``results.json`` holds (:meth:`to_json`'s inverse, as far as the tables need)."""

        def key(d):
            return tuple(d[c] for c in _COORDINATES)

        confusions = tuple(_confusion_from(c) for c in document.get("confusions", []))
        return cls(
            cells=tuple(Cell(**c) for c in document["cells"]),
            comparisons=tuple(Comparison(**c) for c in document.get("comparisons", [])),
            confusions=confusions,
            object_names=tuple(document["object_names"]),
            object_sets=tuple(document["object_sets"]),
            classifiers=tuple(document["classifiers"]),
            settings=document.get("settings", {}),
            selection_kept=document.get("selection_kept", {}),
            timings=document.get("timings_s", {}),
            usage=document.get("usage", {}),
            rates={key(r): np.asarray(r["replicate_by_object"]) for r in document.get("rates", [])},
            stopping=tuple(StoppingCell(**s) for s in document.get("stopping", [])),
            stopping_rates={
                (s["method"], s["protocol"], s["classifier"], s["n_objects"]): (
                    np.asarray(s["correct"]),
                    np.asarray(s["touches"]),
                )
                for s in document.get("stopping_by_object", [])
            },
        )

    def to_json(self) -> dict:
        return {
            "settings": self.settings,
            "object_names": list(self.object_names),
            "object_sets": list(self.object_sets),
            "classifiers": list(self.classifiers),
            "cells": [dataclasses.asdict(c) for c in self.cells],
            "comparisons": [dataclasses.asdict(c) for c in self.comparisons],
            "confusions": [
                {
                    **{f: getattr(c, f) for f in _CONFUSION_FIELDS},
                    "object_names": list(c.object_names),
                    "pairs": np.asarray(c.pairs).tolist(),
                }
                for c in self.confusions
            ],
            "rates": [
                {
                    "method": k[0],
                    "protocol": k[1],
                    "classifier": k[2],
                    "n_objects": k[3],
                    "selection": k[4],
                    "touches": k[5],
                    "replicate_by_object": np.asarray(v).tolist(),
                }
                for k, v in self.rates.items()
            ],
            "selection_kept": self.selection_kept,
            "stopping": [dataclasses.asdict(s) for s in self.stopping],
            "stopping_by_object": [
                {
                    "method": k[0],
                    "protocol": k[1],
                    "classifier": k[2],
                    "n_objects": k[3],
                    "correct": np.asarray(c).tolist(),
                    "touches": np.asarray(t).tolist(),
                }
                for k, (c, t) in self.stopping_rates.items()
            ],
            "timings_s": self.timings,
            "usage": self.usage,
        }


_COORDINATES = ("method", "protocol", "classifier", "n_objects", "selection", "touches")
#: A confusion's coordinates, as ``results.json`` writes them beside its names and pairs.
_CONFUSION_FIELDS = _COORDINATES[:-1]


def _confusion_from(document: dict) -> ConfusionMatrix:
    """A confusion as ``results.json`` holds it: its ``pairs``, or the dense ``counts`` of older files."""
    fields = {f: document[f] for f in _CONFUSION_FIELDS}
    pairs = document["pairs"] if "pairs" in document else counts_pairs(np.asarray(document["counts"]))
    return ConfusionMatrix(
        **fields, object_names=tuple(document["object_names"]), pairs=np.asarray(pairs, np.int64).reshape(-1, 3)
    )


class MissingCell(KeyError):
    """No cell or comparison was measured at the coordinates asked for; the message lists what was."""

    def __str__(self) -> str:
        return str(self.args[0])


def _find(records, key, kind: str):
    for r in records:
        if tuple(getattr(r, c) for c in _COORDINATES) == key:
            return r
    asked = ", ".join(f"{c}={v!r}" for c, v in zip(_COORDINATES, key))
    if not records:
        why = " (comparisons need several methods: each is compared with the baseline)" if kind == "comparison" else ""
        raise MissingCell(f"no {kind} at {asked}: this result has none{why}")
    measured = []
    for i, c in enumerate(_COORDINATES):
        values = sorted({getattr(r, c) for r in records}, key=repr)
        missing = "" if key[i] in values else f" (not {key[i]!r})"
        measured.append(f"{c} {', '.join(map(repr, values))}{missing}")
    raise MissingCell(f"no {kind} at {asked}; measured: {'; '.join(measured)}")


def _title(protocol):
    return {
        "paper": "paper protocol (CV grouped by point)",
        "instance": "instance protocol (train and test on distinct instances)",
        "sequential": "sequential protocol (a touch policy on the instance protocol's instances)",
    }.get(protocol, protocol)


def format_tables(result: ExperimentResult, title="Table 1 layout") -> str:
    """Every table of a result as Markdown: Table 1 per method and protocol, touches, comparisons."""
    blocks = []
    protocols = list(dict.fromkeys(c.protocol for c in result.cells))
    methods = list(dict.fromkeys(c.method for c in result.cells))
    n = result.object_sets[-1]
    for protocol in protocols:
        for method in methods:
            if not any(c.method == method and c.protocol == protocol for c in result.cells):
                continue
            what = "policy" if protocol == "sequential" else "points"
            blocks.append(
                f"### {title}: {method} {what}, {_title(protocol)}, recognition rate (%), single "
                f"touch, mean [95 % interval]\n\n" + result.table(method, protocol)
            )
            if protocol in ("instance", "sequential"):
                for selection in (False, True) if protocol == "instance" else (False,):
                    blocks.append(
                        f"### {method} {what}, {protocol} protocol, {n} objects, "
                        f"{'with' if selection else 'no'} selection: recognition (%) after k touches\n\n"
                        + report.touches_markdown(result.cells, method, protocol, result.classifiers, n, selection)
                    )
    # The place-free classifier the README's tables use, and the place-aware recognizer beside it.
    shown = [c for c in ("knn", "place") if c in result.classifiers] or [result.classifiers[0]]
    if result.comparisons:
        baseline = result.comparisons[0].baseline
        for clf in shown:
            for protocol in [p for p in protocols if p != "sequential"]:
                table = report.comparison_markdown(result.cells, result.comparisons, protocol, clf, n, False)
                if table:
                    policies = " and touch policies" if protocol == "instance" and "sequential" in protocols else ""
                    blocks.append(
                        f"### Point methods{policies} against {baseline}, {_title(protocol)}, {clf}, {n} "
                        f"objects, no selection: rate (%) and paired difference (points) [95 % interval], "
                        f"Wilcoxon p\n\n" + table
                    )
    for clf in shown if result.stopping else ():
        if any((s.classifier, s.n_objects) == (clf, n) for s in result.stopping):
            blocks.append(
                f"### Stopping rule: stop when the top object's posterior reaches p; {clf}, {n} "
                f"objects, no selection: accuracy (%) / mean touches used [95 % intervals in "
                f"stopping.csv]\n\n" + report.stopping_markdown(result.stopping, clf, n)
            )
    notes = [
        c
        for c in result.cells
        if c.protocol == "instance"
        and c.touches > 1
        and 0 < c.touch_sets < result.settings.get("touch_sets_per_object", 0)
    ]
    if notes:
        ks = sorted({c.touches for c in notes})
        blocks.append(
            f"Touch sets: at k = {', '.join(map(str, ks))} touches an object's test instance offers "
            f"fewer distinct sets than the {result.settings.get('touch_sets_per_object')} asked for; "
            f"all of them were used (the table's touch_sets column in results.csv says how many)."
        )
    return "\n\n".join(blocks) + "\n"


def write_outputs(result: ExperimentResult, out_dir) -> None:
    """results.json, results.csv, confusion_<classifier>.png and touches.png under ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report.write_json(out / "results.json", result.to_json())
    report.write_csv(out / "results.csv", result.cells, result.comparisons)
    if result.stopping:
        report.write_stopping_csv(out / "stopping.csv", result.stopping)
    n = result.object_sets[-1]
    for name in result.classifiers:
        panels = [
            (f"{c.method} / {c.protocol} / {'sel' if c.selection else 'no sel'}", c, c.object_names)
            for c in result.confusions
            if c.classifier == name and c.n_objects == n and not c.selection
        ]
        if panels:
            report.write_confusion_png(out / f"confusion_{name}.png", panels)
    clf = "knn" if "knn" in result.classifiers else result.classifiers[0]
    curves = {}
    for method, protocol in dict.fromkeys((c.method, c.protocol) for c in result.cells):
        cells = sorted(
            (
                c
                for c in result.cells
                if (c.method, c.protocol) == (method, protocol)
                and c.classifier == clf
                and c.n_objects == n
                and not c.selection
                and c.protocol in ("instance", "sequential")
            ),
            key=lambda c: c.touches,
        )
        if cells:
            curves[f"policy {method}" if protocol == "sequential" else method] = (
                np.array([c.touches for c in cells]),
                np.array([c.mean for c in cells]),
                np.array([c.ci_low for c in cells]),
                np.array([c.ci_high for c in cells]),
            )
    if curves:
        report.write_touches_png(
            out / "touches.png", curves, f"instance protocol, {clf}, {n} objects, no selection: recognition vs touches"
        )
