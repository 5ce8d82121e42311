"""Roll-invariant imprint descriptors: unchanged by the pad's rotation, changed by the surface."""

import numpy as np
import pytest
import shapes

import tactile
from tactile.features import describe, polar_fourier


def test_quarter_turns_leave_the_descriptor_unchanged_exactly():
    img = np.random.default_rng(0).random((3, 16, 16))
    for k in (1, 2, 3):
        assert np.allclose(polar_fourier(img), polar_fourier(np.rot90(img, k, axes=(1, 2))), atol=1e-12)


def test_a_stack_is_described_block_by_block_as_each_imprint_alone(monkeypatch):
    import tactile.features as features

    stack = np.random.default_rng(1).random((11, 16, 16)).astype(np.float32)
    one_by_one = np.concatenate([polar_fourier(img[None]) for img in stack])
    monkeypatch.setattr(features, "_ROWS", 4)  # blocks of 4, 4 and 3
    blocked = polar_fourier(stack)
    assert blocked.dtype == np.float64 and np.array_equal(blocked, one_by_one)
    assert np.array_equal(blocked, polar_fourier(stack.astype(np.float64)))


def test_a_radially_symmetric_imprint_has_no_angular_harmonics():
    yy, xx = np.mgrid[0:16, 0:16] - 7.5
    dome = np.clip(1.0 - np.hypot(yy, xx) / 8.0, 0, 1)[None]
    f = polar_fourier(dome).reshape(7, 6)
    assert np.all(f[:, 1:] < 0.02 * f[:, :1].max())


def test_a_cylinder_touched_at_any_roll_looks_the_same_to_the_descriptor_not_to_the_taxels():
    rod = shapes.cylinder(radius=12.0, length=120.0, around=256, along=12)
    sensor = tactile.Sensor(mode="pressure")
    P, N = np.array([[0.0, 12.0, 0.0]] * 4), np.array([[0.0, 1.0, 0.0]] * 4)
    images = tactile.imprints(rod, P, N, sensor, angles_deg=[0.0, 37.0, 90.0, 141.0])
    raw, polar = describe(images), describe(images, "polar")
    raw_change = np.linalg.norm(raw[1:] - raw[0], axis=1) / np.linalg.norm(raw[0])
    polar_change = np.linalg.norm(polar[1:] - polar[0], axis=1) / np.linalg.norm(polar[0])
    assert raw_change.min() > 0.3  # the taxels see a turned groove
    assert polar_change.max() < 0.1 and polar_change.max() < raw_change.min() / 4


def test_a_sphere_and_a_cylinder_differ_to_the_descriptor():
    sensor = tactile.Sensor(mode="pressure")
    ball = tactile.imprints(shapes.sphere(radius=12.0, n=64), [[0.0, 12.0, 0.0]], [[0.0, 1.0, 0.0]], sensor)
    rod = tactile.imprints(
        shapes.cylinder(radius=12.0, length=120.0, around=256, along=12), [[0.0, 12.0, 0.0]], [[0.0, 1.0, 0.0]], sensor
    )
    a, b = describe(ball, "polar")[0], describe(rod, "polar")[0]
    assert np.linalg.norm(a - b) > 0.2 * np.linalg.norm(a)


def test_bad_inputs_are_refused():
    with pytest.raises(ValueError, match="unknown features"):
        describe(np.zeros((1, 16, 16)), "sift")
    with pytest.raises(ValueError, match="shape"):
        polar_fourier(np.zeros((16, 16)))
