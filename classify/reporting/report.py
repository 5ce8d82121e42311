"""Reports of the recognition experiment: Markdown tables, CSV/JSON, PNG figures.

Tables follow the paper's Table 1 (and Table 2 for real data): one row per
classifier, one column per object set and similarity selection, each cell
the mean recognition rate in percent with its 95 % interval.  Figures are drawn with
OpenCV (no plotting library): a confusion-matrix sheet per classifier and
recognition rate against the number of touches.  Every file is written
atomically.
"""

from __future__ import annotations

import csv
import io
import json

import cv2
import numpy as np

from classify.reporting.confusion import ConfusionMatrix, counts_pairs, dense_counts, top_pairs
from meshsal.util.atomic import write_png, write_text

__all__ = [
    "CSV_COLUMNS",
    "format_rate",
    "format_diff",
    "table_markdown",
    "touches_markdown",
    "comparison_markdown",
    "stopping_markdown",
    "write_csv",
    "write_stopping_csv",
    "json_text",
    "write_json",
    "confusion_image",
    "touches_image",
    "write_confusion_png",
    "write_touches_png",
]

CSV_COLUMNS = (
    "method",
    "protocol",
    "classifier",
    "n_objects",
    "selection",
    "touches",
    "mean",
    "std",
    "ci_low",
    "ci_high",
    "replicates",
    "touch_sets",
    "baseline",
    "diff",
    "diff_ci_low",
    "diff_ci_high",
    "p_value",
)

_FONT = cv2.FONT_HERSHEY_SIMPLEX
_PALETTE = [
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
]


def format_rate(mean: float, low: float, high: float) -> str:
    """``"87.9 [85.2, 90.1]"``: a rate (percent) and its interval.

    Examples
    --------
    >>> format_rate(87.894, 85.21, 90.06)
    '87.9 [85.2, 90.1]'
    """
    return f"{mean:.1f} [{low:.1f}, {high:.1f}]"


def format_diff(diff: float, low: float, high: float, p: float) -> str:
    """``"+4.2 [1.0, 7.5] p=0.012"``: a paired difference (points), its interval and p-value.

    Examples
    --------
    >>> format_diff(-3.04, -6.0, -0.5, 0.0312)
    '-3.0 [-6.0, -0.5] p=0.031'
    """
    return (
        f"{diff:+.1f} [{low:.1f}, {high:.1f}] p={p:.3f}"
        if p >= 0.001
        else f"{diff:+.1f} [{low:.1f}, {high:.1f}] p<0.001"
    )


def _index(cells):
    return {(c.method, c.protocol, c.classifier, c.n_objects, c.selection, c.touches): c for c in cells}


def table_markdown(cells, method: str, protocol: str, classifiers, object_sets, touches: int = 1) -> str:
    """The Table 1 layout: rows classifiers (those measured for this method and protocol), columns (objects x no
    selection / selection).

    Missing cells print as ``-``.

    Parameters
    ----------
    cells : iterable of records with the ``CSV_COLUMNS`` attributes
    method, protocol : which cells to show
    classifiers : row order
    object_sets : sequence of object counts (e.g. ``(4, 6)``)
    touches : which touch count to show (1: single touch)
    """
    index = _index(cells)
    header = ["classifier"]
    for n in object_sets:
        header += [f"{n} objects, no selection", f"{n} objects, selection"]
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join(["---"] + [":---:"] * (len(header) - 1)) + "|"]
    for name in classifiers:
        if not any(key[:3] == (method, protocol, name) for key in index):
            continue
        row = [name]
        for n in object_sets:
            for selection in (False, True):
                c = index.get((method, protocol, name, n, selection, touches))
                row.append(format_rate(c.mean, c.ci_low, c.ci_high) if c else "-")
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def touches_markdown(
    cells, method: str, protocol: str, classifiers, n_objects: int, selection: bool, touches=(1, 2, 3, 5, 10, 15)
) -> str:
    """Recognition after k touches: rows classifiers (those measured in this setting), columns k (mean [95 %
    interval], percent)."""
    index = _index(cells)
    ks = [k for k in touches if any((method, protocol, c, n_objects, selection, k) in index for c in classifiers)]
    classifiers = [c for c in classifiers if any((method, protocol, c, n_objects, selection, k) in index for k in ks)]
    lines = [
        "| classifier | " + " | ".join(f"{k} touch{'es' if k > 1 else ''}" for k in ks) + " |",
        "|---|" + "|".join([":---:"] * len(ks)) + "|",
    ]
    for name in classifiers:
        row = [name]
        for k in ks:
            c = index.get((method, protocol, name, n_objects, selection, k))
            row.append(format_rate(c.mean, c.ci_low, c.ci_high) if c else "-")
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def comparison_markdown(
    cells, comparisons, protocol: str, classifier: str, n_objects: int, selection: bool, touches=(1, 3, 5, 15)
) -> str:
    """Point methods side by side: rate and paired difference against the baseline at a few k.

    Rows are methods (the baseline first), then for the instance protocol the
    touch policies compared with it (protocol "sequential"); columns the rate
    and the difference at each k, and the fewest touches whose mean rate
    reaches 95 %.  Empty when nothing was compared.
    """
    index = _index(cells)
    protocols = (protocol, "sequential") if protocol == "instance" else (protocol,)
    diffs = {
        (d.method, d.protocol, d.touches): d
        for d in comparisons
        if d.protocol in protocols and (d.classifier, d.n_objects, d.selection) == (classifier, n_objects, selection)
    }
    if not diffs:
        return ""
    baseline = next(iter(diffs.values())).baseline
    rows = [(baseline, protocol)] + list(dict.fromkeys((m, p) for m, p, _ in diffs))
    ks = [k for k in touches if (baseline, protocol, classifier, n_objects, selection, k) in index]
    header = ["points or policy"]
    for k in ks:
        header += [f"{k} touch{'es' if k > 1 else ''}", f"diff at {k}"]
    header.append("touches to 95 %")
    lines = ["| " + " | ".join(header) + " |", "|---|" + "|".join([":---:"] * (len(header) - 1)) + "|"]
    for m, p in rows:
        row = [f"policy {m}" if p == "sequential" else m]
        for k in ks:
            c = index.get((m, p, classifier, n_objects, selection, k))
            d = diffs.get((m, p, k))
            row.append(format_rate(c.mean, c.ci_low, c.ci_high) if c else "-")
            row.append(
                format_diff(d.diff, d.ci_low, d.ci_high, d.p_value) if d else ("baseline" if m == baseline else "-")
            )
        reached = sorted(
            c.touches
            for key, c in index.items()
            if key[:5] == (m, p, classifier, n_objects, selection) and c.mean >= 95.0
        )
        top = max((key[5] for key in index if key[:5] == (m, p, classifier, n_objects, selection)), default=0)
        row.append(str(reached[0]) if reached else f"not within {top}")
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def stopping_markdown(stopping, classifier: str, n_objects: int) -> str:
    """The stopping rule at each level: rows methods and policies, cells accuracy (%) / mean touches used.

    The last column is the mean touches used at the lowest level whose mean accuracy reaches 95 %.
    """
    mine = [s for s in stopping if (s.classifier, s.n_objects) == (classifier, n_objects)]
    levels = sorted({s.level for s in mine})
    index = {(s.method, s.protocol, s.level): s for s in mine}
    rows = list(dict.fromkeys((s.method, s.protocol) for s in mine))
    lines = [
        "| points or policy | " + " | ".join(f"p = {p:g}" for p in levels) + " | touches at 95 % |",
        "|---|" + "|".join([":---:"] * (len(levels) + 1)) + "|",
    ]
    for m, p in rows:
        cells = [index[m, p, level] for level in levels]
        at = next((s for s in cells if s.accuracy >= 95.0), None)
        lines.append(
            f"| {'policy ' + m if p == 'sequential' else m} | "
            + " | ".join(f"{s.accuracy:.1f} / {s.touches:.2f}" for s in cells)
            + f" | {f'{at.touches:.2f} [{at.touches_low:.2f}, {at.touches_high:.2f}]' if at else 'not reached'} |"
        )
    return "\n".join(lines)


def write_stopping_csv(path, stopping) -> None:
    """One row per :class:`~classify.reporting.results.StoppingCell`, its fields as columns."""
    import dataclasses

    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    names = [f.name for f in dataclasses.fields(stopping[0])]
    writer.writerow(names)
    for s in stopping:
        writer.writerow([f"{v:.4f}" if isinstance(v, float) else v for v in (getattr(s, n) for n in names)])
    write_text(path, buffer.getvalue())


def write_csv(path, cells, comparisons=()) -> None:
    """One row per cell, columns ``CSV_COLUMNS``; rates in percent, selection true/false.

    The comparison columns hold the cell's paired difference against the
    baseline method, where there is one (empty otherwise).
    """
    diffs = {(d.method, d.protocol, d.classifier, d.n_objects, d.selection, d.touches): d for d in comparisons}
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for c in cells:
        d = diffs.get((c.method, c.protocol, c.classifier, c.n_objects, c.selection, c.touches))
        extra = (
            [d.baseline, f"{d.diff:.4f}", f"{d.ci_low:.4f}", f"{d.ci_high:.4f}", f"{d.p_value:.6f}"]
            if d
            else ["", "", "", "", ""]
        )
        writer.writerow(
            [
                c.method,
                c.protocol,
                c.classifier,
                c.n_objects,
                "true" if c.selection else "false",
                c.touches,
                f"{c.mean:.4f}",
                f"{c.std:.4f}",
                f"{c.ci_low:.4f}",
                f"{c.ci_high:.4f}",
                c.replicates,
                c.touch_sets,
                *extra,
            ]
        )
    write_text(path, buffer.getvalue())


def json_text(payload, indent: int = 2) -> str:
    """JSON indented by level, with every list of plain values on one line.

    ``json.dumps(payload, indent=2)`` gives each number of a rate matrix a
    line of its own; here a list holding no list or dict stays on one line,
    so a (replicates, objects) matrix takes a line per replicate.  The text
    parses to what ``json.dumps`` writes (numpy scalars and arrays converted).

    Examples
    --------
    >>> print(json_text({"rates": [[1.0, 0.5], [0.0, 1.0]], "name": "cup"}))
    {
      "rates": [
        [1.0, 0.5],
        [0.0, 1.0]
      ],
      "name": "cup"
    }
    """

    def convert(obj):
        if isinstance(obj, np.ndarray):
            return obj.tolist()
        if isinstance(obj, np.generic):
            return obj.item()
        raise TypeError(f"cannot write {type(obj).__name__} to JSON")

    def text(obj, level):
        if isinstance(obj, (np.ndarray, np.generic)):
            obj = convert(obj)
        inner, outer = " " * (indent * (level + 1)), " " * (indent * level)
        if isinstance(obj, dict) and obj:
            items = (
                f"{inner}{json.dumps(k if isinstance(k, str) else json.dumps(k))}: {text(v, level + 1)}"
                for k, v in obj.items()
            )
            return "{\n" + ",\n".join(items) + "\n" + outer + "}"
        if isinstance(obj, (list, tuple)) and any(isinstance(v, (list, tuple, dict, np.ndarray)) for v in obj):
            return "[\n" + ",\n".join(inner + text(v, level + 1) for v in obj) + "\n" + outer + "]"
        return json.dumps(obj, default=convert)

    return text(payload, 0)


def write_json(path, payload) -> None:
    """:func:`json_text` of the payload, written whole or not at all."""
    write_text(path, json_text(payload) + "\n")


def _put(img, text, org, scale=0.45, color=(0, 0, 0), thickness=1, anchor="left"):
    (w, h), _ = cv2.getTextSize(text, _FONT, scale, thickness)
    x, y = org
    if anchor == "center":
        x -= w // 2
    elif anchor == "right":
        x -= w
    cv2.putText(img, text, (int(x), int(y + h // 2)), _FONT, scale, color, thickness, cv2.LINE_AA)


#: Above this many classes a confusion panel lists the largest confusions instead of drawing the grid.
GRID_CLASSES = 24


def top_confusions(counts, names, k: int = 20) -> list[tuple[str, str, int, float]]:
    """The ``k`` largest off-diagonal cells: (true, predicted, count, share of the true class's touches).

    Examples
    --------
    >>> top_confusions(np.array([[8, 2, 0], [1, 9, 0], [0, 5, 5]]), ["a", "b", "c"], k=2)
    [('c', 'b', 5, 0.5), ('a', 'b', 2, 0.2)]
    """
    return top_pairs(counts_pairs(counts), list(names), k)


def _confusion_list(pairs, names, title, k: int = 20, line=22):
    """A panel for many classes: the overall rate and the ``k`` largest confusions as lines of text."""
    rows = top_pairs(pairs, list(names), k)
    img = np.full((70 + line * max(len(rows), 1), 640, 3), 255, np.uint8)
    _put(img, title, (8, 12), 0.5)
    right = pairs[pairs[:, 0] == pairs[:, 1], 2].sum() / max(pairs[:, 2].sum(), 1)
    _put(
        img,
        f"{len(names)} classes: {100 * right:.1f} % right; the largest confusions (true -> predicted):",
        (8, 36),
        0.42,
        (90, 90, 90),
    )
    for r, (a, b, count, share) in enumerate(rows):
        _put(img, f"{a} -> {b}: {count} ({100 * share:.0f} % of {a}'s)", (16, 62 + r * line), 0.42)
    return img


def _confusion_panel(pairs, names, title, cell=44):
    n = len(names)
    if n > GRID_CLASSES:
        return _confusion_list(pairs, names, title)
    matrix = dense_counts(pairs, n).astype(float)
    label_w = max(cv2.getTextSize(s, _FONT, 0.45, 1)[0][0] for s in names) + 16
    top = 56
    img = np.full((top + n * cell + 30, label_w + n * cell + 16, 3), 255, np.uint8)
    _put(img, title, (8, 12), 0.5)
    _put(img, "true \\ predicted", (8, 32), 0.4, (90, 90, 90))
    rows = matrix.sum(axis=1, keepdims=True)
    frac = np.divide(matrix, rows, out=np.zeros(matrix.shape, float), where=rows > 0)
    for j, name in enumerate(names):
        _put(img, name[:5], (label_w + j * cell + cell // 2, top - 10), 0.38, anchor="center")
    for i, name in enumerate(names):
        y0 = top + i * cell
        _put(img, name, (label_w - 8, y0 + cell // 2), 0.45, anchor="right")
        for j in range(n):
            x0 = label_w + j * cell
            f = frac[i, j]
            color = tuple(int(255 - f * (255 - c)) for c in (31, 119, 180))
            cv2.rectangle(img, (x0, y0), (x0 + cell - 1, y0 + cell - 1), color, -1)
            cv2.rectangle(img, (x0, y0), (x0 + cell - 1, y0 + cell - 1), (200, 200, 200), 1)
            _put(
                img,
                f"{100 * f:.0f}",
                (x0 + cell // 2, y0 + cell // 2),
                0.4,
                (255, 255, 255) if f > 0.5 else (0, 0, 0),
                anchor="center",
            )
    return img


def confusion_image(panels) -> np.ndarray:
    """Confusion matrices side by side, each row-normalized (percent of the true class); above
    :data:`GRID_CLASSES` classes, each panel lists the largest confusions instead (:func:`top_confusions`).

    Parameters
    ----------
    panels : sequence of (title, counts, names)
        ``counts`` a :class:`~classify.reporting.confusion.ConfusionMatrix`
        or its dense (n, n) counts, rows true class.

    Returns
    -------
    (H, W, 3) uint8 RGB
    """
    images = [
        _confusion_panel(m.pairs if isinstance(m, ConfusionMatrix) else counts_pairs(m), list(names), title)
        for title, m, names in panels
    ]
    height = max(im.shape[0] for im in images)
    images = [np.pad(im, ((0, height - im.shape[0]), (0, 0), (0, 0)), constant_values=255) for im in images]
    return np.concatenate(images, axis=1)


def touches_image(curves, title: str, size=(760, 460)) -> np.ndarray:
    """Recognition rate (percent) against the number of touches, one line per curve.

    Parameters
    ----------
    curves : dict label -> (touches (k,), mean (k,), low (k,), high (k,)), the band between low and high
    title : str
    size : (width, height)

    Returns
    -------
    (H, W, 3) uint8 RGB
    """
    width, height = size
    img = np.full((height, width, 3), 255, np.uint8)
    left, right, top, bottom = 64, 170, 40, 56
    pw, ph = width - left - right, height - top - bottom
    k_max = max([int(np.max(k)) for k, _, _, _ in curves.values()] + [2])
    lows = [float(np.min(lo)) for _, _, lo, _ in curves.values()]
    y_min = max(0.0, np.floor(min(lows + [50.0]) / 10) * 10)

    def xy(k, rate):
        x = left + (k - 1) / (k_max - 1) * pw
        y = top + (100.0 - rate) / (100.0 - y_min) * ph
        return int(round(x)), int(round(y))

    _put(img, title, (left, 16), 0.5)
    for rate in np.arange(y_min, 100.1, 10):
        p = xy(1, rate)
        cv2.line(img, (left, p[1]), (left + pw, p[1]), (225, 225, 225), 1)
        _put(img, f"{rate:.0f}", (left - 8, p[1]), 0.4, anchor="right")
    for k in range(1, k_max + 1):
        p = xy(k, y_min)
        cv2.line(img, (p[0], top + ph), (p[0], top + ph + 4), (0, 0, 0), 1)
        if k_max <= 15 or k % 2 == 1:
            _put(img, str(k), (p[0], top + ph + 14), 0.4, anchor="center")
    cv2.rectangle(img, (left, top), (left + pw, top + ph), (0, 0, 0), 1)
    _put(img, "touches", (left + pw // 2, height - 14), 0.45, anchor="center")
    _put(img, "%", (12, top + ph // 2), 0.45)
    for n, (label, (ks, mean, low, high)) in enumerate(curves.items()):
        color = _PALETTE[n % len(_PALETTE)]
        pts = np.array([xy(k, r) for k, r in zip(ks, mean)], np.int32)
        band = np.array(
            [xy(k, min(100.0, h)) for k, h in zip(ks, high)]
            + [xy(k, max(y_min, lo)) for k, lo in zip(ks[::-1], low[::-1])],
            np.int32,
        )
        overlay = img.copy()
        cv2.fillPoly(overlay, [band], color)
        img = cv2.addWeighted(overlay, 0.15, img, 0.85, 0)
        cv2.polylines(img, [pts], False, color, 2, cv2.LINE_AA)
        for p in pts:
            cv2.circle(img, tuple(int(v) for v in p), 3, color, -1, cv2.LINE_AA)
        ly = top + 14 + 22 * n
        cv2.line(img, (left + pw + 14, ly), (left + pw + 40, ly), color, 2, cv2.LINE_AA)
        _put(img, label, (left + pw + 46, ly), 0.45)
    return img


def write_confusion_png(path, panels) -> None:
    """Write :func:`confusion_image` as PNG."""
    write_png(path, confusion_image(panels))


def write_touches_png(path, curves, title: str) -> None:
    """Write :func:`touches_image` as PNG."""
    write_png(path, touches_image(curves, title))
