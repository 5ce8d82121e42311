"""The place-aware recognizer: touch codebooks, a likelihood that knows where the pad pressed, and its guards."""

import dataclasses

import numpy as np
import pytest
import shapes
from sklearn.base import clone

import tactile
from classify.experiment.config import Settings
from classify.experiment.controls import donors, shuffled_places
from classify.experiment.samples import SampleTask, instance_samples, nominal_mesh
from classify.policies import InfoGainPolicy, PlaceKnowledge, fit_knowledge, run_episode, signatures
from classify.recognizers.place import PlaceAware
from classify.recognizers.touches import Recognizer
from meshsal.mesh import Mesh
from meshsal.points.places import POOL_FACTOR

SETTINGS = Settings(n_points=3, view_size=32, train_instances=2, train_sessions=1, codebook_draws=4)
PLANE = Mesh(vertices=[[-50, 0, -50], [50, 0, -50], [50, 0, 50], [-50, 0, 50]], faces=[[0, 2, 1], [0, 3, 2]])


# -- codebooks ---------------------------------------------------------------------------------------------


def test_a_codebook_gives_every_touch_its_own_device_and_is_reproducible():
    perturb = tactile.Perturbation(gain_spread=0.2, dead_fraction=0.2, adc_bits=8)
    sensor = tactile.Sensor(mode="pressure")
    book = tactile.touch_codebook(PLANE, [[0, 0, 0]], [[0, 1, 0]], sensor, perturb, draws=6, rng=3)
    assert book.shape == (1, 6, 16, 16)
    dead = book[0] == 0  # a flat plane presses every taxel: zeros are dead taxels
    assert len({d.tobytes() for d in dead}) == 6  # six devices, six dead-taxel maps
    np.testing.assert_array_equal(book, tactile.touch_codebook(PLANE, [[0, 0, 0]], [[0, 1, 0]], sensor, perturb, 6, 3))
    # One device per call instead: acquire's readings share one dead map.
    shared = tactile.acquire(PLANE, [[0, 0, 0]] * 6, [[0, 1, 0]] * 6, sensor, perturb, rng=3)
    assert len({(s == 0).tobytes() for s in shared}) == 1


def test_a_clean_codebook_is_the_clean_imprint_and_bad_draws_are_refused():
    book = tactile.touch_codebook(PLANE, [[0, 0, 0], [5, 0, 5]], [[0, 1, 0]] * 2, None, tactile.Perturbation.none(), 3)
    clean = tactile.imprints(PLANE, [[0, 0, 0], [5, 0, 5]], [[0, 1, 0]] * 2)
    np.testing.assert_array_equal(book, np.repeat(clean[:, None], 3, axis=1))
    with pytest.raises(ValueError, match="draws must be a positive integer"):
        tactile.touch_codebook(PLANE, [[0, 0, 0]], [[0, 1, 0]], draws=0)


def test_exact_acquisition_is_the_exact_section_with_the_same_draws():
    sphere = shapes.sphere(40.0, 60)
    p = sphere.vertices[[10, 400]]
    n = p / np.linalg.norm(p, axis=1, keepdims=True)
    clean = tactile.acquire(sphere, p, n, None, tactile.Perturbation.none(), rng=1, exact=True)
    np.testing.assert_array_equal(clean, tactile.imprints_exact(sphere, p, n))
    perturb = tactile.Perturbation(jitter_mm=0.5, uniform_rotation=True)
    exact = tactile.acquire(sphere, p, n, None, perturb, rng=1, exact=True)
    fast = tactile.acquire(sphere, p, n, None, perturb, rng=1)
    # Two simulators of one contact, with the same draws: alike, not equal.
    assert not np.array_equal(exact, fast) and np.corrcoef(exact.ravel(), fast.ravel())[0, 1] > 0.8


# -- the likelihood on planted stimuli ---------------------------------------------------------------------


def _planted(rng, feel):
    """Two objects x two places x two training instances x 30 touches; ``feel[(obj, place)]`` is the mean felt."""
    X, y, sig, inst, key = [], [], [], [], []
    for (obj, place), mean in feel.items():
        for j in (1, 2):
            X.append(rng.normal(mean, 0.3, (30, 4)))
            y += [obj] * 30
            sig += [[place, 1.0 - place]] * 30
            inst += [j] * 30
            key += [place] * 30
    return np.concatenate(X), np.array(y), np.array(sig, float), np.array(inst), np.array(key)


def test_knowing_the_place_tells_apart_what_no_place_free_classifier_can():
    # Object 0 is flat at place 0 and edged at place 1; object 1 the other way round: felt anywhere, alike.
    flat, edge = np.zeros(4), np.full(4, 3.0)
    X, y, sig, inst, key = _planted(np.random.default_rng(0), {(0, 0): flat, (0, 1): edge, (1, 0): edge, (1, 1): flat})
    model = PlaceAware().fit(X, y, signatures=sig, instances=inst, places=key)
    at0, at1 = np.array([[0.0, 1.0]]), np.array([[1.0, 0.0]])
    assert model.predict(flat[None], at0).tolist() == [0] and model.predict(flat[None], at1).tolist() == [1]
    assert model.predict_proba(edge[None], at0)[0, 1] > 0.9
    # A place-free model of the same touches cannot tell: each object feels flat and edged alike.
    queries = np.random.default_rng(9).normal(0.0, 0.3, (200, 4))  # object 0 touched at place 0
    knn = clone(__import__("classify").make("knn")).fit(X, y)
    assert 0.3 < np.mean(knn.predict(queries) == 0) < 0.7
    assert np.mean(model.predict(queries, np.tile(at0, (200, 1))) == 0) > 0.95


def test_how_well_a_place_matches_is_not_evidence():
    # Both objects feel the same everywhere; the test place matches object 0's places exactly and object 1's
    # poorly.  The belief must not move.
    rng = np.random.default_rng(1)
    same = rng.normal(0, 1, (60, 4))
    X = np.r_[same, same]
    y = np.repeat([0, 1], 60)
    inst = np.tile(np.repeat([1, 2], 30), 2)
    sig = np.r_[np.tile([[0.0, 1.0]], (60, 1)), np.tile([[5.0, 9.0]], (60, 1))]
    model = PlaceAware().fit(X, y, signatures=sig, instances=inst, places=np.zeros(120, int))
    ll = model.log_likelihood(rng.normal(0, 1, (5, 4)), np.tile([[0.0, 1.0]], (5, 1)))
    np.testing.assert_allclose(ll[:, 0], ll[:, 1], rtol=0, atol=1e-9)


def test_the_place_free_term_keeps_a_wrong_match_from_sinking_the_true_object():
    flat, edge = np.zeros(4), np.full(4, 3.0)
    X, y, sig, inst, key = _planted(np.random.default_rng(2), {(0, 0): flat, (0, 1): edge, (1, 0): edge, (1, 1): edge})
    model = PlaceAware().fit(X, y, signatures=sig, instances=inst, places=key)
    # Object 0 touched at place 1 but located at place 0 (a wrong match): it felt an edge, which object 0 has.
    ll = model.log_likelihood(edge[None], np.array([[0.0, 1.0]]))
    assert np.isfinite(ll).all() and model.mixture_ > 0


def test_the_estimator_clones_validates_and_extends_its_banks():
    rng = np.random.default_rng(3)
    X, y, sig, inst, key = _planted(rng, {(0, 0): np.zeros(4), (1, 0): np.ones(4), (0, 1): 0, (1, 1): 1})
    model = PlaceAware(neighbours=2)
    assert clone(model).get_params()["neighbours"] == 2
    with pytest.raises(ValueError, match="at least two training instances"):
        PlaceAware().fit(X, y, signatures=sig, instances=np.ones_like(inst), places=key)
    with pytest.raises(ValueError, match="shortlist and fit_objects must be positive integers"):
        PlaceAware(shortlist=0).fit(X, y, signatures=sig, instances=inst, places=key)
    with pytest.raises(ValueError, match="one row per touch"):
        PlaceAware().fit(X[:-1], y, signatures=sig, instances=inst, places=key)
    with pytest.raises(ValueError, match="temperatures must be positive"):
        PlaceAware(temperatures=(1.0, -2.0)).fit(X, y, signatures=sig, instances=inst, places=key)
    with pytest.raises(ValueError, match=r"mixtures must lie in \(0, 1\)"):
        PlaceAware(mixtures=(0.0, 0.1)).fit(X, y, signatures=sig, instances=inst, places=key)
    model.fit(X, y, signatures=sig, instances=inst, places=key)
    # A new place far from the others, where object 1 feels 5s: the extended model knows it, the old one not.
    new = np.full((20, 4), 5.0) + rng.normal(0, 0.3, (20, 4))
    there = np.tile([[20.0, 20.0]], (20, 1))
    more = model.with_places(
        new, np.ones(20, int), signatures=there, instances=np.repeat([1, 2], 10), places=np.full(20, 7)
    )
    assert more.predict(np.full((1, 4), 5.0), there[:1]).tolist() == [1]
    assert len(model.banks_[1].keys) == 2 and len(more.banks_[1].keys) == 3
    posteriors, weights = more.forecast_table(samples=4)
    assert [p.values.shape for p in posteriors] == [(2, 4, 2), (3, 4, 2)]
    np.testing.assert_allclose(posteriors[1].values.sum(axis=2), 1.0)
    np.testing.assert_allclose(weights[1].sum(axis=1), 1.0)


def _aliased(C=5, places=4, draws=3, seed=4):
    """C objects whose evenly spaced place-free picks (two of them) all fall on instance 1: each place holds
    ``draws`` touches of instances 1 and 2, and the last place only instance 1's."""
    rng = np.random.default_rng(seed)
    X, y, sig, inst, key = [], [], [], [], []
    for c in range(C):
        for p in range(places + 1):
            for j in (1, 2) if p < places else (1,):
                X.append(rng.normal(2.0 * c + 0.3 * p, 0.3, (draws, 4)))
                y += [c] * draws
                sig += [[p, c]] * draws
                inst += [j] * draws
                key += [p] * draws
    return np.concatenate(X), np.array(y), np.array(sig, float), np.array(inst), np.array(key)


def test_the_place_free_subsample_leaves_samples_whichever_instance_is_left_out():
    from classify.recognizers.banks import free_subsample

    X, y, sig, inst, key = _aliased(C=1)
    plain = np.lexsort((inst, key))[[0, len(key) - 1]]
    assert set(inst[plain]) == {1}  # the stimulus: evenly spaced picks see one instance
    picks = free_subsample(key, inst, 2)
    assert set(inst[picks]) == {1, 2} and len(set(picks.tolist())) == len(picks)
    # Picks over several instances are the evenly spaced ones, in place order; one instance keeps them too.
    keys, instances = np.repeat(np.arange(10), 6), np.tile(np.repeat([1, 2, 3], 2), 10)
    spaced = np.lexsort((instances, keys))[np.unique(np.linspace(0, 59, 16).astype(np.int64))]
    np.testing.assert_array_equal(free_subsample(keys, instances, 16), spaced)
    np.testing.assert_array_equal(free_subsample(keys, np.ones(60, int), 16), spaced)
    np.testing.assert_array_equal(free_subsample(keys, instances, 100), np.lexsort((instances, keys)))


def test_past_the_shortlist_a_held_out_instance_still_scores_its_own_object():
    # With every place-free sample on instance 1, leaving it out left the object no sample: it was never
    # screened onto a touch's shortlist and its likelihood was -inf, for every bandwidth, mixture and temperature.
    X, y, sig, inst, key = _aliased()
    model = PlaceAware(free_samples=2, shortlist=2).fit(X, y, signatures=sig, instances=inst, places=key)
    assert all(set(bank.free_instances.tolist()) == {1, 2} for bank in model.banks_)
    assert np.isfinite(model.fit_loss_)
    held = inst == 1
    ll = model.log_likelihood(X[held], sig[held], exclude=inst[held])
    assert np.isfinite(ll[np.arange(held.sum()), y[held]]).all()
    assert np.mean(np.argmax(ll, axis=1) == y[held]) > 0.9


def test_an_object_on_one_training_instance_is_known_but_never_held_out():
    X, y, sig, inst, key = _aliased(C=3)
    lone = y == 2
    inst = np.where(lone, 3, inst)  # object 2 is seen on instance 3 alone
    model = PlaceAware(free_samples=2).fit(X, y, signatures=sig, instances=inst, places=key)
    assert np.isfinite(model.fit_loss_)
    assert model.predict(X[lone][:3], sig[lone][:3]).tolist() == [2, 2, 2]
    with pytest.raises(ValueError, match="an object with touches on two training instances"):
        PlaceAware().fit(X, y, signatures=sig, instances=np.where(y == 0, 1, 2), places=key)


def _many_touches(C=20, instances=2, places=150, draws=8, d=42, seed=0):
    """Codebook-like touches: C objects, each place of each instance touched ``draws`` times (descriptors)."""
    rng = np.random.default_rng(seed)
    y = np.repeat(np.arange(C), instances * places * draws)
    inst = np.tile(np.repeat(np.arange(instances), places * draws), C)
    key = np.tile(np.repeat(np.arange(places), draws), C * instances)
    sig = rng.normal(size=(C * places, 3))[y * places + key]
    X = rng.normal(size=(len(y), d)) + 0.1 * y[:, None] + 0.01 * key[:, None]
    return X, y, sig, inst, key


@pytest.mark.parametrize("screening", ["touch", "place"])
def test_the_fit_standardizes_in_place_as_its_predictions_do_with_few_touch_sized_arrays(screening):
    import tracemalloc

    from classify.recognizers.banks import within_place_whitening
    from classify.recognizers.place import _STACKED

    X, y, sig, inst, key = _many_touches()
    touches = X.nbytes
    model = PlaceAware(fit_sets=5, bandwidths=(0.5, 1.0), mixtures=(0.01, 0.1), screening=screening)
    tracemalloc.start()
    try:
        model.fit(X, y, signatures=sig, instances=inst, places=key)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    # Out of place, the fit held the descriptors, their standardized copy, the places' means, the residuals and
    # the whitened copy at once (4.2 of them here); standardized in place, 3.1; with the standardized copy let go
    # once whitened, so that it never lies beside the banks, 2.2.  Screened by place (20 objects, past the
    # shortlist), the held-out touches gather their matched samples in blocks of a fixed size besides.
    assert peak < 2.6 * touches + (_STACKED if screening == "place" else 0), peak / touches
    # The in-place operations are those of the predictions' standardization, bit for bit.
    expected = within_place_whitening((X - model.mean_) / model.scale_, y, key)
    assert np.array_equal(model.whitening_, expected)
    Z = model._standardized(X)
    for c, bank in enumerate(model.banks_):
        mine = y == c
        order = np.lexsort((inst[mine], key[mine]))
        assert np.array_equal(bank.samples[bank.instances >= 0], Z[mine][order].astype(np.float32))


def test_the_within_place_whitening_forms_its_residuals_a_block_at_a_time():
    # A thousand objects' codebooks are millions of touches: a touch-sized array of residuals beside them is
    # hundreds of megabytes.  In blocks, the same map (the sums' order alone differs); in one block, the same bits.
    import tracemalloc

    from classify.recognizers.banks import within_place_whitening

    X, y, _, _, key = _many_touches()
    whole = within_place_whitening(X, y, key, rows=len(X))
    assert np.array_equal(within_place_whitening(X, y, key), whole)  # fewer touches than a block
    tracemalloc.start()
    try:
        blocked = within_place_whitening(X, y, key, rows=1000)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    np.testing.assert_allclose(blocked, whole, rtol=1e-12, atol=1e-12)
    assert peak < 0.4 * X.nbytes, peak / X.nbytes
    # The map whitens: the pooled within-place spread becomes (nearly) the identity, up to the shrinkage.
    means = np.zeros((y.max() + 1, key.max() + 1, X.shape[1]))
    np.add.at(means, (y, key), X)
    R = (X - means[y, key] / np.bincount(y * (key.max() + 1) + key)[y * (key.max() + 1) + key, None]) @ whole
    spread = R.T @ R / (len(R) - (y.max() + 1) * (key.max() + 1))  # less one degree of freedom per place
    assert np.abs(np.diag(spread) - 1).max() < 0.05 and np.abs(spread - np.diag(np.diag(spread))).max() < 0.05


def test_a_fit_that_may_overwrite_its_descriptors_is_the_same_fit_with_one_touch_sized_array_fewer(monkeypatch):
    import tracemalloc

    X, y, sig, inst, key = _many_touches()
    kept = X.copy()
    params = dict(fit_sets=5, bandwidths=(0.5, 1.0), mixtures=(0.01, 0.1))
    # The banks' peak: up to the choice of the parameters, whose buffers here, a few rows of every object, are
    # as large as the touches themselves (a thousand objects' codebooks are many times larger).
    peaks, choose = [], PlaceAware._choose

    def measured(self, session):
        peaks.append((tracemalloc.get_traced_memory()[1] - held) / X.nbytes)
        return choose(self, session)

    monkeypatch.setattr(PlaceAware, "_choose", measured)
    tracemalloc.start()
    try:
        held = 0
        usual = PlaceAware(**params).fit(X, y, signatures=sig, instances=inst, places=key)
        assert np.array_equal(X, kept)  # left as it is by default
        tracemalloc.reset_peak()
        held = tracemalloc.get_traced_memory()[0]
        model = PlaceAware(**params).fit(X, y, signatures=sig, instances=inst, places=key, overwrite_X=True)
    finally:
        tracemalloc.stop()
    assert not np.array_equal(X, kept)  # standardized and whitened where it lies
    # By default, the standardized copy and a temporary of its size; overwriting, the temporary alone (X is ours).
    assert peaks[0] > 1.9 and peaks[1] < 1.35, peaks
    assert (model.bandwidth_, model.mixture_, model.temperature_) == (
        usual.bandwidth_,
        usual.mixture_,
        usual.temperature_,
    )
    assert np.array_equal(model.whitening_, usual.whitening_)
    for a, b in zip(model.banks_, usual.banks_):
        assert np.array_equal(a.samples, b.samples) and np.array_equal(a.free, b.free)
    # float32 descriptors are converted, never overwritten.
    X32 = kept.astype(np.float32)
    PlaceAware(**params).fit(X32, y, signatures=sig, instances=inst, places=key, overwrite_X=True)
    assert np.array_equal(X32, kept.astype(np.float32))


# Past the shortlist (screened by touch, one width at a time) and within it; a session in instance order and shuffled.
@pytest.mark.parametrize("shortlist, shuffled", [(4, False), (64, True)])
def test_the_fit_scores_its_held_out_touches_a_block_at_a_time_to_the_same_choice_in_less_memory(
    shortlist, shuffled, monkeypatch
):
    import tracemalloc

    import classify.recognizers.place as place

    X, y, sig, inst, key = _many_touches(C=32, instances=3, places=16, draws=2, d=6)
    first = np.unique(np.c_[y, inst, key], axis=0, return_index=True)[1]
    if shuffled:  # an instance's rows are brought together before they are scored
        first = np.random.default_rng(1).permutation(first)
    session = (X[first], y[first], sig[first], inst[first])
    choose = PlaceAware._choose

    def fitted(budget):
        monkeypatch.setattr(place, "_CHUNK", 8)
        monkeypatch.setattr(place, "_HELD_OUT", budget)
        peak = []

        def measured(self, session):
            tracemalloc.start()
            try:
                return choose(self, session)
            finally:
                peak.append(tracemalloc.get_traced_memory()[1])
                tracemalloc.stop()

        monkeypatch.setattr(PlaceAware, "_choose", measured)
        model = PlaceAware(
            fit_sets=5, bandwidths=(0.5, 1.0), mixtures=(0.01, 0.1), shortlist=shortlist, screening="touch"
        )
        model.fit(X, y, signatures=sig, instances=inst, places=key, session=session)
        return (model.fit_loss_, model.bandwidth_, model.mixture_, model.temperature_), peak[0]

    whole, whole_peak = fitted(1 << 40)  # every held-out touch in one block
    blocks, blocks_peak = fitted(1)  # blocks of one chunk: an instance's 16 rows span two or three
    assert blocks == whole  # the loss too, bit for bit
    # All at once, several (held-out touches, objects) arrays and their temporaries; a block at a time, a few rows'.
    assert blocks_peak < whole_peak / 3, (whole_peak, blocks_peak)


# -- the place-aware knowledge on two shapes that differ in one place --------------------------------------


@pytest.fixture(scope="module")
def world():
    """Ball and domed: test instance 0 and training instances 1, 2 with places and codebooks; the knowledge."""
    nominal = {m.name: nominal_mesh(m, SETTINGS) for m in shapes.ball_and_domed()}
    samples = {
        (name, j): instance_samples(SampleTask(mesh, name, (), SETTINGS, 0, j, places=True, codebook=True)).places
        for name, mesh in nominal.items()
        for j in range(3)
    }
    knowledge = fit_knowledge({k: v for k, v in samples.items() if k[1] >= 1}, Recognizer("place"))
    return nominal, samples, knowledge


def test_training_instances_carry_codebooks_and_the_test_instance_none(world):
    _, samples, knowledge = world
    assert isinstance(knowledge, PlaceKnowledge)
    book = samples["domed", 1].codebook
    ok = samples["domed", 1].places.touchable
    assert book.shape[:2] == (len(ok), SETTINGS.codebook_draws) and np.abs(book[ok]).sum(axis=(1, 2)).min() > 0
    assert samples["domed", 0].codebook is None


def test_the_place_aware_belief_finds_the_dome_and_info_gain_touches_it(world):
    nominal, samples, knowledge = world
    apex = nominal["domed"].vertices[np.argmax(nominal["domed"].vertices @ shapes.DOME_APEX)]
    test = samples["domed", 0]
    episode = run_episode(InfoGainPolicy(), test, knowledge, 2, 8.0, np.random.default_rng(0))
    touched = nominal["domed"].vertices[episode.vertex_ids]  # instance 0 keeps the nominal mesh's numbering
    assert np.linalg.norm(touched - apex, axis=1).min() < 25.0
    assert episode.beliefs[-1][knowledge.names.index("domed")] > 0.9


def test_shuffled_imprints_take_the_place_aware_belief_to_the_donor(world):
    _, samples, knowledge = world
    names = knowledge.names
    tests = shuffled_places(tuple(samples[n, 0] for n in names), names, 0, 0)
    for c, test in enumerate(tests):
        # The places stay the test instance's own; only what is felt there comes from the other object.
        assert test.places is samples[names[c], 0].places
        felt = knowledge.posterior(test.imprints[0], test.places)
        dome_like = felt[test.places.touchable].argmax(axis=1)
        assert np.mean(dome_like == c) <= 0.5 + 1e-9  # never better than chance at telling c


def test_donors_are_a_derangement_by_name():
    d = donors(["a", "b", "c", "d"], 0, 3)
    assert sorted(d.values()) == ["a", "b", "c", "d"] and all(k != v for k, v in d.items())
    assert d == donors(["d", "c", "b", "a"], 0, 3)
    with pytest.raises(ValueError, match="at least two objects"):
        donors(["a"], 0, 0)


def test_a_training_instance_with_no_touchable_place_stops_with_its_name(world, monkeypatch):
    nominal, _, _ = world
    import meshsal.points.touch as touch

    monkeypatch.setattr(
        touch, "touchable", lambda mesh, positions, normals, width, scene=None: np.zeros(len(positions), bool)
    )
    task = SampleTask(nominal["ball"], "ball", (), SETTINGS, 0, 1, places=True, codebook=True)
    with pytest.raises(ValueError, match="ball, replicate 0, training instance 1.*no touchable place"):
        instance_samples(task)


def test_a_codebook_from_other_draws_is_recomputed_never_reused(world, tmp_path):
    nominal, _, _ = world
    task = SampleTask(nominal["ball"], "ball", (), SETTINGS, 0, 1, places=True, codebook=True, cache_dir=tmp_path)
    four = instance_samples(task).places.codebook
    again = instance_samples(task).places.codebook
    six = instance_samples(dataclasses.replace(task, settings=dataclasses.replace(SETTINGS, codebook_draws=6)))
    np.testing.assert_array_equal(four, again)
    assert four.shape[1] == 4 and six.places.codebook.shape[1] == 6


def test_signatures_of_the_places_locate_them_on_the_shape(world):
    _, samples, _ = world
    a, b = signatures(samples["domed", 1].places), signatures(samples["domed", 2].places)
    # Two turned, resized copies: the pool is the same places in the same order.
    pool = POOL_FACTOR * SETTINGS.n_points
    np.testing.assert_allclose(a[:pool], b[:pool], atol=1e-9)
    assert not np.allclose(samples["domed", 1].places.positions, samples["domed", 2].places.positions)


def test_places_of_a_retessellated_turned_copy_are_located_where_they_lie():
    from scipy.spatial import cKDTree

    from meshsal.mesh.curvature import mesh_saliency
    from meshsal.objects import toys
    from meshsal.objects.instances import retessellate
    from meshsal.points.places import candidate_places, landmarks_in
    from meshsal.points.places import signatures as located

    cow = nominal_mesh(toys.make("cow"), SETTINGS)  # no symmetry: a place is located by where it lies, not up to one
    P = cow.vertices[candidate_places(cow, mesh_saliency(cow), 15)]
    turn = np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]])
    for kind in ("subdivided", "decimated"):
        copy = retessellate(cow, kind)
        copy = copy.replace(vertices=1.04 * copy.vertices @ turn.T + 3.0)
        Q = copy.vertices[candidate_places(copy, mesh_saliency(copy), 15)]
        back = (Q - 3.0) @ turn / 1.04  # where each place of the copy lies on the original
        tree = cKDTree(located(P, P[:8]))
        error = np.linalg.norm(P[tree.query(located(Q, landmarks_in(Q, P)))[1]] - back, axis=1)
        own = np.linalg.norm(P[tree.query(located(Q, Q[:8]))[1]] - back, axis=1)  # the copy's own landmarks
        spacing = np.median(cKDTree(P).query(P, k=2)[0][:, 1])
        assert np.median(error) < 0.5 * spacing and np.mean(error < spacing) > 0.85, (kind, np.median(error))
        assert np.mean(error < spacing) >= np.mean(own < spacing)


def test_a_scrambled_control_gives_the_donors_imprints_in_another_order(world):
    _, samples, knowledge = world
    names = knowledge.names
    tests = tuple(samples[n, 0] for n in names)
    shuffled = shuffled_places(tests, names, 0, 0, "shuffled")
    scrambled = shuffled_places(tests, names, 0, 0, "scrambled")
    for a, b in zip(shuffled, scrambled):
        assert sorted(x.tobytes() for x in a.imprints[0]) == sorted(x.tobytes() for x in b.imprints[0])
        assert not np.array_equal(a.imprints, b.imprints)
    with pytest.raises(ValueError, match="unknown control"):
        shuffled_places(tests, names, 0, 0, "reversed")


@pytest.mark.parametrize("seed", range(4))
def test_a_registration_onto_places_it_cannot_match_never_collapses_the_shape(seed):
    from meshsal.points.places import landmarks_in, register

    rng = np.random.default_rng(seed)
    moving = rng.normal(size=(60, 3)) * [40, 20, 10]
    # Another object's places, most of them at one spot: the nearest-place fit pulls every moving place there.
    fixed = np.r_[rng.normal(size=(8, 3)) * 40, np.tile([5.0, 5.0, 5.0], (52, 1))]
    s, R, t = register(moving, fixed, rng=seed)
    size = np.sqrt(((fixed - fixed.mean(0)) ** 2).sum(1).mean() / ((moving - moving.mean(0)) ** 2).sum(1).mean())
    assert 1e-3 * size < s < 1e3 * size and np.allclose(R @ R.T, np.eye(3)) and np.isfinite(t).all()
    assert np.isfinite(landmarks_in(moving, fixed, rng=seed)).all()


def test_a_registration_seeded_by_a_number_draws_as_a_new_generator_of_that_seed_each_time():
    """Its RANSAC triples are drawn once per seed and size, then shared: every registration is that of a new
    generator's draws, whatever registrations came before."""
    from meshsal.points.places import _seeded_samples, register

    rng = np.random.default_rng(5)
    moving = rng.normal(size=(40, 3)) * [40, 20, 10]
    turn = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    fixed = (1.3 * moving @ turn.T + 2.0)[rng.permutation(40)] + rng.normal(size=(40, 3)) * 3
    for seed in (0, 3, np.int64(3)):
        expected = register(moving, fixed, rng=np.random.default_rng(seed), rounds=30)
        for _ in range(2):
            got = register(moving, fixed, rng=seed, rounds=30)
            assert all(np.array_equal(a, b) for a, b in zip(got, expected))
    assert not _seeded_samples(3, 30, 40).flags.writeable
    assert not np.array_equal(_seeded_samples(0, 30, 40), _seeded_samples(3, 30, 40))


def test_refinement_that_stops_when_the_pairs_repeat_is_every_round_bit_for_bit():
    """A round that pairs the places as the last one did would repeat its fit: stopping there changes no bit of
    the ten rounds' result, on a true match (which settles) and on another shape (which may not)."""
    from scipy.spatial import cKDTree

    from meshsal.points.places import _unless_collapsed, register, registration_places, similarity_fit
    from meshsal.util.quantiles import percentiles

    rng = np.random.default_rng(11)
    moving = rng.normal(size=(70, 3)) * [40, 20, 10]
    turn = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    turn *= np.sign(np.linalg.det(turn))
    same = (1.3 * moving @ turn.T + 2.0)[rng.permutation(70)]
    other = rng.normal(size=(55, 3)) * [10, 30, 25]
    for fixed in (same, other):
        s, R, t = register(moving, fixed, rng=3, refine=0)
        size = registration_places(fixed).spread / registration_places(moving).spread
        tree = cKDTree(fixed)
        rounds = []
        for _ in range(10):
            dist, nearest = tree.query(s * moving @ R.T + t)
            close = dist <= percentiles(dist[None], 80.0)[0]
            rounds.append(nearest[close].tobytes() + close.tobytes())
            s, R, t = _unless_collapsed(similarity_fit(moving[close], fixed[nearest[close]]), (s, R, t), size)
        got = register(moving, fixed, rng=3)
        assert got[0] == s and np.array_equal(got[1], R) and np.array_equal(got[2], t)
        if fixed is same:  # the exact copy settles within ten rounds: the early stop is exercised
            assert rounds[-1] == rounds[-2]


def test_places_prepared_once_register_as_the_arrays_do():
    from meshsal.points.places import landmarks_in, register, registration_places

    rng = np.random.default_rng(12)
    moving = rng.normal(size=(50, 3)) * [40, 20, 10]
    fixed = [rng.normal(size=(n, 3)) * 30 for n in (50, 64, 5)]  # 5 places: fewer than the landmarks
    once = registration_places(moving)
    assert registration_places(once) is once
    for F in fixed:
        for seed in (0, 4, np.random.default_rng(4)):
            a = register(moving, F, rng=seed)
            b = register(once, registration_places(F), rng=seed if isinstance(seed, int) else np.random.default_rng(4))
            assert a[0] == b[0] and np.array_equal(a[1], b[1]) and np.array_equal(a[2], b[2])
        np.testing.assert_array_equal(landmarks_in(once, registration_places(F)), landmarks_in(moving, F))


def test_registration_misfits_are_the_einsum_and_norm_bit_for_bit():
    from meshsal.points.places import _misfits

    rng = np.random.default_rng(7)
    for k in (3, 17, 110, 331):
        S, T = rng.uniform(0.2, 3.0, 200), rng.normal(size=(200, 3)) * 30
        R = np.linalg.qr(rng.normal(size=(200, 3, 3)))[0]
        M, target = rng.normal(size=(k, 3)) * [40, 20, 10], rng.normal(size=(k, 3)) * 25
        moved = S[:, None, None] * np.einsum("bij,kj->bki", R, M) + T[:, None, :]
        np.testing.assert_array_equal(_misfits(S, R, T, M, target), np.linalg.norm(moved - target[None], axis=2))


def test_places_pair_by_signatures_a_few_rows_at_a_time_as_all_at_once():
    from meshsal.mesh.curvature import mesh_saliency
    from meshsal.objects import toys
    from meshsal.points.places import _pairs, candidate_places, signatures

    def at_once(gm, gf, keep):
        d = np.partition(np.abs(gm[:, None, :] - gf[None, :, :]), keep - 1, axis=2)[:, :, :keep]
        return np.argmin((d**2).sum(axis=2), axis=1)

    cow, cup = (nominal_mesh(toys.make(name), SETTINGS) for name in ("cow", "cup"))
    P, Q = (m.vertices[candidate_places(m, mesh_saliency(m), 15)] for m in (cow, cup))
    rng = np.random.default_rng(2)
    cases = [(signatures(P, P[:8]), signatures(Q, Q[:8]), keep) for keep in (5, 8)]
    cases.append((signatures(P, P[:8]), signatures(P, P[:8]), 5))
    for _ in range(20):  # sizes around the block, few and many coordinates, ties
        m, n, L = int(rng.integers(1, 40)), int(rng.integers(1, 60)), int(rng.integers(1, 9))
        cases.append(
            (np.round(rng.random((m, L)) * 8) / 4, np.round(rng.random((n, L)) * 8) / 4, int(rng.integers(1, L + 1)))
        )
    for gm, gf, keep in cases:
        np.testing.assert_array_equal(_pairs(gm, gf, keep), at_once(gm, gf, keep))


@pytest.mark.parametrize("keep", [1, 2, 5, 7])
def test_numpy_sums_a_short_axis_first_to_last_as_place_pairing_does(keep):
    """``_pairs`` adds fewer than 8 kept squares one plane at a time, first to last; NumPy's sum over that axis
    must give the same bits, or the pairs of near-equal signatures could differ."""
    rng = np.random.default_rng(keep)
    d = np.partition(np.abs(rng.normal(size=(8, 131, 8)) * 3), keep - 1, axis=2)
    squares = d[:, :, :keep] ** 2
    total = squares[:, :, 0].copy()
    for c in range(1, keep):
        total += squares[:, :, c]
    np.testing.assert_array_equal(total, squares.sum(axis=2))


@pytest.mark.parametrize("cells", [1 << 16, 50, 9])  # all rows in one block; blocks of 5 rows; one row at a time
def test_tempered_losses_are_the_logsumexp_of_the_tempered_totals_bit_for_bit(cells, monkeypatch):
    import classify.recognizers.place as place
    from classify.recognizers.banks import lse

    monkeypatch.setattr(place, "_TEMPERED", cells)
    rng = np.random.default_rng(4)
    total = rng.normal(size=(43, 9)) * 20 - 50
    total[:, 3] = -np.inf  # an object no touch reaches
    total[7, 1] = total[7].max()  # two objects share a row's maximum
    truth = rng.integers(0, 3, 43)
    temps = np.geomspace(0.25, 64.0, 17)
    want = [np.mean(lse(total / T, axis=1) - total[np.arange(43), truth] / T) for T in temps]
    assert place._tempered_losses(total, truth, temps).mean(axis=1).tolist() == want
