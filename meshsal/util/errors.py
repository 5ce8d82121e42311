"""Errors that name what was being processed.

A stage deep inside the pipeline (a touch check, a ray cast) knows arrays,
not which object they came from, so its error cannot name it.
:func:`naming` wraps the processing of one object: an error raised inside
comes out naming the object, at the command line and in the API alike.
"""

from __future__ import annotations

from contextlib import contextmanager

__all__ = ["naming"]


@contextmanager
def naming(what):
    """Make every error raised inside name ``what`` (a mesh file, an object's name).

    A ``ValueError`` or ``OSError`` whose message does not already name it
    is raised again, of the same type where possible, as ``"<what>: <message>"``
    (chained to the original): the command line prints these messages.  Any
    other exception, a bug rather than bad input, keeps its type and
    traceback and gains the note ``while processing <what>``.

    Examples
    --------
    >>> try:
    ...     with naming("cow.obj"):
    ...         raise ValueError("normals must be non-zero")
    ... except ValueError as e:
    ...     print(e)
    cow.obj: normals must be non-zero
    """
    name = str(what)
    try:
        yield
    except (ValueError, OSError) as exc:
        if name in str(exc):
            raise
        try:
            renamed = type(exc)(f"{name}: {exc}")
        except Exception:  # noqa: BLE001 - an exception type that takes other arguments
            renamed = ValueError(f"{name}: {exc}") if isinstance(exc, ValueError) else OSError(f"{name}: {exc}")
        raise renamed from exc
    except Exception as exc:
        exc.add_note(f"while processing {name}")
        raise
