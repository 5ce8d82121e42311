"""Named extension points: one registry per kind of choice, read by validation, the CLI and ``--help``.

Point methods, classifiers, attention channels, sensor modes and protocols
each live in one :class:`Registry`; argument choices, help texts and error
messages come from it, so adding an entry in one place adds it everywhere.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass

__all__ = ["Entry", "Registry"]


@dataclass(frozen=True)
class Entry:
    """One registered choice: its name, what it stands for (a function, a class...) and a line of help."""

    name: str
    value: object
    help: str


class Registry:
    """The choices of one extension point, in registration order.

    Examples
    --------
    >>> fruit = Registry("fruit")
    >>> _ = fruit.register("apple", 1, "crisp"); _ = fruit.register("pear", 2, "soft")
    >>> fruit.names(), fruit.get("pear"), "apple" in fruit
    (('apple', 'pear'), 2, True)
    >>> Registry("nut", [("almond", None, "sweet")]).help_text()
    'almond (sweet)'
    >>> fruit.get("plum")
    Traceback (most recent call last):
    ...
    ValueError: unknown fruit 'plum'; choose from apple, pear
    """

    def __init__(self, kind: str, entries: Iterable[tuple[str, object, str]] = ()):
        self.kind = kind
        self._entries: dict[str, Entry] = {}
        for name, value, help in entries:
            self.register(name, value, help)

    def register(self, name: str, value=None, help: str = ""):
        """Add a choice; returns ``value`` (so it can decorate a function)."""
        if not name or name in self._entries:
            raise ValueError(f"{self.kind} {name!r} is empty or already registered")
        self._entries[name] = Entry(name, value, help)
        return value

    def names(self) -> tuple:
        return tuple(self._entries)

    def __contains__(self, name) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[Entry]:
        return iter(self._entries.values())

    def get(self, name: str):
        """The value registered under ``name``; ValueError naming the choices otherwise."""
        if name not in self._entries:
            raise ValueError(f"unknown {self.kind} {name!r}; choose from {', '.join(self._entries)}")
        return self._entries[name].value

    def check(self, names: Iterable[str]) -> tuple:
        """``names`` as a tuple, each registered and none repeated; ValueError otherwise."""
        names = tuple(names)
        bad = [n for n in names if n not in self._entries]
        if bad or not names or len(set(names)) != len(names):
            raise ValueError(
                f"unknown or repeated {self.kind}(s) {bad or list(names)}; choose from {', '.join(self._entries)}"
            )
        return names

    def help_text(self) -> str:
        """``"a (what a is), b (what b is)"`` for ``--help``."""
        return ", ".join(f"{e.name} ({e.help})" if e.help else e.name for e in self)
