"""Small mesh files for the loading tests: shapes, and OBJ / PLY / STL text or bytes written from arrays."""

import warnings

import cv2
import numpy as np
import pytest

from meshsal.mesh import MeshError
from meshsal.mesh.io import load_mesh

SQUARE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float64)
TETRA_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float64)
TETRA_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def load_clean(path):
    """Load and fail on any warning: a clean file needs no repair."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return load_mesh(path)


def load_clean_report(path):
    """Load with the repair report and fail on any warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return load_mesh(path, report=True)


def write(path, text):
    path.write_text(text)
    return path


def obj_text(V, F, colors=None):
    lines = []
    for i, v in enumerate(V):
        c = "" if colors is None else " " + " ".join(f"{x:.6f}" for x in colors[i])
        lines.append("v " + " ".join(repr(float(x)) for x in v) + c)
    lines += ["f " + " ".join(str(i + 1) for i in f) for f in F]
    return "\n".join(lines) + "\n"


def ply_ascii(V, F, colors=None):
    head = ["ply", "format ascii 1.0", f"element vertex {len(V)}"]
    head += [f"property float {c}" for c in "xyz"]
    if colors is not None:
        head += [f"property uchar {c}" for c in ("red", "green", "blue")]
    head += [f"element face {len(F)}", "property list uchar int vertex_indices", "end_header"]
    rows = []
    for i, v in enumerate(V):
        rows.append(" ".join(map(str, v)) + ("" if colors is None else " " + " ".join(map(str, colors[i]))))
    rows += [f"{len(f)} " + " ".join(map(str, f)) for f in F]
    return "\n".join(head + rows) + "\n"


def stl_binary(path, triangles):
    rec = np.zeros(len(triangles), dtype=[("n", "<f4", (3,)), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["v"] = triangles
    path.write_bytes(b"\0" * 80 + np.uint32(len(triangles)).tobytes() + rec.tobytes())
    return path


def textured_obj(tmp_path, image=True, extra_faces=""):
    # 2x4 texture: top row red, bottom row blue.
    if image:
        img = np.zeros((2, 4, 3), np.uint8)
        img[0] = (255, 0, 0)
        img[1] = (0, 0, 255)
        cv2.imwrite(str(tmp_path / "tex.png"), img[:, :, ::-1])
    write(tmp_path / "t.mtl", "newmtl paint\nKd 1 1 1\nmap_Kd -s 1 1 1 tex.png\n")
    text = (
        "mtllib t.mtl\nusemtl paint\n"
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
        "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
        "f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n" + extra_faces
    )
    return write(tmp_path / "t.obj", text)


def expect_error(path, *fragments):
    with pytest.raises(MeshError) as info:
        load_mesh(path)
    message = str(info.value)
    assert path.name in message
    for fragment in fragments:
        assert fragment in message, message
