"""Loading finds, repairs and reports every planted defect of the messy corpus (tests/messy.py), with known answers."""

import dataclasses
import re
import warnings

import igl
import messy
import numpy as np
import pytest
import shapes
from hypothesis import given, settings
from hypothesis import strategies as st

from meshsal.mesh import Mesh, MeshError, normal_defined, vertex_normals
from meshsal.mesh.io import MeshRepairWarning, load_mesh
from meshsal.mesh.repair import MeshReport, repair_arrays, repair_mesh
from meshsal.mesh.topology import Edges, split_fans

COUNTS = [f.name for f in dataclasses.fields(MeshReport) if f.name not in ("source", "vertices", "faces", "notes")]
CASES = {c.name: c for c in messy.cases()}
FILES = [(name, fmt) for name, c in CASES.items() for fmt in c.formats]


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    """The messy corpus written once: {(case name, format): path}."""
    folder = tmp_path_factory.mktemp("messy")
    return {(case.name, fmt): path for path, (case, fmt) in messy.write_corpus(folder).items()}


def load(path):
    """Load with the report, collecting the repair warnings."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mesh, report = load_mesh(path, report=True)
    return mesh, report, [str(w.message) for w in caught if issubclass(w.category, MeshRepairWarning)]


def components(F, n):
    """Face components (joined by two-face edges) of a manifold mesh, and which are closed."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    e = Edges(F, n)
    pairs = e.pairs // 3
    count, label = connected_components(
        coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(F), len(F))), directed=False
    )
    closed = np.ones(count, dtype=bool)
    closed[label[e.boundary() // 3]] = False
    return label, closed


@pytest.mark.parametrize("name, fmt", FILES, ids=[f"{n}.{f}" for n, f in FILES])
def test_every_planted_defect_is_found_and_counted(corpus, name, fmt):
    path = corpus[name, fmt]
    _, report, messages = load(path)
    expected = CASES[name].expected_for(fmt)
    assert {k: getattr(report, k) for k in COUNTS} == {k: expected.get(k, 0) for k in COUNTS}
    assert report.source == str(path)
    if report.repairs() or report.findings():
        # One warning, naming the file and every repair with its count.
        assert len(messages) == 1 and messages[0].startswith(f"{path}: ")
        for phrase in report.repairs() + report.findings():
            assert phrase in messages[0]
        for field in COUNTS[: COUNTS.index("outward_components") + 1]:
            if getattr(report, field):
                assert str(getattr(report, field)) in messages[0]
    else:
        assert messages == []


@pytest.mark.parametrize("name, fmt", FILES, ids=[f"{n}.{f}" for n, f in FILES])
def test_the_repaired_mesh_is_manifold_consistent_and_outward(corpus, name, fmt):
    mesh, report, _ = load(corpus[name, fmt])
    F = mesh.faces.astype(np.int64)
    manifold = igl.is_edge_manifold(F)
    assert manifold[0] if isinstance(manifold, tuple) else manifold
    assert igl.is_vertex_manifold(F).all()
    assert Edges(F, mesh.n_vertices).consistent().all()
    label, closed = components(F, mesh.n_vertices)
    assert len(closed) == report.components and closed.sum() == report.closed_components
    # Every closed component encloses a positive volume: it faces outward.
    N = np.cross(mesh.vertices[F[:, 1]] - mesh.vertices[F[:, 0]], mesh.vertices[F[:, 2]] - mesh.vertices[F[:, 0]])
    volume = np.bincount(label, np.einsum("ij,ij->i", mesh.vertices[F[:, 0]], N))
    assert np.all(volume[closed] > 0)


@pytest.mark.parametrize("name, fmt", FILES, ids=[f"{n}.{f}" for n, f in FILES])
def test_only_the_planted_fold_leaves_vertices_without_a_normal(corpus, name, fmt):
    mesh, report, _ = load(corpus[name, fmt])
    missing = mesh.vertices[~normal_defined(mesh.vertices, mesh.faces)]
    planted = CASES[name].normalless
    assert len(missing) == len(planted) == report.normalless_vertices
    np.testing.assert_allclose(np.sort(missing, axis=0), np.sort(planted, axis=0), atol=1e-5)
    lengths = np.linalg.norm(vertex_normals(mesh.vertices, mesh.faces), axis=1)
    assert np.all(np.isclose(lengths, 1.0)[normal_defined(mesh.vertices, mesh.faces)])


@pytest.mark.parametrize("name", ["double_sided_fin", "composite_double_sided", "everything_apart"])
def test_double_sided_triangles_leave_no_zero_normal(corpus, name):
    # As written, the tip of the fin (and the decal's corners) has only a face and its twin.
    case = CASES[name]
    before = normal_defined(case.vertices, case.faces)
    assert not before[np.unique(case.faces)].all()
    mesh, _, _ = load(corpus[name, "obj"])
    known = normal_defined(mesh.vertices, mesh.faces)
    folded = np.isin(mesh.vertices, case.normalless).all(axis=1)
    assert np.all(known | folded)


def box_faces_by_position(V, F):
    """Faces as sorted tuples of their corners' positions, each rotated to start at its smallest corner."""
    out = set()
    for tri in V[F]:
        rows = [tuple(p) for p in tri]
        k = rows.index(min(rows))
        out.add(tuple(rows[k:] + rows[:k]))
    return out


def test_needles_collapse_and_twins_go_back_to_the_box_they_were_planted_on(corpus):
    V, F = messy.box()
    for name in ("duplicate_faces", "double_sided_faces", "inconsistent_orientation", "inward_box"):
        mesh, _, _ = load(corpus[name, "obj"])
        assert box_faces_by_position(mesh.vertices, mesh.faces) == box_faces_by_position(V, F), name
    needle = messy.plant_needle(V, F, (16, 32, 14))
    fixed, report = repair_mesh(Mesh(vertices=needle[0], faces=needle[1]))
    assert (report.sliver_faces, report.collapsed_vertices) == (2, 1)
    assert box_faces_by_position(fixed.vertices, fixed.faces) == box_faces_by_position(V, F)


def test_a_cap_splits_the_face_across_and_leaves_no_slit():
    V, F = messy.box()
    Vc, Fc = messy.plant_cap(V, F, (16, 0, 18))
    fixed, report = repair_mesh(Mesh(vertices=Vc, faces=Fc))
    assert (report.sliver_faces, report.split_faces, report.boundary_edges) == (1, 1, 0)
    assert fixed.n_vertices == len(V) + 1 and fixed.n_faces == len(F) + 2

    def area(m):
        e1 = m.vertices[m.faces[:, 1]] - m.vertices[m.faces[:, 0]]
        e2 = m.vertices[m.faces[:, 2]] - m.vertices[m.faces[:, 0]]
        return 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)

    assert area(fixed).sum() == pytest.approx(6 * 32 * 32, rel=1e-12)


def test_slivers_are_measured_against_the_mesh_not_the_face():
    # A thin but real triangle (height 1e-4 of the diagonal) stays; one below 1e-7 of it is a sliver.
    V = np.array([[0, 0, 0], [100, 0, 0], [50, 1e-2, 0], [50, 1e-6, 0], [0, 100, 0]], float)
    _, F, _, _, report = repair_arrays(V, [[0, 1, 2], [0, 1, 3], [0, 4, 1]])
    assert report.sliver_faces == 1 and len(F) == 2


def test_split_keeps_the_vertex_order_and_agrees_with_libigl(corpus):
    for name in ("nonmanifold_edges", "nonmanifold_vertex", "double_sided_fin"):
        case = CASES[name]
        V, F = case.vertices, case.faces
        if name == "double_sided_fin":
            F = F[:-1]  # the fin without its twin
        ours = split_fans(V, F, None, Edges(F, len(V)))
        np.testing.assert_array_equal(ours[0][: len(V)], V)  # copies come after the vertices
        _, SF, _ = igl.split_nonmanifold(V, F)
        assert len(np.unique(SF)) == len(ours[0])
        if name == "nonmanifold_edges":
            assert components(ours[1], len(ours[0]))[1].all()  # both boxes stay closed


def test_a_cavity_keeps_facing_into_its_hole():
    outer, inner = messy.sphere((0, 0, 0), 20.0), messy.sphere((0, 0, 0), 10.0)
    V, F = messy.union(outer, (inner[0], inner[1][:, ::-1]))
    fixed, report = repair_mesh(Mesh(vertices=V, faces=F))
    assert not report.repaired and report.closed_components == 2
    np.testing.assert_array_equal(fixed.faces, F)


def facing_away(mesh, center) -> np.ndarray:
    """Whether each face's normal points away from ``center``."""
    from meshsal.mesh import face_normals

    return (
        np.einsum("ij,ij->i", face_normals(mesh.vertices, mesh.faces), mesh.vertices[mesh.faces].mean(1) - center) > 0
    )


def test_an_open_bowl_facing_inward_is_turned_outward_by_ray_casting(tmp_path):
    bowl = shapes.bowl()
    assert facing_away(bowl, 0.0).all()
    inward = bowl.replace(faces=bowl.faces[:, ::-1])
    shapes.write_obj(tmp_path / "bowl.obj", inward)
    with pytest.warns(MeshRepairWarning, match=r"bowl\.obj: turned 1 open components outward \(ray casting\)"):
        fixed, report = load_mesh(tmp_path / "bowl.obj", report=True)
    assert facing_away(fixed, 0.0).all()
    assert (report.outward_open_components, report.outward_components, report.components) == (1, 0, 1)
    assert report.boundary_loops == 1 and report.boundary_edges == 230
    again, _ = repair_mesh(inward)
    np.testing.assert_array_equal(again.faces, fixed.faces)  # seeded: the same rays every time


def test_open_components_that_face_outward_or_either_way_are_left_as_they_are():
    bowl, tube = shapes.bowl(), shapes.cylinder(around=64, along=4)
    V, F = messy.union((bowl.vertices, bowl.faces), (tube.vertices + [0, 0, 150], tube.faces))
    fixed, report = repair_mesh(Mesh(vertices=V, faces=F))
    assert not report.repaired and report.components == 2
    np.testing.assert_array_equal(fixed.faces, F)
    # A flat disc is seen alike from both sides: left as it is, whichever way it faces.
    disc = shapes.plane(size=50.0, n=8)
    for faces in (disc.faces, disc.faces[:, ::-1]):
        fixed, report = repair_mesh(disc.replace(faces=faces))
        assert not report.repaired
        np.testing.assert_array_equal(fixed.faces, faces)


def test_an_open_part_inside_a_closed_one_sees_no_sky_and_is_left_as_it_is():
    # Inside a box no ray escapes: the counts tie at zero and the bowl keeps the way it faces.
    bowl, box = shapes.bowl(radius=20.0, n=16), shapes.box(half=60.0, n=8)
    V, F = messy.union((box.vertices, box.faces), (bowl.vertices, bowl.faces[:, ::-1]))
    fixed, report = repair_mesh(Mesh(vertices=V, faces=F))
    assert report.outward_open_components == 0 and report.closed_components == 1
    np.testing.assert_array_equal(fixed.faces, F)


def test_a_face_on_an_edge_of_three_is_cut_off_even_when_every_vertex_keeps_one_fan():
    # A tetrahedron and a fin on one of its edges, with the fin paired with a tetrahedron face there: around
    # both ends of the edge the faces still form one fan each, yet the edge holds three (the corpus's 523.obj).
    V = np.array([[0, 3, 2], [1, 0, 2], [2, 0, 2], [0, 3, 0], [2, 3, 1]], float)
    F = np.array([[3, 2, 4], [3, 4, 0], [0, 2, 3], [4, 2, 0], [1, 3, 2]])
    V2, F2, _, _, report = repair_arrays(V, F, source="fin")
    assert Edges(F2, len(V2)).counts.max() == 2 and igl.is_vertex_manifold(F2).all()
    assert (report.nonmanifold_edges, report.nonmanifold_vertices, report.added_vertices) == (1, 2, 2)
    assert report.closed_components == 1


def test_uv_and_colours_follow_their_faces_and_vertices():
    V, F = messy.box()
    colours = (V / 32.0).astype(np.float32)
    uv = (V[F][:, :, :2] / 32.0).astype(np.float32)
    Fi = F[:, ::-1].copy()
    uvi = uv[:, ::-1].copy()
    fixed, report = repair_mesh(Mesh(vertices=V, faces=Fi, vertex_colors=colours, uv=uvi))
    assert report.outward_components == 1
    np.testing.assert_allclose(fixed.uv, fixed.vertices[fixed.faces][:, :, :2] / 32.0)
    np.testing.assert_allclose(fixed.vertex_colors, fixed.vertices / 32.0, atol=1e-6)


def test_repair_mesh_reports_in_memory_and_names_the_mesh():
    V, F = messy.box()
    mesh = Mesh(vertices=V, faces=np.vstack([F, F[:1, ::-1]]), name="boxy")
    fixed, report = repair_mesh(mesh)
    assert report.source == "boxy" and report.double_sided_faces == 1 and fixed.name == "boxy"
    assert report.message() == "boxy: dropped 1 double-sided twin faces"
    assert str(report).endswith("1 components (1 closed), 0 boundary edges in 0 loops")
    with pytest.raises(dataclasses.FrozenInstanceError):
        report.faces = 0


@pytest.mark.parametrize(
    "faces, problem",
    [
        ([[0, 1, 5]], "out of range"),
        (np.zeros((0, 3), int), "no faces"),
        ([[0, 1, 1]], "no non-degenerate face left"),
    ],
)
def test_in_memory_meshes_that_cannot_be_repaired_name_themselves(faces, problem):
    with pytest.raises(MeshError, match=rf"^blob: .*{problem}"):
        repair_arrays(np.eye(3), faces, source="blob")


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(3, 25), m=st.integers(1, 60), grid=st.booleans())
def test_any_triangle_soup_becomes_manifold_and_consistent_or_a_mesh_error(seed, n, m, grid):
    rng = np.random.default_rng(seed)
    V = rng.integers(0, 4, (n, 3)).astype(float) if grid else rng.random((n, 3))
    try:
        V2, F2, _, _, report = repair_arrays(V, rng.integers(0, n, (m, 3)), source="soup")
    except MeshError as e:
        assert str(e).startswith("soup: ")
        return
    manifold = igl.is_edge_manifold(F2)
    assert manifold[0] if isinstance(manifold, tuple) else manifold
    assert igl.is_vertex_manifold(F2).all()
    assert Edges(F2, len(V2)).consistent().all()
    assert F2.min() == 0 and F2.max() == len(V2) - 1
    # Positions come from the input: repairs never move a vertex (collapses keep the first).
    assert np.isin(V2.view([("", V2.dtype)] * 3), V.view([("", V.dtype)] * 3)).all()
    assert report.normalless_vertices == int(np.count_nonzero(~normal_defined(V2, F2)))


def test_the_report_message_is_one_line_in_a_fixed_order():
    report = MeshReport(
        source="m.obj",
        merged_vertices=3,
        sliver_faces=2,
        collapsed_vertices=1,
        duplicate_faces=4,
        nonmanifold_vertices=2,
        nonmanifold_edges=1,
        added_vertices=2,
        normalless_vertices=5,
        notes=("texture image 't.png' is missing; loaded without texture",),
    )
    assert report.message() == (
        "m.obj: texture image 't.png' is missing; loaded without texture; merged 3 duplicate vertices, dropped 2 "
        "sliver faces (1 vertices collapsed), dropped 4 duplicate faces, split 2 non-manifold vertices on 1 "
        "non-manifold edges (2 vertices added); 5 vertices have no normal (their faces cancel)"
    )
    assert "\n" not in report.message() and re.match(r"^m\.obj: ", str(report))
