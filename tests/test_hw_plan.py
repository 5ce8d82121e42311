"""hw.plan: probe plans on a sphere with known normals, file frames, quaternions, files and errors."""

import csv
import json

import numpy as np
import pytest
from shapes import icosphere

from hw.plan import load_plan, make_plan, matrix_from_quaternion, quaternion_from_matrix, save_plan
from meshsal.mesh import Similarity
from meshsal.mesh.transform import principal_diagonal


def test_quaternion_round_trip_on_random_rotations():
    rng = np.random.default_rng(0)
    for _ in range(50):
        Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        Q *= np.sign(np.linalg.det(Q))
        q = quaternion_from_matrix(Q)
        assert np.isclose(np.linalg.norm(q), 1) and q[0] >= 0
        assert np.allclose(matrix_from_quaternion(q), Q, atol=1e-9)
    # 180 degrees about x: the trace is -1, the branch without w.
    assert np.allclose(quaternion_from_matrix(np.diag([1.0, -1.0, -1.0])), [0, 1, 0, 0])


def test_plan_on_a_sphere_in_metres(tmp_path):
    # A 5 cm sphere stored in metres, off the origin: the plan must come back in metres, in the file's frame.
    center = np.array([0.3, -0.1, 0.2])
    mesh = icosphere(radius=0.05, center=center)
    plan = make_plan(mesh, n=6, method="uniform", size_mm=150.0, source="ball.obj")
    assert len(plan.points) == 6 and plan.mesh == "ball.obj"
    diagonal_m = principal_diagonal(mesh.vertices, mesh.faces)[1]  # the experiment's sizing rule
    assert plan.frame.scale == pytest.approx(150.0 / diagonal_m)
    assert plan.sensor["width"] == pytest.approx(plan.sensor["width_mm"] / plan.frame.scale)
    for p in plan.points:
        radial = (p.position - center) / np.linalg.norm(p.position - center)
        assert np.linalg.norm(p.position - center) == pytest.approx(0.05, rel=0.01)
        assert np.dot(p.approach, -radial) > 0.999
        R = matrix_from_quaternion(p.quaternion)
        assert np.allclose(R[:, 2], p.approach, atol=1e-9)
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-9) and np.linalg.det(R) == pytest.approx(1.0)
    # The sensor x axis is tactile's column direction at angle 0.
    from tactile.sensor import tangent_frames

    up, right = tangent_frames(-np.array([p.approach for p in plan.points]))
    rotations = np.array([matrix_from_quaternion(p.quaternion) for p in plan.points])
    assert np.allclose(rotations[:, :, 0], right, atol=1e-9) and np.allclose(rotations[:, :, 1], -up, atol=1e-9)
    # The planning frame is the mesh scaled to 150 mm and centred.
    mm = plan.positions_mm()
    assert np.allclose(np.linalg.norm(mm, axis=1), 0.05 * plan.frame.scale, rtol=0.01)

    json_path, csv_path = save_plan(plan, tmp_path / "plan.json")
    data = json.loads(json_path.read_text())
    assert set(data) >= {"sensor", "points"}
    assert set(data["points"][0]) == {"id", "position", "approach", "quaternion"}
    with open(csv_path) as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 6 and float(rows[3]["qw"]) == pytest.approx(plan.points[3].quaternion[0])
    again = load_plan(json_path)
    assert [p.id for p in again.points] == list(range(6))
    assert np.allclose(again.positions_mm(), mm) and again.size_mm == 150.0
    assert all(np.allclose(a.quaternion, b.quaternion) for a, b in zip(again.points, plan.points))


def test_plan_file_errors(tmp_path):
    path = tmp_path / "plan.json"
    with pytest.raises(FileNotFoundError, match="plan.json"):
        load_plan(path)
    path.write_text("{not json")
    with pytest.raises(ValueError, match="plan.json: not a valid probe plan: malformed JSON"):
        load_plan(path)
    path.write_text(json.dumps({"format": "something else"}))
    with pytest.raises(ValueError, match="not a probe plan"):
        load_plan(path)
    good = {
        "format": "visuotactile-probe-plan",
        "version": 1,
        "size_mm": 150,
        "sensor": {},
        "planning_frame": {"scale": 1.0, "offset": [0, 0, 0]},
        "points": [{"id": 0, "position": [0, 0, 0], "approach": [0, 0, 2], "quaternion": [1, 0, 0, 0]}],
    }
    path.write_text(json.dumps(good))
    with pytest.raises(ValueError, match="damaged probe plan.*non-unit"):
        load_plan(path)
    good["points"][0]["approach"] = [0, 0, 1]
    good["points"].append(dict(good["points"][0]))
    path.write_text(json.dumps(good))
    with pytest.raises(ValueError, match="repeated point ids"):
        load_plan(path)


def test_cli_plan_on_a_toy(tmp_path):
    from classify.cli import main

    out = tmp_path / "cup.json"
    assert main(["plan", "cup", "--method", "random", "--n-points", "5", "--out", str(out)]) == 0
    plan = load_plan(out)
    assert len(plan.points) == 5 and (tmp_path / "cup.csv").exists()
    assert main(["plan", str(tmp_path / "nope.obj"), "--out", str(out)]) == 1
    # Similarity sanity: a toy is made in millimetres, so the frame only centres and rescales.
    assert isinstance(plan.frame, Similarity) and plan.frame.scale > 0


def test_cli_plan_with_a_learned_method_needs_and_takes_a_model(tmp_path, capsys):
    from models import one_feature_model

    from classify.cli import main

    out = tmp_path / "cup.json"
    assert main(["plan", "cup", "--method", "learned", "--out", str(out)]) == 1
    assert "visuotactile plan: error: --method learned needs --model FILE" in capsys.readouterr().err
    assert not out.exists()
    one_feature_model("curvature").save(tmp_path / "model.json")
    argv = ["plan", "cup", "--method", "learned", "--model", str(tmp_path / "model.json"), "--n-points", "4"]
    assert main(argv + ["--quiet", "--out", str(out)]) == 0
    assert [p.id for p in load_plan(out).points] == [0, 1, 2, 3]
    assert capsys.readouterr().err == ""  # --quiet: no status line


def test_cli_plan_renders_at_the_view_size_asked_and_warns_when_the_model_was_measured_at_another(tmp_path, capsys):
    import dataclasses

    from models import one_feature_model

    from classify.cli import main

    dataclasses.replace(one_feature_model("curvature"), view_size=48).save(tmp_path / "model.json")
    argv = ["plan", "cup", "--method", "learned", "--model", str(tmp_path / "model.json"), "--n-points", "4", "--quiet"]
    assert main(argv + ["--view-size", "48", "--out", str(tmp_path / "same.json")]) == 0
    assert capsys.readouterr().err == ""
    assert main(argv + ["--view-size", "32", "--out", str(tmp_path / "other.json")]) == 0
    assert "measured on views of 48 pixels, these are 32" in capsys.readouterr().err
