"""Attention maps by their definitions: Itti's N(.), the stacks of many views against each view alone, the
orientation and entropy filters that work only near the object."""

import numpy as np
import pytest

from meshsal import attention
from meshsal.attention.local import local_entropy
from meshsal.attention.pyramid import (
    _warp_upsample,
    gaussian_pyramid,
    normalize_map,
)


def _n_by_definition(m: np.ndarray) -> np.ndarray:
    """N(.) "maxima" of one map, written out plainly: the reference the stacked code must equal bit for bit."""
    import cv2

    lo, hi = float(m.min()), float(m.max())
    if not hi - lo > 1e-6:
        return np.zeros(m.shape, np.float32)
    m = (m - lo) * np.float32(1.0 / (hi - lo))
    peaks = (m == cv2.dilate(m, np.ones((3, 3), np.uint8))) & (m > 0.1)
    r, c = np.unravel_index(int(m.argmax()), m.shape)
    peaks[max(r - 2, 0) : r + 3, max(c - 2, 0) : c + 3] = False
    mean = float(m[peaks].mean()) if peaks.any() else 0.0
    return m * np.float32((1.0 - mean) ** 2)


def test_normalize_maps_gives_each_map_n_by_its_definition():
    import cv2

    from meshsal.attention.pyramid import normalize_maps

    rng = np.random.default_rng(7)
    maps = []
    # Rival peaks from none to hundreds: sums of fewer than 8 values, of 8 to 128 and of more, pairwise.
    for n_peaks in (0, 1, 2, 3, 5, 7, 8, 9, 15, 16, 40, 130, 300):
        m = np.zeros((64, 64), np.float32)
        spots = rng.choice(64 * 64, size=n_peaks + 1, replace=False)
        m.ravel()[spots] = rng.uniform(0.2, 1.0, size=spots.size).astype(np.float32)
        m += rng.uniform(0, 0.01, size=m.shape).astype(np.float32)
        maps.append(m)
    maps.append(np.full((64, 64), 2.5, np.float32))  # flat: zeros
    plateau = np.zeros((64, 64), np.float32)
    plateau[10:14, 20:30] = 1.0  # a tie for the maximum
    maps.append(plateau)
    maps.append(cv2.GaussianBlur(rng.random((64, 64)).astype(np.float32), (0, 0), 2))
    maps = np.stack(maps)
    got = normalize_maps(maps)
    assert got.dtype == np.float32 and got.shape == maps.shape
    for k, m in enumerate(maps):
        np.testing.assert_array_equal(got[k].view(np.int32), _n_by_definition(m).view(np.int32), err_msg=str(k))
        np.testing.assert_array_equal(normalize_map(m), got[k])
    # The order of the stack changes nothing.
    np.testing.assert_array_equal(normalize_maps(maps[::-1]), got[::-1])
    with pytest.raises(ValueError, match="stack"):
        normalize_maps(maps[0])


@pytest.mark.parametrize("shape", [(64, 64), (100, 140), (37, 50), (8, 9)])
def test_conspicuity_maps_of_a_stack_are_each_images_own(shape):
    from meshsal.attention.pyramid import conspicuity_maps

    rng = np.random.default_rng(shape[0])
    features = rng.random((5, 2, *shape)).astype(np.float32)
    features[1] = 0.0  # a blank image among the others
    features[2, :, : shape[0] // 3, : shape[1] // 3] += 2.0  # a planted bright corner
    together = conspicuity_maps(features)
    assert together.shape == (5, *shape) and together.dtype == np.float32
    assert not together[1].any()
    for k in range(5):
        alone = conspicuity_maps(features[k : k + 1])[0]
        np.testing.assert_array_equal(together[k].view(np.int32), alone.view(np.int32))
    np.testing.assert_array_equal(conspicuity_maps(features[::-1]), together[::-1])


def test_image_channels_of_a_stack_are_each_images_own():
    from meshsal.attention.combine import image_channels, image_channels_stack

    rng = np.random.default_rng(3)
    imgs = rng.random((4, 72, 96, 3)).astype(np.float32)
    imgs[1] = 0.5  # flat: no symmetry, no contrast
    imgs[2, 20:40, 30:60] = (0.9, 0.1, 0.1)  # a red patch
    imgs[3] = np.concatenate([imgs[3, :, :48], imgs[3, :, :48][:, ::-1]], axis=1)  # mirror-symmetric
    stacked = image_channels_stack(imgs)
    assert set(stacked) == set(attention.IMAGE_CHANNELS)
    for k, img in enumerate(imgs):
        for name, m in image_channels(img).items():
            np.testing.assert_array_equal(stacked[name][k].view(np.int32), m.view(np.int32), err_msg=f"{name} {k}")
    assert not stacked["symmetry"][1].any() and stacked["symmetry"][3].max() > stacked["symmetry"][0].max()
    with pytest.raises(ValueError, match="at least one image"):
        image_channels_stack(imgs[:0])
    with pytest.raises(ValueError, match="intensity"):
        image_channels_stack(imgs * 2.0, ["intensity"])


@pytest.mark.parametrize(
    "factor, coarse, shape",
    [(2, (37, 50), (73, 100)), (2, (64, 64), (128, 128)), (4, (17, 9), (66, 33)), (4, (64, 64), (256, 256))],
)
def test_upsamples_of_a_stack_are_each_maps_warp(factor, coarse, shape):
    from meshsal.attention.pyramid import upsample_stack
    from meshsal.util.reproducible import kernels

    rng = np.random.default_rng(factor + coarse[0])
    maps = rng.standard_normal((5, *coarse)).astype(np.float32)
    maps[1] = 0.0
    maps[2, 0, :3] = -0.0
    together = upsample_stack(maps, factor, shape)  # five maps: the separable passes
    assert together.shape == (5, *shape) and together.dtype == np.float32
    for k, m in enumerate(maps):
        theirs = _warp_upsample(m, factor, shape)
        if kernels()["opencv"].startswith("baseline"):
            np.testing.assert_array_equal(together[k].view(np.int32), theirs.view(np.int32), err_msg=str(k))
        else:  # OpenCV's own kernels fuse multiply and add: the same up to a rounding
            np.testing.assert_allclose(together[k], theirs, rtol=0, atol=4e-7 * float(np.abs(m).max()))


def test_an_image_stack_checks_once_and_shares_its_grey_levels():
    import cv2

    from meshsal.attention.images import LUMA, MEAN, ImageStack, check_images

    rng = np.random.default_rng(11)
    imgs = rng.random((3, 40, 56, 3)).astype(np.float32)
    stack = ImageStack.of(list(imgs), "intensity")
    assert ImageStack.of(stack) is stack and stack.shape == (40, 56)
    for k, img in enumerate(imgs):
        np.testing.assert_array_equal(stack.intensity[k], cv2.transform(img, MEAN))
        np.testing.assert_array_equal(stack.luma[k], cv2.transform(img, LUMA))
        for level, alone in zip(stack.intensity_pyramid, gaussian_pyramid(cv2.transform(img, MEAN))):
            np.testing.assert_array_equal(level[k], alone)
    assert stack.intensity is stack.intensity  # computed once
    bad = imgs.copy()
    bad[2, 5, 5, 1] = np.nan
    with pytest.raises(ValueError, match="color: image contains NaN"):
        ImageStack.of(bad, "color")
    with pytest.raises(ValueError, match="one shape"):
        check_images([imgs[0], imgs[1, :20]], "dkl")
    with pytest.raises(ValueError, match="dtype uint8"):
        check_images((imgs * 255).astype(np.uint8))
    with pytest.raises(ValueError, match="stack"):
        check_images(imgs[0])
    with pytest.raises(ValueError, match="one shape"):
        check_images([])


def test_single_image_channels_are_stacks_of_one():
    """Each channel's single-image function and its stack function give each image the same bits."""
    from meshsal.attention.dkl import dkl_stack
    from meshsal.attention.itti import color_stack, intensity_stack, orientation_stack
    from meshsal.attention.local import contrast_stack, entropy_stack
    from meshsal.attention.symmetry import symmetry_stack

    rng = np.random.default_rng(12)
    imgs = rng.random((5, 64, 80, 3)).astype(np.float32)
    imgs[1] = 0.3
    imgs[3, 10:30, 20:50] = (0.9, 0.2, 0.1)
    pairs = [
        (attention.intensity, intensity_stack),
        (attention.color, color_stack),
        (attention.orientation, orientation_stack),
        (attention.dkl, dkl_stack),
        (attention.symmetry, symmetry_stack),
        (attention.entropy, entropy_stack),
        (attention.contrast, contrast_stack),
    ]
    for single, stacked in pairs:
        together = stacked(imgs)
        assert together.shape == (5, 64, 80) and together.dtype == np.float32
        for k, img in enumerate(imgs):
            np.testing.assert_array_equal(
                together[k].view(np.int32), single(img).view(np.int32), err_msg=single.__name__
            )


def _orientation_energy_by_definition(img):
    """orientation_energy without crops: each orientation's Gabor energy at levels 0-2 of the whole image,
    brought up map by map, summed over levels, weighted by its share of the four."""
    import cv2

    from meshsal.attention.itti import ORIENTATIONS_DEG, gabor_energy

    gray = cv2.transform(img, np.full((1, 3), 1.0 / 3.0, np.float32))
    base = gaussian_pyramid(gray, 3)
    energy = np.zeros((4, *gray.shape), np.float32)
    for k, theta in enumerate(ORIENTATIONS_DEG):
        for level, g in enumerate(base):
            e = gabor_energy(g, theta)
            energy[k] += _warp_upsample(e, 2**level, gray.shape) if level else e
    total = energy.sum(axis=0)
    floor = np.float32(1e-6 * max(float(total.max()), 1e-30))
    return energy * (energy / np.maximum(total, floor))


@pytest.mark.parametrize(
    "box",
    [
        (slice(20, 50), slice(30, 90)),
        (slice(0, 12), slice(0, 7)),
        (slice(60, 64), slice(70, 80)),
        (slice(33, 34), slice(5, 6)),
    ],
    ids=["inside", "corner", "bottom-right edge", "one pixel"],
)
def test_orientation_energy_on_a_black_background_filters_only_near_the_object(box):
    """A view's black background: the Gabor filters and the coarse levels' upsampling run near the object
    only, with the bits of the whole image's."""
    from meshsal.attention.itti import orientation_energy
    from meshsal.util.reproducible import kernels

    rng = np.random.default_rng(box[0].start)
    img = np.zeros((64, 80, 3), np.float32)
    img[box] = rng.random(img[box].shape)
    got, want = orientation_energy(img), _orientation_energy_by_definition(img)
    if kernels()["opencv"].startswith("baseline"):
        np.testing.assert_array_equal(got.view(np.int32), want.view(np.int32))
    else:  # the separable upsampling and OpenCV's own warp differ by a rounding
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * float(want.max()))
    assert got[:, 58:, :].any() == (box[0].stop > 48)  # nothing far below the object
    assert not orientation_energy(np.zeros((64, 80, 3), np.float32)).any()


@pytest.mark.parametrize("size", [9, 17])  # counts in 8 bits, and in float32 (17 x 17 > 255)
@pytest.mark.parametrize(
    "box", [(slice(20, 40), slice(10, 30)), (slice(0, 5), slice(50, 60)), (slice(58, 60), slice(0, 60)), None]
)
def test_local_entropy_counts_only_near_the_other_bins_with_the_bits_of_the_whole_image(size, box):
    """Windows of bin 0 alone (a black background) share one entropy; the rest is counted on a crop."""
    from meshsal.attention.local import _window_entropy

    rng = np.random.default_rng(size)
    gray = rng.uniform(0, 1 / 16, (60, 60)).astype(np.float32)  # all bin 0, not all zero
    if box is not None:
        gray[box] = rng.random(gray[box].shape)
    got = local_entropy(gray, size)
    want = _window_entropy(np.minimum((gray * 16).astype(np.int32), 15), size, 16)
    np.testing.assert_array_equal(got.view(np.int32), want.view(np.int32))
    assert (got > 0).any() == (box is not None)
