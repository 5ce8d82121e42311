"""Mesh loading (OBJ/PLY/OFF/STL) and its repairs, the variants of valid files, and PLY output."""

import warnings

import cv2
import numpy as np
import pytest
from meshfiles import (
    SQUARE,
    TETRA_F,
    TETRA_V,
    expect_error,
    load_clean,
    load_clean_report,
    obj_text,
    ply_ascii,
    stl_binary,
    textured_obj,
    write,
)

from meshsal.mesh import Mesh, MeshError, face_areas
from meshsal.mesh.io import MeshRepairWarning, load_mesh, load_vertex_quality, save_ply

# --------------------------------------------------------------------------- good files


def test_obj_quad_is_triangulated_named_and_untransformed(tmp_path):
    m = load_clean(write(tmp_path / "square.obj", obj_text(SQUARE, [[0, 1, 2, 3]])))
    assert m.name == "square"
    assert m.faces.shape == (2, 3) and m.faces.dtype == np.int32
    np.testing.assert_array_equal(m.vertices, SQUARE)
    assert face_areas(m.vertices, m.faces).sum() == pytest.approx(1.0)
    assert m.transform.scale == 1.0 and not m.transform.offset.any()
    assert m.vertex_colors is None and m.uv is None and m.texture is None


def test_obj_vertex_colors(tmp_path):
    colors = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [0.2, 0.4, 0.6]])
    m = load_clean(write(tmp_path / "c.obj", obj_text(TETRA_V, TETRA_F, colors)))
    assert m.vertex_colors.dtype == np.float32
    np.testing.assert_allclose(m.vertex_colors, colors, atol=1 / 255)


def test_obj_negative_indices_and_slashes(tmp_path):
    # Two triangles at a right angle, facing out of the angle between them.
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf -3//1 -1//1 -2//1\nv 0 0 1\nf 1 2 -1\n"
    m = load_clean(write(tmp_path / "neg.obj", text))
    np.testing.assert_array_equal(m.faces, [[0, 2, 1], [0, 1, 3]])


def test_obj_texture_and_uv(tmp_path):
    m = load_clean(textured_obj(tmp_path))
    assert m.texture.shape == (2, 4, 3) and m.texture.dtype == np.uint8
    np.testing.assert_array_equal(m.texture[0, 0], [255, 0, 0])  # row 0 is the image's top, RGB order
    np.testing.assert_array_equal(m.texture[1, 0], [0, 0, 255])
    assert m.uv.shape == (2, 3, 2) and m.uv.dtype == np.float32
    # Each corner's uv equals its vertex's xy in this file.
    np.testing.assert_allclose(m.uv, m.vertices[m.faces][:, :, :2])


def test_missing_texture_image_loads_geometry_with_warning(tmp_path):
    path = textured_obj(tmp_path, image=False)
    with pytest.warns(MeshRepairWarning, match=r"t\.obj.*tex\.png.*missing"):
        m = load_mesh(path)
    assert m.n_faces == 2 and m.texture is None and m.uv is None


def test_missing_material_library_warns(tmp_path):
    text = "mtllib gone.mtl\nusemtl paint\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
    with pytest.warns(MeshRepairWarning, match=r"m\.obj: material library 'gone\.mtl' not found"):
        m = load_mesh(write(tmp_path / "m.obj", text))
    assert m.n_faces == 1 and m.texture is None


def test_two_texture_images_warn_and_load_untextured(tmp_path):
    for name in ("a.png", "b.png"):
        cv2.imwrite(str(tmp_path / name), np.zeros((2, 2, 3), np.uint8))
    write(tmp_path / "two.mtl", "newmtl a\nmap_Kd a.png\nnewmtl b\nmap_Kd b.png\n")
    text = (
        "mtllib two.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\nusemtl a\nf 1/1 2/1 3/1\nusemtl b\nf 2/1 4/1 3/1\n"
    )
    with pytest.warns(MeshRepairWarning, match="2 texture images"):
        m = load_mesh(write(tmp_path / "two.obj", text))
    assert m.n_faces == 2 and m.texture is None and m.uv is None


def test_uv_follows_dropped_faces(tmp_path):
    path = textured_obj(tmp_path, extra_faces="v 2 0 0\nvt 0.5 0.5\nf 1/5 2/5 5/5\n")  # collinear face
    with pytest.warns(MeshRepairWarning, match="dropped 1 zero-area faces"):
        m = load_mesh(path)
    assert m.uv.shape == (2, 3, 2) and m.n_vertices == 4  # vertex 5 only served the dropped face
    np.testing.assert_allclose(m.uv, m.vertices[m.faces][:, :, :2])


def test_ply_ascii_with_colors(tmp_path):
    colors = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [10, 20, 30]])
    m = load_clean(write(tmp_path / "a.ply", ply_ascii(TETRA_V, TETRA_F, colors)))
    np.testing.assert_array_equal(m.faces, TETRA_F)
    np.testing.assert_allclose(m.vertex_colors * 255, colors, atol=1e-3)


def test_ply_binary_big_endian_mixed_polygons(tmp_path):
    # A pyramid: square base (one quad) plus 4 triangles; lists of unequal length.
    V = np.vstack([SQUARE, [[0.5, 0.5, 1.0]]]).astype(">f4")
    faces = [[0, 3, 2, 1], [0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]
    header = (
        "ply\nformat binary_big_endian 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
        "property float z\nelement face 5\nproperty list uchar int vertex_indices\nend_header\n"
    )
    body = V.tobytes() + b"".join(bytes([len(f)]) + np.array(f, ">i4").tobytes() for f in faces)
    (tmp_path / "pyr.ply").write_bytes(header.encode() + body)
    m = load_clean(tmp_path / "pyr.ply")
    assert m.n_faces == 6
    assert face_areas(m.vertices, m.faces).sum() == pytest.approx(1 + 4 * 0.5 * np.sqrt(1.25))


@pytest.mark.parametrize("order", [">", "<"])
@pytest.mark.parametrize("kind", ["float", "double"])
def test_ply_binary_coordinates_read_the_same_in_either_byte_order(tmp_path, order, kind):
    # Coordinates that float32 does not hold exactly: a double must come back to the bit.
    V = np.array([[0.1, 0.0, 0.0], [1.0, 0.3, 0.0], [0.0, 1.0, 0.7], [0.0, 0.0, 1.0]]) * [7.0, 9.0, 11.0]
    code = {"float": "f4", "double": "f8"}[kind]
    endian = {">": "big", "<": "little"}[order]
    header = (
        f"ply\nformat binary_{endian}_endian 1.0\nelement vertex 4\nproperty {kind} x\nproperty {kind} y\n"
        f"property {kind} z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n"
    )
    body = V.astype(order + code).tobytes() + b"".join(
        bytes([3]) + np.array(f, order + "i4").tobytes() for f in TETRA_F
    )
    (tmp_path / "tet.ply").write_bytes(header.encode() + body)
    m = load_clean(tmp_path / "tet.ply")
    np.testing.assert_array_equal(m.faces, TETRA_F)
    np.testing.assert_array_equal(m.vertices, V.astype(code).astype(np.float64))


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".off"])
def test_a_byte_order_mark_before_a_text_mesh_changes_nothing(tmp_path, suffix):
    colors = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [10, 20, 30]])
    off = "COFF\n4 4 0\n" + "".join(
        f"{' '.join(map(str, v))} {' '.join(map(str, c))} 255\n" for v, c in zip(TETRA_V, colors)
    )
    off += "".join(f"3 {' '.join(map(str, f))}\n" for f in TETRA_F)
    text = {".obj": obj_text(TETRA_V, TETRA_F, colors / 255), ".ply": ply_ascii(TETRA_V, TETRA_F, colors), ".off": off}
    plain = load_clean(write(tmp_path / f"plain{suffix}", text[suffix]))
    (tmp_path / f"marked{suffix}").write_bytes(b"\xef\xbb\xbf" + text[suffix].encode())
    marked = load_clean(tmp_path / f"marked{suffix}")  # an editor's UTF-8 mark: pymeshlab lost the first vertex
    for field in ("vertices", "faces", "vertex_colors"):
        np.testing.assert_array_equal(getattr(marked, field), getattr(plain, field))
    np.testing.assert_array_equal(plain.vertices, TETRA_V)


def test_off_and_coff(tmp_path):
    m = load_clean(write(tmp_path / "sq.off", "OFF\n# a comment\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n"))
    assert m.n_faces == 2 and m.vertex_colors is None
    text = "COFF 3 1 0\n0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n0 1 0 0 0 255 255\n3 0 1 2\n"
    c = load_clean(write(tmp_path / "tri.off", text))
    np.testing.assert_allclose(c.vertex_colors, np.eye(3), atol=1e-6)


def test_stl_binary_duplicates_merged_with_warning(tmp_path):
    tris = TETRA_V[TETRA_F]
    with pytest.warns(MeshRepairWarning, match=r"tet\.stl: merged 8 duplicate vertices"):
        m = load_mesh(stl_binary(tmp_path / "tet.stl", tris))
    assert m.n_vertices == 4 and m.n_faces == 4
    np.testing.assert_allclose(m.vertices[m.faces], tris)


def test_stl_ascii(tmp_path):
    facets = "".join(
        "facet normal 0 0 0\nouter loop\n" + "".join(f"vertex {x} {y} {z}\n" for x, y, z in t) + "endloop\nendfacet\n"
        for t in TETRA_V[TETRA_F]
    )
    with pytest.warns(MeshRepairWarning, match="merged 8 duplicate vertices"):
        m = load_mesh(write(tmp_path / "tet.stl", f"solid tet\n{facets}endsolid tet\n"))
    assert m.n_vertices == 4 and m.n_faces == 4


def test_unreferenced_vertices_removed_colors_kept(tmp_path):
    V = np.vstack([TETRA_V[:3], [[5, 5, 5]], TETRA_V[3:]])
    colors = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1], [0, 0, 0]])
    F = np.where(TETRA_F == 3, 4, TETRA_F)
    with pytest.warns(MeshRepairWarning, match="removed 1 unreferenced vertices"):
        m = load_mesh(write(tmp_path / "u.obj", obj_text(V, F, colors)))
    np.testing.assert_array_equal(m.vertices, TETRA_V)
    np.testing.assert_allclose(m.vertex_colors, colors[[0, 1, 2, 4]], atol=1 / 255)


def test_duplicates_with_different_colors_are_kept_apart(tmp_path):
    V = np.vstack([TETRA_V, TETRA_V[:1]])
    colors = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1], [0, 0, 0]])
    F = np.where(np.arange(4)[:, None] == 2, np.where(TETRA_F == 0, 4, TETRA_F), TETRA_F)  # a colour seam at vertex 0
    m, report = load_clean_report(write(tmp_path / "twin.obj", obj_text(V, F, colors)))
    assert m.n_vertices == 5
    assert report.boundary_loops == 1 and report.closed_components == 0  # the seam opens the surface


def test_a_face_repeating_a_vertex_is_left_out(tmp_path):
    # It has no area: pymeshlab leaves it out as it reads the file, and the rest needs no repair.
    F = np.vstack([TETRA_F, [[0, 0, 1]]])
    m = load_clean(write(tmp_path / "r.ply", ply_ascii(TETRA_V, F)))
    np.testing.assert_array_equal(m.faces, TETRA_F)


@pytest.mark.parametrize(
    "name, content",
    [
        ("tq.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 3\nf 1 1 3 4\n"),
        ("tq.off", "OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 2\n4 0 0 2 3\n"),
    ],
)
def test_triangles_written_as_quads_with_a_repeated_corner(tmp_path, name, content):
    m = load_clean(write(tmp_path / name, content))
    np.testing.assert_array_equal(m.faces, [[0, 1, 2], [0, 2, 3]])


# --------------------------------------------------------------------------- variants of valid files


@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
def test_meshlab_ply_with_per_face_texture_coordinates(tmp_path, binary):
    # MeshLab writes wedge texture coordinates as a list of floats on each face, after its vertex indices.
    header = (
        f"ply\nformat {'binary_little_endian' if binary else 'ascii'} 1.0\ncomment TextureFile tex.png\n"
        "element vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 4\n"
        "property list uchar int vertex_indices\nproperty list uchar float texcoord\nend_header\n"
    )
    uv = [0, 0, 1, 0, 0, 1]
    if binary:
        faces = np.zeros(4, dtype=[("n", "u1"), ("i", "<i4", (3,)), ("m", "u1"), ("uv", "<f4", (6,))])
        faces["n"], faces["i"], faces["m"], faces["uv"] = 3, TETRA_F, 6, uv
        body = TETRA_V.astype("<f4").tobytes() + faces.tobytes()
    else:
        rows = [" ".join(map(str, v)) for v in TETRA_V]
        rows += [f"3 {a} {b} {c} 6 " + " ".join(map(str, uv)) for a, b, c in TETRA_F]
        body = ("\n".join(rows) + "\n").encode()
    (tmp_path / "meshlab.ply").write_bytes(header.encode() + body)
    m = load_clean(tmp_path / "meshlab.ply")
    np.testing.assert_array_equal(m.faces, TETRA_F)
    np.testing.assert_array_equal(m.vertices, TETRA_V)
    # A damaged index among them is still caught before pymeshlab reads it.
    if binary:
        faces["i"][2, 1] = 400_000_000
        (tmp_path / "bad.ply").write_bytes(header.encode() + TETRA_V.astype("<f4").tobytes() + faces.tobytes())
        expect_error(tmp_path / "bad.ply", "face 2 has a vertex index out of range")


def test_ascii_stl_with_several_solids(tmp_path):
    def solid(name, triangles):
        facets = "".join(
            "facet normal 0 0 0\n outer loop\n"
            + "".join(f"  vertex {x} {y} {z}\n" for x, y, z in t)
            + " endloop\nendfacet\n"
            for t in triangles
        )
        return f"solid {name}\n{facets}endsolid {name}\n"

    second = TETRA_V[TETRA_F] + [5.0, 0.0, 0.0]
    path = write(tmp_path / "two.stl", solid("a", TETRA_V[TETRA_F]) + solid("b", second))
    with pytest.warns(MeshRepairWarning, match="merged 16 duplicate vertices"):
        m, report = load_mesh(path, report=True)
    assert (m.n_vertices, m.n_faces, report.components, report.closed_components) == (8, 8, 2, 2)


def test_obj_polygons_are_triangulated_by_pymeshlab(tmp_path):
    # A concave L-shaped hexagon from a corner beside its notch: a fan from there would cover the notch too
    # (area 4), ear cutting covers the L (with one flat triangle, which the repair drops).
    L = [[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0]]
    text = "".join(f"v {x} {y} {z}\n" for x, y, z in L) + "f 3 4 5 6 1 2\n"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MeshRepairWarning)
        m = load_mesh(write(tmp_path / "L.obj", text))
    areas = face_areas(m.vertices, m.faces)
    assert (areas > 0).all() and areas.sum() == pytest.approx(3.0)
    # A non-planar pentagon: pymeshlab's triangulation is the reading, whatever a fan would count.
    text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 0.5 1\nf 1 2 3 4 5\n"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MeshRepairWarning)
        m = load_mesh(write(tmp_path / "penta.obj", text))
    assert m.n_faces >= 1 and (face_areas(m.vertices, m.faces) > 0).all()


def test_off_with_comments_between_and_after_its_lines(tmp_path):
    # As trimesh's models/comments.off has it: pymeshlab refuses the comment after the second vertex.
    text = (
        "OFF\n#\n#  cube.off\n#  A cube.\n#\n\n8 6 12\n"
        "  1.632993   0.000000   1.154701\n"
        "  0.000000   1.632993   1.154701 # see this vertex be weird\n"
        " -1.632993   0.000000   1.154701\n  0.000000  -1.632993   1.154701\n"
        "  1.632993   0.000000  -1.154701\n  0.000000   1.632993  -1.154701\n"
        " -1.632993   0.000000  -1.154701\n  0.000000  -1.632993  -1.154701\n"
        "# the faces, with an RGBA colour each\n"
        "  4  0 1 2 3  1.000 0.000 0.000 0.75\n  4  7 4 0 3  0.300 0.400 0.000 0.75\n"
        "  4  4 5 1 0  0.200 0.500 0.100 0.75\n  4  5 6 2 1  0.100 0.600 0.200 0.75\n"
        "  4  3 2 6 7  0.000 0.700 0.300 0.75\n  4  6 5 4 7  0.000 1.000 0.000 0.75\n"
    )
    m, report = load_clean_report(write(tmp_path / "comments.off", text))
    assert (m.n_vertices, m.n_faces, report.closed_components) == (8, 12, 1)
    assert m.vertices[1].tolist() == [0.0, 1.632993, 1.154701]


def test_obj_texture_coordinates_after_the_faces(tmp_path):
    text = (
        "mtllib t.mtl\nusemtl paint\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n"
        "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
    )
    textured_obj(tmp_path)  # the texture and its material library
    m = load_clean(write(tmp_path / "late.obj", text))
    assert m.texture.shape == (2, 4, 3)
    np.testing.assert_allclose(m.uv, m.vertices[m.faces][:, :, :2])


def test_pymeshlab_reads_what_it_knows_and_skips_the_rest(tmp_path):
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nhello world\nvn 0 0 1\nf 1//1 2//1 3//1\n"
    m = load_clean(write(tmp_path / "extra.obj", text))
    assert m.n_faces == 1


# --------------------------------------------------------------------------- PLY output


def test_save_ply_round_trip_with_colors_and_quality(tmp_path):
    rng = np.random.default_rng(1)
    colors = rng.integers(0, 256, (4, 3)) / 255.0
    mesh = Mesh(vertices=TETRA_V * 3.5 - 1, faces=TETRA_F, vertex_colors=colors)
    quality = np.array([0.25, -1.5, 3.0, 1e3])
    path = tmp_path / "out.ply"
    save_ply(path, mesh, quality=quality)
    assert path.read_bytes().startswith(b"ply\nformat binary_little_endian 1.0\n")
    back = load_clean(path)
    np.testing.assert_allclose(back.vertices, mesh.vertices, atol=1e-6)
    np.testing.assert_array_equal(back.faces, mesh.faces)
    np.testing.assert_allclose(back.vertex_colors, colors, atol=1e-6)
    np.testing.assert_array_equal(load_vertex_quality(path), quality)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.ply"]  # no temporary left behind


def test_saved_quality_is_meshlab_vertex_quality(tmp_path):
    import pymeshlab

    path = tmp_path / "q.ply"
    save_ply(path, Mesh(vertices=TETRA_V, faces=TETRA_F), quality=[1.0, 2.0, 3.0, 4.0])
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(path))
    np.testing.assert_array_equal(ms.current_mesh().vertex_scalar_array(), [1, 2, 3, 4])


def test_save_ply_without_colors_round_trips(tmp_path):
    path = tmp_path / "plain.ply"
    save_ply(path, Mesh(vertices=TETRA_V, faces=TETRA_F))
    back = load_clean(path)
    assert back.vertex_colors is None
    np.testing.assert_array_equal(back.faces, TETRA_F)


def test_save_ply_rejects_wrong_quality_shape_and_writes_nothing(tmp_path):
    with pytest.raises(ValueError, match=r"q\.ply.*shape \(4,\)"):
        save_ply(tmp_path / "q.ply", Mesh(vertices=TETRA_V, faces=TETRA_F), quality=[1.0, 2.0])
    assert list(tmp_path.iterdir()) == []


def test_load_vertex_quality_needs_a_ply(tmp_path):
    with pytest.raises(MeshError, match=r"q\.obj.*only stored in PLY"):
        load_vertex_quality(write(tmp_path / "q.obj", "v 0 0 0\n"))


def test_load_vertex_quality_without_quality(tmp_path):
    path = tmp_path / "noq.ply"
    save_ply(path, Mesh(vertices=TETRA_V, faces=TETRA_F))
    with pytest.raises(MeshError, match=r"noq\.ply.*quality"):
        load_vertex_quality(path)


# --------------------------------------------------------------------------- shared meshes


def test_spot_cow_has_uv_and_texture(shared_mesh):
    m = load_clean(shared_mesh("spot/spot.obj"))
    assert m.name == "spot"
    assert m.texture.shape == (1024, 1024, 3)
    assert m.uv.shape == (m.n_faces, 3, 2)
    # The first face's corners carry the file's own vt values.
    lines = shared_mesh("spot/spot.obj").read_text().splitlines()
    vt = [[float(x) for x in ln.split()[1:3]] for ln in lines if ln.startswith("vt ")]
    first = next(ln for ln in lines if ln.startswith("f ")).split()[1:4]
    np.testing.assert_allclose(m.uv[0], [vt[int(c.split("/")[1]) - 1] for c in first], atol=1e-6)
    assert m.texture.std() > 20  # painted, not a flat color


@pytest.mark.parametrize(
    "name",
    ["cow.obj", "teapot.obj", "stanford-bunny.obj", "fandisk.obj", "rocker-arm.obj",
     "suzanne.obj", "beetle.obj", "nefertiti.obj"],
)  # fmt: skip
def test_shared_meshes_load(shared_mesh, name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MeshRepairWarning)
        m = load_mesh(shared_mesh(name))
    assert m.n_faces > 500
    assert np.isfinite(m.vertices).all()
    assert m.faces.min() == 0 and m.faces.max() == m.n_vertices - 1  # every vertex referenced
    assert (face_areas(m.vertices, m.faces) > 0).all()
