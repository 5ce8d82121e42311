"""Read the project's JSON documents with errors that name the file and the problem."""

from __future__ import annotations

import json
from pathlib import Path


def read_json(path, what: str):
    """Parse the JSON file ``path``, a ``what`` (e.g. ``"points file"``), into Python objects.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist; the message names it.
    ValueError
        The file is not UTF-8 text or not valid JSON; the message names the
        file, says it is not a ``what`` and gives the line and column.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> bad = pathlib.Path(tempfile.mkdtemp()) / "p.json"
    >>> _ = bad.write_text('{"points": [}')
    >>> read_json(bad, "points file")
    Traceback (most recent call last):
    ...
    ValueError: ...p.json: not a valid points file: malformed JSON at line 1 column 13: Expecting value
    """
    path = Path(path)
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: {what} not found") from None
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a valid {what}: not UTF-8 text") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not a valid {what}: malformed JSON at line {exc.lineno} "
                         f"column {exc.colno}: {exc.msg}") from None
