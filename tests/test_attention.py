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
