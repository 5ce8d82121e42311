"""Object instances: uniform rotations, sizes that ignore the file's pose, repaint, a similarity with a turn."""

import numpy as np
import pytest
import shapes

import meshsal
from meshsal.mesh import Similarity
from meshsal.mesh.transform import principal_diagonal, scale_to_principal
from meshsal.objects import instances


def test_random_rotations_are_proper_and_uniform():
    rng = np.random.default_rng(0)
    R = np.stack([instances.random_rotation(rng) for _ in range(4000)])
    assert np.allclose(np.einsum("nij,nkj->nik", R, R), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(R), 1.0)
    # Uniform over SO(3): the image of a fixed axis is uniform on the sphere (mean 0, second moment I/3),
    # and the rotation angle has density (1 - cos t) / pi, whose mean cos t is -1/2 ... E[trace] = 0.
    z = R[:, :, 2]
    assert np.allclose(z.mean(axis=0), 0.0, atol=0.05)
    assert np.allclose(z.T @ z / len(z), np.eye(3) / 3, atol=0.03)
    assert abs(np.trace(R, axis1=1, axis2=2).mean()) < 0.06


def test_similarity_with_a_turn_round_trips_points_and_directions():
    rng = np.random.default_rng(1)
    s = Similarity(2.5, rng.standard_normal(3), instances.random_rotation(rng))
    t = Similarity(0.5, rng.standard_normal(3), instances.random_rotation(rng))
    P = rng.standard_normal((10, 3))
    assert np.allclose(s.to_source(s.apply(P)), P)
    assert np.allclose(s.inverse().apply(s.apply(P)), P)
    assert np.allclose(s.then(t).apply(P), t.apply(s.apply(P)))
    N = rng.standard_normal((10, 3))
    assert np.allclose(s.direction_to_source(s.apply_direction(N)), N)
    with pytest.raises(ValueError, match="proper 3x3 rotation"):
        Similarity(rotation=np.diag([1.0, 1.0, -1.0]))


def test_principal_size_ignores_how_the_object_was_turned_in_its_file():
    mesh = shapes.bumps(n=24)
    turned = mesh.replace(vertices=mesh.vertices @ instances.random_rotation(np.random.default_rng(2)).T)
    _, d0 = principal_diagonal(mesh.vertices, mesh.faces)
    _, d1 = principal_diagonal(turned.vertices, turned.faces)
    assert d1 == pytest.approx(d0, rel=1e-9)
    a, b = scale_to_principal(mesh, 150.0), scale_to_principal(turned, 150.0)
    assert np.linalg.norm(a.vertices, axis=1).max() == pytest.approx(np.linalg.norm(b.vertices, axis=1).max())
    assert np.allclose(b.transform.to_source(b.vertices), turned.vertices)


def test_instance_turns_resizes_and_recolours_and_leads_back_to_the_file():
    base = scale_to_principal(shapes.bumps(n=24), 100.0)
    base = base.replace(vertex_colors=np.tile([0.8, 0.2, 0.2], (base.n_vertices, 1)))
    spec = instances.draw_instance(np.random.default_rng(3))
    inst = instances.make_instance(base, spec)
    radii = np.linalg.norm(inst.vertices, axis=1) / np.linalg.norm(base.vertices, axis=1)
    assert np.allclose(radii, spec.scale)
    assert 0.95 <= spec.scale <= 1.05
    assert np.allclose(inst.transform.to_source(inst.vertices), base.transform.to_source(base.vertices))
    assert not np.allclose(inst.vertex_colors, base.vertex_colors)
    grey = instances.recolor(np.array([[0.4, 0.4, 0.4]]), spec.hue_deg, 1.0)
    assert np.allclose(grey, 0.4)  # a hue turn leaves grey alone


def test_toy_instances_take_a_new_paint_not_a_hue_turn():
    cup = scale_to_principal(meshsal.objects.toys.make("cup"), 150.0)
    inst = instances.make_instance(cup, instances.InstanceSpec(np.eye(3), 1.0, 7, 0.0, 1.0))
    assert np.allclose(inst.vertices, cup.vertices)
    assert np.array_equal(inst.vertex_colors, meshsal.objects.toys.make("cup", seed=7).vertex_colors)


def test_draw_instance_refuses_bad_spreads():
    with pytest.raises(ValueError, match="spreads"):
        instances.draw_instance(np.random.default_rng(0), scale_spread=1.5)
