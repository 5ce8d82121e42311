"""`visuotactile points`: every file in the source frame, baselines, progress, fewer points than asked, none, an
open bowl facing inward, a mesh that cannot be read, a negative seed."""

import dataclasses
import json

import numpy as np
import pytest
import shapes
from planted import distance_to_surface, planted_sphere

from meshsal.points import InterestPoints, interest_points


def test_cli_writes_every_file_in_the_source_frame(tmp_path, capsys):
    from classify.cli import main
    from meshsal.mesh.io import load_mesh, load_vertex_quality, save_ply

    mesh, _, _ = planted_sphere(radius=0.4)
    source = mesh.replace(vertices=mesh.vertices + [2.0, 1.0, -3.0])
    path = tmp_path / "planted.ply"
    save_ply(path, source)
    out = tmp_path / "out"
    assert main(["points", str(path), "--n-points", "6", "--view-size", "48", "--quiet", "--out", str(out)]) == 0
    for name in ("saliency.ply", "points.json", "points.csv", "views.png", "contact_sheet.png"):
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    quality = load_vertex_quality(out / "saliency.ply")
    assert quality.shape == (source.n_vertices,) and np.ptp(quality) > 0
    reloaded = load_mesh(out / "saliency.ply")
    np.testing.assert_allclose(reloaded.vertices, source.vertices, atol=1e-5)
    doc = json.loads((out / "points.json").read_text())
    assert doc["mesh"] == str(path) and doc["settings"]["method"] == "attention"
    pts = doc["points"]
    assert [p["id"] for p in pts] == list(range(6))  # from 0, as probe plans and capture sessions
    positions = np.array([p["position"] for p in pts])
    assert distance_to_surface(positions, source).max() < 1e-6
    assert np.allclose(np.linalg.norm([p["normal"] for p in pts], axis=1), 1.0)
    from meshsal.mesh.transform import principal_diagonal  # the experiment's sizing rule

    diagonal = principal_diagonal(source.vertices, source.faces)[1]
    np.testing.assert_allclose(doc["min_spacing"], 16.0 / 150.0 * diagonal)
    np.testing.assert_allclose(doc["frame"]["scale"], 150.0 / diagonal)  # the frame the points were chosen in
    assert doc["combination"] == "equal" and doc["untouchable"] >= 0
    assert (doc["format"], doc["version"]) == ("visuotactile.points", 2)
    again = InterestPoints.load(out / "points.json")  # the versioned format round-trips
    np.testing.assert_allclose(again.positions, positions)
    assert again.method == "attention" and len(again.vertex_saliency) == source.n_vertices
    assert again.ids.tolist() == list(range(6)) and again.votes.tolist() == [p["votes"] for p in pts]
    rows = (out / "points.csv").read_text().strip().splitlines()
    assert rows[0].startswith("id,") and len(rows) == 7
    np.testing.assert_allclose([float(v) for v in rows[1].split(",")[2:5]], positions[0])
    assert "6 attention points" in capsys.readouterr().out


def test_cli_baseline_and_progress(tmp_path, capsys):
    from classify.cli import main
    from meshsal.mesh.io import save_ply

    mesh, _, _ = planted_sphere()
    path = tmp_path / "s.ply"
    save_ply(path, mesh)
    assert (
        main(
            [
                "points",
                str(path),
                "--method",
                "uniform",
                "--n-points",
                "5",
                "--view-size",
                "32",
                "--out",
                str(tmp_path / "o"),
            ]
        )
        == 0
    )
    assert "saliency" in capsys.readouterr().err
    assert len(json.loads((tmp_path / "o" / "points.json").read_text())["points"]) == 5


def test_cli_old_spellings_still_work_for_a_release_with_a_warning(tmp_path, capsys):
    from classify.cli import main

    argv = ["points", "cup", "--method", "uniform", "--quiet", "--out", str(tmp_path)]
    assert main(argv + ["--n", "4", "--size", "32", "--threshold", "0.4"]) == 0
    err = capsys.readouterr().err
    for old, new in (("--n", "--n-points"), ("--size", "--view-size"), ("--threshold", "--peak-threshold")):
        assert f"visuotactile points: warning: {old} is deprecated and goes in 0.3: use {new}" in err
    settings = json.loads((tmp_path / "points.json").read_text())["settings"]
    assert (settings["n_points"], settings["view_size"], settings["peak_threshold"]) == (4, 32, 0.4)


def test_cli_says_when_a_mesh_holds_fewer_points_than_asked(tmp_path, capsys):
    from classify.cli import main

    argv = ["points", "cup", "--method", "uniform", "--n-points", "8", "--min-spacing-mm", "120"]
    assert main(argv + ["--view-size", "32", "--quiet", "--out", str(tmp_path)]) == 0
    got = len(json.loads((tmp_path / "points.json").read_text())["points"])
    assert 1 <= got < 8
    err = capsys.readouterr().err
    assert f"visuotactile points: warning: cup: {got} of the 8 uniform points asked for" in err
    assert "no more lie 120 mm apart on the mesh at 150 mm" in err


def test_cli_fails_and_writes_nothing_when_no_point_is_found(tmp_path, capsys, monkeypatch):
    import meshsal.points
    from classify.cli import main

    def nothing(mesh, methods, **options):
        pts = interest_points(mesh, n=1, method="uniform")
        none = np.zeros(0, np.int64)
        empty = InterestPoints(
            none, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), none, pts.vertex_saliency, (), "uniform", -1, 16.0
        )
        return {methods[0]: dataclasses.replace(empty, untouchable=809)}

    monkeypatch.setattr(meshsal.points, "points_by_method", nothing)
    out = tmp_path / "out"
    assert main(["points", "cup", "--method", "uniform", "--view-size", "16", "--quiet", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "visuotactile points: error: cup: no uniform point found (809 candidates the pad could not touch" in err
    assert not out.exists() or not any(out.iterdir())


def test_cli_an_open_bowl_facing_inward_gets_its_points(tmp_path, capsys):
    # Its faces point into it, as in many scans of open objects: turned outward as it loads, it is touchable.
    from classify.cli import main

    bowl = shapes.bowl()
    shapes.write_obj(tmp_path / "bowl.obj", bowl.replace(faces=bowl.faces[:, ::-1]))
    argv = ["points", str(tmp_path / "bowl.obj"), "--method", "mesh_saliency", "--view-size", "32", "--quiet"]
    assert main(argv + ["--out", str(tmp_path / "out")]) == 0
    captured = capsys.readouterr()
    assert "turned 1 open components outward" in captured.err and "asked for" not in captured.err
    points = json.loads((tmp_path / "out" / "points.json").read_text())["points"]
    assert len(points) == 15
    # Every normal points away from the bowl's centre, out of its convex side.
    radial = np.array([p["position"] for p in points])
    assert (np.einsum("ij,ij->i", np.array([p["normal"] for p in points]), radial) > 0).all()


def test_cli_bad_mesh_fails_with_the_loader_message(tmp_path, capsys):
    from classify.cli import main

    bad = tmp_path / "broken.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nf 1 2 9\n")
    assert main(["points", str(bad), "--quiet", "--out", str(tmp_path / "o")]) != 0
    err = capsys.readouterr().err
    assert "points" in err and "broken.obj" in err
    assert not (tmp_path / "o" / "points.json").exists()


@pytest.mark.parametrize("method", ["uniform", "random"])
def test_a_negative_seed_is_refused_whether_the_method_draws_or_not(tmp_path, capsys, method):
    from classify.cli import main

    out = tmp_path / "pts"
    assert main(["points", "cup", "--method", method, "--seed", "-1", "--quiet", "--out", str(out)]) == 1
    assert "visuotactile points: error: cup: seed must be a non-negative integer, got -1" in capsys.readouterr().err
    assert not out.exists()
