"""A generated corpus of messy meshes: each defect planted on small shapes, with the report it must give.

The shapes are small and composite like the meshes researchers bring: a box
(grid of ``4 x 4`` quads a side, 192 faces), two boxes that interpenetrate,
a box with a sphere stuck into it, an open cup, two boxes that share an
edge or a corner, a flat fold.  Each :class:`Case` plants one defect (or
all of them at once) and says what ``load_mesh(..., report=True)`` must
report (:class:`meshsal.mesh.repair.MeshReport` fields); :func:`write_case`
writes it as OBJ, PLY (binary), OFF or STL.  Box coordinates are multiples
of 4, exact in float32, so that STL, which stores every corner separately
in float32, keeps every planted defect but the ones too thin for float32
(slivers) or that it cannot hold (unreferenced vertices).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from shapes import _box_points, _orient, _weld

FORMATS = ("obj", "ply", "off", "stl")
SIDE = 4  # quads along each side of a box


@dataclass(frozen=True)
class Case:
    """A messy mesh and what its repair report must say.

    ``expected`` holds :class:`MeshReport` counts; fields not named must be
    0, except ``components``, ``closed_components``, ``boundary_edges`` and
    ``boundary_loops``, which are always given.  ``normalless`` lists the
    positions of the vertices that must be left without a normal.
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    expected: dict
    formats: tuple = FORMATS
    normalless: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    def expected_for(self, fmt: str) -> dict:
        """The expected counts for one file format (STL merges every corner's copy; the other formats' readers
        leave out a face that repeats a vertex index, so the repair never sees it)."""
        out = dict(self.expected)
        if fmt == "stl":
            used = np.unique(self.vertices[self.faces.reshape(-1)], axis=0)
            out["merged_vertices"] = 3 * len(self.faces) - len(used)
        else:
            F = np.sort(self.faces, axis=1)
            repeated = int(np.count_nonzero((F[:, 1:] == F[:, :-1]).any(axis=1)))
            if repeated:
                out["zero_area_faces"] -= repeated
        return out


# --------------------------------------------------------------------------- shapes


def box(lo=(0, 0, 0), hi=(32, 32, 32), n: int = SIDE) -> tuple[np.ndarray, np.ndarray]:
    """A closed box facing outward, each side an ``n x n`` grid of quads."""
    V, F = _box_points(n)
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    V = lo + (V + 1.0) / 2.0 * (hi - lo)
    center = (lo + hi) / 2.0
    return V, _orient(V, F, lambda c: c - center)


def sphere(center=(16, 16, 32), radius: float = 12.0, n: int = SIDE) -> tuple[np.ndarray, np.ndarray]:
    """A closed sphere facing outward: a cube grid pushed onto it."""
    V, F = _box_points(n)
    V = V / np.linalg.norm(V, axis=1, keepdims=True) * radius + np.asarray(center, dtype=np.float64)
    return V, _orient(V, F, lambda c: c - np.asarray(center, dtype=np.float64))


def cup(radius: float = 16.0, height: float = 24.0, around: int = 16, along: int = 4, offset=(80, 0, 0)):
    """An open cup: a tube around z with a bottom, open at the top (one boundary loop of ``around`` edges)."""
    t = np.linspace(0.0, 2.0 * np.pi, around, endpoint=False)
    z = np.linspace(0.0, height, along + 1)
    Z, T = np.meshgrid(z, t, indexing="ij")
    V = np.stack([radius * np.cos(T.ravel()), radius * np.sin(T.ravel()), Z.ravel()], 1)
    idx = np.arange(len(V)).reshape(along + 1, around)
    a, b = idx[:-1], idx[1:]
    c, d = np.roll(b, -1, axis=1), np.roll(a, -1, axis=1)
    F = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    bottom = len(V)
    V = np.vstack([V, [[0.0, 0.0, 0.0]]])
    F = np.vstack([F, np.stack([np.full(around, bottom), idx[0], np.roll(idx[0], -1)], 1)])
    F = _orient(V, F, lambda p: np.where(p[:, 2:3] < 1e-9, [[0.0, 0.0, -1.0]], p * [1.0, 1.0, 0.0]))
    return V + np.asarray(offset, dtype=np.float64), F


def fold(offset=(100, 0, 0)) -> tuple[np.ndarray, np.ndarray]:
    """Two triangles folded flat onto each other along an edge: its two ends have no normal."""
    v, a, b = np.array([0.0, 0, 0]), np.array([16.0, 0, 0]), np.array([0.0, 16, 0])
    V = np.stack([v, a, b, a + b - v]) + np.asarray(offset, dtype=np.float64)
    return V, np.array([[0, 1, 2], [0, 2, 3]])


def union(*parts, weld: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Several meshes as one; with ``weld``, vertices at the same position become one."""
    Vs, Fs, count = [], [], 0
    for V, F in parts:
        Vs.append(V)
        Fs.append(F + count)
        count += len(V)
    V, F = np.concatenate(Vs), np.concatenate(Fs)
    return _weld(V, F) if weld else (V, F)


def _diagonal(V) -> float:
    return float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))


# --------------------------------------------------------------------------- planting


def _across(F, a, b) -> tuple[int, int]:
    """The faces holding directed edges a->b and b->a."""
    start, end = F.reshape(-1), F[:, [1, 2, 0]].reshape(-1)
    forward = np.flatnonzero((start == a) & (end == b))
    backward = np.flatnonzero((start == b) & (end == a))
    assert forward.size == 1 and backward.size == 1, (a, b)
    return int(forward[0] // 3), int(backward[0] // 3)


def _third(face, a, b) -> int:
    return int(next(v for v in face if v != a and v != b))


def _edge_at(V, F, point) -> tuple[int, int]:
    """The interior edge of a box side nearest ``point`` (a directed edge of some face)."""
    centres = 0.5 * (V[F] + V[F[:, [1, 2, 0]]])
    f, i = np.unravel_index(np.argmin(np.linalg.norm(centres - np.asarray(point, float), axis=2)), (len(F), 3))
    return int(F[f, i]), int(F[f, (i + 1) % 3])


def plant_needle(V, F, point):
    """Split the edge nearest ``point`` 1e-9 of the diagonal from one end: two needles (2 slivers, 1 collapse)."""
    a, b = _edge_at(V, F, point)
    f1, f2 = _across(F, a, b)
    c, d = _third(F[f1], a, b), _third(F[f2], a, b)
    m = len(V)
    V = np.vstack([V, V[a] + 1e-9 * _diagonal(V) * (V[b] - V[a]) / np.linalg.norm(V[b] - V[a])])
    F = F.copy()
    F[f1], F[f2] = (a, m, c), (b, m, d)
    return V, np.vstack([F, [(m, b, c), (m, a, d)]])


def plant_cap(V, F, point):
    """Split the edge nearest ``point`` at a vertex 1e-9 of the diagonal off its middle, closed by a cap (1 sliver)."""
    a, b = _edge_at(V, F, point)
    f1, _ = _across(F, a, b)
    c = _third(F[f1], a, b)
    mid = 0.5 * (V[a] + V[b])
    m = len(V)
    V = np.vstack([V, mid + 1e-9 * _diagonal(V) * (V[c] - mid) / np.linalg.norm(V[c] - mid)])
    F = F.copy()
    F[f1] = (a, m, c)
    return V, np.vstack([F, [(m, b, c), (a, b, m)]])


def plant_collinear(V, F, point, step: float = 32.0 / SIDE):
    """A zero-area face on three consecutive grid vertices of a line, the middle one nearest ``point``."""
    middle = int(np.argmin(np.linalg.norm(V - np.asarray(point, float), axis=1)))
    for direction in np.eye(3):
        ends = [np.flatnonzero(np.all(V == V[middle] + s * step * direction, axis=1)) for s in (-1, 1)]
        if all(e.size for e in ends):
            return V, np.vstack([F, [(ends[0][0], middle, ends[1][0])]])
    raise AssertionError("no collinear neighbours")


def plant_faces_near(V, F, point, k) -> np.ndarray:
    """Indices of the ``k`` faces whose centres are nearest ``point``."""
    return np.argsort(np.linalg.norm(V[F].mean(axis=1) - np.asarray(point, float), axis=1), kind="stable")[:k]


def side_faces(V, F, axis: int, value: float) -> np.ndarray:
    """Indices of the faces lying in the plane ``V[:, axis] == value`` (a side of a box)."""
    return np.flatnonzero(np.all(V[F][:, :, axis] == value, axis=1))


def plant_fin(V, F, point):
    """A double-sided triangle standing on the edge nearest ``point``: its tip's only faces are the pair."""
    a, b = _edge_at(V, F, point)
    f1, _ = _across(F, a, b)
    p, q, r = V[F[f1]]
    normal = np.cross(q - p, r - p)
    tip = len(V)
    V = np.vstack([V, 0.5 * (V[a] + V[b]) + 8.0 * normal / np.linalg.norm(normal)])
    return V, np.vstack([F, [(a, b, tip), (b, a, tip)]])


# --------------------------------------------------------------------------- the cases


def _box_counts(boxes: int = 1, **more) -> dict:
    return {"components": boxes, "closed_components": boxes, "boundary_edges": 0, "boundary_loops": 0, **more}


def cases() -> list[Case]:
    """Every planted defect, one case each, then the composite shapes, then everything at once."""
    out = []
    V, F = box()

    # Duplicate vertices: the last two vertices written again, and the faces of one of them use the copy.
    Vd = np.vstack([V, V[-2:]])
    Fd = np.where(F == len(V) - 1, len(V) + 1, F)
    out.append(Case("duplicate_vertices", Vd, Fd, _box_counts(merged_vertices=2)))

    out.append(
        Case(
            "unreferenced_vertices",
            np.vstack([V, [[50.0, 50, 50], [60.0, 60, 60]]]),
            F,
            _box_counts(unreferenced_vertices=2),
            formats=("obj", "ply", "off"),
        )
    )

    Vz, Fz = plant_collinear(V, F, (16, 16, 32))
    Fz = np.vstack([Fz, [Fz[0][[0, 0, 1]]]])  # a face that repeats a vertex
    out.append(Case("zero_area_faces", Vz, Fz, _box_counts(zero_area_faces=2)))

    Vs, Fs = plant_needle(V, F, (16, 32, 14))
    Vs, Fs = plant_cap(Vs, Fs, (16, 0, 18))
    out.append(
        Case(
            "sliver_faces",
            Vs,
            Fs,
            _box_counts(sliver_faces=3, collapsed_vertices=1, split_faces=1),
            formats=("obj", "ply", "off"),
        )
    )

    dup = plant_faces_near(V, F, (16, 16, 32), 3)
    out.append(Case("duplicate_faces", V, np.vstack([F, F[dup][:, [1, 2, 0]]]), _box_counts(duplicate_faces=3)))

    # Twins written before the faces they copy: the copy that agrees with its neighbours is kept.
    twin = plant_faces_near(V, F, (0, 16, 16), 4)
    out.append(Case("double_sided_faces", V, np.vstack([F[twin][:, ::-1], F]), _box_counts(double_sided_faces=4)))

    Vf, Ff = plant_fin(V, F, (16, 32, 14))
    out.append(
        Case(
            "double_sided_fin",
            Vf,
            Ff,
            {
                **_box_counts(double_sided_faces=1, nonmanifold_edges=1, nonmanifold_vertices=2, added_vertices=2),
                "components": 2,
                "boundary_edges": 3,
                "boundary_loops": 1,
            },
        )
    )

    side = side_faces(V, F, 0, 32.0)
    Fo = F.copy()
    Fo[side] = Fo[side][:, ::-1]
    out.append(Case("inconsistent_orientation", V, Fo, _box_counts(flipped_faces=2 * SIDE * SIDE)))
    out.append(Case("inward_box", V, F[:, ::-1], _box_counts(outward_components=1)))

    Ve, Fe = union(box(), box((32, 32, 0), (64, 64, 32)), weld=True)
    out.append(
        Case(
            "nonmanifold_edges",
            Ve,
            Fe,
            _box_counts(2, nonmanifold_edges=SIDE, nonmanifold_vertices=SIDE + 1, added_vertices=SIDE + 1),
        )
    )
    Vv, Fv = union(box(), box((32, 32, 32), (64, 64, 64)), weld=True)
    out.append(Case("nonmanifold_vertex", Vv, Fv, _box_counts(2, nonmanifold_vertices=1, added_vertices=1)))

    Vb, Fb = union(box(), box((18, 10, 6), (50, 42, 38)))
    out.append(Case("interpenetrating_boxes", Vb, Fb, _box_counts(2)))
    Vsp, Fsp = union(box(), sphere())
    out.append(Case("box_with_sphere", Vsp, Fsp, _box_counts(2)))
    Vi, Fi = union(box(), (lambda b: (b[0], b[1][:, ::-1]))(box((18, 10, 6), (50, 42, 38))))
    out.append(Case("interpenetrating_one_inward", Vi, Fi, _box_counts(2, outward_components=1)))

    Vc, Fc = cup()
    out.append(
        Case("cup", Vc, Fc, {"components": 1, "closed_components": 0, "boundary_edges": 16, "boundary_loops": 1})
    )
    holes = np.concatenate([plant_faces_near(V, F, p, 1) for p in ((16, 16, 32), (16, 16, 0), (0, 16, 16))])
    out.append(
        Case(
            "box_with_holes",
            V,
            np.delete(F, holes, axis=0),
            {"components": 1, "closed_components": 0, "boundary_edges": 9, "boundary_loops": 3},
        )
    )

    Vn, Fn = union(box(), fold())
    out.append(
        Case(
            "fold_without_normals",
            Vn,
            Fn,
            {
                "components": 2,
                "closed_components": 1,
                "boundary_edges": 4,
                "boundary_loops": 1,
                "normalless_vertices": 2,
            },
            normalless=fold()[0][[0, 2]],
        )
    )

    Vx, Fx = union(box(), sphere(), box((18, 10, 6), (50, 42, 38)))
    decal = np.array([[200.0, 0, 0], [216, 0, 0], [200, 16, 0]])
    Vx, Fx = union((Vx, Fx), (decal, np.array([[0, 1, 2], [0, 2, 1]])))
    out.append(
        Case(
            "composite_double_sided",
            Vx,
            Fx,
            {
                "components": 4,
                "closed_components": 3,
                "boundary_edges": 3,
                "boundary_loops": 1,
                "double_sided_faces": 1,
            },
        )
    )

    out.append(everything_on_one_box(V, F))
    out.append(everything_apart())
    return out + normalless_cases()


def normalless_cases() -> list[Case]:
    """Meshes whose repair leaves vertices without a normal, where point methods meet them: a flat fold
    alone, and nine folds beside a box."""
    Vf, Ff = fold()
    alone = Case(
        "fold_alone",
        Vf,
        Ff,
        {"components": 1, "closed_components": 0, "boundary_edges": 4, "boundary_loops": 1, "normalless_vertices": 2},
        normalless=Vf[[0, 2]],
    )
    folds = [fold((40 + 20 * i, 20 * j, 0)) for i in range(3) for j in range(3)]
    Vg, Fg = union(box(), *folds)
    grid = Case(
        "folds_beside_a_box",
        Vg,
        Fg,
        {
            "components": 10,
            "closed_components": 1,
            "boundary_edges": 36,
            "boundary_loops": 9,
            "normalless_vertices": 18,
        },
        normalless=np.concatenate([f[0][[0, 2]] for f in folds]),
    )
    return [alone, grid]


def everything_on_one_box(V, F) -> Case:
    """One box with every defect that a box can hold, each on its own side."""
    Fo = F.copy()
    side = side_faces(V, F, 0, 32.0)  # +x side flipped
    Fo[side] = Fo[side][:, ::-1]
    twins = plant_faces_near(V, F, (0, 16, 16), 2)  # -x side: twins first
    dups = plant_faces_near(V, F, (16, 16, 32), 2)  # +z side: copies after
    Fo = np.vstack([Fo[twins][:, ::-1], Fo, Fo[dups][:, [2, 0, 1]]])
    Vo, Fo = plant_needle(V, Fo, (16, 32, 14))  # +y side
    Vo, Fo = plant_cap(Vo, Fo, (16, 0, 18))  # -y side
    Vo, Fo = plant_collinear(Vo, Fo, (16, 16, 0))  # -z side
    Vo = np.vstack([Vo, [[90.0, 90, 90]]])  # unreferenced
    expected = _box_counts(
        flipped_faces=2 * SIDE * SIDE,
        double_sided_faces=2,
        duplicate_faces=2,
        sliver_faces=3,
        collapsed_vertices=1,
        split_faces=1,
        zero_area_faces=1,
        unreferenced_vertices=1,
    )
    return Case("everything_on_one_box", Vo, Fo, expected, formats=("obj", "ply", "off"))


def everything_apart() -> Case:
    """A composite of parts, each with its defect: the counts add up."""
    V, F = box()
    Fo = F.copy()
    side = side_faces(V, F, 0, 32.0)
    Fo[side] = Fo[side][:, ::-1]
    twins = plant_faces_near(V, F, (0, 16, 16), 3)
    parts = [
        (V, np.vstack([Fo, F[twins][:, ::-1]])),  # flipped side, three twins
        sphere(),  # stuck into the box
        (lambda b: (b[0], b[1][:, ::-1]))(box((18, 10, 6), (50, 42, 38))),  # interpenetrating, inward
        cup(),  # open
        union(box((0, 0, -100), (32, 32, -68)), box((32, 32, -100), (64, 64, -68)), weld=True),  # an edge shared
        fold(),  # no normal at two vertices
    ]
    Vn, Fn = plant_fin(*box((0, 100, 0), (32, 132, 32)), (16, 132, 14))
    parts.append((Vn, Fn))  # a double-sided fin
    Va, Fa = union(*parts)
    expected = {
        "flipped_faces": 2 * SIDE * SIDE,
        "double_sided_faces": 3 + 1,
        "outward_components": 1,
        "nonmanifold_edges": SIDE + 1,
        "nonmanifold_vertices": SIDE + 1 + 2,
        "added_vertices": SIDE + 1 + 2,
        "components": 1 + 1 + 1 + 1 + 2 + 1 + 2,
        "closed_components": 1 + 1 + 1 + 2 + 1,
        "boundary_edges": 16 + 4 + 3,
        "boundary_loops": 3,
        "normalless_vertices": 2,
    }
    return Case("everything_apart", Va, Fa, expected, normalless=fold()[0][[0, 2]])


# --------------------------------------------------------------------------- files


def write_case(case: Case, folder, fmt: str) -> Path:
    """Write ``case`` as ``folder/<name>.<fmt>``; returns the path."""
    path = Path(folder) / f"{case.name}.{fmt}"
    V, F = case.vertices, case.faces
    if fmt == "obj":
        lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in V.tolist()]
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in F.tolist()]
        path.write_text("\n".join(lines) + "\n")
    elif fmt == "off":
        lines = ["OFF", f"{len(V)} {len(F)} 0"] + [f"{x!r} {y!r} {z!r}" for x, y, z in V.tolist()]
        lines += [f"3 {a} {b} {c}" for a, b, c in F.tolist()]
        path.write_text("\n".join(lines) + "\n")
    elif fmt == "ply":
        header = (
            "ply\nformat binary_little_endian 1.0\n"
            f"element vertex {len(V)}\nproperty double x\nproperty double y\nproperty double z\n"
            f"element face {len(F)}\nproperty list uchar int vertex_indices\nend_header\n"
        )
        faces = np.zeros(len(F), dtype=[("n", "u1"), ("i", "<i4", (3,))])
        faces["n"], faces["i"] = 3, F
        path.write_bytes(header.encode() + V.astype("<f8").tobytes() + faces.tobytes())
    elif fmt == "stl":
        records = np.zeros(len(F), dtype=[("normal", "<f4", (3,)), ("corners", "<f4", (3, 3)), ("attr", "<u2")])
        records["corners"] = V[F]
        path.write_bytes(b"messy".ljust(80, b" ") + np.uint32(len(F)).tobytes() + records.tobytes())
    else:
        raise ValueError(f"unknown format {fmt!r}")
    return path


def write_corpus(folder, formats=FORMATS) -> dict:
    """Every case in every format it supports: ``{path: (case, format)}``."""
    Path(folder).mkdir(parents=True, exist_ok=True)
    return {write_case(c, folder, f): (c, f) for c in cases() for f in formats if f in c.formats}
