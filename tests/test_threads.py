"""Views and interest points do not depend on how many threads compute them."""

import numpy as np

import meshsal
from meshsal.views.cameras import view_rig
from meshsal.views.render import render_views


def test_views_are_the_same_with_one_thread_and_with_two():
    cup = meshsal.scale_to(meshsal.objects.toys.make("cup"), 150.0)
    cameras = [c for s in view_rig()[:6] for c in s]
    one = render_views(cup, cameras, size=48, threads=1)
    two = render_views(cup, cameras, size=48, threads=2)
    for a, b in zip(one, two):
        for name in ("rgb", "depth", "face_id", "bary", "mask"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_attention_points_are_the_same_with_one_thread_and_with_two():
    cup = meshsal.scale_to(meshsal.objects.toys.make("cup"), 150.0)
    one = meshsal.interest_points(cup, n=10, size=48, threads=1)
    two = meshsal.interest_points(cup, n=10, size=48, threads=2)
    for name in ("vertex_ids", "positions", "normals", "scores", "votes"):
        np.testing.assert_array_equal(getattr(one, name), getattr(two, name), err_msg=name)
    assert one.views == two.views and one.best_set == two.best_set
