"""Symmetry: the channel (local mirror correlation) on pop-out stimuli, its contract, bad inputs."""

import importlib

import cv2
import numpy as np
import pytest

from meshsal.attention import symmetry

SIZE = 224


def smooth_noise(rng, shape, sigma=2.0):
    """Random texture in [0, 1] with blobs of about ``sigma`` pixels (SIFT finds keypoints in it)."""
    n = cv2.GaussianBlur(rng.random(shape).astype(np.float32), (0, 0), sigma)
    return (n - n.min()) / (n.max() - n.min())


def polar_grid(size):
    yy, xx = np.mgrid[:size, :size] - (size - 1) / 2.0
    return xx, yy


def asymmetric_blob(rng, size):
    """A blob whose radius carries random harmonics with random phases: no mirror or rotational symmetry."""
    xx, yy = polar_grid(size)
    t = np.arctan2(yy, xx)
    radius = np.ones_like(t)
    for m in range(1, 5):
        radius += rng.uniform(0.05, 0.2) * np.cos(m * t + rng.uniform(0, 2 * np.pi))
    return np.hypot(xx, yy) <= 0.5 * size * radius / radius.max()


def butterfly(size):
    """Mask mirror-symmetric about the vertical centre line: four wings round a long body."""
    xx, yy = (c / (0.5 * size) for c in polar_grid(size))
    t = np.arctan2(yy, np.abs(xx))
    wings = np.hypot(xx, yy) <= 0.55 + 0.45 * np.abs(np.sin(2 * t + 0.3))
    body = (xx / 0.15) ** 2 + (yy / 0.95) ** 2 <= 1.0
    return wings | body


def star(size, points, inner=0.45):
    """Mask of a star polygon with ``points`` tips (rotational symmetry of that order)."""
    xx, yy = polar_grid(size)
    t = np.arctan2(yy, xx)
    tip = np.abs((t * points / (2 * np.pi)) % 1.0 - 0.5) * 2.0
    return np.hypot(xx, yy) / (0.5 * size) <= inner + (1.0 - inner) * tip


class Scene:
    """A gray canvas where shapes are pasted at free places (4 px apart)."""

    def __init__(self, rng, background):
        self.rng = rng
        self.img = np.full((SIZE, SIZE), background, np.float32)
        self.taken = np.zeros((SIZE, SIZE), bool)

    def paste(self, patch, mask):
        s = mask.shape[0]
        for _ in range(500):
            top, left = (int(v) for v in self.rng.integers(0, SIZE - s, 2))
            if not self.taken[max(0, top - 4) : top + s + 4, max(0, left - 4) : left + s + 4].any():
                break
        else:
            return None
        self.img[top : top + s, left : left + s][mask] = patch[mask]
        self.taken[top : top + s, left : left + s] = True
        where = np.zeros((SIZE, SIZE), bool)
        where[top : top + s, left : left + s] = mask
        return where

    def rgb(self):
        return np.repeat(np.clip(self.img, 0, 1)[:, :, None], 3, axis=2)


def butterfly_scene(seed, symmetric=True):
    """A textured butterfly (mirror-symmetric texture and outline) among textured asymmetric blobs.

    ``symmetric=False`` is the control: the same scene, but the target gets an
    independent right half and an asymmetric outline (one more blob).
    """
    rng = np.random.default_rng(seed)
    scene = Scene(rng, rng.uniform(0.2, 0.8))
    size = 2 * int(rng.integers(28, 40))
    half = smooth_noise(rng, (size, size // 2))
    other, outline = smooth_noise(rng, half.shape), asymmetric_blob(rng, size)
    if symmetric:
        target = scene.paste(np.hstack([half, half[:, ::-1]]), butterfly(size))
    else:
        target = scene.paste(np.hstack([half, other]), outline)
    for _ in range(int(rng.integers(4, 7))):
        s = int(rng.integers(40, 70))
        scene.paste(smooth_noise(rng, (s, s)), asymmetric_blob(rng, s))
    return scene.rgb(), target


def star_scene(seed):
    """A plain star with 5 to 7 tips among plain asymmetric blobs of random gray levels."""
    rng = np.random.default_rng(seed)
    scene = Scene(rng, rng.uniform(0.1, 0.4))
    size = int(rng.integers(60, 90))
    target = scene.paste(np.full((size, size), rng.uniform(0.7, 1.0), np.float32), star(size, int(rng.integers(5, 8))))
    for _ in range(int(rng.integers(4, 7))):
        s = int(rng.integers(30, 60))
        scene.paste(np.full((s, s), rng.uniform(0.5, 1.0), np.float32), asymmetric_blob(rng, s))
    return scene.rgb(), target


def texture_field(rng, shape, sigma):
    """Gaussian-blurred white noise of zero mean and unit variance (the variance follows from the kernel)."""
    k = cv2.getGaussianKernel(2 * int(np.ceil(4 * sigma)) + 1, sigma)
    n = cv2.sepFilter2D(rng.standard_normal(shape).astype(np.float32), -1, k, k, borderType=cv2.BORDER_REFLECT)
    return n / np.float32((k**2).sum())


def mirrored(t, twice_axis):
    """``t`` made mirror-symmetric about column ``twice_axis / 2`` (a pixel or between two): left copied onto right."""
    cols = np.arange(t.shape[1])
    source = twice_axis - cols
    copy = (2 * cols > twice_axis) & (source >= 0)
    out = t.copy()
    out[:, cols[copy]] = t[:, source[copy]]
    return out


def place_apart(rng, n, radius, gap):
    """n integer centres of disks of ``radius`` inside the image, ``gap`` pixels apart."""
    centres = []
    while len(centres) < n:
        c = rng.integers(radius + 2, SIZE - radius - 2, size=2)
        if all(np.hypot(*(c - d)) > 2 * radius + gap for d in centres):
            centres.append(c)
    return centres


def symmetric_patch_scene(seed, horizontal=False, symmetric=True, n_distractors=5):
    """A mirror-symmetric disk of texture hidden in the same texture, among disks of unmirrored texture.

    The ground and every patch are independent draws of one random texture
    (blob size and contrast vary with the seed); each patch is blended in
    over a 4-pixel ramp that keeps the variance constant, so no patch has an
    outline, a contrast or a texture of its own.  The target patch is the
    same draw with one half mirrored onto the other about the line through
    its centre (vertical, or horizontal with ``horizontal``; on a pixel or
    between two); ``symmetric=False`` leaves it unmirrored, the control.
    Returns the RGB image and the target disk.
    """
    rng = np.random.default_rng(seed)
    sigma = rng.uniform(1.5, 3.0)
    radius = int(rng.integers(20, 29))
    field = texture_field(rng, (SIZE, SIZE), sigma)
    rows, cols = np.indices((SIZE, SIZE))
    target = None
    for i, (r0, c0) in enumerate(place_apart(rng, n_distractors + 1, radius, gap=8)):
        patch = texture_field(rng, (SIZE, SIZE), sigma)
        half = int(rng.integers(0, 2))
        if i == 0 and symmetric:
            patch = mirrored(patch.T, 2 * r0 + half).T if horizontal else mirrored(patch, 2 * c0 + half)
        ar, ac = (r0 + 0.5 * half, c0) if horizontal else (r0, c0 + 0.5 * half)
        r = np.hypot(rows - ar, cols - ac)
        a = np.clip((radius - r) / 4.0 + 0.5, 0, 1).astype(np.float32)
        field = (a * patch + (1 - a) * field) / np.sqrt(a * a + (1 - a) ** 2)
        if i == 0:
            target = r <= radius
    img = np.clip(rng.uniform(0.4, 0.6) + rng.uniform(0.1, 0.16) * field, 0, 1).astype(np.float32)
    return np.repeat(img[:, :, None], 3, axis=2), target


def symmetric_item_scene(seed, horizontal=False, symmetric=True, n_distractors=5):
    """Textured items with irregular soft outlines on a flat ground, one with a mirror-symmetric texture.

    Every item is an asymmetric blob (its own outline, blurred) filled with a
    zero-mean draw of one random texture, so items have the ground's mean
    luminance and one contrast.  The target's texture is mirrored about the
    vertical (or horizontal) line through the blob's centre; its outline
    stays as asymmetric as the others'.  ``symmetric=False`` is the control.
    """
    rng = np.random.default_rng(seed)
    sigma = rng.uniform(1.5, 3.0)
    size = int(rng.integers(44, 60))
    ground = rng.uniform(0.35, 0.65)
    contrast = rng.uniform(0.1, 0.16)
    field = np.zeros((SIZE, SIZE), np.float32)
    target = None
    for i, (r0, c0) in enumerate(place_apart(rng, n_distractors + 1, size // 2 + 2, gap=6)):
        mask = asymmetric_blob(rng, size).astype(np.float32)
        texture = texture_field(rng, (size, size), sigma)
        if i == 0 and symmetric:
            texture = mirrored(texture.T, size - 1).T if horizontal else mirrored(texture, size - 1)
        top, left = r0 - size // 2, c0 - size // 2
        field[top : top + size, left : left + size] += cv2.GaussianBlur(mask, (0, 0), 1.5) * texture
        if i == 0:
            target = np.zeros((SIZE, SIZE), bool)
            target[top : top + size, left : left + size] = mask > 0
    img = np.clip(ground + contrast * field, 0, 1).astype(np.float32)
    return np.repeat(img[:, :, None], 3, axis=2), target


def assert_pops_out(m, target):
    argmax = np.unravel_index(np.argmax(m), m.shape)
    assert target[argmax], f"argmax {argmax} outside the target"
    inside, outside = m[target].mean(), m[~target].mean()
    assert inside >= 2.0 * outside, f"mean inside {inside:.3f} < 2 x mean outside {outside:.3f}"


# --- pop-out stimuli -------------------------------------------------------------


@pytest.mark.parametrize("seed", range(6))
def test_mirror_symmetric_butterfly_pops_out_among_asymmetric_blobs(seed):
    img, target = butterfly_scene(seed)
    assert_pops_out(symmetry(img), target)


@pytest.mark.parametrize("seed", range(6))
def test_radially_symmetric_star_pops_out_among_clutter(seed):
    img, target = star_scene(seed)
    assert_pops_out(symmetry(img), target)


def test_butterfly_without_symmetry_does_not_pop_out():
    """Control: the same scenes with the target's symmetry broken (texture and outline)."""

    def ratio(img, target):
        m = symmetry(img)
        return m[target].mean() / max(m[~target].mean(), 1e-6)

    seeds = range(12)
    broken = np.median([ratio(*butterfly_scene(seed, symmetric=False)) for seed in seeds])
    intact = np.median([ratio(*butterfly_scene(seed)) for seed in seeds])
    assert broken < 2.0
    assert broken < 0.25 * intact


@pytest.mark.parametrize("horizontal", [False, True], ids=["vertical axis", "horizontal axis"])
@pytest.mark.parametrize("seed", range(4))
def test_mirror_symmetric_patch_pops_out_of_the_same_texture(seed, horizontal):
    """Only the symmetry of its texture sets the target apart: no outline, contrast or texture statistics."""
    img, target = symmetric_patch_scene(seed, horizontal)
    assert_pops_out(symmetry(img), target)


@pytest.mark.parametrize("horizontal", [False, True], ids=["vertical axis", "horizontal axis"])
@pytest.mark.parametrize("seed", range(4))
def test_item_with_mirror_symmetric_texture_pops_out_among_asymmetric_items(seed, horizontal):
    """All outlines are irregular and unlike each other: the target differs only in its texture's symmetry."""
    img, target = symmetric_item_scene(seed, horizontal)
    assert_pops_out(symmetry(img), target)


@pytest.mark.parametrize("scene", [symmetric_patch_scene, symmetric_item_scene], ids=["patches", "items"])
def test_unmirrored_target_does_not_pop_out(scene):
    """Control: the same displays with the target's texture left unmirrored."""
    peaks_in_target = 0
    for seed in range(4):
        for horizontal in (False, True):
            img, target = scene(seed, horizontal, symmetric=False)
            m = symmetry(img)
            peaks_in_target += bool(target[np.unravel_index(np.argmax(m), m.shape)])
            control = m[target].mean() / m[~target].mean()
            img, target = scene(seed, horizontal)
            m = symmetry(img)
            assert m[target].mean() / m[~target].mean() > 2.0 * control
            if scene is symmetric_patch_scene:
                assert control < 2.0
    # Chance: one item in six holds the strongest chance symmetry.
    assert peaks_in_target <= 2


# --- contract -------------------------------------------------------------------


def test_flat_image_gives_a_zero_map():
    m = symmetry(np.full((200, 180, 3), 0.4, np.float32))
    assert m.shape == (200, 180) and m.dtype == np.float32
    assert not m.any()


@pytest.mark.parametrize("seed", range(4))
def test_random_texture_gives_a_weak_map_and_its_mirror_image_a_strong_one(seed):
    """The map's peak is the strongest symmetry: chance symmetries of noise stay far below a real one."""
    rng = np.random.default_rng(seed)
    texture = smooth_noise(rng, (128, 128), rng.uniform(1.0, 4.0))
    assert symmetry(np.repeat(texture[:, :, None], 3, axis=2)).max() < 0.1
    half = texture[:, :64]
    for mirror in (np.hstack([half, half[:, ::-1]]), np.hstack([half, half[:, ::-1]]).T):
        assert symmetry(np.repeat(np.ascontiguousarray(mirror)[:, :, None], 3, axis=2)).max() > 0.4


@pytest.mark.parametrize("shape", [(1, 1, 3), (2, 2, 3), (5, 7, 3), (16, 16, 3), (31, 200, 3), (200, 3, 3)])
def test_tiny_and_thin_images_give_valid_maps(shape):
    img = np.random.default_rng(0).random(shape).astype(np.float32)
    m = symmetry(img)
    assert m.shape == shape[:2] and m.dtype == np.float32
    assert np.isfinite(m).all() and m.min() >= 0.0 and m.max() <= 1.0


@pytest.mark.parametrize("pattern", ["edge", "diagonal edge", "ramp"])
def test_an_edge_or_a_ramp_is_no_axis(pattern):
    """Such patterns are their own mirror images about every line across them, which is no symmetric object."""
    rows, cols = np.indices((128, 128))
    gray = {
        "edge": np.where(rows > 60, 0.8, 0.2),
        "diagonal edge": np.where(rows > cols, 0.8, 0.2),
        "ramp": cols / 127.0,
    }[pattern]
    assert symmetry(np.repeat(gray.astype(np.float32)[:, :, None], 3, axis=2)).max() < 0.05


def test_output_shape_dtype_range_and_determinism():
    img, _ = butterfly_scene(11)
    img = np.ascontiguousarray(img[:203, :187])
    m = symmetry(img)
    assert m.shape == (203, 187) and m.dtype == np.float32
    assert m.min() >= 0.0 and m.max() <= 1.0 and m.max() > 0.0
    assert np.array_equal(m, symmetry(img.copy()))


def test_color_image_works_through_its_luminance():
    img, target = star_scene(2)
    tinted = (img * np.array([1.0, 0.6, 0.3], np.float32)).astype(np.float32)
    assert_pops_out(symmetry(tinted), target)


@pytest.mark.parametrize(
    "bad, message",
    [
        (np.zeros((64, 64), np.float32), "shape"),
        (np.zeros((64, 64, 4), np.float32), "shape"),
        (np.zeros((0, 64, 3), np.float32), "empty"),
        (np.zeros((64, 64, 3), np.uint8), "float"),
        (np.full((64, 64, 3), np.nan, np.float32), "NaN"),
        (np.full((64, 64, 3), 1.5, np.float32), r"\[0, 1\]"),
        (np.full((64, 64, 3), -0.1, np.float32), r"\[0, 1\]"),
    ],
)
def test_bad_images_raise_clear_errors(bad, message):
    with pytest.raises(ValueError, match=message):
        symmetry(bad)


def test_map_follows_the_image_when_it_is_flipped_or_transposed():
    img, target = symmetric_patch_scene(0)
    m = symmetry(img)
    flipped = symmetry(np.ascontiguousarray(img[:, ::-1]))[:, ::-1]
    transposed = symmetry(np.ascontiguousarray(img.transpose(1, 0, 2))).T
    # Not exact: the pyramid's grid does not flip with the image.
    assert np.corrcoef(m.ravel(), flipped.ravel())[0, 1] > 0.9
    assert np.corrcoef(m.ravel(), transposed.ravel())[0, 1] > 0.9


def test_texture_contrast_hardly_changes_the_map():
    """A correlation: halving the contrast keeps the map's shape; only the contrast floor lowers it a little."""
    img, target = symmetric_patch_scene(1)
    full = symmetry(img)
    half = symmetry((0.5 + 0.5 * (img - 0.5)).astype(np.float32))
    assert np.corrcoef(full.ravel(), half.ravel())[0, 1] > 0.99
    assert 0.7 * full.max() <= half.max() <= full.max()
    assert_pops_out(half, target)


def test_map_is_independent_of_the_thread_count():
    img, _ = symmetric_item_scene(2)
    threads = cv2.getNumThreads()
    try:
        cv2.setNumThreads(1)
        single = symmetry(img)
    finally:
        cv2.setNumThreads(threads)
    assert np.array_equal(single, symmetry(img))


def _correlation_by_definition(b: np.ndarray):
    """The windowed mirror correlation about vertical lines, pair by pair in float64 (the module notes)."""
    from scipy.ndimage import convolve1d

    module = importlib.import_module("meshsal.attention.symmetry")
    h, w = b.shape
    r = module._R
    pad = np.pad(b.astype(np.float64), ((0, 0), (r, r)))
    c = np.arange(w) + r
    along = module._ALONG_KERNEL.ravel().astype(np.float64)
    out = []
    for k, first in ((module._K_ON, lambda m: c - m), (module._K_BETWEEN, lambda m: c + 1 - m)):
        num = sum(k[m - 1] * pad[:, first(m)] * pad[:, c + m] for m in range(1, r + 1))
        den = sum(k[m - 1] * 0.5 * (pad[:, first(m)] ** 2 + pad[:, c + m] ** 2) for m in range(1, r + 1))
        present = sum(k[m - 1] * ((first(m) >= r) & (first(m) < w + r) & (c + m < w + r)) for m in range(1, r + 1))
        rows = convolve1d(np.ones(h), along, mode="constant")
        num, den = (convolve1d(a, along, axis=0, mode="constant") for a in (num, den))
        out.append(num / (den + module._FLOOR) * (present[None, :] * rows[:, None]) ** 2)
    return out


@pytest.mark.parametrize("where", ["middle", "corner", "whole"])
def test_mirror_correlation_is_its_definition_on_a_patch_on_black(where):
    _mirror_correlation = importlib.import_module("meshsal.attention.symmetry")._mirror_correlation
    rng = np.random.default_rng(3)
    b = np.zeros((60, 70), np.float32)
    patch = {"middle": (slice(20, 35), slice(25, 50)), "corner": (slice(0, 12), slice(58, 70))}.get(where)
    if patch is None:
        b[:] = rng.normal(size=b.shape)
    else:
        b[patch] = rng.normal(size=b[patch].shape)
    for got, want in zip(_mirror_correlation(b[None]), _correlation_by_definition(b)):
        got = got[0]
        np.testing.assert_allclose(got, want, atol=2e-5)
        # Off the columns between the patch's first and last, no pair has two non-zero partners.
        assert not got[:, ~b.any(axis=0)].any() or where == "whole"


def test_mirror_correlation_of_a_stack_is_each_map_s_alone_bit_for_bit():
    """Maps whose patches lie in different places share one crop (the union of their boxes) and one call."""
    _mirror_correlation = importlib.import_module("meshsal.attention.symmetry")._mirror_correlation
    rng = np.random.default_rng(5)
    b = np.zeros((4, 60, 70), np.float32)
    for k, (rows, cols) in enumerate(
        [
            (slice(20, 35), slice(25, 50)),
            (slice(0, 12), slice(58, 70)),
            (slice(40, 60), slice(0, 9)),
            (slice(0, 0), slice(0, 0)),
        ]
    ):
        b[k][rows, cols] = rng.normal(size=b[k][rows, cols].shape)
    stacked = _mirror_correlation(b)
    for k in range(len(b)):
        for got, alone in zip(stacked, _mirror_correlation(b[k : k + 1])):
            assert np.array_equal(got[k], alone[0])
