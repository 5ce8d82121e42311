"""Read the project's JSON documents within caps, with errors that name the file and the problem.

``json.loads`` trusts its input: a file of any size is read whole, nesting
deeper than Python's recursion limit raises ``RecursionError``, and an
integer longer than Python's integer-string limit raises a ``ValueError``
that names no file.  :func:`read_json` caps the file's size before reading
it and its nesting before parsing it, and turns every failure into a
``ValueError`` that names the file.
"""

from __future__ import annotations

import json
import os
import re
import sys
from pathlib import Path

import numpy as np

__all__ = ["read_json", "parse_json", "MAX_BYTES", "MAX_DEPTH"]

#: Default cap on a JSON file's size: 256 MiB.  The largest JSON the toolkit writes, the points file of
#: a mesh with its vertex saliency, takes about 22 bytes per vertex (1.1 MB for a 50k-vertex mesh).
MAX_BYTES = 256 << 20
#: Default cap on nesting (arrays and objects inside each other).  The toolkit's files nest 5 deep at most
#: (results.json, a batch entry's meta).
MAX_DEPTH = 100

# A JSON string, escapes included (brackets inside strings do not nest), or an unterminated one up to the
# end of the text: so every quote starts a match and the search stays linear in the text's length.
_STRING = re.compile(r'"[^"\\]*(?:\\.[^"\\]*)*(?:"|\\?\Z)', re.DOTALL)
# Every byte but the four brackets, for bytes.translate to delete.
_NOT_BRACKETS = bytes(b for b in range(256) if b not in b"[]{}")
_CHUNK = 1 << 20


def read_json(path, what: str, max_bytes: int = MAX_BYTES, max_depth: int = MAX_DEPTH):
    """Parse the JSON file ``path``, a ``what`` (e.g. ``"points file"``), into Python objects.

    Parameters
    ----------
    path : str or Path
    what : str
        What the file should be; it goes into every error message.
    max_bytes : int
        Files larger than this are refused before they are read (default
        :data:`MAX_BYTES`, 256 MiB).
    max_depth : int
        Documents nesting arrays and objects deeper than this are refused
        before they are parsed (default :data:`MAX_DEPTH`, 100).

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist; the message names it.
    ValueError
        The file is larger than ``max_bytes``, not UTF-8 text, not valid
        JSON, nested deeper than ``max_depth``, or holds an integer longer
        than Python's integer-string limit (``sys.get_int_max_str_digits()``,
        4300 digits by default); the message names the file, says it is
        not a valid ``what`` and why.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> bad = pathlib.Path(tempfile.mkdtemp()) / "p.json"
    >>> _ = bad.write_text('{"points": [}')
    >>> read_json(bad, "points file")
    Traceback (most recent call last):
    ...
    ValueError: ...p.json: not a valid points file: malformed JSON at line 1 column 13: Expecting value
    >>> _ = bad.write_text('[' * 1000 + ']' * 1000)
    >>> read_json(bad, "points file")
    Traceback (most recent call last):
    ...
    ValueError: ...p.json: not a valid points file: arrays and objects nested more than 100 deep
    """
    path = Path(path)
    too_large = f"{path}: not a valid {what}: larger than the cap of {max_bytes} bytes"
    try:
        with open(path, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            if size > max_bytes:
                raise ValueError(too_large)
            data = _read_at_most(fh, max_bytes + 1, size)
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: {what} not found") from None
    except IsADirectoryError:
        raise ValueError(f"{path}: not a valid {what}: a directory") from None
    if len(data) > max_bytes:
        raise ValueError(too_large)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a valid {what}: not UTF-8 text") from None
    return parse_json(text, path, what, max_depth)


def parse_json(text: str, source, what: str, max_depth: int = MAX_DEPTH):
    """Parse the JSON ``text`` read from ``source`` (a file name, for the messages), like :func:`read_json`.

    For JSON held inside another file, e.g. the ``meta`` string of an ``.npz`` archive.

    Examples
    --------
    >>> parse_json('{"a": [1, "]]"]}', "x.npz", "batch entry")
    {'a': [1, ']]']}
    >>> parse_json('[' * 200 + ']' * 200, "x.npz", "batch entry")
    Traceback (most recent call last):
    ...
    ValueError: x.npz: not a valid batch entry: arrays and objects nested more than 100 deep
    """
    if _too_deep(text, max_depth):
        raise ValueError(f"{source}: not a valid {what}: arrays and objects nested more than {max_depth} deep")
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(
            f"{source}: not a valid {what}: malformed JSON at line {exc.lineno} column {exc.colno}: {exc.msg}"
        ) from None
    except RecursionError:
        # Only when max_depth is above what this thread's stack allows.
        raise ValueError(f"{source}: not a valid {what}: nested deeper than Python's recursion limit") from None
    except ValueError as exc:
        if "integer string conversion" not in str(exc):
            raise
        raise ValueError(
            f"{source}: not a valid {what}: an integer of more than {sys.get_int_max_str_digits()} "
            f"digits (Python's integer-string limit)"
        ) from None


def _read_at_most(fh, limit: int, size: int) -> bytes:
    """Up to ``limit`` bytes of ``fh``.  Reads as much as stat promised, then in chunks: a file growing
    meanwhile, a pipe or /dev/zero (size 0) never gets past the limit, and no read asks for more memory
    than it needs (``read(n)`` allocates n bytes first)."""
    parts, total = [], 0
    while total < limit:
        part = fh.read(min(limit - total, max(size + 1 - total, _CHUNK)))
        if not part:
            break
        parts.append(part)
        total += len(part)
    return b"".join(parts)


def _too_deep(text: str, cap: int) -> bool:
    """Whether ``text`` nests brackets outside strings more than ``cap`` deep, in time linear in its length."""
    if text.count("[") + text.count("{") <= cap:
        return False
    brackets = _STRING.sub("", text).encode("utf-8", "replace").translate(None, _NOT_BRACKETS)
    level = 0
    for start in range(0, len(brackets), _CHUNK):
        chunk = np.frombuffer(brackets, np.uint8, count=min(_CHUNK, len(brackets) - start), offset=start)
        # "[" and "{" end in 0xB, "]" and "}" in 0xD.
        levels = level + np.cumsum(np.where(chunk & 0x0F == 0x0B, 1, -1))
        if levels.max() > cap:
            return True
        level = int(levels[-1])
    return False
