"""Imprint sets on disk (round trip, damaged and foreign files) and the ``imprints`` command."""

import dataclasses
import json
import re

import numpy as np
import pytest
import shapes

from tactile import ImprintSet, Perturbation, Sensor


def small_set(perturbation=None, seed=None) -> ImprintSet:
    rng = np.random.default_rng(0)
    sensor = Sensor(rows=8, cols=12, mode="pressure", pitch_mm=1.5)
    return ImprintSet(
        imprints=rng.random((5, 8, 12)),
        labels=[0, 0, 1, 2, 2],
        object_names=("cup", "hand", "cow"),
        point_ids=[1, 2, 1, 1, 2],
        positions=rng.normal(size=(5, 3)),
        normals=rng.normal(size=(5, 3)),
        sensor=sensor,
        perturbation=perturbation,
        seed=seed,
        source="test",
    )


@pytest.mark.parametrize("perturbation,seed", [(None, None), (Perturbation.typical(), 42)])
def test_save_load_round_trip(tmp_path, perturbation, seed):
    original = small_set(perturbation, seed)
    path = tmp_path / "set.npz"
    original.save(path)
    loaded = ImprintSet.load(path)
    for name in ("imprints", "labels", "point_ids", "positions", "normals"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(original, name))
        assert getattr(loaded, name).dtype == getattr(original, name).dtype
    assert loaded.object_names == original.object_names
    assert loaded.sensor == original.sensor and loaded.perturbation == perturbation
    assert loaded.seed == seed and loaded.source == "test"
    assert [p.name for p in tmp_path.iterdir()] == ["set.npz"]  # no temporary left behind


def test_truncated_file_error_names_the_file(tmp_path):
    path = tmp_path / "set.npz"
    small_set().save(path)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="set.npz.*(damaged|truncated)"):
        ImprintSet.load(path)


def test_foreign_files_are_refused(tmp_path):
    foreign = tmp_path / "other.npz"
    np.savez(foreign, weights=np.zeros(3))
    with pytest.raises(ValueError, match="other.npz: not an imprint set"):
        ImprintSet.load(foreign)
    wrong_format = tmp_path / "fmt.npz"
    np.savez(wrong_format, meta=np.array(json.dumps({"format": "something.else", "version": 1})))
    with pytest.raises(ValueError, match="fmt.npz: not an imprint set"):
        ImprintSet.load(wrong_format)
    text = tmp_path / "notes.npz"
    text.write_text("hello")
    with pytest.raises(ValueError, match="notes.npz"):
        ImprintSet.load(text)
    with pytest.raises(OSError, match="missing.npz"):
        ImprintSet.load(tmp_path / "missing.npz")
    bare = tmp_path / "array.npy"
    np.save(bare, np.zeros(3))
    with pytest.raises(ValueError, match="array.npy: not an imprint set"):
        ImprintSet.load(bare)


def test_other_version_is_refused(tmp_path):
    path = tmp_path / "v9.npz"
    s = small_set()
    meta = {"format": "visuotactile.ImprintSet", "version": 9}
    np.savez(path, meta=np.array(json.dumps(meta)), imprints=s.imprints)
    with pytest.raises(ValueError, match="v9.npz: imprint set version 9"):
        ImprintSet.load(path)


def test_inconsistent_fields_are_refused():
    s = small_set()
    with pytest.raises(ValueError, match="labels"):
        dataclasses.replace(s, labels=[0, 0, 1, 2, 3])
    with pytest.raises(ValueError, match="sensor"):
        dataclasses.replace(s, sensor=Sensor())
    with pytest.raises(ValueError, match="positions"):
        dataclasses.replace(s, positions=s.positions[:3])


def test_subset_keeps_names_and_fields():
    s = small_set(Perturbation(noise=0.1), 3)
    sub = s.subset(s.labels == 2)
    assert len(sub) == 2 and sub.object_names == s.object_names and sub.seed == 3
    np.testing.assert_array_equal(sub.point_ids, [1, 2])


def write_points(path, mesh_scale, positions, normals):
    records = [
        {"id": i + 1, "position": (np.asarray(p) / mesh_scale).tolist(), "normal": list(n)}
        for i, (p, n) in enumerate(zip(positions, normals))
    ]
    path.write_text(json.dumps({"mesh": "sphere.obj", "points": records}))


def test_imprints_command_writes_set_and_picture(tmp_path):
    from classify.cli import main

    # A sphere of radius 0.4 in file units, scaled as the experiment scales objects: 150 mm principal-frame diagonal.
    from meshsal.mesh.transform import principal_diagonal

    sphere = shapes.sphere(radius=0.4, n=24)
    shapes.write_obj(tmp_path / "sphere.obj", sphere)
    scale = 150.0 / principal_diagonal(sphere.vertices, sphere.faces)[1]
    radius_mm = 0.4 * scale
    top, side = [0.0, radius_mm, 0.0], [radius_mm, 0.0, 0.0]
    write_points(tmp_path / "points.json", scale, [top, side], [[0, 1, 0], [1, 0, 0]])
    out = tmp_path / "out" / "set.npz"
    assert (
        main(
            [
                "imprints",
                str(tmp_path / "sphere.obj"),
                "--points",
                str(tmp_path / "points.json"),
                "--mode",
                "pressure",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    s = ImprintSet.load(out)
    assert len(s) == 2 and s.sensor.mode == "pressure" and s.object_names == ("sphere",)
    np.testing.assert_allclose(s.positions, [top, side], atol=1e-6)
    np.testing.assert_array_equal(s.point_ids, [0, 1])  # a points file of the old layout counts from 1: read from 0
    # A sphere looks the same everywhere: both imprints are the same centred disc.
    assert s.imprints[0, 7:9, 7:9].min() > 0.9
    np.testing.assert_allclose(s.imprints[0], s.imprints[1], atol=0.1)
    import cv2

    picture = cv2.imread(str(out.parent / "imprints.png"))
    assert picture is not None and picture.shape[0] > 16 * 8 and picture.shape[1] > 2 * 16 * 8


def _face_points(mesh, path):
    """A points.json of the centroids of every 7th face (surface points that are no vertex), in file units."""
    faces = mesh.faces[::7]
    centroids = mesh.vertices[faces].mean(axis=1)
    normals = np.cross(*(mesh.vertices[faces[:, k]] - mesh.vertices[faces[:, 0]] for k in (1, 2)))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    write_points(path, 1.0, centroids, normals.tolist())
    return len(faces)


@pytest.mark.parametrize("other", ["box", "edited"])
def test_imprints_command_refuses_points_off_the_meshs_surface(tmp_path, capsys, other):
    from classify.cli import main

    ball = shapes.icosphere(radius=1.0, subdivisions=2)
    shapes.write_obj(tmp_path / "ball.obj", ball)
    n = _face_points(ball, tmp_path / "points.json")
    out = tmp_path / "set.npz"
    args = ["--points", str(tmp_path / "points.json"), "--out", str(out)]
    assert main(["imprints", str(tmp_path / "ball.obj"), *args]) == 0
    assert len(ImprintSet.load(out)) == n
    out.unlink()
    if other == "box":
        mesh = shapes.box(half=1.0, n=8)
    else:
        V = ball.vertices.copy()
        V[0] *= 1.2
        mesh = dataclasses.replace(ball, vertices=V)
    shapes.write_obj(tmp_path / f"{other}.obj", mesh)
    capsys.readouterr()
    assert main(["imprints", str(tmp_path / f"{other}.obj"), *args]) == 1
    err = capsys.readouterr().err
    assert f"{tmp_path / 'points.json'}: " in err and f"off the surface of {tmp_path / other}.obj" in err, err
    off = int(re.search(r"(\d+) of (\d+) points lie off", err).group(1))
    assert 1 <= off <= n and f"of {n} points" in err
    if other == "edited":
        # Only the faces around the moved vertex left the surface.
        assert off < n
    assert not out.exists()


@pytest.mark.parametrize(
    "content,message",
    [
        (None, "points.json: points file not found"),
        ("{not json", "points.json: not a valid points file: malformed JSON at line 1"),
        ('{"points": []}', "points.json: the 'points' list is empty"),
        ("[1, 2]", "points.json: expected an object with a 'points' list"),
        ('{"points": [{"position": [0, 1], "normal": [0, 1, 0]}]}', r"points.json: points\[0\]: 'position'"),
        ('{"points": [{"position": [0, 1, 0], "normal": [0, 0, 0]}]}', r"points.json: points\[0\]: 'normal' is zero"),
    ],
)
def test_imprints_command_reports_bad_points_file(tmp_path, capsys, content, message):
    from classify.cli import main

    shapes.write_obj(tmp_path / "sphere.obj", shapes.sphere(radius=1.0, n=4))
    points = tmp_path / "points.json"
    if content is not None:
        points.write_text(content)
    out = tmp_path / "set.npz"
    assert main(["imprints", str(tmp_path / "sphere.obj"), "--points", str(points), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "visuotactile imprints: error:" in err
    assert re.search(message, err), err
    assert not out.exists()
