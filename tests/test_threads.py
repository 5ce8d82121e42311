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


def test_saliency_views_leaves_the_process_thread_settings_as_it_found_them(monkeypatch):
    import sys

    import cv2
    import pytest

    from meshsal import attention
    from meshsal.attention import combine

    cup = meshsal.scale_to(meshsal.objects.toys.make("cup"), 150.0)
    # More views than a stack holds, so that two threads share them.
    views = render_views(cup, [c for s in view_rig()[:10] for c in s], size=32, threads=1)
    assert len(views) > combine._VIEWS_PER_STACK
    before = (sys.getswitchinterval(), cv2.getNumThreads())
    one = attention.saliency_views(views, cup, threads=1)
    seen, channels = [], combine.image_channels_stack
    monkeypatch.setattr(
        combine, "image_channels_stack", lambda imgs: seen.append(sys.getswitchinterval()) or channels(imgs)
    )
    two = attention.saliency_views(views, cup, threads=2)
    assert seen == [combine._SWITCH_S] * 2 and combine._SWITCH_S != before[0]
    assert (sys.getswitchinterval(), cv2.getNumThreads()) == before
    for a, b in zip(one, two):
        np.testing.assert_array_equal(a.map, b.map)
    broken = list(views)
    broken[-1] = type(views[0])(**{**vars(views[0]), "rgb": np.full((32, 32, 3), np.nan, np.float32)})
    with pytest.raises(ValueError):
        attention.saliency_views(broken, cup, threads=2)
    assert (sys.getswitchinterval(), cv2.getNumThreads()) == before
