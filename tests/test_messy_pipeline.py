"""The whole toolkit on messy meshes (tests/messy.py): every point method, imprints, the batch, the experiment,
and errors that name the object, in the API and on the command line.

No point is ever on a vertex without a normal (``meshsal.mesh.normal_defined``):
neither a vertex candidate nor a surface point (attention, random) whose
nearest corner has none.
"""

import dataclasses
import json
import warnings

import messy
import numpy as np
import pytest
import quick
import shapes
from quick import QUICK, SMALL

import meshsal
import tactile
from classify import batch
from classify.cli import main
from meshsal.mesh import Mesh, normal_defined
from meshsal.mesh.io import MeshRepairWarning, load_mesh

METHODS = ("attention", "attention_itti", "random", "uniform", "mesh_saliency", "curvature")
CASES = {c.name: c for c in messy.cases()}
# The other shapes are parts of "everything_apart", which every method meets one by one.
COMPOSITES = (
    "composite_double_sided",
    "double_sided_fin",
    "nonmanifold_edges",
    "box_with_sphere",
    "everything_on_one_box",
)
NORMALLESS = [(name, m) for name in ("fold_alone", "folds_beside_a_box") for m in METHODS]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("messy_obj")
    return {name: messy.write_case(case, folder, "obj") for name, case in CASES.items()}


def loaded(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MeshRepairWarning)
        return meshsal.scale_to(load_mesh(path), 150.0)


def check(mesh, pts):
    """Points a pad can be pressed at, and their imprints."""
    assert len(pts) > 0 and np.isfinite(pts.positions).all()
    np.testing.assert_allclose(np.linalg.norm(pts.normals, axis=1), 1.0, atol=1e-9)
    assert normal_defined(mesh.vertices, mesh.faces)[pts.vertex_ids].all()
    images = tactile.imprints(mesh, pts.positions, pts.normals, workers=1)
    assert images.shape == (len(pts), 16, 16) and np.isfinite(images).all()


@pytest.mark.parametrize("method", METHODS)
def test_every_point_method_and_imprints_on_everything_at_once(files, method):
    mesh = loaded(files["everything_apart"])
    check(mesh, meshsal.interest_points(mesh, n=6, method=method, size=32))


@pytest.mark.parametrize("name", COMPOSITES)
def test_all_point_methods_and_imprints_on_composite_meshes(files, name):
    mesh = loaded(files[name])
    for pts in meshsal.points_by_method(mesh, METHODS, n=6, size=32).values():
        check(mesh, pts)


@pytest.mark.parametrize("name, method", [pytest.param(n, m, id=f"{n}-{m}") for n, m in NORMALLESS])
def test_point_methods_never_choose_a_vertex_without_a_normal(files, name, method):
    mesh = loaded(files[name])
    check(mesh, meshsal.interest_points(mesh, n=6, method=method, size=32))


def test_a_composite_with_a_double_sided_triangle_gets_its_points(files, tmp_path, capsys):
    # The farthest-point baseline may propose a corner whose only faces are the triangle and its twin; that
    # corner has no normal to press along, so it must not reach the touch check ("normals must be non-zero").
    assert (
        main(
            [
                "points",
                str(files["composite_double_sided"]),
                "--out",
                str(tmp_path),
                "--method",
                "uniform",
                "--n-points",
                "6",
                "--view-size",
                "32",
                "--quiet",
            ]
        )
        == 0
    )
    assert len(json.loads((tmp_path / "points.json").read_text())["points"]) == 6
    assert (
        main(
            [
                "imprints",
                str(files["composite_double_sided"]),
                "--points",
                str(tmp_path / "points.json"),
                "--out",
                str(tmp_path / "set.npz"),
            ]
        )
        == 0
    )
    assert tactile.ImprintSet.load(tmp_path / "set.npz").imprints.shape == (6, 16, 16)


def test_a_folder_of_messy_meshes_goes_through_the_batch(tmp_path):
    folder = tmp_path / "lab"
    folder.mkdir()
    names = ("everything_apart", "composite_double_sided", "double_sided_fin", "inward_box")
    for name, fmt in zip(names, ("obj", "ply", "off", "stl")):
        messy.write_case(CASES[name], folder, fmt)
    (folder / "broken.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n")
    settings = batch.BatchSettings(methods=("attention", "uniform"), n_points=4, view_size=32)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MeshRepairWarning)
        summary = batch.run_batch(folder, tmp_path / "store", settings, quiet=True, skip_bad=True)
    assert (summary.done, summary.failed) == (len(names), 1)
    failures = [json.loads(line) for line in (tmp_path / "store" / "failures.jsonl").read_text().splitlines()]
    assert [f["name"] for f in failures] == ["broken"]
    assert "broken.obj" in failures[0]["error"] and "out of range" in failures[0]["error"]
    store = batch.load_store(tmp_path / "store")
    assert sorted(store) == sorted(names)
    for entry in store.values():
        for method in settings.methods:
            assert entry.imprints[method].imprints.shape[1:] == (16, 16)
            assert np.isfinite(entry.points[method].normals).all()


def test_the_experiment_runs_on_messy_objects(files, tmp_path):
    objects = [str(files["composite_double_sided"]), str(files["everything_apart"])]
    config = QUICK.replace(methods=("uniform", "random"), settings=dataclasses.replace(SMALL, view_size=32))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MeshRepairWarning)
        r = quick.run(objects, config, n_jobs=1, out_dir=tmp_path)
    cell = r.cell("uniform", "instance", "knn", 2, False, 1)
    assert 0.0 <= cell.ci_low <= cell.mean <= cell.ci_high <= 100.0
    assert (tmp_path / "results.csv").exists()


def test_meshes_built_in_memory_are_repaired_as_files_are(tmp_path):
    composite = CASES["composite_double_sided"]
    mesh = Mesh(vertices=composite.vertices, faces=composite.faces, name="composite")
    small = dataclasses.replace(SMALL, n_points=4, view_size=32)
    config = QUICK.replace(methods=("uniform",), protocols=("instance",), settings=small)
    with pytest.warns(MeshRepairWarning, match="composite: .*double-sided"):
        r = quick.run([mesh, shapes.box(half=30.0, n=12).replace(name="box")], config, n_jobs=1)
    assert 0.0 <= r.cell("uniform", "instance", "knn", 2, False, 1).mean <= 100.0


def fail_in_curvature(monkeypatch, error):
    """Make every object fail deep in a per-object stage (the Gaussian averages of mesh saliency)."""
    import meshsal.mesh.curvature as curvature

    def broken(*args, **kwargs):
        raise error

    monkeypatch.setattr(curvature, "gaussian_average", broken)


@pytest.mark.parametrize("command", ["points", "render"])
def test_an_error_deep_in_a_command_names_the_mesh(files, tmp_path, capsys, monkeypatch, command):
    path = files["cup"]
    if command == "points":
        fail_in_curvature(monkeypatch, ValueError("curvature went wrong"))
    else:
        import meshsal.views.render as render

        monkeypatch.setattr(render, "render_views", lambda *a, **k: (_ for _ in ()).throw(ValueError("no light")))
    argv = [command, str(path), "--out", str(tmp_path), "--view-size", "32"] + (
        ["--quiet"] if command == "points" else []
    )
    assert main(argv) == 1
    message = capsys.readouterr().err
    assert f"visuotactile {command}: error: {path}: " in message, message


def test_an_error_in_imprints_names_the_mesh(files, tmp_path, capsys, monkeypatch):
    path = files["cup"]
    assert (
        main(
            [
                "points",
                str(path),
                "--out",
                str(tmp_path),
                "--method",
                "uniform",
                "--n-points",
                "3",
                "--view-size",
                "32",
                "--quiet",
            ]
        )
        == 0
    )
    import tactile.raycast as raycast

    monkeypatch.setattr(raycast, "imprints", lambda *a, **k: (_ for _ in ()).throw(ValueError("pad fell off")))
    assert (
        main(["imprints", str(path), "--points", str(tmp_path / "points.json"), "--out", str(tmp_path / "set.npz")])
        == 1
    )
    assert f"visuotactile imprints: error: {path}: pad fell off" in capsys.readouterr().err


def test_a_bug_deep_in_a_command_keeps_its_traceback_and_names_the_mesh(files, tmp_path, monkeypatch):
    fail_in_curvature(monkeypatch, IndexError("index 7 is out of bounds"))
    with pytest.raises(IndexError) as info:
        main(["points", str(files["cup"]), "--out", str(tmp_path), "--view-size", "32", "--quiet"])
    assert f"while processing {files['cup']}" in info.value.__notes__


def test_an_error_in_the_experiment_names_the_object(files, monkeypatch):
    fail_in_curvature(monkeypatch, ValueError("curvature went wrong"))
    config = QUICK.replace(methods=("uniform",), settings=dataclasses.replace(SMALL, n_points=4))
    with pytest.raises(ValueError, match=r"(composite_double_sided|cup)"):
        quick.run([str(files["composite_double_sided"]), str(files["cup"])], config, n_jobs=1)
