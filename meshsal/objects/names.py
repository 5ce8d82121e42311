"""Objects by name: the embedded sets (the toys, the YCB scans), single objects, mesh files.

The command line and the experiment take objects as a list of strings, each
a set name (``toys``, ``ycb``), an object's name (``cow``, ``power_drill``),
a mesh file, a folder (every mesh file under it) or a list file (``.txt``:
one item per line, ``#`` comments), possibly comma-separated (``toys,ycb``).
:func:`resolve_objects` turns such a list into :class:`ObjectRef` records
without loading anything; :func:`load_ref` loads one.  Two files with the
same bytes are one object (:func:`distinct_files`): never two classes that
nothing could tell apart.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from meshsal.mesh import Mesh
from meshsal.objects import toys, ycb

__all__ = ["OBJECT_SETS", "ObjectRef", "resolve_objects", "distinct_files", "load_ref", "load_object"]

OBJECT_SETS = {"toys": toys.NAMES, "ycb": ycb.NAMES}


@dataclass(frozen=True)
class ObjectRef:
    """One object to load.

    Attributes
    ----------
    name : str
        Unique name: the toy's or YCB object's name, or the file's stem.
    kind : str
        ``"toy"``, ``"ycb"`` or ``"file"``.
    path : str or None
        The file for ``"ycb"`` (embedded) and ``"file"``; None for toys.
    units_mm : float or None
        Millimetres per unit of the object's coordinates where they are real
        (the toys are in millimetres, the YCB scans in metres); None for a
        file, whose units are not known.
    """

    name: str
    kind: str
    path: str | None = None
    units_mm: float | None = None


def _folder(folder: Path) -> list[ObjectRef]:
    """Every mesh file under ``folder`` (recursively, sorted by path), named by its stem, or by its path
    below the folder where stems repeat."""
    from collections import Counter

    from meshsal.mesh.io import SUPPORTED_EXTENSIONS, mesh_files

    files = mesh_files(folder)
    if not files:
        raise ValueError(f"{folder}: no mesh file ({', '.join(SUPPORTED_EXTENSIONS)}) under this folder")
    stems = Counter(p.stem for p in files)
    return [
        ObjectRef(p.stem if stems[p.stem] == 1 else p.relative_to(folder).with_suffix("").as_posix(), "file", str(p))
        for p in files
    ]


def _listed(path: Path) -> list[str]:
    """The items of a list file: one per line, blank lines and ``#`` comments skipped, relative paths taken from
    the list's folder."""
    items = []
    for line in path.read_text().splitlines():
        item = line.split("#", 1)[0].strip()
        if item:
            local = path.parent / item
            items.append(str(local) if not Path(item).is_absolute() and local.exists() else item)
    if not items:
        raise ValueError(f"{path}: the list names no object")
    return items


def _ref(item: str) -> ObjectRef:
    if Path(item).is_file():
        return ObjectRef(Path(item).stem, "file", str(item))
    if item in toys.NAMES:
        return ObjectRef(item, "toy", units_mm=1.0)
    if item in ycb.NAMES:
        return ObjectRef(item, "ycb", str(ycb.path(item)), units_mm=1000.0)
    raise ValueError(
        f"object {item!r} is neither a set ({', '.join(OBJECT_SETS)}), a known object "
        f"({', '.join(toys.NAMES + ycb.NAMES)}) nor an existing mesh file"
    )


def resolve_objects(specs) -> tuple[ObjectRef, ...]:
    """Object references for a list of set names, object names and mesh files.

    Parameters
    ----------
    specs : iterable of str
        Each may hold several items separated by commas.  An existing file
        wins over a name; a folder stands for every mesh file under it, a
        ``.txt`` file for the items it lists.

    Returns
    -------
    tuple of ObjectRef, in the order given (sets expanded in their order)

    Raises
    ------
    ValueError
        An unknown item, an empty list, or two objects with one name.

    Examples
    --------
    >>> [r.name for r in resolve_objects(["cow,cup", "power_drill"])]
    ['cow', 'cup', 'power_drill']
    >>> len(resolve_objects(["toys,ycb"]))
    16
    """
    refs = []
    for spec in specs:
        for item in (s.strip() for s in str(spec).split(",")):
            if not item:
                continue
            path = Path(item)
            if item in OBJECT_SETS and not path.is_file():
                refs.extend(_ref(name) for name in OBJECT_SETS[item])
            elif path.is_dir():
                refs.extend(_folder(path))
            elif path.is_file() and path.suffix.lower() == ".txt":
                refs.extend(resolve_objects(_listed(path)))
            else:
                refs.append(_ref(item))
    if not refs:
        raise ValueError("no objects given")
    names = [r.name for r in refs]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f"objects must have distinct names; given more than once: {', '.join(twice)}")
    return tuple(refs)


def distinct_files(refs) -> tuple[tuple[ObjectRef, ...], dict]:
    """The references without a file whose bytes an earlier one already has, and what was dropped.

    Returns
    -------
    kept : tuple of ObjectRef, in the order given
    same : dict name -> name of the earlier object with the same bytes

    Examples
    --------
    >>> kept, same = distinct_files(resolve_objects(["cow", "cup"]))
    >>> [r.name for r in kept], same
    (['cow', 'cup'], {})
    """
    import hashlib

    seen, kept, same = {}, [], {}
    for ref in refs:
        if ref.path is not None:
            digest = hashlib.sha256(Path(ref.path).read_bytes()).hexdigest()
            if digest in seen:
                same[ref.name] = seen[digest]
                continue
            seen[digest] = ref.name
        kept.append(ref)
    return tuple(kept), same


def load_ref(ref: ObjectRef, seed: int = 0) -> Mesh:
    """Load one object; ``seed`` is a toy's paint seed.  The mesh is named ``ref.name``."""
    from meshsal.mesh.io import load_mesh

    if ref.kind == "toy":
        return toys.make(ref.name, seed=seed)
    return load_mesh(ref.path).replace(name=ref.name)


def load_object(spec, seed: int = 0) -> Mesh:
    """One object by name or file: a mesh file, a toy or a YCB scan (a file of that name wins).

    The command line accepts any of these wherever it takes a mesh, so the
    embedded objects need no export step.

    Parameters
    ----------
    spec : str or os.PathLike
        A mesh file path (OBJ, PLY, OFF, STL), one of ``toys.NAMES`` or one of ``ycb.NAMES``.
    seed : int
        The toy's paint seed.

    Examples
    --------
    >>> load_object("cup").name, load_object("banana").name
    ('cup', 'banana')
    """
    return load_ref(_ref(str(spec)), seed)
