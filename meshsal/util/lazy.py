"""Load a package's public names on first use, and keep the old paths of moved modules importable."""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys


def attach(package: str, exports: dict[str, str], submodules=(), moved: dict[str, str] | None = None):
    """Module-level ``__getattr__``, ``__dir__`` and ``__all__`` for a lazily loaded package.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    exports : dict
        Public name -> submodule (dotted, relative to the package) that defines it.
    submodules : iterable of str
        Submodules reachable as attributes.
    moved : dict, optional
        Old submodule name -> its new dotted path (relative to the package):
        ``import package.old`` and ``package.old`` keep giving the module
        that now lives at ``package.new`` (:func:`alias_modules`).

    Examples
    --------
    >>> getattr_, dir_, all_ = attach("meshsal", {"Mesh": "mesh"})
    >>> getattr_("Mesh").__name__, all_
    ('Mesh', ['Mesh'])
    """
    moved = dict(moved or {})
    if moved:
        alias_modules(package, moved)
    submodules = set(submodules)
    names = sorted(exports) + sorted(submodules)

    def __getattr__(name):
        if name in exports:
            value = getattr(importlib.import_module(f"{package}.{exports[name]}"), name)
            # Bind it in the package, so the next access skips this hook.
            setattr(importlib.import_module(package), name, value)
            return value
        if name in submodules or name in moved:
            return importlib.import_module(f"{package}.{name}")
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__():
        return names

    return __getattr__, __dir__, names


class _MovedModules(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds ``old.path`` as the module now at ``new.path``: one module object under both names."""

    def __init__(self, aliases: dict[str, str]):
        self.aliases = aliases

    def find_spec(self, fullname, path=None, target=None):
        if fullname not in self.aliases:
            return None
        return importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec):
        return importlib.import_module(self.aliases[spec.name])

    def exec_module(self, module):
        """Nothing to run: the module under its new name is already executed."""


def alias_modules(package: str, moved: dict[str, str]) -> None:
    """Make ``package.old`` import as ``package.new`` for every ``old: new`` of ``moved``.

    Code written against an earlier layout keeps working; the alias is the
    very module object, so a change made through either name is seen by both.

    Examples
    --------
    >>> import meshsal.toys, meshsal.objects.toys
    >>> meshsal.toys is meshsal.objects.toys
    True
    """
    aliases = {f"{package}.{old}": f"{package}.{new}" for old, new in moved.items()}
    if not any(isinstance(f, _MovedModules) and f.aliases == aliases for f in sys.meta_path):
        sys.meta_path.append(_MovedModules(aliases))
