"""Mesh files that must be refused with the file's name: bad input, garbage that never crashes, caps on sizes."""

import subprocess
import sys
import warnings

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from meshfiles import SQUARE, TETRA_F, TETRA_V, expect_error, obj_text, ply_ascii, stl_binary, textured_obj, write

from meshsal.mesh import Mesh, MeshError
from meshsal.mesh.io import MAX_MESH_BYTES, MeshRepairWarning, load_mesh, save_ply
from meshsal.mesh.texture import image_size, read_texture

# --------------------------------------------------------------------------- bad input


def test_missing_file(tmp_path):
    expect_error(tmp_path / "nothing.obj", "no such file")


def test_directory(tmp_path):
    (tmp_path / "folder.obj").mkdir()
    expect_error(tmp_path / "folder.obj", "directory")


def test_unknown_extension(tmp_path):
    expect_error(write(tmp_path / "m.xyz", "1 2 3\n"), "unknown extension '.xyz'")


@pytest.mark.parametrize("content", ["", "  \n\n"])
def test_empty_file(tmp_path, content):
    expect_error(write(tmp_path / "e.ply", content), "empty file")


@pytest.mark.parametrize(
    "name, content",
    [
        ("bad.obj", "v 0 0 zero\n"),
        ("bad.ply", "plyx\nformat ascii 1.0\nend_header\n"),
        ("bad.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n2\n3\n"),
        ("bad.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"),
        ("bad.off", "FOO\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"),
        ("bad.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n"),
        ("bad.stl", "not an stl at all, long enough to hold a binary header. " * 3),
    ],
)
def test_unparseable_content(tmp_path, name, content):
    expect_error(write(tmp_path / name, content), "unparseable content")


def test_binary_garbage_in_text_format(tmp_path):
    path = tmp_path / "bin.obj"
    path.write_bytes(b"v 0 0 0\n\0\1\2\3")
    expect_error(path, "unparseable content", "binary")


@pytest.mark.parametrize(
    "name, content, problem",
    [
        ("i.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "out of range"),
        ("i.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "out of range"),
        ("i.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n", "out of range"),
        ("i.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 100000000\n", "out of range"),  # pymeshlab: SIGSEGV
        ("i.obj", "f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n", "out of range"),  # before its vertices
        ("i.ply", ply_ascii(TETRA_V[:3], [[0, 1, 3]]), "out of range"),
        ("i.ply", ply_ascii(SQUARE, [[0, 1, 2, 400000000]]), "out of range"),  # pymeshlab: SIGSEGV
        ("i.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n", "out of range"),
        ("i.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 -5\n", "out of range"),  # pymeshlab: SIGSEGV
    ],
)
def test_face_index_out_of_range(tmp_path, name, content, problem):
    expect_error(write(tmp_path / name, content), problem)


def test_texture_index_out_of_range(tmp_path):
    expect_error(write(tmp_path / "vt.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/1\n"), "out of range")


@pytest.mark.parametrize(
    "name, content",
    [
        ("n.obj", "v 0 0 0\nv 1 nan 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\n"),
        ("n.ply", ply_ascii(TETRA_V, TETRA_F).replace("\n1.0 0.0 0.0\n", "\n1.0 inf 0.0\n")),
        ("n.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 NaN 0\n3 0 1 2\n"),
        # Beyond single precision, the type the file declares.
        ("big.ply", ply_ascii(TETRA_V, TETRA_F).replace("\n1.0 0.0 0.0\n", "\n1e48 0.0 0.0\n")),
        ("big.stl", "solid s\nfacet normal 0 0 0\nouter loop\nvertex 0 0 0\nvertex 1e48 0 0\nvertex 0 1 0\n"
         "endloop\nendfacet\nendsolid s\n"),
    ],
)  # fmt: skip
def test_non_finite_coordinates(tmp_path, name, content):
    expect_error(write(tmp_path / name, content), "non-finite")


def test_non_finite_binary_stl(tmp_path):
    tris = TETRA_V[TETRA_F].copy()
    tris[2, 1, 0] = np.inf
    expect_error(stl_binary(tmp_path / "inf.stl", tris), "non-finite")


@pytest.mark.parametrize(
    "name, content",
    [
        ("cloud.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n"),
        ("cloud.ply", "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
         "property float z\nend_header\n0 0 0\n1 1 1\n"),
        ("cloud.off", "OFF\n2 0 0\n0 0 0\n1 1 1\n"),
    ],
)  # fmt: skip
def test_point_cloud(tmp_path, name, content):
    expect_error(write(tmp_path / name, content), "no faces", "point cloud")


@pytest.mark.parametrize(
    "name, content",
    [
        ("flat.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 3 0 0\nf 1 2 3\nf 2 3 4\n"),
        ("flat.ply", ply_ascii(TETRA_V, [[0, 0, 1], [2, 2, 2]])),
        ("flat.stl", "solid s\nfacet normal 0 0 0\nouter loop\nvertex 0 0 0\nvertex 1 1 1\nvertex 2 2 2\n"
         "endloop\nendfacet\nendsolid s\n"),
    ],
)  # fmt: skip
def test_no_non_degenerate_face_left(tmp_path, name, content):
    expect_error(write(tmp_path / name, content), "no non-degenerate face left")


def test_truncated_binary_ply(tmp_path):
    good = tmp_path / "good.ply"
    save_ply(good, Mesh(vertices=TETRA_V, faces=TETRA_F))
    data = good.read_bytes()
    for cut in (len(data) - 1, len(data) - 13, data.index(b"end_header") + 20):
        (tmp_path / "cut.ply").write_bytes(data[:cut])
        expect_error(tmp_path / "cut.ply", "unparseable content", "truncated")


def test_truncated_binary_stl(tmp_path):
    data = stl_binary(tmp_path / "good.stl", TETRA_V[TETRA_F]).read_bytes()
    (tmp_path / "cut.stl").write_bytes(data[:-7])
    expect_error(tmp_path / "cut.stl", "unparseable content", "truncated")


@pytest.mark.parametrize(
    "header",
    [
        "ply\nformat ascii 1.0\nelement vertex 1000000000000\nproperty float x\nproperty float y\nproperty float z\n",
        "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1000000000000\nproperty list uchar int vertex_indices\n",
    ],
)
def test_a_ply_header_declaring_more_than_the_file_holds_is_refused_before_pymeshlab_allocates(tmp_path, header):
    # pymeshlab allocates what the header declares: std::bad_alloc or std::length_error for 10^12.
    path = tmp_path / "huge.ply"
    path.write_bytes(header.encode() + b"end_header\n" + b"0 0 0\n" * 3)
    expect_error(path, "the PLY header declares", "1,000,000,000,000", "more than the")


def test_an_off_header_declaring_more_than_the_file_holds_is_refused(tmp_path):
    expect_error(write(tmp_path / "huge.off", "OFF\n1000000000000 1 0\n0 0 0\n"), "declares 1000000000000 vertices")


def test_a_binary_stl_declaring_more_facets_than_it_holds_is_refused(tmp_path):
    # pymeshlab reads the 10^9 facets its bytes 80-84 declare from 134 bytes for minutes.
    path = tmp_path / "huge.stl"
    path.write_bytes(b"\0" * 80 + np.uint32(10**9).tobytes() + bytes(50))
    expect_error(path, "binary STL of 1000000000 facets has 50000000084")


# --------------------------------------------------------------------------- garbage never crashes

EXTENSIONS = (".obj", ".ply", ".off", ".stl")
PREFIXES = (
    b"",
    b"ply\nformat binary_little_endian 1.0\nelement vertex 3\n",
    b"OFF\n3 1 0\n",
    b"solid x\n",
    b"v 1 2 3\nf ",
)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(ext=st.sampled_from(EXTENSIONS), prefix=st.sampled_from(PREFIXES), body=st.binary(max_size=300))
def test_random_bytes_raise_mesh_error(tmp_path, ext, prefix, body):
    path = tmp_path / f"garbage{ext}"
    path.write_bytes(prefix + body)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            load_mesh(path)
        except MeshError as e:
            assert path.name in str(e)


GARBAGE_SCRIPT = """
import sys, warnings
import numpy as np
from meshsal.mesh.io import load_mesh, save_ply
from meshsal.mesh import Mesh, MeshError
warnings.simplefilter("ignore")
root = sys.argv[1]
rng = np.random.default_rng(0)
V = rng.random((30, 3)); F = rng.integers(0, 30, (40, 3))
save_ply(root + "/seed.ply", Mesh(vertices=V, faces=F))
seeds = {".ply": open(root + "/seed.ply", "rb").read(),
         ".stl": b"\\0" * 80 + np.uint32(4).tobytes() + rng.bytes(200),
         ".obj": "".join(f"v {a} {b} {c}\\n" for a, b, c in V).encode() + b"f 1 2 3\\nf 4 5 6\\n",
         ".off": b"OFF\\n30 40 0\\n" + b"".join(b"%f %f %f\\n" % tuple(v) for v in V)}
count = 0
for ext, seed in seeds.items():
    for trial in range(25):
        data = bytearray(seed[: rng.integers(0, len(seed) + 1)])
        for _ in range(rng.integers(0, 4)):
            if data:
                data[rng.integers(0, len(data))] = rng.integers(0, 256)
        if trial % 5 == 0:
            data = rng.bytes(rng.integers(1, 400))
        path = f"{root}/g{trial}{ext}"
        open(path, "wb").write(bytes(data))
        try:
            load_mesh(path)
        except MeshError:
            pass
        count += 1
print(count)
"""


def test_truncated_and_corrupted_files_do_not_crash_the_interpreter(tmp_path):
    # A child process, so a segfault shows as a failed test rather than killing pytest.
    result = subprocess.run(
        [sys.executable, "-c", GARBAGE_SCRIPT, str(tmp_path)], capture_output=True, text=True, timeout=300
    )
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.split()[-1] == "100"


# --------------------------------------------------------------------------- caps on file and texture sizes


def test_a_mesh_file_over_the_cap_is_refused_before_it_is_read(tmp_path, monkeypatch):
    path = write(tmp_path / "big.obj", obj_text(TETRA_V, TETRA_F))
    size = path.stat().st_size
    monkeypatch.setattr(type(path), "read_bytes", lambda self: pytest.fail(f"{self} was read"))
    with pytest.raises(MeshError, match=rf"big\.obj: {size:,} bytes, over the cap of 40 bytes"):
        load_mesh(path, max_bytes=40)


def test_the_mesh_cap_can_be_raised_or_lifted(tmp_path):
    path = write(tmp_path / "t.obj", obj_text(TETRA_V, TETRA_F))
    assert MAX_MESH_BYTES == 256 * 2**20
    assert load_mesh(path, max_bytes=path.stat().st_size).n_faces == 4
    assert load_mesh(path, max_bytes=None).n_faces == 4


def png_header(width, height):
    """The first bytes of a PNG that declares its size (the rest does not matter: it is never decoded)."""
    ihdr = np.array([width, height], ">u4").tobytes() + bytes([8, 2, 0, 0, 0])
    return b"\x89PNG\r\n\x1a\n" + np.uint32(13).astype(">u4").tobytes() + b"IHDR" + ihdr + b"\0" * 4 + b"garbage"


def test_a_texture_over_the_pixel_cap_is_dropped_before_it_is_decoded(tmp_path, monkeypatch):
    path = textured_obj(tmp_path, image=False)
    (tmp_path / "tex.png").write_bytes(png_header(100_000, 50_000))
    monkeypatch.setattr(cv2, "imread", lambda *a, **k: pytest.fail("the texture was decoded"))
    with pytest.warns(
        MeshRepairWarning,
        match=r"t\.obj: texture image 'tex\.png' has 100000 x 50000 = "
        r"5,000,000,000 pixels, over the cap of 67,108,864",
    ):
        m = load_mesh(path)
    assert m.texture is None and m.uv is None and m.n_faces == 2


def png_bomb(path, width, height):
    """A grey PNG of ``width x height`` zero pixels in a few hundred kB, compressed row by row."""
    import struct
    import zlib

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    z = zlib.compressobj(9)
    row = bytes(width + 1)
    idat = b"".join(z.compress(row) for _ in range(height)) + z.flush()
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", idat) + chunk(b"IEND", b""))


BOMB_SCRIPT = """
import resource, sys, warnings
from meshsal.mesh.io import load_mesh
warnings.simplefilter("ignore")
load_mesh(sys.argv[1] + "/small.obj")
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
mesh = load_mesh(sys.argv[1] + "/t.obj")
print(mesh.texture is None, (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) // 1024)
"""


def test_no_reader_decodes_a_texture_over_the_cap(tmp_path):
    # pymeshlab decodes the images a material library names, whatever their size (this one: 144 MB as grey
    # bytes, 200 MB more at its peak): it reads the OBJ without its library, and only our capped reader reads it.
    textured_obj(tmp_path, image=False)
    write(tmp_path / "t.mtl", "newmtl paint\nmap_Kd tex.png\n")  # without options, which pymeshlab skips
    png_bomb(tmp_path / "tex.png", 12000, 12000)
    write(tmp_path / "small.obj", obj_text(TETRA_V, TETRA_F))
    result = subprocess.run(
        [sys.executable, "-c", BOMB_SCRIPT, str(tmp_path)], capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr[-2000:]
    dropped, grown_mb = result.stdout.split()
    assert dropped == "True" and int(grown_mb) < 32, result.stdout


@pytest.mark.parametrize("suffix", [".png", ".jpg", ".bmp", ".tiff"])
def test_texture_sizes_from_headers_or_after_decoding(tmp_path, suffix):
    image = np.random.default_rng(0).integers(0, 255, (30, 50, 3), dtype=np.uint8)
    cv2.imwrite(str(tmp_path / f"im{suffix}"), image)
    assert image_size(tmp_path / f"im{suffix}") == (None if suffix == ".tiff" else (50, 30))
    assert read_texture(tmp_path / f"im{suffix}", max_pixels=1500)[0].shape == (30, 50, 3)
    texture, note = read_texture(tmp_path / f"im{suffix}", max_pixels=1499)
    assert texture is None and note == (
        f"texture image 'im{suffix}' has 50 x 30 = 1,500 pixels, over the cap of 1,499; loaded without texture"
    )


def test_load_mesh_passes_its_texture_cap_on(tmp_path):
    path = textured_obj(tmp_path)  # a 4 x 2 texture
    assert load_mesh(path, max_texture_pixels=8).texture.shape == (2, 4, 3)
    with pytest.warns(MeshRepairWarning, match="8 pixels, over the cap of 7"):
        assert load_mesh(path, max_texture_pixels=7).texture is None


def test_a_material_library_over_its_cap_is_not_read(tmp_path, monkeypatch):
    from meshsal.mesh import texture

    path = textured_obj(tmp_path)
    monkeypatch.setattr(texture, "MAX_MATERIAL_BYTES", 10)
    with pytest.warns(MeshRepairWarning, match=r"t\.obj: material library 't\.mtl' has \d+ bytes, over the cap of 10"):
        assert load_mesh(path).texture is None
