"""Objects by name: the embedded YCB scans, object sets, resolution errors."""

import numpy as np
import pytest
import shapes

import meshsal
from classify.cli import main
from meshsal import objects
from meshsal.objects import ycb


@pytest.mark.parametrize("name", ycb.NAMES)
def test_every_embedded_ycb_object_loads_closed_in_metres(name):
    mesh = ycb.load(name)
    assert mesh.name == name and mesh.n_faces == 15728
    diagonal = np.linalg.norm(mesh.vertices.max(axis=0) - mesh.vertices.min(axis=0))
    assert 0.05 < diagonal < 0.4
    assert (mesh.vertex_colors is not None) == (name in ("banana", "scissors"))


def test_baked_colours_are_the_textures_own(shared_mesh):
    source = meshsal.load_mesh(shared_mesh("ycb/banana.obj"))
    embedded = ycb.load("banana")
    assert np.allclose(embedded.vertices, source.vertices, atol=1e-9)
    banana = embedded.vertex_colors.mean(axis=0)
    assert banana[0] > 2 * banana[2] and banana[1] > 2 * banana[2]  # yellow: the texture's, not grey
    assert embedded.vertex_colors.std(axis=0).max() > 0.02  # and its spots, not one colour


def test_sets_names_and_files_resolve_in_order(tmp_path):
    assert [r.name for r in objects.resolve_objects(["toys,ycb"])] == list(meshsal.objects.toys.NAMES + ycb.NAMES)
    assert len(objects.resolve_objects(["ycb"])) == 10
    path = tmp_path / "pebble.obj"
    shapes.write_obj(path, shapes.sphere(radius=5.0, n=8))
    refs = objects.resolve_objects(["cow", f"power_drill,{path}"])
    assert [(r.name, r.kind) for r in refs] == [("cow", "toy"), ("power_drill", "ycb"), ("pebble", "file")]
    assert objects.load_ref(refs[2]).name == "pebble"
    assert objects.load_ref(refs[1]).n_faces == 15728


@pytest.mark.parametrize(
    "specs, message",
    [
        (["unicorn"], "'unicorn' is neither a set"),
        (["cow", "toys"], "given more than once: cow"),
        ([" , "], "no objects given"),
    ],
)
def test_bad_object_lists_are_refused_by_name(specs, message):
    with pytest.raises(ValueError, match=message):
        objects.resolve_objects(specs)


def test_every_command_taking_a_mesh_takes_a_ycb_name(tmp_path, capsys):
    assert (
        main(
            [
                "points",
                "foam_brick",
                "--out",
                str(tmp_path),
                "--n-points",
                "3",
                "--method",
                "uniform",
                "--view-size",
                "32",
                "--quiet",
            ]
        )
        == 0
    )
    assert (tmp_path / "points.json").exists()
