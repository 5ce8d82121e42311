"""Interest points: planted features, invariances, baselines, spacing, the CLI and the paper's projection."""

import json

import igl
import numpy as np
import pytest
from planted import distance_to_surface, pairwise_min, planted_sphere

from meshsal.mesh import Mesh
from meshsal.points import (
    METHODS,
    MODEL_METHODS,
    InterestPoints,
    attention_points,
    best_view_set,
    interest_points,
    map_peaks,
    project_pixel_paper,
    saliency_maps,
)
from meshsal.points.sampling import (
    farthest_points,
    field_peaks,
    random_surface_points,
    suppress,
)

SIZE = 64


@pytest.fixture(scope="module")
def planted():
    mesh, to_bump, to_spot = planted_sphere()
    return mesh, to_bump, to_spot, interest_points(mesh, n=15, size=SIZE)


# ---------------------------------------------------------------- sampling blocks


def test_random_surface_points_follow_area():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [3, 0, 1], [0, 2, 1.0]])
    F = np.array([[0, 1, 2], [3, 4, 5]])  # areas 0.5 and 3
    faces, bary = random_surface_points(V, F, 20000, seed=4)
    assert abs(np.mean(faces == 1) - 3 / 3.5) < 0.01
    assert np.all(bary >= 0) and np.allclose(bary.sum(axis=1), 1)
    # Uniform inside the triangle: the mean of the barycentric weights is its centroid.
    assert np.allclose(bary.mean(axis=0), 1 / 3, atol=0.01)
    again = random_surface_points(V, F, 20000, seed=4)
    assert np.array_equal(again[0], faces) and np.array_equal(again[1], bary)


def test_farthest_points_spread_over_a_line():
    P = np.c_[np.linspace(0, 1, 101), np.zeros(101), np.zeros(101)]
    idx = farthest_points(P, 3, start=50)
    assert idx.tolist()[0] == 50 and set(idx[1:].tolist()) == {0, 100}


def test_field_peaks_finds_every_local_maximum():
    GV, F = igl.triangulated_grid(20, 20)
    f = np.exp(-np.sum((GV - [0.25, 0.25]) ** 2, axis=1) / 0.01) + 0.5 * np.exp(
        -np.sum((GV - [0.75, 0.7]) ** 2, axis=1) / 0.01
    )
    peaks = field_peaks(f, F)
    assert len(peaks) == 2
    assert np.allclose(GV[peaks[0]], [0.25, 0.25], atol=0.06)
    assert np.allclose(GV[peaks[1]], [0.75, 0.7], atol=0.06)


def test_suppress_keeps_order_and_spacing():
    rng = np.random.default_rng(0)
    P = rng.random((500, 3))
    keep = suppress(P, 0.2).chosen
    assert keep[0] == 0 and np.all(np.diff(keep) > 0)
    assert pairwise_min(P[keep]) >= 0.2
    # Maximal: every dropped point is too close to a kept one.
    d = np.linalg.norm(P[:, None] - P[keep][None], axis=2).min(axis=1)
    assert np.all(d[np.setdiff1d(np.arange(500), keep)] < 0.2)
    assert len(suppress(P, 0.2, n=3).chosen) == 3


def test_suppress_respects_taken_points_and_ids():
    P = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0.0]])
    keep = suppress(P, 0.5, ids=[7, 7, 8, 9], taken_points=[[3.1, 0, 0]], taken_ids=[8]).chosen
    assert keep.tolist() == [0]
    with pytest.raises(ValueError, match="min_spacing"):
        suppress(P, -1.0)


def greedy_one_by_one(P, spacing, n, ids, ok):
    """The selection suppress makes, written plainly: each candidate in turn, asked about alone."""
    chosen, refused = [], 0
    for i in range(len(P)):
        if len(chosen) == n:
            break
        if any(np.linalg.norm(P[i] - P[j]) < spacing or ids[i] == ids[j] for j in chosen):
            continue
        if not ok[i]:
            refused += 1
            continue
        chosen.append(i)
    return chosen, refused


@pytest.mark.parametrize("seed", range(6))
def test_suppress_batches_change_nothing_but_the_calls(seed):
    rng = np.random.default_rng(seed)
    k = 600
    P = rng.random((k, 3)) * 4.0
    ids = rng.integers(0, 500, k)
    ok = rng.random(k) < (0.05 if seed % 2 else 0.5)  # mostly refused, or half
    asked = []

    def accept(batch):
        asked.append(batch.copy())
        return ok[batch]

    n = 12
    got = suppress(P, 0.6, n, ids, accept=accept)
    chosen, refused = greedy_one_by_one(P, 0.6, n, ids, ok)
    assert got.chosen.tolist() == chosen and got.refused == refused
    everyone = np.concatenate(asked)
    assert np.unique(everyone).size == everyone.size  # each candidate asked once
    if seed % 2:
        # Hundreds refused on the way, asked in batches that grow with the refusals.
        assert refused > 100 and len(asked) < 25


def test_suppress_asks_about_a_long_refused_run_in_few_calls():
    P = np.c_[np.arange(2000.0), np.zeros(2000), np.zeros(2000)]
    calls = []
    got = suppress(P, 0.5, 1, accept=lambda batch: calls.append(len(batch)) or batch == 1500)
    assert got.chosen.tolist() == [1500] and got.refused == 1500
    assert len(calls) <= 13 and sum(calls) < 2 * 1501


# ---------------------------------------------------------------- the attention pipeline


def test_planted_bump_and_red_spot_are_among_top_three(planted):
    mesh, to_bump, to_spot, pts = planted
    top = pts.vertex_ids[:3]
    assert to_bump[top].min() < 0.25, f"no top-3 point near the bump: {to_bump[top]}"
    # The spot has a 0.2 rad radius; its colour edge is salient too.
    assert to_spot[top].min() < 0.35, f"no top-3 point on the red spot: {to_spot[top]}"


def test_points_lie_on_the_surface_with_unit_outward_normals(planted):
    mesh, _, _, pts = planted
    assert len(pts) == 15 and pts.method == "attention" and 0 <= pts.best_set < 18
    assert distance_to_surface(pts.positions, mesh).max() < 1e-6 * 50
    assert np.allclose(np.linalg.norm(pts.normals, axis=1), 1.0)
    radial = pts.positions / np.linalg.norm(pts.positions, axis=1, keepdims=True)
    assert np.all(np.einsum("ij,ij->i", pts.normals, radial) > 0.5)
    # The vertex reported is a corner of the face the point lies on: within one edge length.
    assert np.linalg.norm(mesh.vertices[pts.vertex_ids] - pts.positions, axis=1).max() < 0.1 * 50


def test_points_are_distinct_spaced_and_votes_match_views(planted):
    mesh, _, _, pts = planted
    assert len(set(pts.vertex_ids.tolist())) == len(pts)
    assert pairwise_min(pts.positions) >= pts.min_spacing
    assert pts.min_spacing == 16.0  # half the 32 mm pad, as on the command line
    assert pts.votes.dtype == np.int64 and np.all((pts.votes >= 0) & (pts.votes <= 72))
    assert [len(v) for v in pts.views] == pts.votes.tolist()
    assert all(0 <= k < 72 for v in pts.views for k in v)
    assert pts.vertex_saliency.shape == (mesh.n_vertices,)
    # The planted features are seen by many views: the best point's votes are high.
    assert pts.votes.max() >= 10


def test_translation_and_uniform_scale_keep_the_points(planted):
    mesh, _, _, pts = planted
    moved = mesh.replace(vertices=mesh.vertices * 7.5 + [300.0, -120.0, 45.0])
    other = interest_points(moved, n=15, size=SIZE, pad_width=7.5 * 32.0)  # the pad scaled alike
    # Invariant up to float32 rounding in Embree, whose kernels differ between CPUs: a rounding may swap two
    # candidates whose saliency ties, so most points must be the same vertices, at the same places.
    same = np.isin(other.vertex_ids, pts.vertex_ids)
    assert same.sum() >= 13 and len(other) == len(pts)
    where = {v: k for k, v in enumerate(pts.vertex_ids.tolist())}
    mine = [where[v] for v in other.vertex_ids[same].tolist()]
    np.testing.assert_allclose(
        other.positions[same], pts.positions[mine] * 7.5 + [300.0, -120.0, 45.0], atol=1e-4 * 375
    )
    np.testing.assert_allclose(other.normals[same], pts.normals[mine], atol=1e-4)


def test_same_input_same_output(planted):
    mesh, _, _, pts = planted
    again = interest_points(mesh, n=15, size=SIZE)
    assert again.vertex_ids.tolist() == pts.vertex_ids.tolist()
    assert np.array_equal(again.positions, pts.positions) and np.array_equal(again.votes, pts.votes)


def test_wide_spacing_fills_from_saliency_and_never_duplicates():
    mesh, _, _ = planted_sphere()
    views, maps = saliency_maps(mesh, size=SIZE)
    from meshsal.mesh.curvature import mesh_saliency

    vs = mesh_saliency(mesh)
    # A 1.2-radius spacing leaves room for only a handful of points on a 50 mm sphere.
    pts = attention_points(mesh, views, maps, vs, n=15, min_spacing=60.0)
    assert 2 <= len(pts) < 15
    assert len(set(pts.vertex_ids.tolist())) == len(pts)
    assert pairwise_min(pts.positions) >= 60.0
    # Zero spacing: 15 distinct vertices even where peaks crowd.
    dense = attention_points(mesh, views, maps, vs, n=15, min_spacing=0.0)
    assert len(dense) == 15 and len(set(dense.vertex_ids.tolist())) == 15


# ---------------------------------------------------------------- baselines


@pytest.mark.parametrize("method", [m for m in METHODS if not m.startswith("attention") and m not in MODEL_METHODS])
def test_baselines_return_n_distinct_spaced_points(method):
    mesh, _, _ = planted_sphere()
    pts = interest_points(mesh, n=12, method=method, seed=3)
    assert len(pts) == 12 and pts.method == method and pts.best_set == -1
    assert len(set(pts.vertex_ids.tolist())) == 12
    assert pairwise_min(pts.positions) >= pts.min_spacing
    assert distance_to_surface(pts.positions, mesh).max() < 1e-6 * 50
    assert np.allclose(np.linalg.norm(pts.normals, axis=1), 1.0)
    same = interest_points(mesh, n=12, method=method, seed=3, vertex_saliency=pts.vertex_saliency)
    assert same.vertex_ids.tolist() == pts.vertex_ids.tolist()
    spaced = interest_points(mesh, n=6, method=method, seed=3, min_spacing=30.0, vertex_saliency=pts.vertex_saliency)
    assert len(spaced) == 6 and pairwise_min(spaced.positions) >= 30.0


@pytest.mark.parametrize("method", ["random", "uniform"])
def test_random_baselines_depend_on_the_seed(method):
    mesh, _, _ = planted_sphere()
    a = interest_points(mesh, n=10, method=method, seed=0)
    b = interest_points(mesh, n=10, method=method, seed=1, vertex_saliency=a.vertex_saliency)
    assert a.vertex_ids.tolist() != b.vertex_ids.tolist()


def test_every_method_of_a_call_shares_one_embree_scene(monkeypatch):
    import meshsal.mesh.embree as embree
    from meshsal.points import PointOptions, method_points, points_by_method

    mesh, _, _ = planted_sphere()
    methods = ["uniform", "mesh_saliency", "random", "curvature"]
    alone = points_by_method(mesh, methods, PointOptions(n=6, seed=2))
    built = []
    real = embree.embree_scene
    monkeypatch.setattr(embree, "embree_scene", lambda m, *a, **k: built.append(m) or real(m, *a, **k))
    shared = points_by_method(mesh, methods, PointOptions(n=6, seed=2))
    assert len(built) == 1
    held = real(mesh)
    given = method_points(mesh, methods, PointOptions(n=6, seed=2), scene=held)
    assert len(built) == 1  # the caller's scene serves every method
    for m in methods:
        assert shared[m].vertex_ids.tolist() == alone[m].vertex_ids.tolist() == given[m].vertex_ids.tolist()


def test_saliency_and_curvature_baselines_start_at_the_bump():
    mesh, to_bump, _ = planted_sphere()
    for method in ("mesh_saliency", "curvature"):
        pts = interest_points(mesh, n=5, method=method)
        assert to_bump[pts.vertex_ids[0]] < 0.15, method


def test_bad_arguments_are_rejected():
    mesh, _, _ = planted_sphere()
    with pytest.raises(ValueError, match="unknown interest-point method"):
        interest_points(mesh, method="magic")
    with pytest.raises(ValueError, match="positive integer"):
        interest_points(mesh, n=0, method="random")
    with pytest.raises(ValueError, match="min_spacing"):
        interest_points(mesh, method="random", min_spacing=-2.0)
    with pytest.raises(ValueError, match="no faces"):
        interest_points(Mesh(vertices=np.eye(3), faces=np.zeros((0, 3))), method="random")


# ---------------------------------------------------------------- map helpers


def test_best_view_set_picks_the_most_salient_set():
    maps = np.zeros((72, 8, 8), np.float32)
    maps[4 * 11 + 2] = 0.9
    maps[4 * 5 : 4 * 5 + 4, :4] = 0.4  # 0.2 average per view: less than 0.9 / 4
    assert best_view_set(maps) == 11
    with pytest.raises(ValueError):
        best_view_set(maps[:70])


def test_map_peaks_thresholds_relative_to_the_maximum():
    m = np.zeros((64, 64), np.float32)
    m[10, 10], m[40, 50], m[50, 20] = 1.0, 0.6, 0.25
    mask = np.ones_like(m, bool)
    rows, cols = map_peaks(m, mask, threshold=0.5)
    assert list(zip(rows.tolist(), cols.tolist())) == [(10, 10), (40, 50)]
    mask[10, 10] = False
    rows, cols = map_peaks(m, mask, threshold=0.5)
    assert list(zip(rows.tolist(), cols.tolist())) == [(40, 50)]  # 0.25 < 0.5 * 0.6


# ---------------------------------------------------------------- the paper's analytic projection


@pytest.mark.parametrize("projection", ["orthographic", "perspective"])
def test_project_pixel_paper_matches_face_id_mapping(projection):
    from meshsal.views.cameras import Camera, view_rig
    from meshsal.views.render import render, surface_points

    mesh, _, _ = planted_sphere()
    cameras = [view_rig()[0][0], view_rig()[9][3], view_rig()[17][1], Camera(direction=[0.2, -0.9, 0.3], up=[0, 0, 1])]
    for cam in cameras:
        cam = Camera(direction=cam.direction, up=cam.up, projection=projection)
        view = render(mesh, cam, size=48)
        rows, cols = np.nonzero(view.mask)
        paper = project_pixel_paper(view, rows, cols, mesh)
        exact = surface_points(mesh, view, rows, cols)
        assert not np.isnan(paper).any()
        assert np.linalg.norm(paper - exact, axis=1).max() < view.pixel_size
        # Background pixels miss the mesh.
        assert np.isnan(project_pixel_paper(view, [0], [0], mesh)).all()


def test_a_points_file_of_a_newer_version_or_another_format_is_refused(tmp_path):
    path = tmp_path / "points.json"
    for document, message in (
        ({"format": "visuotactile.points", "version": 99, "points": []}, "version 99"),
        ({"format": "something.else", "points": []}, "something.else"),
    ):
        path.write_text(json.dumps(document))
        with pytest.raises(ValueError, match=message):
            InterestPoints.load(path)


def test_combination_is_a_choice_and_is_recorded(tmp_path):
    from meshsal.attention import plateau_fraction

    mesh, _, _ = planted_sphere()
    equal = interest_points(mesh, n=6, size=SIZE)
    itti = interest_points(mesh, n=6, size=SIZE, method="attention_itti")
    assert (equal.method, equal.combination) == ("attention", "equal")
    assert (itti.method, itti.combination) == ("attention_itti", "itti")
    itti.save(tmp_path / "points.json")
    assert InterestPoints.load(tmp_path / "points.json").combination == "itti"
    views, plain = saliency_maps(mesh, size=SIZE, combination="equal")
    _, weighted = saliency_maps(mesh, size=SIZE, combination="itti")
    assert not np.allclose(plain, weighted)
    for maps in (plain, weighted):
        shares = [plateau_fraction(m, v.mask) for m, v in zip(maps, views)]
        assert all(0.0 <= s <= 1.0 for s in shares) and max(shares) > 0
    with pytest.raises(ValueError, match="combination"):
        interest_points(mesh, n=3, size=SIZE, combination="loudest")


def test_each_attention_method_keeps_its_own_combination():
    from meshsal.points import PointOptions, points_by_method

    mesh, _, _ = planted_sphere()
    with pytest.warns(FutureWarning, match="PointOptions.combination is deprecated"):
        both = points_by_method(mesh, ["attention", "attention_itti"], PointOptions(n=6, size=SIZE, combination="itti"))
    assert (both["attention"].combination, both["attention_itti"].combination) == ("equal", "itti")
    equal = interest_points(mesh, n=6, size=SIZE)
    itti = interest_points(mesh, n=6, size=SIZE, method="attention_itti")
    assert equal.vertex_ids.tolist() != itti.vertex_ids.tolist()  # two combinations, two sets of points
    assert both["attention"].vertex_ids.tolist() == equal.vertex_ids.tolist()
    assert both["attention_itti"].vertex_ids.tolist() == itti.vertex_ids.tolist()
    with pytest.warns(FutureWarning):  # asked for alone, 'attention' still takes it until 0.3
        old = interest_points(mesh, n=6, size=SIZE, combination="itti")
    assert old.combination == "itti" and old.vertex_ids.tolist() == itti.vertex_ids.tolist()


def test_points_are_saved_in_the_frame_of_the_file_they_came_from(tmp_path):
    from meshsal.mesh.transform import scale_to_principal

    mesh, _, _ = planted_sphere(radius=0.4)
    source = mesh.replace(vertices=mesh.vertices + [2.0, 1.0, -3.0])
    pts = interest_points(scale_to_principal(source, 150.0), n=4, method="uniform")
    pts.save(tmp_path / "points.json")  # no frame= : the points carry theirs
    pts.save_csv(tmp_path / "points.csv")
    again = InterestPoints.load(tmp_path / "points.json")
    assert distance_to_surface(again.positions, source).max() < 1e-6
    rows = (tmp_path / "points.csv").read_text().strip().splitlines()[1:]
    np.testing.assert_allclose([[float(v) for v in r.split(",")[2:5]] for r in rows], again.positions)
    assert [int(r.split(",")[0]) for r in rows] == again.ids.tolist() == [0, 1, 2, 3]


def test_a_version_1_points_file_counts_from_1_and_reads_from_0(tmp_path):
    path = tmp_path / "points.json"
    records = [{"id": k, "position": [k, 0, 0], "normal": [0, 0, 1]} for k in (1, 2, 7)]
    path.write_text(json.dumps({"format": "visuotactile.points", "version": 1, "points": records}))
    assert InterestPoints.load(path).ids.tolist() == [0, 1, 6]


def test_plateau_fraction_tells_a_peak_from_a_plateau():
    from meshsal.attention import plateau_fraction

    mask = np.zeros((64, 64), bool)
    mask[8:56, 8:56] = True
    peak = np.zeros((64, 64), np.float32)
    peak[30:34, 30:34] = 1.0
    flat = np.where(mask, 0.9, 0.0).astype(np.float32)
    flat[30, 30] = 1.0
    assert plateau_fraction(peak, mask, erode=0) == pytest.approx(16 / 48**2)
    assert plateau_fraction(flat, mask, erode=0) == 1.0
    assert plateau_fraction(np.zeros((64, 64), np.float32), mask) == 0.0


def test_equal_maps_of_the_views_channels_are_their_recombination():
    from meshsal.attention import combine_maps
    from meshsal.points import attention_maps, view_channels

    mesh, _, _ = planted_sphere()
    seen = view_channels(mesh, size=SIZE, threads=1)
    again = np.stack(
        [combine_maps(r.channels, v.mask, None, normalize=False) for v, r in zip(seen.views, seen.results)]
    )
    np.testing.assert_array_equal(attention_maps(seen, "equal"), again)
    _, maps = saliency_maps(mesh, size=SIZE, threads=1, combination="equal")
    np.testing.assert_array_equal(attention_maps(seen, "equal"), maps)
