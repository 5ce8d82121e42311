"""The curvature channel and the combined saliency map of rendered views."""

from types import SimpleNamespace

import numpy as np
import pytest
from shapes import icosphere

from meshsal import attention
from meshsal.attention import CHANNELS, SaliencyResult, combine_maps, curvature, erode_mask, saliency
from meshsal.attention.combine import outline_radius
from meshsal.views.cameras import project, view_rig
from meshsal.views.render import render, surface_points

SIZE = 96


@pytest.fixture(scope="module")
def sphere():
    # A coloured sphere: a red cap on a gray body, so every channel sees something.
    mesh = icosphere(radius=1.0, subdivisions=3)
    cap = mesh.vertices[:, 0] > 0.6
    colors = np.where(cap[:, None], [0.8, 0.15, 0.1], [0.6, 0.6, 0.6]).astype(np.float32)
    return mesh.replace(vertex_colors=colors)


@pytest.fixture(scope="module")
def view(sphere):
    return render(sphere, view_rig()[0][0], size=SIZE)


def planted_field(mesh, view):
    """A smooth bump on the sphere centred on the point seen at the image centre."""
    point = surface_points(mesh, view, np.array([SIZE // 2 - 10]), np.array([SIZE // 2 + 12]))[0]
    d2 = ((mesh.vertices - point) ** 2).sum(axis=1)
    return np.exp(-d2 / (2 * 0.3**2)), point


# ------------------------------------------------------------- curvature


def test_curvature_interpolates_vertex_values_exactly():
    v = SimpleNamespace(
        face_id=np.array([[0, 1], [-1, 0]]),
        faces=np.array([[0, 1, 2], [1, 2, 3]]),
        bary=np.array([[[1, 0, 0], [0.2, 0.3, 0.5]], [[0, 0, 0], [0.25, 0.25, 0.5]]], np.float32),
    )
    values = np.array([10.0, 12.0, 14.0, 20.0])  # min-max over the mesh: (v - 10) / 10
    got = curvature(v, values)
    expected = np.array([[0.0, 0.2 * 0.2 + 0.3 * 0.4 + 0.5 * 1.0], [0.0, 0.25 * 0.0 + 0.25 * 0.2 + 0.5 * 0.4]])
    np.testing.assert_allclose(got, expected, atol=1e-6)
    assert got.dtype == np.float32


def test_curvature_on_rendered_sphere_matches_a_linear_field(sphere, view):
    # A linear field is reproduced exactly by barycentric interpolation on the flat faces.
    a = np.array([0.3, -0.5, 0.8])
    field = sphere.vertices @ a
    got = curvature(view, field)
    rows, cols = np.nonzero(view.mask)
    points = surface_points(sphere, view, rows, cols)
    expected = (points @ a - field.min()) / np.ptp(field)
    np.testing.assert_allclose(got[rows, cols], expected, atol=1e-4)
    assert not got[~view.mask].any()
    assert got.min() >= 0.0 and got.max() <= 1.0


def test_curvature_peaks_on_the_planted_bump(sphere, view):
    field, point = planted_field(sphere, view)
    got = curvature(view, field)
    peak = np.array(np.unravel_index(np.argmax(got), got.shape))
    ((row, col),) = project(view, point[None])
    assert np.hypot(peak[0] - row, peak[1] - col) <= 3.0
    assert got.max() > 0.95


def test_curvature_bad_inputs(sphere, view):
    n = sphere.vertices.shape[0]
    with pytest.raises(ValueError, match="one value per vertex"):
        curvature(view, np.zeros((n, 2)))
    with pytest.raises(ValueError, match="vertex_saliency has"):
        curvature(view, np.zeros(10))
    with pytest.raises(ValueError, match="NaN"):
        curvature(view, np.full(n, np.nan))
    # A constant field carries no saliency.
    assert not curvature(view, np.full(n, 3.0)).any()


# ------------------------------------------------------------- the mask


def test_erode_mask_shrinks_a_disk_by_the_radius():
    rows, cols = np.indices((101, 101))
    d = np.hypot(rows - 50, cols - 50)
    eroded = erode_mask(d <= 30, 5)
    assert eroded[50, 50] and eroded[50, 50 + 24] and not eroded[50, 50 + 26]
    assert np.array_equal(erode_mask(d <= 30, 0), d <= 30)
    # The image border counts as background.
    full = erode_mask(np.ones((20, 20), bool), 2)
    assert not full[:2].any() and full[2:-2, 2:-2].all()
    assert outline_radius((256, 256)) == 5 and outline_radius((1024, 512)) == 20


# ------------------------------------------------------------- combination


def test_combine_maps_promotes_a_peaked_channel_over_a_flat_one():
    mask = np.zeros((128, 128), bool)
    mask[8:120, 8:120] = True
    rows, cols = np.indices(mask.shape)
    blob = np.exp(-((rows - 40) ** 2 + (cols - 90) ** 2) / (2 * 8.0**2)).astype(np.float32)
    flat = np.ones(mask.shape, np.float32)
    channels = {"intensity": blob, "contrast": flat}
    weights = {"intensity": 1.0, "contrast": 1.0}
    # Without the floor, N(.) alone must keep the flat channel out.
    plain = combine_maps(channels, mask, weights, normalize=False, floor=None)
    normalized = combine_maps(channels, mask, weights, floor=None)
    # Without N(.) the flat channel lifts the whole object to half the peak;
    # with N(.) a channel that is the same everywhere carries no information.
    assert plain[100, 20] == pytest.approx(0.5, abs=0.01)
    assert normalized[100, 20] < 0.01
    assert np.unravel_index(np.argmax(normalized), mask.shape) == (40, 90)


def test_combine_maps_shows_a_hot_spot_not_a_plateau():
    # Known answer: a channel high all over the object (a shallow dome, 0.85 to 0.95),
    # one constant over it, and one small hot spot at (40, 90).
    mask = np.zeros((128, 128), bool)
    mask[8:120, 8:120] = True
    rows, cols = np.indices(mask.shape)
    channels = {name: np.zeros(mask.shape, np.float32) for name in CHANNELS}
    channels["symmetry"] = (0.95 - 0.1 * (np.hypot(rows - 64, cols - 64) / 80) ** 2).astype(np.float32)
    channels["color"] = np.full(mask.shape, 0.8, np.float32)
    channels["curvature"] = np.exp(-((rows - 40) ** 2 + (cols - 90) ** 2) / (2 * 2.5**2)).astype(np.float32)
    without_constant = dict(channels, color=np.zeros(mask.shape, np.float32))
    far = erode_mask(mask) & (np.hypot(rows - 40, cols - 90) > 10)
    for normalize in (False, True):
        m = combine_maps(channels, mask, normalize=normalize)
        # Without the median removed, half the maximum would cover all the object with
        # equal weights and 19% of it with N(.).
        assert attention.plateau_fraction(m, mask) < 0.01, normalize
        assert np.hypot(*np.subtract(np.unravel_index(np.argmax(m), m.shape), (40, 90))) <= 1.0
        assert m[far].max() < 0.1
        # The constant channel contributes nothing at all.
        np.testing.assert_array_equal(m, combine_maps(without_constant, mask, normalize=normalize))
    with pytest.raises(ValueError, match="percentile"):
        combine_maps(channels, mask, floor=101.0)


def test_combine_maps_validates_weights_and_channels():
    mask = np.ones((32, 32), bool)
    ch = {name: np.zeros((32, 32), np.float32) for name in CHANNELS}
    with pytest.raises(ValueError, match="unknown channel"):
        combine_maps(ch, mask, {"intensity": 1.0, "loudness": 1.0})
    with pytest.raises(ValueError, match="non-negative"):
        combine_maps(ch, mask, {"intensity": -1.0})
    with pytest.raises(ValueError, match="all zero"):
        combine_maps(ch, mask, {"intensity": 0.0})
    with pytest.raises(ValueError, match="not given"):
        combine_maps({"color": ch["color"]}, mask, {"intensity": 1.0})
    with pytest.raises(ValueError, match="shape"):
        combine_maps({"intensity": np.zeros((8, 8), np.float32)}, mask, {"intensity": 1.0})


# ------------------------------------------------------------- saliency()


@pytest.fixture(scope="module")
def result(sphere, view):
    field, _ = planted_field(sphere, view)
    return saliency(view, sphere, vertex_saliency=field)


def test_saliency_result_contract(result, view):
    assert isinstance(result, SaliencyResult)
    assert tuple(result.channels) == CHANNELS
    for name, m in result.channels.items():
        assert m.shape == (SIZE, SIZE) and m.dtype == np.float32, name
        assert m.min() >= 0.0 and m.max() <= 1.0, name
    m = result.map
    assert m.shape == (SIZE, SIZE) and m.dtype == np.float32
    assert m.min() >= 0.0 and m.max() == pytest.approx(1.0)
    assert not m[~view.mask].any()
    # The band along the outline is removed too.
    assert not m[~erode_mask(view.mask)].any()
    assert m[erode_mask(view.mask)].mean() > 0.05


@pytest.mark.parametrize("name", CHANNELS)
def test_weights_selecting_one_channel_reproduce_it(sphere, view, result, name):
    field, _ = planted_field(sphere, view)
    one = saliency(view, sphere, weights={name: 2.5}, vertex_saliency=field)
    inside = erode_mask(view.mask)
    # The channel on the eroded silhouette, above its median there, scaled to max.
    channel = np.where(inside, result.channels[name], 0.0)
    channel = np.where(inside, np.maximum(channel - np.median(channel[inside]), 0.0), 0.0)
    expected = channel / channel.max() if channel.max() > 0 else channel
    np.testing.assert_allclose(one.map, expected, atol=1e-5)


def test_saliency_follows_the_planted_curvature(sphere, view):
    field, point = planted_field(sphere, view)
    m = saliency(view, sphere, weights={"curvature": 1.0}, vertex_saliency=field).map
    ((row, col),) = project(view, point[None])
    peak = np.unravel_index(np.argmax(m), m.shape)
    assert np.hypot(peak[0] - row, peak[1] - col) <= 3.0


def test_saliency_computes_mesh_saliency_when_not_given(sphere, view):
    from meshsal.mesh.curvature import mesh_saliency

    a = saliency(view, sphere, weights={"curvature": 1.0})
    b = saliency(view, sphere, weights={"curvature": 1.0}, vertex_saliency=mesh_saliency(sphere))
    np.testing.assert_array_equal(a.channels["curvature"], b.channels["curvature"])


def test_saliency_rejects_bad_weights(sphere, view):
    field = np.zeros(sphere.vertices.shape[0])
    with pytest.raises(ValueError, match="unknown channel"):
        saliency(view, sphere, weights={"depth": 1.0}, vertex_saliency=field)
    with pytest.raises(ValueError, match="dict"):
        saliency(view, sphere, weights=[1.0] * 8, vertex_saliency=field)


def test_saliency_views_matches_one_by_one(sphere):
    cams = view_rig()[1][:3]
    views = [render(sphere, c, size=64) for c in cams]
    field = sphere.vertices[:, 1] ** 2
    batch = attention.saliency_views(views, sphere, vertex_saliency=field, threads=2)
    for v, r in zip(views, batch):
        # OpenCV may split work differently across threads: equal up to float32 rounding.
        np.testing.assert_allclose(r.map, saliency(v, sphere, vertex_saliency=field).map, atol=1e-5)


def test_saliency_views_does_not_depend_on_how_views_are_stacked(sphere, monkeypatch):
    from meshsal.attention import combine

    cams = [c for s in view_rig()[:3] for c in s]
    # Views of two sizes: a stack only holds views of one.
    views = [render(sphere, c, size=48 if k in (4, 5) else 40) for k, c in enumerate(cams)]
    field = sphere.vertices[:, 1] ** 2
    runs = {}
    for per_stack in (1, 5, 18):
        monkeypatch.setattr(combine, "_VIEWS_PER_STACK", per_stack)
        runs[per_stack] = attention.saliency_views(views, sphere, vertex_saliency=field, threads=1)
    for k, view in enumerate(views):
        alone = saliency(view, sphere, vertex_saliency=field)
        for run in runs.values():
            assert run[k].map.shape == view.mask.shape
            np.testing.assert_array_equal(run[k].map, alone.map)
            for name in CHANNELS:
                np.testing.assert_array_equal(run[k].channels[name], alone.channels[name], err_msg=name)


@pytest.mark.parametrize("q", [0.0, 12.5, 50.0, 50.5, 87.0, 99.9, 100.0])
def test_percentiles_of_rows_are_numpys_bit_for_bit(q):
    from meshsal.util.quantiles import percentiles

    rng = np.random.default_rng(int(q * 10))
    for dtype in (np.float32, np.float64):
        for n in (1, 2, 7, 331, 1000, 16383):
            values = rng.random((3, n), dtype=dtype) * 40.0
            values[1] = np.round(values[1] * 4) / 4  # ties
            got = percentiles(values, q)
            assert got.dtype == dtype
            np.testing.assert_array_equal(got, [dtype(np.percentile(row, q)) for row in values])
            np.testing.assert_array_equal(got, [dtype(np.quantile(row, q / 100.0)) for row in values])


def _combine_on_whole_images(channels, mask, erode=None, normalize=True, floor=50.0):
    """combine_maps with equal weights by its definition, on whole images: every channel cut to the eroded
    silhouette (zero elsewhere), scaled to its maximum, lowered by its floor percentile, weighted by N(.)."""
    import cv2

    from meshsal.attention.pyramid import normalize_maps, scale_to_max
    from meshsal.util.quantiles import percentiles

    inside = erode_mask(mask, erode)
    h, w = inside.shape
    total = np.zeros((h, w), np.float32)
    for name in CHANNELS:
        cut = scale_to_max(np.where(inside, channels[name], 0.0).astype(np.float32))
        if floor is not None and inside.any():
            cut = np.maximum(cut - percentiles(cut[inside][None], floor)[0], np.float32(0.0))
        gain = 1.0
        if normalize and cut.any():
            small = cv2.resize(cut, (max(1, w // 16), max(1, h // 16)), interpolation=cv2.INTER_AREA)
            gain *= float(normalize_maps(small[None]).max())
        total += np.float32(gain) * cut
    return scale_to_max(total)


@pytest.mark.parametrize("normalize, floor", [(True, 50.0), (False, 50.0), (True, None), (False, 90.0)])
def test_combine_maps_on_the_silhouettes_pixels_is_its_whole_image_definition(normalize, floor):
    rng = np.random.default_rng(17)
    mask = np.zeros((96, 112), bool)
    mask[10:80, 20:100] = True
    mask[40:50, 50:60] = False  # a hole
    channels = {name: rng.random((96, 112)).astype(np.float32) for name in CHANNELS}
    channels["contrast"][:] = 0.0  # a channel that does not respond
    channels["color"][30:40, 30:40] += 3.0  # a peaked one
    channels["entropy"] = channels["entropy"].astype(np.float64)  # taken as float32
    got = combine_maps(channels, mask, normalize=normalize, floor=floor)
    want = _combine_on_whole_images(channels, mask, normalize=normalize, floor=floor)
    assert got.dtype == np.float32 and got.shape == mask.shape and not got[~erode_mask(mask)].any()
    np.testing.assert_array_equal(got.view(np.int32), want.view(np.int32))
    assert not combine_maps(channels, np.zeros_like(mask), normalize=normalize, floor=floor).any()
