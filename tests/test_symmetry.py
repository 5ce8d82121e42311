"""Symmetry channel (Loy & Eklundh 2006): planted axes and centres, pop-out stimuli, bad inputs."""

import cv2
import numpy as np
import pytest

from meshsal.attention import symmetry
from meshsal.attention.symmetry import mirror_descriptors, symmetries

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


def assert_pops_out(m, target):
    argmax = np.unravel_index(np.argmax(m), m.shape)
    assert target[argmax], f"argmax {argmax} outside the target"
    inside, outside = m[target].mean(), m[~target].mean()
    assert inside >= 2.0 * outside, f"mean inside {inside:.3f} < 2 x mean outside {outside:.3f}"


# --- mirrored descriptors ---------------------------------------------------


def test_mirror_descriptors_equal_descriptors_of_the_flipped_image():
    rng = np.random.default_rng(3)
    g8 = (smooth_noise(rng, (160, 160), 3.0) * 255).astype(np.uint8)
    sift = cv2.SIFT_create(nfeatures=80)
    kps, desc = sift.detectAndCompute(g8, None)
    assert len(kps) > 20
    w = g8.shape[1]
    flipped_kps = [
        cv2.KeyPoint(w - 1 - k.pt[0], k.pt[1], k.size, (180.0 - k.angle) % 360.0, k.response, k.octave, k.class_id)
        for k in kps
    ]
    kept, flipped_desc = sift.compute(np.ascontiguousarray(g8[:, ::-1]), flipped_kps)
    assert len(kept) == len(kps)

    def cosine(a, b):
        return (a * b).sum(1) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))

    mirrored = mirror_descriptors(desc)
    assert np.median(cosine(mirrored, flipped_desc)) > 0.98
    # Without the permutation the descriptors differ: the test can tell.
    assert np.median(cosine(desc, flipped_desc)) < 0.9
    assert np.array_equal(mirror_descriptors(mirrored), desc)


def test_mirror_descriptors_rejects_wrong_shape():
    with pytest.raises(ValueError, match="128"):
        mirror_descriptors(np.zeros((4, 64), np.float32))


# --- planted axes and centres -------------------------------------------------


def mirror_image(seed, h, w, axis_col):
    """Texture mirror-symmetric about column ``axis_col`` (exactly, pixel for pixel), gray RGB."""
    rng = np.random.default_rng(seed)
    half = smooth_noise(rng, (h, axis_col), 2.0)
    img = np.zeros((h, w), np.float32)
    img[:, :axis_col] = half
    right = min(axis_col, w - axis_col - 1)
    img[:, axis_col] = smooth_noise(rng, (h, 1), 1.0)[:, 0]
    img[:, axis_col + 1 : axis_col + 1 + right] = half[:, ::-1][:, :right]
    return np.repeat(img[:, :, None], 3, axis=2)


@pytest.mark.parametrize("seed, axis_col", [(0, 90), (1, 110), (2, 130)])
def test_vertical_mirror_axis_is_found(seed, axis_col):
    h, w = 192, 224
    img = mirror_image(seed, h, w, axis_col)
    found = symmetries(img, sigma_d=None)
    assert len(found.axes) and np.all(np.diff(found.axes[:, 2]) <= 0)  # strongest first
    theta, r, strength = found.axes[0]
    assert min(theta, np.pi - theta) < np.radians(4)  # normal horizontal: a vertical axis
    x_axis = (w - 1) / 2.0 + (r if theta < np.pi / 2 else -r)
    assert abs(x_axis - axis_col) <= 1.0
    pairs = found.axis_pairs[0]
    xy = found.keypoints.xy
    # Supporting pairs sit on either side of the axis, at about the same height.
    assert np.all((xy[pairs[:, 0], 0] - axis_col) * (xy[pairs[:, 1], 0] - axis_col) < 0)
    assert np.median(np.abs(xy[pairs[:, 0], 1] - xy[pairs[:, 1], 1])) < 2.0
    # True mirror partners have angular symmetry and scale agreement near 1 each.
    assert strength >= 0.8 * len(pairs)


def test_horizontal_mirror_axis_is_found_in_the_transposed_image():
    img = np.ascontiguousarray(mirror_image(4, 224, 192, 100).transpose(1, 0, 2))
    found = symmetries(img)
    theta, r, _ = found.axes[0]
    assert abs(theta - np.pi / 2) < np.radians(4)
    assert abs((img.shape[0] - 1) / 2.0 + r - 100) <= 1.0


@pytest.mark.parametrize("seed, degrees", [(5, 30.0), (6, 65.0), (7, 140.0)])
def test_oblique_mirror_axis_is_found(seed, degrees):
    """A mirror texture turned about a point of its axis: the axis turns with it."""
    big = mirror_image(seed, 321, 321, 160)  # axis on column 160, through the centre pixel
    turn = cv2.getRotationMatrix2D((160.0, 160.0), degrees, 1.0)
    img = cv2.warpAffine(big, turn, (321, 321), flags=cv2.INTER_LINEAR)[48:273, 48:273]
    found = symmetries(np.ascontiguousarray(np.clip(img, 0, 1)), sigma_d=None)
    normal = turn[:, :2] @ [1.0, 0.0]  # the axis' normal, turned
    expected = np.arctan2(normal[1], normal[0]) % np.pi
    theta, r, strength = found.axes[0]
    assert abs(np.angle(np.exp(2j * (theta - expected)))) < np.radians(3)
    assert abs(r) <= 1.5  # the axis still runs through the centre pixel (112, 112)
    assert strength >= 0.8 * len(found.axis_pairs[0])  # orientations agree with an oblique mirror


@pytest.mark.parametrize("seed, centre", [(0, (100, 90)), (1, (120, 110))])
def test_rotation_centre_is_found(seed, centre):
    """A texture copied at 0, 90, 180 and 270 degrees about a known pixel."""
    rng = np.random.default_rng(seed)
    q = 56
    quarter = smooth_noise(rng, (q, q), 2.0)
    block = np.zeros((2 * q, 2 * q), np.float32)
    block[:q, q:] = quarter
    block = np.max([np.rot90(block, k) for k in range(4)], axis=0)
    img = np.full((192, 224), 0.5, np.float32)
    cx, cy = centre
    img[cy - q : cy + q, cx - q : cx + q] = block
    found = symmetries(np.repeat(img[:, :, None], 3, axis=2), sigma_d=None)
    assert len(found.centres)
    x, y, strength = found.centres[0]
    # The block's rotation centre is the corner shared by its four quarters.
    assert np.hypot(x - (cx - 0.5), y - (cy - 0.5)) <= 1.5
    assert strength >= 0.8 * len(found.centre_pairs[0])  # rotated copies agree in scale


def test_symmetries_move_with_the_scene():
    """Translating a star on a flat background translates its centre and its axes."""
    mask = star(70, 5)
    found = []
    for top, left in [(40, 30), (52, 50)]:  # even shifts: SIFT's half-size image shifts by whole pixels
        img = np.full((192, 224), 0.3, np.float32)
        img[top : top + 70, left : left + 70][mask] = 0.9
        found.append(symmetries(np.repeat(img[:, :, None], 3, axis=2), n_axes=5, min_strength=0.0))
    (x0, y0, _), (x1, y1, _) = found[0].centres[0], found[1].centres[0]
    assert abs(x0 - (30 + 34.5)) <= 1.0 and abs(y0 - (40 + 34.5)) <= 1.0
    assert abs(x1 - x0 - 20) <= 0.5 and abs(y1 - y0 - 12) <= 0.5
    # The five axes of the star, 36 degrees apart, each through the centre.
    before, after = found[0].axes, found[1].axes
    assert len(before) == len(after) == 5
    assert np.allclose(np.sort(np.diff(np.sort(before[:, 0]))), np.radians(36), atol=np.radians(2))
    for theta, r, _ in before:
        normal = np.array([np.cos(theta), np.sin(theta)])
        assert abs(normal @ ([x0, y0] - np.array([223, 191]) / 2.0) - r) <= 1.0
        t1, r1, _ = after[np.argmin(np.abs(np.angle(np.exp(2j * (after[:, 0] - theta)))))]
        assert abs(np.angle(np.exp(2j * (t1 - theta)))) < np.radians(2)
        if abs(t1 - theta) > np.pi / 2:  # the same line written across the wrap
            r1 = -r1
        assert abs(r1 - r - normal @ [20.0, 12.0]) <= 1.0


# --- pop-out stimuli -------------------------------------------------------------


@pytest.mark.parametrize("seed", range(6))
def test_mirror_symmetric_butterfly_pops_out_among_asymmetric_blobs(seed):
    img, target = butterfly_scene(seed)
    assert_pops_out(symmetry(img), target)


@pytest.mark.parametrize("seed", range(6))
def test_radially_symmetric_star_pops_out_among_clutter(seed):
    img, target = star_scene(seed)
    assert_pops_out(symmetry(img), target)
    # Its rotational symmetry is found, not only its mirror axes.
    x, y, _ = symmetries(img).centres[0]
    rows, cols = np.nonzero(target)
    assert np.hypot(x - cols.mean(), y - rows.mean()) <= 2.0


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


# --- contract -------------------------------------------------------------------


def test_flat_image_gives_a_zero_map():
    m = symmetry(np.full((200, 180, 3), 0.4, np.float32))
    assert m.shape == (200, 180) and m.dtype == np.float32
    assert not m.any()


def test_no_matches_gives_a_zero_map():
    rng = np.random.default_rng(5)
    img = np.repeat(smooth_noise(rng, (96, 96))[:, :, None], 3, axis=2)
    assert len(symmetries(img).keypoints.xy) > 10
    assert not symmetry(img, match_ratio=1e-3).any()


@pytest.mark.parametrize("shape", [(1, 1, 3), (5, 7, 3), (16, 16, 3), (31, 200, 3)])
def test_tiny_and_thin_images_give_valid_maps(shape):
    img = np.random.default_rng(0).random(shape).astype(np.float32)
    m = symmetry(img)
    assert m.shape == shape[:2] and m.dtype == np.float32
    assert m.min() >= 0.0 and m.max() <= 1.0


def test_more_neighbours_than_keypoints_is_fine():
    img, target = star_scene(1)
    assert_pops_out(symmetry(img, k=500), target)


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


@pytest.mark.parametrize(
    "params",
    [
        {"n_features": 1},
        {"work_scale": 0.0},
        {"work_scale": 1.5},
        {"k": 0},
        {"match_ratio": 0.0},
        {"sigma_s": -1.0},
        {"sigma_d": 0.0},
        {"n_axes": -1},
        {"min_strength": 2.0},
        {"min_pairs": 0},
        {"splat": 0.0},
    ],
)
def test_bad_parameters_raise(params):
    img = np.full((64, 64, 3), 0.5, np.float32)
    with pytest.raises(ValueError, match="symmetry"):
        symmetry(img, **params)
