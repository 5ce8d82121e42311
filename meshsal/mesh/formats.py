"""The mesh file formats: what pymeshlab is not trusted with, checked before it reads a file; OFF, read here.

pymeshlab reads OBJ, PLY and STL files (:mod:`meshsal.mesh.io`): its reading,
polygons triangulated, colours and texture coordinates included, is the
one the toolkit uses.  :func:`check` refuses, before pymeshlab sees the
file, only what pymeshlab 2025.7 misreads or does not survive, each
measured:

* a face index out of range: in an OBJ, one past the last vertex is kept
  out of range, two past is dropped silently, far past crashes the
  interpreter (SIGSEGV); in a PLY polygon it crashes too (pymeshlab checks
  only a triangle's);
* a PLY header line it cannot parse (``element vertex`` without its count:
  SIGSEGV), or a header that declares more elements than the file's bytes
  can hold: pymeshlab allocates what a PLY or OFF header declares
  (``std::bad_alloc`` for 10^12 vertices) and loops over what a binary STL
  declares (10^9 facets in 134 bytes: still running after minutes);
* a bad or non-finite coordinate: pymeshlab reads ``v 0 0 zero`` as a
  vertex and drops a non-finite one silently, with every face on it (STL
  included: :mod:`meshsal.mesh.io` compares the vertices it read with the
  count the file declares);
* binary bytes in an ASCII STL, which pymeshlab would take for a binary
  STL of whatever facet count its bytes 80-84 say.

One thing it misreads is not refused but read here: a big-endian binary
PLY's double coordinates, which pymeshlab swaps wrong (1.0 becomes 3e-319,
and every face degenerate).  :func:`check` reads them
(``Declared.coordinates``) and :mod:`meshsal.mesh.io` takes them instead of
pymeshlab's; big-endian floats and little-endian doubles it reads right.

pymeshlab also decodes an OBJ's texture images whatever their size (a
424 kB PNG of 20000 x 20000 pixels: 496 MB), so it is given the OBJ
without its material library, and :mod:`meshsal.mesh.texture` reads the
library and the image the faces use, within caps.

OFF files are read here (:func:`read_off`), not by pymeshlab: it refuses
comments at the end of a line, which the format allows, and crashes on a
face index out of range.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from meshsal.mesh.record import MeshError
from meshsal.mesh.texture import material_textures

__all__ = ["SUPPORTED_EXTENSIONS", "Declared", "check", "read_off", "fail"]

SUPPORTED_EXTENSIONS = (".obj", ".off", ".ply", ".stl")


@dataclass
class Declared:
    """What a file says of itself, to check pymeshlab's reading against.

    ``n_vertices`` and ``n_faces`` count the file's own records (vertex
    lines, a header's element counts, facets), not triangles: pymeshlab
    triangulates polygons and drops faces that repeat a vertex.
    """

    n_vertices: int
    n_faces: int
    has_colors: bool = False
    vertex_properties: tuple = ()  # PLY: the vertex element's property names
    coordinates: object = None  # PLY: (n, 3) float64 vertex coordinates read here, where pymeshlab misreads them
    textures: list = field(default_factory=list)  # OBJ: texture images the faces use
    libraries: bool = False  # OBJ: it names a material library
    notes: list = field(default_factory=list)  # warnings about the file itself


def fail(path, problem: str):
    """Raise :class:`MeshError` naming the file and the problem."""
    raise MeshError(f"{path}: {problem}")


def _text(path, data: bytes, kind: str) -> str:
    if b"\0" in data:
        fail(path, f"unparseable content: binary data in what should be a text {kind} file")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def _finite_coordinates(path, coords, where) -> np.ndarray:
    """Three numbers per vertex, (n, 3) float64, or a MeshError naming the first bad one's ``where``."""
    try:
        xyz = np.array(coords, dtype=np.float64).reshape(-1, 3)
    except ValueError:
        bad = next(i for i, c in enumerate(coords) if len(c) != 3 or not _all_numbers(c))
        fail(path, f"unparseable content: {where(bad)}: a vertex needs 3 numbers, got {coords[bad]}")
    bad = np.flatnonzero(~np.isfinite(xyz).all(axis=1))
    if bad.size:
        fail(path, f"{where(bad[0])}: vertex {bad[0] + 1} has non-finite coordinates")
    return xyz


def _all_numbers(tokens) -> bool:
    try:
        np.array(tokens, dtype=np.float64)
    except ValueError:
        return False
    return True


# ---------------------------------------------------------------------------
# OBJ


_PLURALS = {"vertex": "vertices"}


def _obj_indices(path, tokens: list, sizes: list, lines: list, defined, what: str) -> None:
    """Check OBJ face indices (1-based, negative: relative) against ``defined`` elements, per face."""
    first = np.cumsum(sizes) - sizes
    try:
        index = np.array(tokens).astype(np.int64)
    except (ValueError, OverflowError):
        bad = next((j for j, t in enumerate(tokens) if not re.fullmatch(r"[-+]?\d{1,18}", t)), 0)
        face = np.searchsorted(first, bad, side="right") - 1
        fail(path, f"unparseable content: line {lines[face]}: bad {what} index {tokens[bad]!r}")
    count = np.repeat(np.broadcast_to(np.asarray(defined, dtype=np.int64), len(sizes)), sizes)
    resolved = np.where(index > 0, index, count + index + 1)
    bad = np.flatnonzero((index == 0) | (resolved < 1) | (resolved > count))
    if bad.size:
        j = bad[0]
        face = np.searchsorted(first, j, side="right") - 1
        noun = what if count[j] == 1 else _PLURALS.get(what, f"{what}s")
        fail(path, f"line {lines[face]}: face {what} index {index[j]} out of range ({count[j]} {noun} defined)")


def _check_obj(path: Path, data: bytes) -> Declared:
    text = _text(path, data, "OBJ").replace("\\\r\n", " ").replace("\\\n", " ")
    n_uv = n_colored = 0
    coords, coord_lines = [], []
    corners, sizes, face_lines, face_nv = [], [], [], []
    libraries, materials_used = [], []
    material = None
    for lineno, line in enumerate(text.splitlines(), 1):
        parts = line.split()
        if not parts:
            continue
        key = parts[0]
        if key == "v":
            coords.append(parts[1:4])
            coord_lines.append(lineno)
            n_colored += len(parts) >= 7
        elif key == "vt":
            n_uv += 1
        elif key == "f":
            corners += parts[1:]
            sizes.append(len(parts) - 1)
            face_lines.append(lineno)
            face_nv.append(len(coords))
            if material is not None and material not in materials_used:
                materials_used.append(material)
        elif key == "mtllib":
            libraries.append(line.split(None, 1)[1].strip() if len(parts) > 1 else "")
        elif key == "usemtl":
            material = line.split(None, 1)[1].strip() if len(parts) > 1 else ""
    _finite_coordinates(path, coords, lambda i: f"line {coord_lines[i]}")
    if sizes:
        # Corners are v, v/vt, v//vn or v/vt/vn; regular expressions split them all at C speed.
        joined = " ".join(corners)
        _obj_indices(path, re.sub(r"/\S*", "", joined).split(" "), sizes, face_lines, face_nv, "vertex")
        if "/" in joined:
            # pymeshlab reads texture coordinates given after the faces that use them.
            uv = np.array(re.findall(r"(?<!\S)[^\s/]*/?([^\s/]*)\S*", joined))
            textured = np.flatnonzero(uv != "")
            uv_sizes = np.bincount(np.searchsorted(np.cumsum(sizes), textured, side="right"), minlength=len(sizes))
            _obj_indices(path, uv[textured].tolist(), uv_sizes, face_lines, n_uv, "texture coordinate")
    n = len(coords)
    declared = Declared(n, len(sizes), has_colors=n > 0 and n_colored == n, libraries=bool(libraries))
    if materials_used:
        declared.textures, declared.notes = material_textures(path, libraries, materials_used)
    return declared


# ---------------------------------------------------------------------------
# PLY: the header's counts against the bytes that follow it, the faces' vertex indices

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip
_PLY_FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}


@dataclass
class _PlyElement:
    name: str
    count: int
    props: list  # (name, dtype str, list-count dtype str or None)

    def smallest(self, binary: bool) -> int:
        """The fewest bytes a record can take: scalars and list counts (binary), a digit and a space each (ASCII)."""
        if not binary:
            return 2 * len(self.props)
        return sum(np.dtype(count or kind).itemsize for _, kind, count in self.props)


def _ply_header(path, data: bytes):
    if not re.match(rb"ply\r?\n", data):
        fail(path, "unparseable content: not a PLY file (it does not start with 'ply')")
    end = re.search(rb"\nend_header[ \t]*\r?\n", data)
    if end is None:
        fail(path, "unparseable content: PLY header has no 'end_header' line (truncated file?)")
    fmt, elements = None, []
    for line in data[: end.start()].decode("latin-1").splitlines()[1:]:
        parts = line.split()
        if not parts or parts[0] in ("comment", "obj_info"):
            continue
        if parts[0] == "format" and len(parts) == 3 and parts[1] in _PLY_FORMATS:
            fmt = parts[1]
        elif parts[0] == "element" and len(parts) == 3 and parts[2].isascii() and parts[2].isdigit():
            elements.append(_PlyElement(parts[1], int(parts[2]), []))
        elif parts[0] == "property" and elements and len(parts) == 3 and parts[1] in _PLY_TYPES:
            elements[-1].props.append((parts[2], _PLY_TYPES[parts[1]], None))
        elif (
            parts[0] == "property"
            and elements
            and len(parts) == 5
            and parts[1] == "list"
            and _PLY_TYPES.get(parts[2], "f")[0] in "iu"
            and parts[3] in _PLY_TYPES
        ):
            elements[-1].props.append((parts[4], _PLY_TYPES[parts[3]], _PLY_TYPES[parts[2]]))
        else:
            # pymeshlab crashes (SIGSEGV) on some, such as an 'element' line without its count.
            fail(path, f"unparseable content: bad PLY header line {line.strip()[:60]!r}")
    if fmt is None:
        fail(path, "unparseable content: PLY header has no valid 'format' line")
    body = len(data) - end.end()
    need = sum(el.count * max(el.smallest(fmt != "ascii"), 1) for el in elements) - (fmt == "ascii")
    if need > body:
        # pymeshlab allocates what the header declares before it reads.
        counts = ", ".join(f"{el.count:,} {el.name}" for el in elements)
        fail(
            path,
            f"unparseable content: the PLY header declares {counts}, more than the {body:,} bytes after it can "
            "hold (truncated or damaged file)",
        )
    return fmt, elements, end.end()


def _ply_binary_element(path, data, offset, el: _PlyElement, order: str):
    """Read one element's records; returns ({prop: array or list of arrays}, new offset)."""
    # Fast path: every record's lists have the lengths of the first record's (a mesh of triangles).
    fields, lengths = [], []
    for name, kind, count_kind in el.props:
        if count_kind is None:
            fields.append((name, order + kind))
            continue
        at = offset + np.dtype(fields).itemsize
        if at + np.dtype(count_kind).itemsize > len(data):
            break
        length = int(np.frombuffer(data, order + count_kind, 1, at)[0])
        if not 0 <= length <= len(data):
            break
        fields += [(f"count {name}", order + count_kind), (name, order + kind, (length,))]
        lengths.append((f"count {name}", length))
    else:
        dtype = np.dtype(fields)
        if offset + el.count * dtype.itemsize <= len(data):
            records = np.frombuffer(data, dtype, el.count, offset)
            if all(np.all(records[count] == length) for count, length in lengths):
                return {name: records[name] for name, _, _ in el.props}, offset + el.count * dtype.itemsize
    out = {name: [] for name, _, _ in el.props}
    try:
        for _ in range(el.count):
            for name, kind, count_kind in el.props:
                if count_kind is None:
                    out[name].append(np.frombuffer(data, order + kind, 1, offset)[0])
                    offset += np.dtype(kind).itemsize
                else:
                    n = int(np.frombuffer(data, order + count_kind, 1, offset)[0])
                    if n < 0:
                        raise ValueError
                    offset += np.dtype(count_kind).itemsize
                    out[name].append(np.frombuffer(data, order + kind, n, offset))
                    offset += n * np.dtype(kind).itemsize
    except ValueError:
        fail(path, f"unparseable content: PLY element {el.name!r} is malformed or cut short (truncated file?)")
    return {k: (v if el.props[i][2] else np.array(v)) for i, (k, v) in enumerate(out.items())}, offset


def _ply_ascii_element(path, tokens, pos, el: _PlyElement):
    try:
        if all(c is None for _, _, c in el.props):
            k = len(el.props)
            block = tokens[pos : pos + el.count * k]
            if len(block) < el.count * k:
                raise IndexError
            values = np.array(block, dtype=np.float64).reshape(el.count, k)
            # Values that overflow their declared type become inf, as they do for pymeshlab.
            with np.errstate(over="ignore", invalid="ignore"):
                out = {name: values[:, i].astype(kind) for i, (name, kind, _) in enumerate(el.props)}
            return out, pos + el.count * k
        out = {name: [] for name, _, _ in el.props}
        for _ in range(el.count):
            for name, kind, count_kind in el.props:
                if count_kind is None:
                    with np.errstate(over="ignore", invalid="ignore"):
                        out[name].append(np.float64(tokens[pos]).astype(kind))
                    pos += 1
                else:
                    n = int(tokens[pos])
                    if n < 0 or pos + 1 + n > len(tokens):
                        raise IndexError
                    out[name].append(np.array(tokens[pos + 1 : pos + 1 + n], dtype=np.float64))
                    pos += 1 + n
    except IndexError:
        fail(path, f"unparseable content: PLY data ends inside element {el.name!r} (truncated file?)")
    except ValueError:
        fail(path, f"unparseable content: bad number in PLY element {el.name!r}")
    return {k: (v if el.props[i][2] else np.array(v)) for i, (k, v) in enumerate(out.items())}, pos


def _read_ply(path, data: bytes) -> tuple[str, list, dict]:
    """The format, the header's elements and every element's values: {element: {property: values}}."""
    fmt, elements, offset = _ply_header(path, data)
    out = {}
    if fmt == "ascii":
        tokens = data[offset:].split()
        pos = 0
        for el in elements:
            out[el.name], pos = _ply_ascii_element(path, tokens, pos, el)
    else:
        for el in elements:
            out[el.name], offset = _ply_binary_element(path, data, offset, el, _PLY_FORMATS[fmt])
    return fmt, elements, out


def _check_ply(path: Path, data: bytes) -> Declared:
    fmt, elements, ply = _read_ply(path, data)
    vertex = ply.get("vertex", {})
    n_vertices = len(next(iter(vertex.values()), ()))
    coordinates = None
    if all(c in vertex for c in "xyz"):
        xyz = np.column_stack([np.asarray(vertex[c], dtype=np.float64) for c in "xyz"])
        _finite_coordinates(path, xyz, lambda i: "PLY vertex data")
        kinds = {name: kind for el in elements if el.name == "vertex" for name, kind, _ in el.props}
        if fmt == "binary_big_endian" and any(kinds[c] == "f8" for c in "xyz"):
            coordinates = xyz  # pymeshlab 2025.7 reads big-endian doubles byte-swapped wrong (1.0 as 3e-319)
    face = ply.get("face", {})
    indices = face.get("vertex_indices", face.get("vertex_index"))
    if indices is not None and len(indices):
        # pymeshlab checks a triangle's indices, but a polygon's out of range crash it (SIGSEGV).
        if isinstance(indices, np.ndarray):
            bad = np.flatnonzero(((indices < 0) | (indices >= n_vertices)).any(axis=1))
        else:
            bad = [i for i, f in enumerate(indices) if len(f) and (f.min() < 0 or f.max() >= n_vertices)]
        if len(bad):
            fail(path, f"face {bad[0]} has a vertex index out of range (the file has {n_vertices} vertices)")
    colors = any(c in vertex for c in ("red", "diffuse_red"))
    n_faces = len(indices) if indices is not None else 0
    return Declared(n_vertices, n_faces, colors, tuple(vertex), coordinates=coordinates)


# ---------------------------------------------------------------------------
# STL

_STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("corners", "<f4", (3, 3)), ("attr", "<u2")])


def _check_stl(path: Path, data: bytes) -> Declared:
    if len(data) >= 84:
        n = int.from_bytes(data[80:84], "little")
        if len(data) == 84 + _STL_RECORD.itemsize * n:
            return Declared(3 * n, n)
    if data.lstrip()[:5].lower() != b"solid":
        size = f"{len(data)} bytes"
        if len(data) >= 84:
            size += f", but a binary STL of {n} facets has {84 + _STL_RECORD.itemsize * n}"
        fail(path, f"unparseable content: neither ASCII STL (no 'solid' header) nor binary STL ({size}; truncated?)")
    if not data.isascii():
        fail(path, "unparseable content: non-ASCII bytes in an ASCII STL (or a binary STL of the wrong size)")
    facets = len(re.findall(rb"(?i)\bendfacet\b", data))  # every solid's: a file may hold several
    return Declared(3 * facets, facets)


# ---------------------------------------------------------------------------
# OFF, read here

_OFF_HEADER = re.compile(r"(ST)?(C)?(N)?(4)?(n)?OFF")


def read_off(path, data: bytes):
    """The vertices, triangles and vertex colours of an OFF file.

    Comments (``#`` to the end of a line) and blank lines may stand
    anywhere.  Polygons are split into fans from their first corner; the
    triangles of a fan that repeat a vertex are left out (a triangle
    written as a quad with a repeated corner is one triangle).  Vertex
    colours (``COFF``) are integers 0-255 or, with a decimal point, floats
    0-1; normals and texture coordinates are skipped.

    Returns
    -------
    V : (n, 3) float64
    F : (m, 3) int64
    C : (n, 3) float32 in [0, 1], or None
    n_faces : int
        The faces the file holds, before triangulation.

    Raises
    ------
    MeshError
        Unparseable content, a face index out of range or non-finite
        coordinates, naming the file and the line's problem.

    Examples
    --------
    >>> V, F, C, n = read_off("sq.off", b"OFF # a square\\n4 1 0\\n0 0 0\\n1 0 0\\n1 1 0 # corner\\n0 1 0\\n4 0 1 2 3\\n")
    >>> F.tolist(), C, n
    ([[0, 1, 2], [0, 2, 3]], None, 1)
    """
    text = _text(path, data, "OFF")
    lines = [ln.split("#", 1)[0].split() for ln in text.splitlines()]
    lines = [ln for ln in lines if ln]
    header = _OFF_HEADER.fullmatch(lines[0][0]) if lines else None
    if header is None:
        fail(path, f"unparseable content: an OFF file starts with 'OFF', not {(lines[0][0] if lines else '')[:20]!r}")
    if header.group(4) or header.group(5):
        fail(path, "unparseable content: only 3D OFF files are supported (not 4OFF or nOFF)")
    counts, body = (lines[0][1:], lines[1:]) if len(lines[0]) > 1 else ((lines[1:2] or [[]])[0], lines[2:])
    try:
        nv, nf = int(counts[0]), int(counts[1])
    except (IndexError, ValueError):
        fail(path, "unparseable content: OFF header has no 'vertices faces edges' counts")
    if nv < 0 or nf < 0 or len(body) < nv + nf:
        fail(
            path, f"unparseable content: OFF file declares {nv} vertices and {nf} faces but has {len(body)} data lines"
        )
    # Coordinates, then normals (N), texture coordinates (ST), then maybe a colour.
    width = 3 + 3 * bool(header.group(3)) + 2 * bool(header.group(1))
    rows = body[:nv]
    widths = {len(ln) for ln in rows}
    if nv and (len(widths) > 1 or min(widths) - width not in (0, 3, 4)):
        fail(path, f"unparseable content: OFF vertex lines must all hold {width} numbers, plus an optional color")
    V = _finite_coordinates(path, [ln[:3] for ln in rows], lambda i: f"vertex line {i + 1}")
    C = None
    if header.group(2) and nv and min(widths) > width:
        tokens = [ln[width : width + 3] for ln in rows]
        C = np.array(tokens, dtype=np.float64)
        if not any("." in t or "e" in t.lower() for row in tokens for t in row):
            C = C / 255.0
        C = np.clip(C, 0.0, 1.0).astype(np.float32)
    triangles = []
    for i, ln in enumerate(body[nv : nv + nf]):
        corners = _off_face(ln)
        if corners is None:
            fail(path, f"unparseable content: bad face line {' '.join(ln)[:60]!r} in OFF data")
        if min(corners) < 0 or max(corners) >= nv:
            fail(path, f"face {i} has vertex index out of range (the file has {nv} vertices)")
        a = corners[0]
        triangles += [(a, b, c) for b, c in zip(corners[1:-1], corners[2:]) if a != b and b != c and a != c]
    return V, np.array(triangles, dtype=np.int64).reshape(-1, 3), C, nf


def _off_face(tokens: list) -> list | None:
    """The corners of an OFF face line (``k i1 .. ik`` and maybe a colour), or None if it is not one."""
    try:
        k = int(tokens[0])
        corners = [int(t) for t in tokens[1 : 1 + k]]
    except ValueError:
        return None
    if k < 3 or len(tokens) - 1 - k not in (0, 1, 3, 4) or not _all_numbers(tokens[1 + k :]):
        return None
    return corners


_CHECKS = {".obj": _check_obj, ".ply": _check_ply, ".stl": _check_stl}


def check(path: Path, data: bytes) -> Declared:
    """Refuse what pymeshlab would misread in the file ``path`` with content ``data``; what the file declares.

    Its extension picks the format (OBJ, PLY or STL; OFF files are read by :func:`read_off`).

    Raises
    ------
    MeshError
        A face index out of range, a bad or non-finite coordinate, a header
        declaring more than the file holds; the message names the file.
    """
    return _CHECKS[path.suffix.lower()](path, data)
