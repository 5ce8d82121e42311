"""Units: the API's defaults are the command line's (millimetres, a 32 mm pad), and a mesh whose size disagrees
with the pad's (one in metres, loaded as it is) is told so, never answered with silent zeros."""

import json
import warnings

import numpy as np
import pytest
import shapes

import tactile
from meshsal.mesh.io import MeshRepairWarning, load_mesh
from meshsal.mesh.transform import UnitsWarning, check_pad_size, scale_to_principal
from meshsal.points import PointOptions, interest_points
from meshsal.points.touch import PAD_WIDTH


def quietly_loaded(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MeshRepairWarning)
        return load_mesh(path)


def no_units_warning():
    """A context in which a UnitsWarning fails the test."""
    context = warnings.catch_warnings()
    context.__enter__()
    warnings.simplefilter("error", UnitsWarning)
    return context


def test_the_api_pad_and_spacing_are_the_command_lines():
    assert PAD_WIDTH == tactile.Sensor().width_mm == 32.0
    sphere = shapes.sphere(radius=60.0, n=12)
    rules = PointOptions().rules(sphere)
    assert (rules.pad_width, rules.min_spacing) == (32.0, 16.0)


@pytest.mark.parametrize(
    "radius, pitch, problem",
    [
        (0.06, 2.0, "the pad's taxels, 2 apart, miss it"),  # metres
        (8.0, None, "the pad covers it whole"),  # a 16 mm ball (28 mm box diagonal) under a 32 mm pad
        (60000.0, None, "the pad feels a flat patch of it anywhere"),  # micrometres
    ],
)
def test_a_mesh_whose_size_disagrees_with_the_pads_is_named_with_both_sizes(radius, pitch, problem):
    ball = shapes.icosphere(radius=radius, subdivisions=1)
    ball = ball.replace(name="ball")
    size = np.linalg.norm(np.ptp(ball.vertices, axis=0))
    with pytest.warns(UnitsWarning) as caught:
        assert check_pad_size(ball, 32.0, pitch) is False
    message = str(caught[0].message)
    assert message.startswith(f"ball: {size:.3g} units across (its bounding-box diagonal), and the pad 32 wide: ")
    assert problem in message and "scale_to_principal" in message


def test_a_mesh_in_millimetres_passes_silently():
    context = no_units_warning()
    try:
        for radius in (20.0, 75.0, 500.0):  # a 70 mm ball to a 1.7 m one
            assert check_pad_size(shapes.icosphere(radius=radius, subdivisions=1), 32.0, 2.0)
    finally:
        context.__exit__(None, None, None)


def test_the_bunny_in_metres_is_told_so_by_points_and_imprints(shared_mesh):
    bunny = quietly_loaded(shared_mesh("stanford-bunny.obj"))
    assert np.linalg.norm(np.ptp(bunny.vertices, axis=0)) < 0.3  # metres
    with pytest.warns(UnitsWarning, match=r"stanford-bunny: 0\.\d+ units across .* the pad 32 wide: the pad covers"):
        pts = interest_points(bunny, n=5, method="uniform", pad_width=32.0)
    assert len(pts) == 1  # the pad covers the whole bunny: one point is all a 16 mm spacing admits
    with pytest.warns(UnitsWarning, match=r"stanford-bunny: .* the pad's taxels, 2 apart, miss it"):
        images = tactile.imprints(bunny, pts.positions, pts.normals)
    assert not images.any()  # the zeros the warning explains
    # Scaled to millimetres, as the command line does: no warning, and the pad feels it.
    scaled = scale_to_principal(bunny, 150.0)
    context = no_units_warning()
    try:
        pts = interest_points(scaled, n=5, method="uniform")
        images = tactile.imprints(scaled, pts.positions, pts.normals, tactile.Sensor(mode="pressure"))
    finally:
        context.__exit__(None, None, None)
    assert len(pts) == 5 and (images.reshape(5, -1).max(axis=1) > 0).all()


def test_imprints_refuses_a_set_in_which_the_pad_met_nothing(tmp_path, capsys):
    from classify.cli import main

    ball = shapes.icosphere(radius=60.0, subdivisions=3).replace(name="ball")
    shapes.write_obj(tmp_path / "ball.obj", ball)
    pts = interest_points(scale_to_principal(quietly_loaded(tmp_path / "ball.obj"), 150.0), n=4, method="uniform")
    points = tmp_path / "points.json"
    pts.save(points, source="ball.obj")
    document = json.loads(points.read_text())
    for p in document["points"]:  # normals into the ball: the pad presses from inside, on back faces only
        p["normal"] = [-x for x in p["normal"]]
    points.write_text(json.dumps(document))
    out = tmp_path / "set.npz"
    assert main(["imprints", str(tmp_path / "ball.obj"), "--points", str(points), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert f"visuotactile imprints: error: {points}: the pad met {tmp_path / 'ball.obj'} at none of its 4 points" in err
    assert not out.exists() and not (tmp_path / "imprints.png").exists()
    # The file as written: every pad meets the ball, flat contacts included (a blank contour image).
    pts.save(points, source="ball.obj")
    assert main(["imprints", str(tmp_path / "ball.obj"), "--points", str(points), "--out", str(out)]) == 0
    assert tactile.ImprintSet.load(out).point_ids.tolist() == [0, 1, 2, 3]
