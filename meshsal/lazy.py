"""Load a package's public names on first use, so importing it (and the CLI) stays cheap."""

from __future__ import annotations

import importlib


def attach(package: str, exports: dict[str, str], submodules=(), eager: tuple[str, ...] = ()):
    """Module-level ``__getattr__``, ``__dir__`` and ``__all__`` for a lazily loaded package.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    exports : dict
        Public name -> submodule that defines it.
    submodules : iterable of str
        Submodules reachable as attributes.
    eager : tuple of str
        Names the package defines itself, listed first in ``__all__``.

    Examples
    --------
    >>> getattr_, dir_, all_ = attach("meshsal", {"Mesh": "mesh"})
    >>> getattr_("Mesh").__name__, all_
    ('Mesh', ['Mesh'])
    """
    submodules = set(submodules)
    names = list(eager) + sorted(exports) + sorted(submodules)

    def __getattr__(name):
        if name in exports:
            value = getattr(importlib.import_module(f"{package}.{exports[name]}"), name)
            # Bind it in the package, so the next access skips this hook.
            setattr(importlib.import_module(package), name, value)
            return value
        if name in submodules:
            return importlib.import_module(f"{package}.{name}")
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__():
        return names

    return __getattr__, __dir__, names
