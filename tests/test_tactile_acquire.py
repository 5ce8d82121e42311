"""Acquisition realism: clean when asked, reproducible when seeded, each error doing what it says."""

import numpy as np
import pytest
import shapes

import tactile
from tactile import Perturbation, Sensor, acquire

P = np.array([[3.0, 0.0, 2.0], [-10.0, 0.0, 5.0], [0.0, 0.0, -12.0], [12.0, 0.0, 12.0]])
N = np.tile([0.0, 1.0, 0.0], (4, 1))


@pytest.fixture(scope="module")
def surface():
    return shapes.bumps()


@pytest.mark.parametrize("mode", ["contour", "pressure"])
def test_no_perturbation_gives_exactly_the_clean_imprints(surface, mode):
    sensor = Sensor(mode=mode)
    clean = tactile.imprints(surface, P, N, sensor)
    np.testing.assert_array_equal(acquire(surface, P, N, sensor, Perturbation.none(), rng=5), clean)
    np.testing.assert_array_equal(acquire(surface, P, N, sensor, None, rng=None), clean)


def test_seeded_acquisitions_are_reproducible_and_seeds_matter(surface):
    perturb = Perturbation.typical()
    a = acquire(surface, P, N, Sensor(), perturb, rng=11)
    b = acquire(surface, P, N, Sensor(), perturb, rng=np.random.default_rng(11))
    c = acquire(surface, P, N, Sensor(), perturb, rng=12)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    assert a.dtype == np.float32 and a.min() >= 0.0 and a.max() <= 1.0
    # Without a seed the default one applies: two calls read alike.
    np.testing.assert_array_equal(acquire(surface, P, N, Sensor(), perturb), acquire(surface, P, N, Sensor(), perturb))


def test_adc_quantizes_to_its_levels_and_dead_taxels_read_zero(surface):
    sensor = Sensor(mode="pressure")
    out = acquire(surface, P, N, sensor, Perturbation(adc_bits=3, dead_fraction=0.2), rng=1)
    np.testing.assert_allclose(out * 7, np.round(out * 7), atol=1e-5)
    dead = (out == 0).all(axis=0)
    # The same device for every imprint: the dead map is shared, about 20 % of taxels.
    clean = tactile.imprints(surface, P, N, sensor)
    assert 0.1 < dead.mean() < 0.3
    assert ((clean > 0.1).all(axis=0) & ~dead).any()


def test_noise_has_the_requested_spread():
    plane = shapes.plane()
    sensor = Sensor(mode="pressure", rows=32, cols=32)
    points = np.tile([0.0, 0.0, 0.0], (20, 1))
    normals = np.tile([0.0, 1.0, 0.0], (20, 1))
    # A plane presses every taxel to full scale; only noise below full scale survives the clip.
    out = acquire(plane, points, normals, sensor, Perturbation(noise=0.05), rng=2)
    below = 1.0 - out[out < 1.0]
    # Clipping at 1 keeps the lower half of a normal distribution: its mean is sd * sqrt(2/pi).
    assert abs(below.mean() - 0.05 * np.sqrt(2 / np.pi)) < 0.005


def test_gain_spread_is_one_map_per_device():
    plane = shapes.plane()
    sensor = Sensor(mode="pressure")
    points = np.tile([0.0, 0.0, 0.0], (3, 1))
    normals = np.tile([0.0, 1.0, 0.0], (3, 1))
    out = acquire(plane, points, normals, sensor, Perturbation(gain_spread=0.1), rng=4)
    np.testing.assert_array_equal(out[0], out[1])
    assert out.std() > 0.02


def test_one_session_stream_is_one_device_whatever_it_touches():
    plane = shapes.plane()
    sensor = Sensor(mode="pressure")
    device = Perturbation(gain_spread=0.2, dead_fraction=0.1, uniform_rotation=True)  # rolls are drawn per touch
    up = np.array([[0.0, 1.0, 0.0]])
    one = acquire(plane, [[0.0, 0.0, 0.0]], up, sensor, device, rng=np.random.default_rng([5, 1]))
    three = acquire(
        plane,
        [[20.0, 0.0, 0.0], [0.0, 0.0, 0.0], [-20.0, 0.0, 5.0]],
        np.repeat(up, 3, axis=0),
        sensor,
        device,
        rng=np.random.default_rng([5, 1]),
    )
    # A flat plane looks the same under any roll: the same gain map and dead taxels read the same imprint.
    np.testing.assert_array_equal(one[0], three[1])
    other = acquire(plane, [[0.0, 0.0, 0.0]], up, sensor, device, rng=np.random.default_rng([5, 2]))
    assert not np.array_equal(one[0], other[0])


def test_cover_blur_spreads_a_sharp_edge():
    cube = shapes.box(half=30.0, n=60)
    sensor = Sensor(mode="pressure", plane="paper")
    point, normal = [[29.75, 30.0, 0.1]], [[0.0, 1.0, 0.0]]
    sharp = acquire(cube, point, normal, sensor, Perturbation.none(), rng=0)[0]
    soft = acquire(cube, point, normal, sensor, Perturbation(blur_mm=2.0), rng=0)[0]
    assert sharp[8, 8] == 0.0 and soft[8, 8] > 0.1
    assert soft[8, 7] < 1.0
    assert abs(soft.sum() - sharp.sum()) < 0.2 * sharp.sum()


def test_uniform_rotation_turns_the_image(surface):
    sensor = Sensor()
    clean = tactile.imprints(surface, P, N, sensor)
    turned = acquire(surface, P, N, sensor, Perturbation(uniform_rotation=True), rng=9)
    assert not np.allclose(turned, clean)
    # Rotation keeps the amount of contour roughly (only the pad corners change).
    assert np.allclose(turned.sum(axis=(1, 2)), clean.sum(axis=(1, 2)), rtol=0.35)


def test_jitter_and_tilt_move_the_imprint(surface):
    sensor = Sensor(mode="pressure")
    clean = tactile.imprints(surface, P, N, sensor)
    for perturb in (Perturbation(jitter_mm=2.0), Perturbation(tilt_deg=5.0)):
        moved = acquire(surface, P, N, sensor, perturb, rng=3)
        assert not np.array_equal(moved, clean)
        assert moved.max() > 0.5


@pytest.mark.parametrize(
    "bad",
    [
        dict(noise=-0.1),
        dict(dead_fraction=1.0),
        dict(adc_bits=40),
        dict(adc_bits=2.5),
        dict(jitter_mm=float("inf")),
        dict(uniform_rotation="yes"),
        dict(blur_mm="x"),
    ],
)
def test_perturbation_rejects_bad_fields(bad):
    with pytest.raises(ValueError, match="Perturbation"):
        Perturbation(**bad)


def test_acquire_rejects_bad_rng_and_perturbation(surface):
    with pytest.raises(ValueError, match="rng"):
        acquire(surface, P, N, Sensor(), Perturbation.none(), rng="seed")
    with pytest.raises(ValueError, match="Perturbation"):
        acquire(surface, P, N, Sensor(), {"noise": 0.1}, rng=0)


def test_perturbation_flags():
    assert Perturbation.none().is_clean and not Perturbation.typical().is_clean
    assert Perturbation(**Perturbation.typical().to_dict()) == Perturbation.typical()


@pytest.mark.parametrize("exact", [False, True])
def test_requests_cast_together_read_what_each_reads_alone(surface, exact):
    # Sessions and codebooks mixed, every placement error on, one request with no point: each its own stream.
    perturb = Perturbation.typical()
    tilted = Perturbation(jitter_mm=0.5, tilt_deg=5.0, rotation_deg=10.0, noise=0.01)
    requests = [
        tactile.Acquisition(P, N, perturb, 1),
        tactile.Acquisition(P[:0], N[:0], perturb, 2),
        tactile.Acquisition(P[1:3], N[1:3], tilted, np.random.default_rng(3), draws=3),
        tactile.Acquisition(P[::-1], N, tilted, 4),
    ]
    together = tactile.acquire_all(surface, requests, Sensor(), exact=exact)
    alone = [
        acquire(surface, P, N, Sensor(), perturb, 1, exact=exact),
        acquire(surface, P[:0], N[:0], Sensor(), perturb, 2, exact=exact),
        tactile.touch_codebook(surface, P[1:3], N[1:3], Sensor(), tilted, 3, np.random.default_rng(3))
        if not exact
        else tactile.acquire_all(
            surface, [tactile.Acquisition(P[1:3], N[1:3], tilted, np.random.default_rng(3), 3)], exact=True
        )[0],
        acquire(surface, P[::-1], N, Sensor(), tilted, 4, exact=exact),
    ]
    assert [t.shape for t in together] == [(4, 16, 16), (0, 16, 16), (2, 3, 16, 16), (4, 16, 16)]
    for t, a in zip(together, alone):
        np.testing.assert_array_equal(t, a)
    # The same points in another order read the same images, reordered: no pad depends on the others.
    assert not np.array_equal(together[0], together[3][::-1])  # other streams, other readings
    clean = tactile.acquire_all(surface, [tactile.Acquisition(P, N), tactile.Acquisition(P[::-1], N)], exact=exact)
    np.testing.assert_array_equal(clean[0], clean[1][::-1])


def test_acquire_all_rejects_what_is_not_a_request(surface):
    with pytest.raises(ValueError, match="tactile.Acquisition"):
        tactile.acquire_all(surface, [(P, N)])
    with pytest.raises(ValueError, match="draws must be a positive integer"):
        tactile.acquire_all(surface, [tactile.Acquisition(P, N, draws=0)])
    assert tactile.acquire_all(surface, []) == []
