"""Surface frames: known moments of a box and a cone, invariance to pose, size and tessellation, and bad input."""

import igl
import numpy as np
import pytest

from meshsal.points.frames import ShapeFrame, lay_landmarks, shape_frame

# Two triangles per side of the box of corners (+-1, +-1, +-1), corner k = 4 [x > 0] + 2 [y > 0] + [z > 0].
BOX_FACES = np.array(
    [0, 1, 3, 0, 3, 2, 4, 6, 7, 4, 7, 5, 0, 4, 5, 0, 5, 1, 2, 3, 7, 2, 7, 6, 0, 2, 6, 0, 6, 4, 1, 5, 7, 1, 7, 3]
).reshape(-1, 3)


def _box(half):
    return np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * half


def _cone(height=3.0, radius=0.5, segments=48):
    """A closed cone standing on the z = 0 plane, its apex at (0, 0, height)."""
    t = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    ring = np.c_[radius * np.cos(t), radius * np.sin(t), np.zeros(segments)]
    V = np.vstack([ring, [[0.0, 0.0, height], [0.0, 0.0, 0.0]]])
    apex, base = segments, segments + 1
    F = [[k, (k + 1) % segments, apex] for k in range(segments)]
    F += [[(k + 1) % segments, k, base] for k in range(segments)]
    return V, np.array(F)


def _lopsided():
    """A tetrahedron with six unequal edges: no symmetry, three distinct spreads, no balanced axis."""
    V = np.array([[0.0, 0, 0], [4.0, 0.3, 0.1], [0.7, 2.2, -0.2], [0.4, 0.9, 1.3]])
    F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    return V, F


def _turn(seed):
    Q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return Q * np.sign(np.linalg.det(Q))


def test_a_box_has_its_centre_its_sides_as_axes_and_its_surfaces_rms_radius():
    V = _box([3.0, 2.0, 1.0]) + [1.0, 2.0, 3.0]
    frame = shape_frame(V, BOX_FACES)
    np.testing.assert_allclose(frame.center, [1.0, 2.0, 3.0], atol=1e-12)
    np.testing.assert_allclose(np.abs(frame.axes), np.eye(3), atol=1e-12)  # longest side first
    # Mean squared distance over the six faces (areas 8, 12 and 24, two of each): 602 2/3 over 88.
    assert frame.scale == pytest.approx(np.sqrt((360.0 + 181.0 + 1 / 3 + 61.0 + 1 / 3) / 88.0), rel=1e-12)


def test_a_tall_cones_first_axis_points_to_its_apex_however_it_stands():
    V, F = _cone()
    assert shape_frame(V, F).axes[0] == pytest.approx([0.0, 0.0, 1.0], abs=1e-9)
    upside_down = V * [1.0, 1.0, -1.0]
    assert shape_frame(upside_down, F).axes[0] == pytest.approx([0.0, 0.0, -1.0], abs=1e-9)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_frame_turns_moves_and_scales_with_the_shape(seed):
    V, F = _lopsided()
    R, s, t = _turn(seed), 0.3 + seed, np.array([5.0, -2.0, 7.0]) * seed
    one, other = shape_frame(V, F), shape_frame(s * V @ R.T + t, F)
    assert np.linalg.det(one.axes) == pytest.approx(1.0) and np.linalg.det(other.axes) == pytest.approx(1.0)
    np.testing.assert_allclose(other.center, s * R @ one.center + t, atol=1e-9)
    np.testing.assert_allclose(other.axes, one.axes @ R.T, atol=1e-9)
    assert other.scale == pytest.approx(s * one.scale, rel=1e-12)
    # Every point has the same frame coordinates on both.
    np.testing.assert_allclose(other.to_shape(s * V @ R.T + t), one.to_shape(V), atol=1e-9)
    np.testing.assert_allclose(one.from_shape(one.to_shape(V)), V, atol=1e-12)


def test_another_tessellation_of_the_same_surface_has_the_same_frame():
    V, F = _lopsided()
    U, G = igl.upsample(V, F, 2)  # each face split in sixteen, the surface unchanged
    flipped = F[:, ::-1]
    double_sided = np.vstack([F, flipped])
    want = shape_frame(V, F)
    for W, H in ((U, G), (V, flipped), (V, double_sided)):
        got = shape_frame(W, H)
        np.testing.assert_allclose(got.center, want.center, atol=1e-12)
        np.testing.assert_allclose(got.axes, want.axes, atol=1e-9)
        assert got.scale == pytest.approx(want.scale, rel=1e-12)


def test_landmarks_laid_onto_a_decimated_turned_instance_land_where_they_lie_on_it():
    from meshsal.mesh import Mesh
    from meshsal.objects import toys
    from meshsal.objects.instances import retessellate
    from meshsal.points.places import LANDMARKS, candidate_pool

    hand = toys.make("hand")
    R, s = _turn(7), 1.4
    turned = retessellate(hand, "decimated")
    turned = Mesh(vertices=s * turned.vertices @ R.T + 3.0, faces=turned.faces)
    L = hand.vertices[candidate_pool(hand, 2)[:LANDMARKS]]
    laid = lay_landmarks(shape_frame(turned.vertices, turned.faces), shape_frame(hand.vertices, hand.faces), L)
    frame = shape_frame(hand.vertices, hand.faces)
    # Back in the hand's own pose, each laid landmark is within 1 % of the hand's size of where it is.
    back = ((laid - 3.0) / s) @ R
    assert np.linalg.norm(back - L, axis=1).max() < 0.01 * frame.scale


def test_a_stored_frame_reads_back_and_a_wrong_shape_is_refused():
    frame = shape_frame(*_lopsided())
    back = ShapeFrame.from_array(frame.to_array())
    np.testing.assert_array_equal(back.center, frame.center)
    np.testing.assert_array_equal(back.axes, frame.axes)
    assert back.scale == frame.scale
    with pytest.raises(ValueError, match=r"\(5, 3\), got \(4, 3\)"):
        ShapeFrame.from_array(np.zeros((4, 3)))


def test_faces_without_area_are_refused():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
    with pytest.raises(ValueError, match="no area"):
        shape_frame(V, [[0, 1, 2]])
    with pytest.raises(ValueError, match="no area"):
        shape_frame(V, np.zeros((0, 3), int))
