"""Image channels of the attention model: pop-out stimuli, as in psychophysics.

Each stimulus holds one target that differs from its distractors (and its
ground) only in the feature of the channel under test; the channel's map
must peak inside the target and be at least twice as high there on average
as elsewhere.  Target position, size and background vary with the seed.
"""

import numpy as np
import pytest

from meshsal import attention
from meshsal.attention.dkl import RGB_TO_LMS, dkl_axes, rgb_to_lms
from meshsal.attention.local import default_contrast_window, local_entropy
from meshsal.attention.pyramid import (
    _warp_upsample,
    across_scale_sum,
    center_surround_map,
    gaussian_pyramid,
    normalize_map,
    upsample,
)

SIZE = 256
SEEDS = range(4)


def disk(shape, center, radius):
    rows, cols = np.ogrid[: shape[0], : shape[1]]
    return (rows - center[0]) ** 2 + (cols - center[1]) ** 2 <= radius**2


def place(rng, n, radius, size=SIZE, gap=6):
    """n non-overlapping disk centres of the given radius inside the image."""
    centers = []
    while len(centers) < n:
        c = rng.uniform(radius + 2, size - radius - 2, size=2)
        if all(np.hypot(*(c - d)) > 2 * radius + gap for d in centers):
            centers.append(c)
    return [tuple(c) for c in centers]


def gray(value, size=SIZE):
    return np.full((size, size, 3), value, np.float32)


def assert_pops_out(m, target):
    assert m.shape == target.shape and m.dtype == np.float32
    peak = np.unravel_index(np.argmax(m), m.shape)
    assert target[peak], f"argmax {peak} outside the target"
    inside, outside = float(m[target].mean()), float(m[~target].mean())
    assert inside >= 2.0 * outside, f"mean inside {inside:.3f} < 2 x mean outside {outside:.3f}"


def disks_stimulus(seed, n_distractors=6, radii=(14, 24)):
    """Target disk and distractor disks of one radius; returns (rng, target mask, distractor masks)."""
    rng = np.random.default_rng(seed)
    radius = int(rng.integers(*radii))
    centers = place(rng, n_distractors + 1, radius)
    masks = [disk((SIZE, SIZE), c, radius) for c in centers]
    return rng, masks[0], masks[1:]


# ---------------------------------------------------------------- pop-out


@pytest.mark.parametrize("seed", SEEDS)
def test_intensity_bright_disk_among_dim(seed):
    rng, target, distractors = disks_stimulus(seed)
    ground = rng.uniform(0.05, 0.3)
    img = gray(ground)
    for d in distractors:
        img[d] = ground + 0.2
    img[target] = ground + 0.65
    assert_pops_out(attention.intensity(img), target)


@pytest.mark.parametrize("seed", SEEDS)
def test_color_red_disk_among_green(seed):
    rng, target, distractors = disks_stimulus(seed)
    img = gray(rng.uniform(0.3, 0.6))
    for d in distractors:
        img[d] = (0.15, 0.6, 0.15)
    img[target] = (0.75, 0.1, 0.1)
    assert_pops_out(attention.color(img), target)


def bar(shape, center, length, width, angle_deg):
    """A bar whose long axis is angle_deg counter-clockwise from vertical (image coordinates)."""
    rows, cols = np.mgrid[: shape[0], : shape[1]].astype(np.float64)
    a = np.deg2rad(angle_deg)
    along = -(rows - center[0]) * np.cos(a) - (cols - center[1]) * np.sin(a)
    across = -(rows - center[0]) * np.sin(a) + (cols - center[1]) * np.cos(a)
    return (np.abs(along) <= length / 2) & (np.abs(across) <= width / 2)


def search_grid(rng, n=3, size=SIZE, jitter=0.15):
    """Centres of an n x n search display, jittered by a fraction of the cell."""
    cell = size / n
    centers = [((i + 0.5) * cell, (j + 0.5) * cell) for i in range(n) for j in range(n)]
    return [(r + rng.uniform(-jitter, jitter) * cell, c + rng.uniform(-jitter, jitter) * cell) for r, c in centers]


@pytest.mark.parametrize("seed", SEEDS)
def test_orientation_oblique_bar_among_vertical(seed):
    rng = np.random.default_rng(seed)
    length = int(rng.integers(44, 56))
    width = int(rng.integers(7, 11))
    centers = search_grid(rng)
    k = int(rng.integers(len(centers)))
    ground = rng.uniform(0.1, 0.4)
    img = gray(ground)
    for i, c in enumerate(centers):
        img[bar(img.shape, c, length, width, 45.0 if i == k else 0.0)] = ground + 0.5
    # The target item is the disk the bar spins in: the map is coarser than a bar's width.
    target = disk(img.shape[:2], centers[k], length / 2)
    assert_pops_out(attention.orientation(img), target)


def dense_display(seed, spacing, odd_deg, base_deg):
    """A full regular grid of thin bars (length and width scale with the spacing), one at odd_deg."""
    rng = np.random.default_rng(seed)
    length, width = 0.6 * spacing, max(2, spacing // 10)
    ground = rng.uniform(0.05, 0.3)
    img = gray(ground)
    n = SIZE // spacing
    offset = (SIZE - n * spacing) / 2 + spacing / 2
    cells = [
        (offset + i * spacing + rng.uniform(-2, 2), offset + j * spacing + rng.uniform(-2, 2))
        for i in range(n)
        for j in range(n)
    ]
    k = int(rng.integers(len(cells)))
    for i, c in enumerate(cells):
        img[bar(img.shape, c, length, width, odd_deg if i == k else base_deg)] = ground + 0.6
    return img, disk(img.shape[:2], cells[k], spacing / 2)


@pytest.mark.parametrize("spacing", [24, 32, 48])
@pytest.mark.parametrize("odd_deg,base_deg", [(45, 0), (0, 45), (90, 0), (135, 45)])
def test_orientation_odd_bar_in_a_dense_grid(spacing, odd_deg, base_deg):
    """Pop-out in a dense display: every item has the same contrast, size and ends; only one angle differs."""
    for seed in SEEDS:
        img, target = dense_display(seed, spacing, odd_deg, base_deg)
        assert_pops_out(attention.orientation(img), target)


def srgb_from_lms(lms):
    lin = np.linalg.solve(RGB_TO_LMS.astype(np.float64), np.asarray(lms, np.float64))
    lin = np.clip(lin, 0.0, 1.0)
    return np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)


@pytest.mark.parametrize("seed", SEEDS)
def test_dkl_isoluminant_s_cone_target(seed):
    rng, target, distractors = disks_stimulus(seed)
    ground = rng.uniform(0.35, 0.55)
    img = gray(ground)
    # Distractors differ from the ground in luminance only: DKL must ignore them.
    for d, lum in zip(distractors, rng.uniform(0.1, 0.9, len(distractors))):
        img[d] = lum
    lms = rgb_to_lms(gray(ground, 1))[0, 0].astype(np.float64)
    lms[2] *= 1.6  # raise S only: L and M, hence luminance L + M, are unchanged
    color = srgb_from_lms(lms)
    img[target] = color
    # The target really is isoluminant with its surround and its intensity is not special.
    got = rgb_to_lms(img[target][:1][None])[0, 0]
    ref = rgb_to_lms(gray(ground, 1))[0, 0]
    assert abs((got[0] + got[1]) - (ref[0] + ref[1])) < 0.02 * (ref[0] + ref[1])
    assert_pops_out(attention.dkl(img), target)


@pytest.mark.parametrize("seed", SEEDS)
def test_entropy_noise_patch_on_flat_ground(seed):
    rng, target, _ = disks_stimulus(seed, 0, (16, 32))
    img = gray(rng.uniform(0.1, 0.9))
    img[target] = rng.uniform(0.0, 1.0, size=(int(target.sum()), 1))
    assert_pops_out(attention.entropy(img), target)


@pytest.mark.parametrize("seed", SEEDS)
def test_contrast_high_variance_region(seed):
    rng, target, _ = disks_stimulus(seed, 0, (30, 45))
    ground = rng.uniform(0.3, 0.7)
    # Low-variance texture everywhere, a high-variance checkerboard in the target.
    img = np.clip(ground + rng.normal(0, 0.02, (SIZE, SIZE, 1)), 0, 1).astype(np.float32)
    img = np.repeat(img, 3, axis=2)
    rows, cols = np.indices((SIZE, SIZE))
    checks = ((rows // 3 + cols // 3) % 2).astype(np.float32)
    img[target] = (ground + 0.25 * (2 * checks[target] - 1))[:, None]
    assert_pops_out(attention.contrast(img), target)


# ----------------------------------------------------- contracts and details


IMAGE_FUNCTIONS = [
    attention.intensity,
    attention.color,
    attention.orientation,
    attention.dkl,
    attention.entropy,
    attention.contrast,
]


def test_channels_constant():
    assert attention.CHANNELS == (
        "intensity",
        "color",
        "orientation",
        "dkl",
        "symmetry",
        "curvature",
        "entropy",
        "contrast",
    )


@pytest.mark.parametrize("fn", IMAGE_FUNCTIONS, ids=lambda f: f.__name__)
@pytest.mark.parametrize("shape", [(96, 160), (1, 1), (5, 7), (300, 40)])
def test_output_shape_dtype_range(fn, shape):
    img = np.random.default_rng(1).uniform(0, 1, shape + (3,)).astype(np.float32)
    m = fn(img)
    assert m.shape == shape and m.dtype == np.float32
    assert np.isfinite(m).all() and m.min() >= 0.0 and m.max() <= 1.0


@pytest.mark.parametrize("fn", IMAGE_FUNCTIONS, ids=lambda f: f.__name__)
def test_constant_image_gives_zero_map(fn):
    m = fn(gray(0.4, 64))
    assert m.shape == (64, 64) and not m.any()


@pytest.mark.parametrize("fn", IMAGE_FUNCTIONS, ids=lambda f: f.__name__)
@pytest.mark.parametrize(
    "img, message",
    [
        (np.zeros((8, 8), np.float32), "shape"),
        (np.zeros((8, 8, 4), np.float32), "shape"),
        (np.zeros((8, 8, 3), np.uint8), "dtype"),
        (np.full((8, 8, 3), 1.5, np.float32), r"\[0, 1\]"),
        (np.full((8, 8, 3), -0.1, np.float32), r"\[0, 1\]"),
        (np.full((8, 8, 3), np.nan, np.float32), "NaN"),
    ],
    ids=["gray", "rgba", "uint8", "above-1", "negative", "nan"],
)
def test_bad_images_raise(fn, img, message):
    with pytest.raises(ValueError, match=message):
        fn(img)


def test_float64_input_accepted():
    img = np.random.default_rng(2).uniform(0, 1, (64, 64, 3))
    np.testing.assert_allclose(attention.intensity(img), attention.intensity(img.astype(np.float32)), atol=1e-6)


def test_maps_follow_the_target_when_image_is_flipped():
    """Equivariance: flipping the stimulus flips the map (no built-in spatial bias)."""
    _, target, distractors = disks_stimulus(7)
    img = gray(0.2)
    for d in distractors:
        img[d] = 0.4
    img[target] = (0.9, 0.3, 0.2)
    for fn in (attention.intensity, attention.color, attention.entropy, attention.contrast):
        a = fn(img)
        b = fn(np.ascontiguousarray(img[:, ::-1]))[:, ::-1]
        assert np.corrcoef(a.ravel(), b.ravel())[0, 1] > 0.95, fn.__name__


def test_contrast_window_scales_with_image_and_is_configurable():
    assert default_contrast_window((512, 512)) == 81
    assert default_contrast_window((256, 256)) == 41
    # A thin high-variance stripe: a small window keeps the response narrow.
    img = gray(0.5, 128)
    img[:, 60:68] = np.where(np.indices((128, 8))[0] % 2 == 0, 0.0, 1.0)[..., None]
    narrow = attention.contrast(img, window=5)
    wide = attention.contrast(img, window=41)
    assert narrow[:, 30].max() == 0.0 and wide[:, 50].max() > 0.1
    with pytest.raises(ValueError, match="window"):
        attention.contrast(img, window=0)


def test_local_entropy_known_values():
    # Two gray levels in a checkerboard: 41 and 40 of the 81 window pixels.
    pattern = (np.indices((32, 32)).sum(axis=0) % 2).astype(np.float32)
    h = local_entropy(pattern, size=9, bins=16)
    assert h[16, 16] == pytest.approx(-(41 / 81) * np.log2(41 / 81) - (40 / 81) * np.log2(40 / 81), abs=1e-5)
    assert local_entropy(np.full((16, 16), 0.3, np.float32)).max() == 0.0


def test_local_entropy_matches_brute_force_histograms():
    rng = np.random.default_rng(3)
    img = rng.uniform(0, 1, (40, 40)).astype(np.float32) ** 2
    h = local_entropy(img, size=9, bins=16)
    q = np.minimum((img * 16).astype(int), 15)
    for r, c in rng.integers(4, 36, size=(20, 2)):
        counts = np.bincount(q[r - 4 : r + 5, c - 4 : c + 5].ravel(), minlength=16)
        p = counts[counts > 0] / 81.0
        assert h[r, c] == pytest.approx(-(p * np.log2(p)).sum(), abs=1e-4)


def test_gaussian_pyramid_levels_and_tiny_images():
    levels = gaussian_pyramid(np.zeros((256, 200), np.float32), 9)
    assert [p.shape for p in levels][:3] == [(256, 200), (128, 100), (64, 50)]
    assert len(levels) == 9
    assert len(gaussian_pyramid(np.zeros((5, 5), np.float32), 9)) == 4  # 5, 3, 2, 1
    assert len(gaussian_pyramid(np.zeros((1, 9), np.float32), 9)) == 1


def test_across_scale_sum_is_at_scale_four():
    feature = np.random.default_rng(0).random((256, 256)).astype(np.float32)
    assert across_scale_sum(gaussian_pyramid(feature)).shape == (16, 16)


def test_normalize_map_promotes_a_single_peak_over_many():
    rows, cols = np.indices((32, 32))

    def blobs(centers):
        return sum(np.exp(-((rows - r) ** 2 + (cols - c) ** 2) / 8.0) for r, c in centers).astype(np.float32)

    one = blobs([(16, 16)])
    many = blobs([(r, c) for r in range(4, 32, 8) for c in range(4, 32, 8)])
    for method in ("maxima", "iterative"):
        a, b = normalize_map(one, method), normalize_map(many, method)
        assert a.max() > 2 * b.max(), method
    assert not normalize_map(np.full((8, 8), 3.0, np.float32)).any()
    with pytest.raises(ValueError, match="method"):
        normalize_map(one, "median")


@pytest.mark.parametrize("level", [1, 2, 4])
def test_upsample_puts_coarse_levels_back_in_place(level):
    f = np.zeros((256, 256), np.float32)
    f[96, 160] = 1.0
    coarse = gaussian_pyramid(f, level + 1)[level]
    back = upsample(coarse, 2**level, f.shape)
    assert np.unravel_index(np.argmax(back), back.shape) == (96, 160)


@pytest.mark.parametrize(
    "factor, coarse, shape",
    [(16, (16, 16), (256, 256)), (16, (8, 8), (128, 128)), (8, (16, 16), (128, 128))]
    + [(8, (23, 17), (180, 130)), (16, (9, 12), (129, 190)), (32, (5, 6), (150, 161))],
)
def test_large_upsamples_have_the_bits_of_opencvs_warp_with_the_pinned_kernels(factor, coarse, shape, monkeypatch):
    import cv2

    from meshsal.util.reproducible import kernels

    rng = np.random.default_rng(factor)
    m = rng.standard_normal(coarse).astype(np.float32)
    m[0, 0], m[1, 1], m[2, 2:6] = -0.0, 0.0, 0.0  # a zero's sign survives as in OpenCV's kernel
    theirs = _warp_upsample(m, factor, shape)
    with monkeypatch.context() as patch:
        patch.setattr(cv2, "warpAffine", None)  # these sizes take the two separable passes
        mine = upsample(m, factor, shape)
    assert mine.shape == shape and mine.dtype == np.float32
    if kernels()["opencv"].startswith("baseline"):
        np.testing.assert_array_equal(mine.view(np.int32), theirs.view(np.int32))
    else:  # OpenCV's own kernels fuse multiply and add: the same up to a rounding
        np.testing.assert_allclose(mine, theirs, rtol=0, atol=4e-7 * float(np.abs(m).max()))


def test_center_surround_map_is_resolution_independent_in_placement():
    for size in (64, 128, 256, 512):
        f = np.zeros((size, size), np.float32)
        f[size // 8 : size // 4, 5 * size // 8 : 3 * size // 4] = 1.0
        m = center_surround_map(f)
        r, c = np.unravel_index(np.argmax(m), m.shape)
        assert abs(r - 3 * size / 16) < size / 8 and abs(c - 11 * size / 16) < size / 8, size


def test_dkl_axes_ignore_luminance():
    ramp = np.repeat(np.linspace(0, 1, 50, dtype=np.float32)[None, :, None], 3, axis=2)
    lm, s = dkl_axes(ramp)
    assert np.abs(lm).max() < 1e-5 and np.abs(s).max() < 1e-5
    # A pure luminance pattern leaves the DKL channel silent.
    img = np.ascontiguousarray(np.repeat(ramp, 50, axis=0))
    assert attention.intensity(img).any() and not attention.dkl(img).any()


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
