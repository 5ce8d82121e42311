"""Read triangle meshes from OBJ, PLY, OFF and STL files; write PLY.

``load_mesh`` reads OBJ, PLY and STL files with pymeshlab and OFF files
with :func:`meshsal.mesh.formats.read_off`, after
:func:`meshsal.mesh.formats.check` has refused what pymeshlab would misread
or not survive; pymeshlab's result is checked against the vertices the file
declares.  Then :mod:`meshsal.mesh.repair` finds and repairs what real
meshes get wrong (duplicate, degenerate and double-sided faces, inconsistent
orientation, non-manifold edges and vertices, parts facing inward...) and
the one :class:`MeshRepairWarning` names the file and every repair.
Anything that cannot be loaded in full, or repaired without changing the
shape, raises :class:`meshsal.MeshError` naming the file and the problem,
before any work.  Files over ``MAX_MESH_BYTES`` are refused before they are
read; textures over ``MAX_TEXTURE_PIXELS`` are left out
(:mod:`meshsal.mesh.texture`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import shutil
import tempfile
import warnings
from pathlib import Path

import numpy as np

from meshsal.mesh import Mesh
from meshsal.mesh.formats import SUPPORTED_EXTENSIONS, Declared, check, fail, read_off
from meshsal.mesh.repair import MeshRepairWarning, MeshReport, repair_arrays
from meshsal.mesh.texture import MAX_TEXTURE_PIXELS, read_texture
from meshsal.util.atomic import atomic_path

__all__ = [
    "MeshRepairWarning",
    "MeshReport",
    "load_mesh",
    "mesh_files",
    "save_ply",
    "load_vertex_quality",
    "MAX_MESH_BYTES",
    "MAX_TEXTURE_PIXELS",
    "SUPPORTED_EXTENSIONS",
]

#: Largest mesh file read, in bytes (256 MiB).  Scanning an OBJ takes about 30 times its size in
#: memory (nefertiti: 3.7 MB of OBJ, 100 MB), so this admits a 7-million-face OBJ in about 7 GB.
MAX_MESH_BYTES = 256 * 2**20


def mesh_files(folder) -> list[Path]:
    """Every mesh file under ``folder``, searched recursively, sorted by path; hidden files are skipped.

    A mesh file is one whose extension is in :data:`SUPPORTED_EXTENSIONS` (any case).

    Examples
    --------
    >>> import tempfile
    >>> root = Path(tempfile.mkdtemp())
    >>> for name in ("b.OBJ", "a/c.ply", ".hidden.stl", "notes.txt"):
    ...     (root / name).parent.mkdir(exist_ok=True)
    ...     _ = (root / name).write_text("")
    >>> [p.relative_to(root).as_posix() for p in mesh_files(root)]
    ['a/c.ply', 'b.OBJ']
    """
    return sorted(
        p
        for p in Path(folder).rglob("*")
        if p.is_file() and p.suffix.lower() in SUPPORTED_EXTENSIONS and not p.name.startswith(".")
    )


def _read_checked(path: Path, max_bytes: int | None) -> bytes:
    if not path.exists():
        fail(path, "no such file")
    if path.is_dir():
        fail(path, "is a directory, not a mesh file")
    if path.suffix.lower() not in SUPPORTED_EXTENSIONS:
        fail(path, f"unknown extension {path.suffix!r} (supported: {', '.join(SUPPORTED_EXTENSIONS)})")
    try:
        size = path.stat().st_size
        if max_bytes is not None and size > max_bytes:
            fail(
                path,
                f"{size:,} bytes, over the cap of {max_bytes:,} bytes for a mesh file "
                "(load_mesh's max_bytes raises it)",
            )
        data = path.read_bytes()
    except OSError as e:
        fail(path, f"cannot be read ({e.strerror or e})")
    if not data.strip():
        fail(path, "empty file")
    return data


_UTF8_BOM = b"\xef\xbb\xbf"


def _without_bom(path: Path, data: bytes) -> bytes | None:
    """A text mesh file's bytes without the UTF-8 byte order mark some editors write first, or None if it has none.

    pymeshlab takes the mark for part of the first line: an OBJ loses its
    first vertex (and every face on the last one points past the others),
    and a PLY has no header.
    """
    if path.suffix.lower() in (".obj", ".off", ".ply") and data.startswith(_UTF8_BOM):
        return data[len(_UTF8_BOM) :]
    return None


@contextlib.contextmanager
def _readable(path: Path, declared: Declared, content: bytes | None):
    """The path pymeshlab reads: the file, or in a new folder the file's ``content`` (when given) or a link to the
    file alone (for an OBJ naming a material library).

    pymeshlab decodes the texture images a material library names, whatever
    their size; without the library beside it, it reads the geometry and the
    texture coordinates only, and :func:`_load_texture` reads the image within its cap.
    """
    if content is None and not declared.libraries:
        yield path
        return
    with tempfile.TemporaryDirectory(prefix="visuotactile-mesh-") as folder:
        alone = Path(folder) / path.name
        if content is not None:
            alone.write_bytes(content)
        else:
            try:
                os.symlink(path.resolve(), alone)
            except OSError:  # no symbolic links here (Windows without the privilege): a copy
                shutil.copyfile(path, alone)
        yield alone


# pymeshlab's words for a file that ends too soon.
_TRUNCATED = ("Unexpected EOF", "Unexpected end of file")


def _pymeshlab_load(path: Path, declared: Declared, content: bytes | None = None):
    """pymeshlab's reading of the file ``path``, or of ``content`` in its place."""
    from meshsal.util.meshlab import import_pymeshlab

    pymeshlab = import_pymeshlab()
    ms = pymeshlab.MeshSet()
    params = {"unify_vertices": False} if path.suffix.lower() == ".stl" else {}
    with _readable(path, declared, content) as readable:
        try:
            ms.load_new_mesh(str(readable), **params)
        except pymeshlab.PyMeshLabException as e:
            detail = " ".join(str(e).split("Error details:")[-1].split())
            truncated = " (truncated file?)" if any(t in detail for t in _TRUNCATED) else ""
            fail(path, f"unparseable content (pymeshlab: {detail}){truncated}")
        except (MemoryError, RuntimeError, ValueError) as e:  # pymeshlab's std::bad_alloc, std::length_error
            fail(path, f"pymeshlab could not read it ({type(e).__name__}: {e})")
    pm = ms.current_mesh()
    if pm.vertex_number() != declared.n_vertices:
        fail(
            path,
            f"pymeshlab read {pm.vertex_number()} of the {declared.n_vertices} vertices the file holds: "
            "the others have non-finite coordinates or are damaged",
        )
    return ms  # the caller keeps the MeshSet alive: its meshes die with it


def _no_faces(path: Path, n_vertices: int, n_faces: int):
    if n_faces:
        fail(path, "no non-degenerate face left (every face repeats a vertex)")
    if n_vertices == 0:
        fail(path, "unparseable content: no vertices and no faces found")
    fail(path, f"no faces (a point cloud of {n_vertices} vertices)")


def _read_arrays(path: Path, data: bytes, notes: list, max_texture_pixels: int | None):
    """Vertices, triangles, vertex colours, per-corner uv and texture of the file, as read."""
    content = _without_bom(path, data)
    data = data if content is None else content
    if path.suffix.lower() == ".off":
        V, F, C, n_faces = read_off(path, data)
        if len(F) == 0:
            _no_faces(path, len(V), n_faces)
        return V, F, C, None, None
    declared = check(path, data)
    ms = _pymeshlab_load(path, declared, content)
    pm = ms.current_mesh()
    if pm.face_number() == 0:
        _no_faces(path, pm.vertex_number(), declared.n_faces)
    # pymeshlab keeps a PLY's vertices in the file's order (the count is checked): coordinates it misreads are replaced.
    V = np.asarray(pm.vertex_matrix() if declared.coordinates is None else declared.coordinates, dtype=np.float64)
    F = np.asarray(pm.face_matrix(), dtype=np.int64)
    C = None
    if declared.has_colors and pm.has_vertex_color():
        C = np.asarray(pm.vertex_color_matrix(), dtype=np.float32)[:, :3]
    notes += declared.notes
    texture = UV = None
    if declared.textures:
        texture = _load_texture(declared, notes, max_texture_pixels)
        if texture is not None and pm.has_wedge_tex_coord():
            UV = np.asarray(pm.wedge_tex_coord_matrix(), dtype=np.float32).reshape(-1, 3, 2)
        else:
            texture = None
    return V, F, C, UV, texture


def _load_texture(declared: Declared, notes: list, max_pixels: int | None):
    """The (H,W,3) uint8 RGB texture the OBJ's faces use, or None (with a note why)."""
    if len(declared.textures) > 1:
        names = ", ".join(t.name for t in declared.textures)
        notes.append(
            f"faces use {len(declared.textures)} texture images ({names}); only one is supported, texture dropped"
        )
        return None
    image, note = read_texture(declared.textures[0], max_pixels)
    if note:
        notes.append(note)
    return image


def load_mesh(
    path,
    *,
    report: bool = False,
    max_bytes: int | None = MAX_MESH_BYTES,
    max_texture_pixels: int | None = MAX_TEXTURE_PIXELS,
):
    """Load a triangle mesh from an OBJ, PLY, OFF or STL file, repaired.

    OBJ, PLY and STL files are read by pymeshlab, which triangulates
    polygons (ear cutting; a face that repeats a vertex is left out); OFF
    files by :func:`meshsal.mesh.formats.read_off`.  OBJ files bring their MTL texture image
    (``uv`` per face corner and ``texture``) and ``v x y z r g b`` vertex
    colors; PLY and OFF files bring vertex colors.  The mesh is then
    repaired (:func:`meshsal.mesh.repair.repair_arrays`: duplicate vertices
    merged, zero-area, sliver, duplicate and double-sided faces dropped,
    components oriented consistently and closed ones outward, non-manifold
    vertices split, unreferenced vertices removed); every repair is reported
    in one :class:`MeshRepairWarning` naming the file.  A mesh that needs
    none loads exactly as the file has it.  A texture image that is
    missing, unreadable or over ``max_texture_pixels`` is reported the same
    way and the geometry loads without it.

    Parameters
    ----------
    path : str or os.PathLike
        A ``.obj``, ``.ply`` (ASCII or binary), ``.off`` or ``.stl`` (ASCII or binary) file.
    report : bool
        Also return the :class:`~meshsal.mesh.repair.MeshReport` of what was found and done.
    max_bytes : int or None
        Files larger than this are refused before they are read (default
        :data:`MAX_MESH_BYTES`, 256 MiB; None: no cap).
    max_texture_pixels : int or None
        Textures with more pixels are left out, before they are decoded when
        the format's header says their size (default
        :data:`~meshsal.mesh.texture.MAX_TEXTURE_PIXELS`, 8192 x 8192; None: no cap).

    Returns
    -------
    Mesh, or (Mesh, MeshReport) with ``report=True``
        ``vertices`` (n, 3) float64 in the file's units, ``faces`` (m, 3)
        int32, ``name`` the file's stem, ``transform`` the identity.

    Raises
    ------
    MeshError
        The message names the file and the problem: missing file, a
        directory, unknown extension, a file over ``max_bytes`` (its size
        and the cap), empty file, unparseable content, face index out of
        range, non-finite coordinates, a header declaring more than the file
        holds, no faces (a point cloud), no non-degenerate face left, or
        fewer vertices read than the file holds.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "quad.obj"
    >>> _ = p.write_text("v 0 0 0\\nv 1 0 0\\nv 1 1 0\\nv 0 1 0\\nf 1 2 3 4\\nf 1 3 2\\n")
    >>> m, found = load_mesh(p, report=True)     # the last face is the first's flipped twin
    >>> m.name, m.vertices.shape, m.faces.shape, found.double_sided_faces, found.boundary_loops
    ('quad', (4, 3), (2, 3), 1, 1)
    """
    path = Path(path)
    notes = []
    V, F, C, UV, texture = _read_arrays(path, _read_checked(path, max_bytes), notes, max_texture_pixels)
    V, F, C, UV, found = repair_arrays(V, F, C, UV, source=str(path))
    found = dataclasses.replace(found, notes=tuple(notes))
    if found.noteworthy:
        warnings.warn(found.message(), MeshRepairWarning, stacklevel=2)
    mesh = Mesh(vertices=V, faces=F, vertex_colors=C, uv=UV, texture=texture, name=path.stem)
    return (mesh, found) if report else mesh


# ---------------------------------------------------------------------------
# PLY output


def save_ply(path, mesh: Mesh, quality=None) -> None:
    """Write a mesh as binary little-endian PLY, atomically.

    Vertices are written as ``x y z`` double, followed by ``red green blue``
    uchar when the mesh has vertex colors and by ``quality`` float when
    ``quality`` is given (MeshLab reads it as vertex quality; read it back
    with :func:`load_vertex_quality`).

    Parameters
    ----------
    path : str or os.PathLike
    mesh : Mesh
    quality : (n,) array_like of float, optional
        One value per vertex.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> m = Mesh(vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0]], faces=[[0, 1, 2]])
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "tri.ply"
    >>> save_ply(p, m, quality=[0.0, 0.5, 1.0])
    >>> load_vertex_quality(p)
    array([0. , 0.5, 1. ])
    """
    n = mesh.n_vertices
    # Doubles: float32 would fuse the near-coincident vertices marching cubes makes into degenerate faces.
    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    if mesh.vertex_colors is not None:
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    if quality is not None:
        quality = np.asarray(quality, dtype=np.float64)
        if quality.shape != (n,):
            raise ValueError(f"{path}: quality must have shape ({n},) (one per vertex), got {quality.shape}")
        fields.append(("quality", "<f4"))
    vertices = np.empty(n, dtype=fields)
    for i, c in enumerate("xyz"):
        vertices[c] = mesh.vertices[:, i]
    if mesh.vertex_colors is not None:
        rgb = np.round(mesh.vertex_colors * 255.0).astype(np.uint8)
        for i, c in enumerate(("red", "green", "blue")):
            vertices[c] = rgb[:, i]
    if quality is not None:
        vertices["quality"] = quality
    faces = np.empty(mesh.n_faces, dtype=[("n", "u1"), ("vertex_indices", "<i4", (3,))])
    faces["n"] = 3
    faces["vertex_indices"] = mesh.faces
    types = {"<f8": "double", "<f4": "float", "u1": "uchar"}
    header = ["ply", "format binary_little_endian 1.0", "comment written by visuotactile"]
    header += [f"element vertex {n}"] + [f"property {types[t]} {name}" for name, t in fields]
    header += [f"element face {mesh.n_faces}", "property list uchar int vertex_indices", "end_header"]
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        f.write(vertices.tobytes())
        f.write(faces.tobytes())


def load_vertex_quality(path) -> np.ndarray:
    """Per-vertex ``quality`` values of a PLY file (as written by :func:`save_ply`).

    Returns
    -------
    (n,) float64

    Raises
    ------
    MeshError
        The file is missing, not a PLY, damaged, or has no vertex quality.
    """
    path = Path(path)
    data = _read_checked(path, MAX_MESH_BYTES)
    if path.suffix.lower() != ".ply":
        fail(path, "vertex quality is only stored in PLY files")
    content = _without_bom(path, data)
    declared = check(path, data if content is None else content)
    if "quality" not in declared.vertex_properties:
        fail(path, "has no per-vertex 'quality' property")
    ms = _pymeshlab_load(path, declared, content)
    return np.asarray(ms.current_mesh().vertex_scalar_array(), dtype=np.float64).reshape(-1)
