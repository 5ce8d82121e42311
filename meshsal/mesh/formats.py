"""The four mesh file formats, scanned for what each file declares.

pymeshlab loads the meshes (:mod:`meshsal.mesh.io`), but it silently drops
faces that point at missing or non-finite vertices and can crash the
interpreter on malformed input.  So every file is first scanned here, by
format (OBJ with its MTL, PLY ASCII or binary, OFF, STL ASCII or binary):
the counts it declares, its index ranges and finite coordinates are checked,
and :func:`scan` returns what pymeshlab must then produce (:class:`Declared`).
Anything that cannot be loaded in full raises :class:`meshsal.MeshError`
naming the file and the problem.

Over 500 lines because it is one concept, the scanner, four times: one
short section per format, each read beside the others' when a check changes.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from meshsal.mesh.record import MeshError

__all__ = ["SUPPORTED_EXTENSIONS", "Declared", "scan", "read_ply", "fail"]

SUPPORTED_EXTENSIONS = (".obj", ".off", ".ply", ".stl")

#: A material library larger than this is not read (its textures are left out, with a note): MTL files
#: hold a few lines per material, so anything near this size is not one.
MAX_MATERIAL_BYTES = 16 * 2**20


@dataclass
class Declared:
    """What a file declares, from our own scan, to check pymeshlab against."""

    n_vertices: int
    n_triangles: int  # pymeshlab should make: fan split, triangles repeating a vertex left out
    n_repeated: int = 0  # faces pymeshlab drops for repeating a vertex
    has_colors: bool = False
    textures: list = field(default_factory=list)  # OBJ: texture images the faces use
    notes: list = field(default_factory=list)  # warnings about the file itself


def fail(path, problem: str):
    """Raise :class:`MeshError` naming the file and the problem."""
    raise MeshError(f"{path}: {problem}")


# ---------------------------------------------------------------------------
# OBJ

_OBJ_IGNORED = {
    "vn", "vp", "o", "g", "s", "l", "p", "usemap", "maplib", "cstype", "deg", "bmat", "step",
    "curv", "curv2", "surf", "parm", "trim", "hole", "scrv", "sp", "end", "con", "mg", "bevel",
    "c_interp", "d_interp", "lod", "shadow_obj", "trace_obj", "ctech", "stech", "call", "csh",
}  # fmt: skip


def _text(path, data: bytes, kind: str) -> str:
    if b"\0" in data:
        fail(path, f"unparseable content: binary data in what should be a text {kind} file")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def _obj_indices(path, tokens, sizes, lines, defined, what: str) -> np.ndarray:
    """Resolve OBJ face indices (1-based, negative = relative) to 0-based, checking range.

    ``tokens`` holds one index string per face corner, ``defined`` how many
    elements each face's line could refer to; ``sizes`` and ``lines`` give
    each face's corner count and line number.
    """
    first = np.cumsum(sizes) - sizes
    try:
        index = np.array(tokens).astype(np.int64)
    except (ValueError, OverflowError):
        bad = next((j for j, t in enumerate(tokens) if not re.fullmatch(r"[-+]?\d{1,18}", t)), 0)
        face = np.searchsorted(first, bad, side="right") - 1
        fail(path, f"unparseable content: line {lines[face]}: bad {what} index {tokens[bad]!r}")
    count = np.repeat(np.asarray(defined, dtype=np.int64), sizes)
    resolved = np.where(index > 0, index, count + index + 1)
    bad = np.flatnonzero((index == 0) | (resolved < 1) | (resolved > count))
    if bad.size:
        j = bad[0]
        face = np.searchsorted(first, j, side="right") - 1
        fail(
            path,
            f"line {lines[face]}: face {what} index {index[j]} out of range ({count[j]} {what}s defined so far)",
        )
    return resolved - 1


def _scan_obj(path: Path, data: bytes) -> Declared:
    text = _text(path, data, "OBJ").replace("\\\r\n", " ").replace("\\\n", " ")
    nvt = n_colored = 0
    coords, coord_lines, extras = [], [], []
    corners, sizes, face_lines, face_nv, face_nvt = [], [], [], [], []
    libraries, materials_used = [], []
    material = None
    for lineno, line in enumerate(text.splitlines(), 1):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        key = parts[0]
        if key == "v":
            if len(parts) not in (4, 5, 7):
                fail(path, f"unparseable content: line {lineno}: a vertex needs 3 coordinates")
            coords.append(parts[1:4])
            coord_lines.append(lineno)
            extras += parts[4:]
            n_colored += len(parts) == 7
        elif key == "vt":
            nvt += 1
        elif key == "f":
            if len(parts) < 4:
                fail(path, f"unparseable content: line {lineno}: a face needs at least 3 vertices")
            corners += parts[1:]
            sizes.append(len(parts) - 1)
            face_lines.append(lineno)
            face_nv.append(len(coords))
            face_nvt.append(nvt)
            if material is not None and material not in materials_used:
                materials_used.append(material)
        elif key == "mtllib":
            libraries.append(line.split(None, 1)[1].strip() if len(parts) > 1 else "")
        elif key == "usemtl":
            material = line.split(None, 1)[1].strip() if len(parts) > 1 else ""
        elif key not in _OBJ_IGNORED:
            fail(path, f"unparseable content: line {lineno}: unknown statement {key[:20]!r}")
    try:
        xyz = np.array(coords, dtype=np.float64).reshape(-1, 3)
    except ValueError:
        bad = next(i for i, c in enumerate(coords) if not _all_numbers(c))
        fail(path, f"unparseable content: line {coord_lines[bad]}: bad number in vertex {coords[bad]}")
    if not _all_numbers(extras):
        fail(path, "unparseable content: bad number in a vertex color")
    bad = np.flatnonzero(~np.isfinite(xyz).all(axis=1))
    if bad.size:
        fail(path, f"line {coord_lines[bad[0]]}: vertex {bad[0] + 1} has non-finite coordinates")
    n_tri = n_repeated = 0
    if sizes:
        # Corners are v, v/vt, v//vn or v/vt/vn; regular expressions split them all at C speed.
        joined = " ".join(corners)
        index = _obj_indices(path, re.sub(r"/\S*", "", joined).split(" "), sizes, face_lines, face_nv, "vertex")
        if "/" in joined:
            uv = np.array(re.findall(r"(?<!\S)[^\s/]*/?([^\s/]*)\S*", joined))
            textured = np.flatnonzero(uv != "")
            uv_sizes = np.bincount(np.searchsorted(np.cumsum(sizes), textured, side="right"), minlength=len(sizes))
            _obj_indices(path, uv[textured].tolist(), uv_sizes, face_lines, face_nvt, "texture coordinate")
        sizes = np.asarray(sizes)
        polygons = np.split(index, np.cumsum(sizes)[:-1]) if (sizes > 3).any() else index.reshape(-1, 3)
        n_tri, n_repeated = _faces_declared(path, polygons, len(xyz))
    declared = Declared(len(xyz), n_tri, n_repeated, has_colors=len(xyz) > 0 and n_colored == len(xyz))
    if materials_used:
        _obj_textures(path, libraries, materials_used, declared)
    return declared


def _all_numbers(tokens) -> bool:
    try:
        np.array(tokens, dtype=np.float64)
    except ValueError:
        return False
    return True


def _mtl_map_kd(rest: list) -> str:
    """The file name of a ``map_Kd`` statement, skipping its options (``-s 1 1 1``)."""
    i = 0
    while i < len(rest) - 1 and rest[i].startswith("-"):
        i += 1
        while i < len(rest) - 1 and (rest[i] in ("on", "off") or re.fullmatch(r"[-+.\deE]+", rest[i])):
            i += 1
    return " ".join(rest[i:])


def _obj_textures(path: Path, libraries, materials_used, declared: Declared):
    maps = {}
    for name in libraries:
        lib = path.parent / name
        if not lib.is_file():
            declared.notes.append(f"material library {name!r} not found")
            continue
        try:
            size = lib.stat().st_size
            text = lib.read_bytes().decode("utf-8", errors="replace") if size <= MAX_MATERIAL_BYTES else None
        except OSError as e:
            declared.notes.append(f"material library {name!r} cannot be read ({e.strerror or e})")
            continue
        if text is None:
            declared.notes.append(
                f"material library {name!r} has {size} bytes, over the cap of "
                f"{MAX_MATERIAL_BYTES}; loaded without its textures"
            )
            continue
        current = None
        for line in text.splitlines():
            parts = line.split()
            if len(parts) >= 2 and parts[0] == "newmtl":
                current = " ".join(parts[1:])
            elif len(parts) >= 2 and parts[0] == "map_Kd" and current is not None:
                maps[current] = (lib.parent / _mtl_map_kd(parts[1:])).resolve()
    for material in materials_used:
        image = maps.get(material)
        if image is not None and image not in declared.textures:
            declared.textures.append(image)


# ---------------------------------------------------------------------------
# PLY

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


def _ply_header(path, data: bytes):
    if not re.match(rb"ply\r?\n", data):
        fail(path, "unparseable content: not a PLY file (it does not start with 'ply')")
    end = re.search(rb"\nend_header[ \t]*\r?\n", data)
    if end is None:
        fail(path, "unparseable content: PLY header has no 'end_header' line")
    header = data[: end.start()].decode("latin-1").splitlines()[1:]
    fmt, elements = None, []
    for line in header:
        parts = line.split()
        if not parts or parts[0] in ("comment", "obj_info"):
            continue
        if parts[0] == "format" and len(parts) == 3 and parts[1] in _PLY_FORMATS:
            fmt = parts[1]
        elif parts[0] == "element" and len(parts) == 3 and parts[2].isdigit():
            elements.append(_PlyElement(parts[1], int(parts[2]), []))
        elif parts[0] == "property" and elements:
            if len(parts) == 3 and parts[1] in _PLY_TYPES:
                elements[-1].props.append((parts[2], _PLY_TYPES[parts[1]], None))
            elif (
                len(parts) == 5
                and parts[1] == "list"
                and _PLY_TYPES.get(parts[2], "f")[0] in "iu"
                and _PLY_TYPES.get(parts[3], "f")[0] in "iu"
            ):
                elements[-1].props.append((parts[4], _PLY_TYPES[parts[3]], _PLY_TYPES[parts[2]]))
            else:
                fail(path, f"unparseable content: bad PLY property line {line.strip()[:60]!r}")
        else:
            fail(path, f"unparseable content: bad PLY header line {line.strip()[:60]!r}")
    if fmt is None:
        fail(path, "unparseable content: PLY header has no valid 'format' line")
    return fmt, elements, end.end()


def _ply_binary_element(path, data, offset, el: _PlyElement, order: str):
    """Read one element's records; returns ({prop: array or list of arrays}, new offset)."""
    lists = [p for p in el.props if p[2] is not None]
    if len(lists) <= 1:
        # Fast path: every list has the length of the first record's list.
        fields, lead = [], 0
        for name, kind, count_kind in el.props:
            if count_kind is None:
                fields.append((name, order + kind))
                continue
            lead_size = np.dtype(fields).itemsize
            if offset + lead_size + np.dtype(count_kind).itemsize > len(data):
                break
            lead = int(np.frombuffer(data, order + count_kind, 1, offset + lead_size)[0])
            if not 0 <= lead <= len(data):
                break
            fields += [("__count__", order + count_kind), (name, order + kind, (lead,))]
        else:
            dtype = np.dtype(fields)
            if offset + el.count * dtype.itemsize <= len(data):
                records = np.frombuffer(data, dtype, el.count, offset)
                if not lists or np.all(records["__count__"] == lead):
                    out = {name: records[name] for name, _, _ in el.props}
                    return out, offset + el.count * dtype.itemsize
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
                    out[name].append(np.array(tokens[pos + 1 : pos + 1 + n], dtype=np.int64))
                    pos += 1 + n
    except IndexError:
        fail(path, f"unparseable content: PLY data ends inside element {el.name!r} (truncated file?)")
    except ValueError:
        fail(path, f"unparseable content: bad number in PLY element {el.name!r}")
    return {k: (v if el.props[i][2] else np.array(v)) for i, (k, v) in enumerate(out.items())}, pos


def read_ply(path, data: bytes) -> dict:
    """All elements of a PLY file: {element: {property: values}}."""
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
    return out


def _polygon_triangles(corners) -> int:
    """Triangles pymeshlab keeps of a polygon: it splits it as a fan from the
    first corner and drops the triangles that repeat a vertex."""
    a = corners[0]
    return sum(a != b and b != c and a != c for b, c in zip(corners[1:-1], corners[2:]))


def _faces_declared(path, faces, n_vertices: int) -> tuple[int, int]:
    """Check polygon index lists; returns (triangles pymeshlab should make, faces it should drop)."""
    if isinstance(faces, np.ndarray) and faces.ndim == 2:
        k = faces.shape[1]
        if faces.shape[0] and k < 3:
            fail(path, "unparseable content: a face needs at least 3 vertices")
        flat = faces.astype(np.int64)
        bad = np.flatnonzero(((flat < 0) | (flat >= n_vertices)).any(axis=1))
        if bad.size:
            fail(
                path,
                f"face {bad[0]} has vertex index {faces[bad[0]].tolist()} out of range "
                f"(the file has {n_vertices} vertices)",
            )
        ordered = np.sort(flat, axis=1)
        repeats = np.flatnonzero((ordered[:, 1:] == ordered[:, :-1]).any(axis=1))
        triangles = [_polygon_triangles(flat[i].tolist()) for i in repeats]
        n_tri = (faces.shape[0] - repeats.size) * (k - 2) + sum(triangles)
        return n_tri, triangles.count(0)
    n_tri = dropped = 0
    for i, f in enumerate(faces):
        f = np.asarray(f, dtype=np.int64)
        if f.size < 3:
            fail(path, f"unparseable content: face {i} has fewer than 3 vertices")
        if f.min() < 0 or f.max() >= n_vertices:
            fail(path, f"face {i} has vertex index out of range (the file has {n_vertices} vertices)")
        triangles = _polygon_triangles(f.tolist())
        n_tri += triangles
        dropped += triangles == 0
    return n_tri, dropped


def _check_finite(path, xyz: np.ndarray):
    bad = np.flatnonzero(~np.isfinite(xyz).all(axis=1))
    if bad.size:
        fail(path, f"{bad.size} vertices have non-finite coordinates (first: vertex {bad[0]})")


def _scan_ply(path: Path, data: bytes) -> Declared:
    ply = read_ply(path, data)
    vertex = ply.get("vertex")
    if vertex is None or not all(c in vertex for c in "xyz"):
        fail(path, "unparseable content: PLY file has no vertex element with x, y, z")
    xyz = np.column_stack([np.asarray(vertex[c], dtype=np.float64) for c in "xyz"]).reshape(-1, 3)
    _check_finite(path, xyz)
    n_tri = repeated = 0
    face = ply.get("face")
    if face is not None and face:
        key = "vertex_indices" if "vertex_indices" in face else "vertex_index"
        if key not in face:
            fail(path, "unparseable content: PLY face element has no vertex_indices list")
        n_tri, repeated = _faces_declared(path, face[key], len(xyz))
    colors = any(c in vertex for c in ("red", "diffuse_red"))
    return Declared(len(xyz), n_tri, repeated, has_colors=colors)


# ---------------------------------------------------------------------------
# OFF

_OFF_HEADER = re.compile(r"(ST)?(C)?(N)?(4)?OFF")


def _scan_off(path: Path, data: bytes) -> Declared:
    text = _text(path, data, "OFF")
    lines = [ln.split("#", 1)[0].split() for ln in text.splitlines()]
    lines = [ln for ln in lines if ln]
    if not lines or not _OFF_HEADER.fullmatch(lines[0][0]):
        first = lines[0][0][:20] if lines else ""
        fail(path, f"unparseable content: an OFF file starts with 'OFF', not {first!r}")
    header = _OFF_HEADER.fullmatch(lines[0][0])
    if header.group(4):
        fail(path, "unparseable content: 4D OFF files are not supported")
    counts, body = (lines[0][1:], lines[1:]) if len(lines[0]) > 1 else ((lines[1:2] or [[]])[0], lines[2:])
    try:
        nv, nf = int(counts[0]), int(counts[1])
    except (IndexError, ValueError):
        fail(path, "unparseable content: OFF header has no 'vertices faces edges' counts")
    if nv < 0 or nf < 0 or len(body) < nv + nf:
        fail(
            path,
            f"unparseable content: OFF file declares {nv} vertices and {nf} faces but has only {len(body)} data lines",
        )
    # Coordinates, then normals (N), texture coordinates (ST), maybe a color.
    width = 3 + 3 * bool(header.group(3)) + 2 * bool(header.group(1))
    widths = {len(ln) for ln in body[:nv]}
    if nv and (len(widths) > 1 or widths.pop() - width not in (0, 3, 4)):
        fail(path, f"unparseable content: OFF vertex lines must all hold {width} numbers, plus an optional color")
    try:
        xyz = np.array([[float(t) for t in ln][:3] for ln in body[:nv]], dtype=np.float64).reshape(-1, 3)
        faces = []
        for ln in body[nv : nv + nf]:
            k = int(ln[0])
            if len(ln) - 1 - k not in (0, 1, 3, 4):
                raise ValueError
            faces.append([int(t) for t in ln[1 : 1 + k]])
            for t in ln[1 + k :]:
                float(t)  # a face color must be numeric
    except ValueError:
        fail(path, "unparseable content: bad vertex or face line in OFF data")
    _check_finite(path, xyz)
    n_tri, repeated = _faces_declared(path, faces, nv)
    return Declared(nv, n_tri, repeated, has_colors=bool(header.group(2)))


# ---------------------------------------------------------------------------
# STL

_STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("corners", "<f4", (3, 3)), ("attr", "<u2")])
# facet normal n n n outer loop vertex x y z (x3) endloop endfacet
_STL_FACET_SIZE = 21
_STL_FACET_WORDS = [
    (0, b"facet"), (1, b"normal"), (5, b"outer"), (6, b"loop"), (7, b"vertex"),
    (11, b"vertex"), (15, b"vertex"), (19, b"endloop"), (20, b"endfacet"),
]  # fmt: skip


def _scan_stl(path: Path, data: bytes) -> Declared:
    if len(data) >= 84:
        n = int.from_bytes(data[80:84], "little")
        if len(data) == 84 + 50 * n:
            corners = np.frombuffer(data, _STL_RECORD, n, 84)["corners"].reshape(-1, 3)
            _check_finite(path, corners.astype(np.float64))
            return Declared(3 * n, n)
    if not data.lstrip()[:5].lower() == b"solid":
        size = f"{len(data)} bytes"
        if len(data) >= 84:
            size += f", but a binary STL of {n} facets has {84 + 50 * n}"
        fail(path, f"unparseable content: neither ASCII STL (no 'solid' header) nor binary STL ({size}; truncated?)")
    if not data.isascii():
        # pymeshlab would take it for binary and read garbage facets.
        fail(path, "unparseable content: non-ASCII bytes in an ASCII STL (or a binary STL of the wrong size)")
    tokens = data.lstrip().partition(b"\n")[2].split()  # after the 'solid name' line
    i = 0
    corners = []
    while i < len(tokens) and tokens[i].lower() == b"facet":
        facet = [t.lower() for t in tokens[i : i + _STL_FACET_SIZE]]
        try:
            if len(facet) < _STL_FACET_SIZE or any(facet[j] != word for j, word in _STL_FACET_WORDS):
                raise ValueError
            numbers = [float(t) for t in facet[2:5] + facet[8:11] + facet[12:15] + facet[16:19]]
        except ValueError:
            fail(path, f"unparseable content: ASCII STL facet {len(corners)} is malformed or cut short")
        corners.append(numbers[3:])
        i += _STL_FACET_SIZE
    if i >= len(tokens) or tokens[i].lower() != b"endsolid":
        fail(path, f"unparseable content: ASCII STL has no 'endsolid' after facet {len(corners)} (truncated?)")
    with np.errstate(over="ignore"):
        xyz = np.array(corners, dtype=np.float32).astype(np.float64).reshape(-1, 3)  # STL is single precision
    n_facets = len(corners)
    _check_finite(path, xyz)
    return Declared(3 * n_facets, n_facets)


_SCANNERS = {".obj": _scan_obj, ".ply": _scan_ply, ".off": _scan_off, ".stl": _scan_stl}


def scan(path: Path, data: bytes) -> Declared:
    """What the file ``path`` with content ``data`` declares, checked; its extension picks the format.

    Raises
    ------
    MeshError
        Unparseable content, a face index out of range, non-finite
        coordinates; the message names the file.
    """
    return _SCANNERS[path.suffix.lower()](path, data)
