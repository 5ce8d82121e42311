"""Shortlists: past ``shortlist`` objects a touch is scored in full only under its nearest objects, or under every
object with its place located cheaply (``screening="place"``).

Built on synthetic codebooks: ten objects whose places lie at the same
positions in another order, each place with a descriptor of its own.
"""

import copy
import sys

import numpy as np
import pytest

from classify.policies import (
    Felt,
    Forecasts,
    Places,
    PlaceSample,
    episode_steps,
    expected_entropy,
    fit_place_knowledge,
    hypotheses,
    run_episode,
    run_episodes,
    signatures,
)
from classify.policies.policy import InfoGainPolicy
from classify.recognizers.place import PlaceAware
from classify.recognizers.shortlist import FreeStack, SparseRows, nearest_classes
from meshsal.points.frames import ShapeFrame
from meshsal.points.learned import FEATURES

OBJECTS, PLACES = 10, 24


def _training(seed=0):
    rng = np.random.default_rng(seed)
    positions = rng.normal(size=(PLACES, 3)) * 50.0
    training, feels = {}, {}
    for j in range(OBJECTS):
        order = np.r_[np.arange(8), 8 + rng.permutation(PLACES - 8)]  # the landmarks first, as on a real pool
        feel = rng.normal(size=(PLACES, 42)) * 2.0
        feels[j] = feel[order]
        for i in (1, 2):
            book = (feel[order][:, None] + 0.5 * rng.normal(size=(PLACES, 6, 42))).astype(np.float32)
            imprints = rng.random((1, PLACES, 16, 16)).astype(np.float32)
            training[f"object{j:02d}", i] = PlaceSample(_places(positions[order], rng), imprints, book)
    return training, feels


def _places(positions, rng):
    """Places in one frame for every instance (the identity): each object's landmarks laid onto another
    instance lie where its own are."""
    n = len(positions)
    frame = ShapeFrame(np.zeros(3), np.eye(3), 1.0)
    return Places(
        np.arange(n), positions, rng.normal(size=(n, 3)), np.zeros((n, len(FEATURES))), np.ones(n, bool), frame
    )


@pytest.fixture(scope="module")
def fitted():
    """The same training set fitted with every object on the shortlist, and with three."""
    training, feels = _training()
    full = fit_place_knowledge(training, {"place": {"shortlist": 16, "screening": "touch"}})
    short = fit_place_knowledge(training, {"place": {"shortlist": 3, "screening": "touch"}})
    return training, feels, full, short


def test_free_stack_finds_each_objects_nearest_sample_and_leaves_out_an_instance():
    rng = np.random.default_rng(1)
    frees = [rng.normal(size=(n, 5)) for n in (4, 7, 2)]
    insts = [np.array([1, 2, 1, 2]), np.arange(7) % 2 + 1, np.array([1, 1])]
    stack = FreeStack.of(frees, insts)
    Z = rng.normal(size=(6, 5))
    exclude = np.array([-1, 1, 2, -1, 1, 2])
    d2, count = stack.nearest(Z, exclude)
    for r in range(6):
        for c, (f, i) in enumerate(zip(frees, insts)):
            keep = i != exclude[r]
            want = ((f[keep] - Z[r]) ** 2).sum(axis=1).min() if keep.any() else np.inf
            assert count[r, c] == keep.sum()
            np.testing.assert_allclose(d2[r, c], want, rtol=1e-4, atol=1e-4)
    assert np.isinf(d2[1, 2]) and count[1, 2] == 0  # object 2 has instance 1 only
    # An instance no object holds leaves nothing out.
    np.testing.assert_array_equal(stack.nearest(Z, np.full(6, 7))[0], stack.nearest(Z, np.full(6, -1))[0])
    assert stack.nearest(Z, np.full(6, 7))[1].tolist() == [[4, 7, 2]] * 6


def test_nearest_classes_are_the_least_distances_in_order():
    d2 = np.array([[5.0, 1.0, 3.0, 0.5, 9.0], [0.0, 0.1, 0.2, 0.3, 0.4]])
    assert nearest_classes(d2, 2).tolist() == [[1, 3], [0, 1]]
    assert nearest_classes(d2, 9).tolist() == [[0, 1, 2, 3, 4]] * 2


def test_sparse_rows_keep_a_distribution_and_give_any_columns():
    rows = SparseRows(np.array([[0.5, 0.2]]), np.array([[1, 3]]), np.array([0.1]), 5)
    assert rows.over(np.arange(5)).tolist() == [[0.1, 0.5, 0.1, 0.2, 0.1]]
    dense = SparseRows(np.array([[0.7, 0.3]]), np.array([[0, 1]]), np.zeros(1), 2)
    assert dense.dense and dense.over(np.arange(2)).tolist() == [[0.7, 0.3]]


def test_shortlisted_objects_score_exactly_and_the_others_get_lower_bounds(fitted):
    training, feels, full, _ = fitted
    model = full.model
    limited = copy.copy(model)
    limited.shortlist = 3
    rng = np.random.default_rng(2)
    # Touches at four places of each object, located where they lie (every object has its places there).
    X = np.concatenate([feels[j][8:12] + 0.5 * rng.normal(size=(4, 42)) for j in range(OBJECTS)])
    G = np.concatenate([signatures(training[f"object{j:02d}", 1].places)[8:12] for j in range(OBJECTS)])
    every = model.log_likelihood(X, G)
    few = limited.log_likelihood(X, G)
    d2, _ = model.free_.nearest(model._standardized(X), np.full(len(X), -1))
    listed = np.zeros(every.shape, bool)
    np.put_along_axis(listed, nearest_classes(d2, 3), True, axis=1)
    assert listed.sum(axis=1).tolist() == [3] * len(X)
    np.testing.assert_array_equal(few[listed], every[listed])
    assert np.all(few[~listed] <= every[~listed] + 1e-9)
    assert np.all(np.isfinite(few))
    # The touch's own object is on its shortlist here, and the shortlist decides as the full model does.
    truth = np.repeat(np.arange(OBJECTS), 4)
    assert listed[np.arange(len(X)), truth].mean() > 0.9
    assert (every.argmax(axis=1) == truth).mean() > 0.9
    np.testing.assert_array_equal(few.argmax(axis=1), every.argmax(axis=1))


def test_a_touch_registers_the_test_instance_only_onto_its_shortlist(fitted):
    training, feels, _, short = fitted
    knowledge = copy.copy(short)
    object.__setattr__(knowledge, "_landmarks", {})
    test = training["object04", 1]
    knowledge.posterior_at(test.codebook[:1, 0], test.places.positions[:1], test.places)
    assert 1 <= len(knowledge._landmarks[id(test.places)][1]) <= 3


def _limited(knowledge, shortlist, exact_places):
    """``knowledge`` whose recognizer scores ``shortlist`` objects per touch and registers onto ``exact_places``, with
    an empty cache of registrations."""
    import dataclasses

    model = copy.copy(knowledge.model)
    model.shortlist, model.exact_places = shortlist, exact_places
    out = dataclasses.replace(knowledge, model=model)
    object.__setattr__(out, "_landmarks", {})
    return out


def _touches_of_object(training, feels, j, rng):
    test = training[f"object{j:02d}", 2]
    return feels[j][8:14] + 0.5 * rng.normal(size=(6, 42)), test.places.positions[8:14], test.places


def test_past_the_shortlist_only_the_nearest_objects_ask_for_the_exact_place(fitted):
    training, feels, full, _ = fitted
    model = copy.copy(full.model)
    model.shortlist, model.exact_places = 6, 2
    X, positions, places = _touches_of_object(training, feels, 3, np.random.default_rng(4))
    asked = {}

    def where(c, rows, exact):
        asked[c] = (rows.copy(), None if exact is None else exact.copy())
        return full.signatures_at(positions[rows], places, [c])[:, 0]

    model.log_likelihood(X, where)
    d2, _ = model.free_.nearest(model._standardized(X), np.full(len(X), -1))
    rank = np.argsort(np.argsort(d2, axis=1, kind="stable"), axis=1)  # 0: the nearest object
    for r in range(len(X)):
        listed = sorted(c for c, (rows, _) in asked.items() if r in rows)
        assert listed == sorted(np.flatnonzero(rank[r] < 6).tolist())
        exact = sorted(c for c in listed if asked[c][1][np.flatnonzero(asked[c][0] == r)[0]])
        assert exact == sorted(np.flatnonzero(rank[r] < 2).tolist())
    # With every object scored there is no screening, and every place is asked for in full.
    asked.clear()
    full.model.log_likelihood(X, where)
    assert sorted(asked) == list(range(OBJECTS)) and all(e is None for _, e in asked.values())


def test_past_the_shortlist_a_turned_resized_instance_is_located_through_its_frame(fitted):
    # The test instance turned, moved and resized, its frame with it: every object's landmarks are laid onto it
    # through the frames, so its touches are located, and scored, as on the instance in the training frame.
    import dataclasses

    training, feels, full, _ = fitted
    X, positions, places = _touches_of_object(training, feels, 5, np.random.default_rng(8))
    Q, _ = np.linalg.qr(np.random.default_rng(9).normal(size=(3, 3)))
    R, s, t = Q * np.sign(np.linalg.det(Q)), 2.5, np.array([30.0, -4.0, 9.0])
    frame = ShapeFrame(t, R.T.copy(), s)  # the identity frame, turned, moved and resized
    turned = dataclasses.replace(places, positions=s * places.positions @ R.T + t, frame=frame)
    moved = s * positions @ R.T + t
    nowhere = _limited(full, 6, 0)
    np.testing.assert_allclose(
        nowhere.signatures_at(moved, turned, None, np.zeros(len(moved), bool)),
        nowhere.signatures_at(positions, places, None, np.zeros(len(moved), bool)),
        atol=1e-12,
    )
    post = nowhere.posterior_at(X, moved, turned)
    np.testing.assert_allclose(post, nowhere.posterior_at(X, positions, places), atol=1e-9)
    assert int(np.argmax(post.prod(axis=0))) == 5
    # A frame that does not turn with the instance lays the landmarks elsewhere.
    astray = dataclasses.replace(turned, frame=ShapeFrame(t, np.eye(3), s))
    wrong = nowhere.signatures_at(moved, astray, None, np.zeros(len(moved), bool))
    assert np.abs(wrong - nowhere.signatures_at(positions, places, None, np.zeros(len(moved), bool))).max() > 0.1
    # Places without a frame cannot be located past the shortlist: a clear error, not another location.
    bare = dataclasses.replace(places, frame=None)
    with pytest.raises(ValueError, match="no surface frame"):
        nowhere.posterior_at(X, positions, bare)


def test_registration_onto_the_whole_shortlist_is_the_full_location_bit_for_bit(fitted):
    training, feels, full, _ = fitted
    X, positions, places = _touches_of_object(training, feels, 5, np.random.default_rng(5))
    everywhere = _limited(full, 6, 6)
    # Every object's place by registration, given as an array: what the shortlist then reads of it.
    G = full.signatures_at(positions, places)
    np.testing.assert_array_equal(everywhere.posterior_at(X, positions, places), everywhere.model.predict_proba(X, G))
    # With no exact place, every object's landmarks are laid onto the instance through the frames: here where
    # the instance's own lie.
    nowhere = _limited(full, 6, 0)
    post = nowhere.posterior_at(X, positions, places)
    np.testing.assert_array_equal(post, nowhere.model.predict_proba(X, signatures(places)[8:14]))
    assert not nowhere._landmarks or not nowhere._landmarks[id(places)][1]  # nothing registered
    assert int(np.argmax(post.prod(axis=0))) == 5


def test_registrations_per_test_instance_stay_bounded_past_the_shortlist(fitted):
    training, feels, full, _ = fitted
    rng = np.random.default_rng(6)
    X, positions, places = _touches_of_object(training, feels, 7, rng)
    counts = []
    for exact_places in (1, 2, 6):
        knowledge = _limited(full, 6, exact_places)
        knowledge.posterior_at(X, positions, places)
        registered = knowledge._landmarks[id(places)][1]
        assert 1 <= len(registered) <= exact_places * len(X)
        counts.append(len(registered))
        # A forecast past the shortlist registers onto none of its hypotheses.
        before = set(registered)
        forecast = knowledge.forecast(places, np.array([0, 3, 7, 9]))
        assert set(knowledge._landmarks[id(places)][1]) == before
        np.testing.assert_allclose(forecast.weights.sum(axis=-1), 1.0)
    assert counts[0] < counts[-1]  # the whole shortlist of six touches reaches more objects


def test_exact_places_is_a_non_negative_integer():
    X = np.random.default_rng(0).normal(size=(8, 3))
    with pytest.raises(ValueError, match="exact_places must be a non-negative integer or None, got -1"):
        PlaceAware(exact_places=-1).fit(
            X, np.repeat([0, 1], 4), signatures=np.zeros((8, 2)), instances=np.tile([1, 2], 4), places=np.zeros(8, int)
        )
    assert PlaceAware().get_params()["exact_places"] is None
    assert PlaceAware(screening="touch")._exact_places() == 8 and PlaceAware()._exact_places() == 0
    assert PlaceAware(screening="place", exact_places=3)._exact_places() == 3


def test_a_forecast_over_some_objects_is_the_full_forecast_restricted(fitted):
    training, _, full, _ = fitted
    places = training["object02", 2].places
    whole = full.forecast(places)
    J = np.array([1, 2, 7])
    part = full.forecast(places, J)
    np.testing.assert_array_equal(part.classes, J)
    np.testing.assert_array_equal(part.posteriors, whole.posteriors[J][..., J])
    np.testing.assert_array_equal(part.weights, whole.weights[J])
    belief = np.random.default_rng(3).dirichlet(np.ones(OBJECTS))
    restricted = type(whole)(whole.posteriors[J][..., J], whole.weights[J])
    np.testing.assert_allclose(
        expected_entropy(belief, part), expected_entropy(belief[J] / belief[J].sum(), restricted), rtol=1e-12
    )


def test_forecast_rows_past_the_shortlist_keep_their_objects_in_order(fitted):
    _, _, _, short = fitted
    rows = short.table[0]
    assert rows.values.shape[-1] == 3 and not rows.dense
    assert np.all(rows.values.sum(axis=-1) <= 1.0 + 1e-9) and np.all(rows.rest >= 0)
    assert np.all(np.diff(rows.classes, axis=-1) > 0)


@pytest.mark.parametrize("which", ["full", "short"])
def test_forecast_rows_do_not_depend_on_which_objects_rows_are_scored_together(fitted, monkeypatch, which):
    from classify.recognizers import place as place_module

    model = fitted[2 if which == "full" else 3].model
    together = model.forecast_table(samples=3)
    # One object's rows per call: the finest grouping.
    monkeypatch.setattr(place_module, "_CHUNK", 1)
    monkeypatch.setattr(place_module, "_FORECAST", 1)
    alone = model.forecast_table(samples=3)
    for (a, wa), (b, wb) in zip(zip(*together), zip(*alone)):
        np.testing.assert_array_equal(a.classes, b.classes)
        np.testing.assert_array_equal(wa, wb)
        if which == "full":  # every object scored: bit for bit
            np.testing.assert_array_equal(a.values, b.values)
        else:  # the screening's float32 products round with the rows beside them
            np.testing.assert_allclose(a.values, b.values, rtol=1e-6)
            np.testing.assert_allclose(a.rest, b.rest, rtol=1e-6)
    # A row is its touch's own posterior: scored alone, with its instance left out.
    bank = model.banks_[4]
    e, s = 5, int(np.flatnonzero(bank.instances[5] >= 0)[-1])
    mixed = model._mixed(bank.samples[e, s][None], bank.signatures[e][None], bank.instances[e, s][None])[0][0]
    ll = mixed / model.temperature_
    post = np.exp(ll - np.logaddexp.reduce(ll))
    last = min(3, int((bank.instances[e] >= 0).sum())) - 1  # the entry's last pick is its last valid sample
    row = together[0][4][e, last]
    np.testing.assert_allclose(row.values, post[row.classes], rtol=1e-6)
    assert row.classes.shape == ((OBJECTS,) if which == "full" else (3,)) and together[1][4][e, last] > 0


def test_hypotheses_are_the_most_probable_with_ties_drawn():
    belief = np.array([0.05, 0.4, 0.05, 0.3, 0.2])
    assert hypotheses(belief, 3, np.random.default_rng(0)).tolist() == [1, 3, 4]
    assert hypotheses(belief, 5, None) is None
    flat = np.full(40, 1 / 40)
    draws = {tuple(hypotheses(flat, 4, np.random.default_rng(s)).tolist()) for s in range(6)}
    assert len(draws) == 6  # a flat belief gives a random sample, not the first names
    assert (
        hypotheses(flat, 4, np.random.default_rng(9)).tolist() == hypotheses(flat, 4, np.random.default_rng(9)).tolist()
    )


def test_info_gain_runs_on_its_shortlist_and_finds_the_object(fitted, monkeypatch):
    import classify.policies.episodes as episodes

    training, _, _, short = fitted
    test = PlaceSample(training["object06", 2].places, training["object06", 2].codebook[None, :, 0, :])
    asked = []

    class Counting(Forecasts):
        def over(self, classes=None):
            asked.append(None if classes is None else len(classes))
            return super().over(classes)

    monkeypatch.setattr(episodes, "Forecasts", Counting)
    episode = run_episode(InfoGainPolicy(), test, short, 3, 0.0, np.random.default_rng(0))
    assert asked and set(asked) == {3}  # never a forecast over all ten objects
    np.testing.assert_allclose(episode.beliefs.sum(axis=1), 1.0)
    assert int(np.argmax(episode.beliefs[-1])) == 6
    felt = Felt(short, test.imprints[0], test.places)
    assert felt._all is None and felt[0].shape == (OBJECTS,)


def test_another_objects_touches_at_an_objects_places_do_not_point_to_it(fitted):
    # The shuffled control in miniature: object j's places, touched with what object j + 1 feels there.
    training, feels, _, short = fitted
    rng = np.random.default_rng(6)
    named, donor = [], []
    for j in range(OBJECTS):
        test = training[f"object{j:02d}", 2]
        d = (j + 1) % OBJECTS
        touches = feels[d][8:14] + 0.5 * rng.normal(size=(6, 42))
        post = short.posterior_at(touches, test.places.positions[8:14], test.places)
        named.append(np.argmax(post, axis=1) == j)
        donor.append(np.argmax(post, axis=1) == d)
    assert np.mean(named) <= 2.0 / OBJECTS  # the places do not give the object away
    assert np.mean(donor) > 0.5  # what was felt does


def test_the_place_free_knowledge_keeps_each_touchs_most_probable_objects(monkeypatch):
    from classify.policies import TouchKnowledge, fit_knowledge
    from classify.recognizers.touches import Recognizer

    rng = np.random.default_rng(7)
    training = {}
    for j in range(6):  # six objects, each a bump of its own height under the pad at every place
        for i in (1, 2):
            imprints = np.clip(rng.normal(0.1 * j, 0.05, (1, 12, 16, 16)), 0, 1).astype(np.float32)
            training[f"object{j}", i] = PlaceSample(_places(rng.normal(size=(12, 3)) * 40, rng), imprints)
    recognizer = Recognizer("knn", features="polar")
    whole = fit_knowledge(training, recognizer)
    monkeypatch.setattr(TouchKnowledge, "hypotheses", 3)
    short = fit_knowledge(training, recognizer)
    assert whole.posteriors[0].dense and short.posteriors[0].values.shape[-1] == 3
    assert short.calibration == whole.calibration
    for a, b in zip(whole.posteriors, short.posteriors):
        top = np.sort(np.argsort(-a.values, axis=-1, kind="stable")[..., :3], axis=-1)
        ranked = -np.sort(-a.values, axis=-1)
        untied = ranked[..., 2] > ranked[..., 3] * (1 + 1e-9)
        assert untied.mean() > 0.5
        np.testing.assert_array_equal(b.classes[untied], top[untied])  # where the top three are not tied
        np.testing.assert_allclose(b.values.sum(axis=-1) + 3 * b.rest, 1.0)
    # A forecast over three objects reads them off the kept rows.
    places = training["object2", 1].places
    part = short.forecast(places, np.array([1, 2, 3]))
    assert part.posteriors.shape[0] == part.posteriors.shape[-1] == 3


def test_episodes_stepped_together_end_as_alone_and_feel_each_round_in_one_batch(monkeypatch):
    from classify.policies import TouchKnowledge, fit_knowledge
    from classify.recognizers.touches import Recognizer

    monkeypatch.setattr(TouchKnowledge, "hypotheses", 3)  # past it a place is felt when first touched
    rng = np.random.default_rng(8)
    training, tests = {}, []
    for j in range(6):
        for i in (0, 1, 2):
            imprints = np.clip(rng.normal(0.1 * j, 0.05, (1, 12, 16, 16)), 0, 1).astype(np.float32)
            sample = PlaceSample(_places(rng.normal(size=(12, 3)) * 40, rng), imprints)
            if i:
                training[f"object{j}", i] = sample
            else:
                tests.append(sample)
    knowledge = fit_knowledge(training, Recognizer("knn", features="polar"))
    calls = []
    scored = TouchKnowledge.posterior

    def counted(self, imprints, places=None):
        calls.append(len(imprints))
        return scored(self, imprints, places)

    monkeypatch.setattr(TouchKnowledge, "posterior", counted)
    for spacing in (0.0, 90.0):  # every episode touches four times; episodes run out of places at different touches
        calls.clear()
        alone = [
            run_episode(InfoGainPolicy(), t, knowledge, 4, spacing, np.random.default_rng(c))
            for c, t in enumerate(tests)
        ]
        lengths = [len(e.touched) for e in alone]
        assert calls == [1] * sum(lengths)
        calls.clear()
        steps = [
            episode_steps(InfoGainPolicy(), t, knowledge, 4, spacing, np.random.default_rng(c))
            for c, t in enumerate(tests)
        ]
        together = run_episodes(steps, [Felt(knowledge, t.imprints[0], t.places) for t in tests])
        # One batch per round, of the episodes still touching.
        assert calls == [sum(n > k for n in lengths) for k in range(max(lengths))]
        for a, b in zip(alone, together):
            np.testing.assert_array_equal(a.touched, b.touched)
            np.testing.assert_allclose(a.beliefs, b.beliefs, rtol=1e-9)
    assert len(set(lengths)) > 1


def test_place_free_episodes_step_together_and_place_aware_ones_one_at_a_time(fitted, monkeypatch):
    # Stepping together batches a place-free knowledge's touches; a place-aware one's would only hold more
    # forecasts at once.
    import classify.experiment.sequential as sequential
    from classify.policies import fit_knowledge
    from classify.recognizers.touches import Recognizer

    training, _, _, short = fitted
    alive, most = [0], [0]
    steps = sequential.episode_steps

    def counted(*args, **kwargs):
        alive[0] += 1
        most[0] = max(most[0], alive[0])
        try:
            return (yield from steps(*args, **kwargs))
        finally:
            alive[0] -= 1

    monkeypatch.setattr(sequential, "episode_steps", counted)
    names = short.names
    described = tuple(PlaceSample(training[n, 2].places, training[n, 2].codebook[None, :, 0, :]) for n in names)
    imprinted = tuple(training[n, 2] for n in names)
    place_free = fit_knowledge(training, Recognizer("knn", features="polar"))
    for knowledge, tests, expected in ((short, described, 1), (place_free, imprinted, OBJECTS)):
        most[0] = 0
        out = sequential.run_policies(knowledge, tests, names, ("info_gain",), 2, 0.0, 0, 0, ())
        assert most[0] == expected and alive[0] == 0
        assert (out.touched >= 0).all()


@pytest.mark.parametrize("grid", [True, False])
def test_knn_shortlist_with_every_object_a_candidate_is_predict_proba(grid):
    import classify
    from classify.recognizers.shortlist import knn_shortlist

    rng = np.random.default_rng(11)
    y = rng.integers(0, 9, 400)
    X, Q = rng.random((9, 5))[y] + 0.2 * rng.random((400, 5)), rng.random((50, 5))
    if grid:
        X, Q = np.round(X * 255) / 255, np.round(Q * 255) / 255
    model = classify.make("knn").fit(X, y)
    P = model.predict_proba(Q)
    values, classes = knn_shortlist(model, Q, 4, candidates=9)
    expected = np.sort(nearest_classes(-P, 4), axis=1)
    np.testing.assert_array_equal(classes, expected)
    np.testing.assert_array_equal(values, np.take_along_axis(P, expected, axis=1))


def test_knn_shortlist_screens_in_each_touchs_object_among_many():
    # Forty objects, each a tight cluster: a query beside its cluster has it first, as the full kNN does,
    # though only eight of the forty objects' rows are read in full.
    import classify
    from classify.recognizers.shortlist import knn_shortlist

    rng = np.random.default_rng(12)
    centres = rng.random((40, 6)) * 10
    y = np.repeat(np.arange(40), 30)
    model = classify.make("knn").fit(centres[y] + rng.normal(0, 0.1, (1200, 6)), y)
    truth = rng.integers(0, 40, 200)
    Q = centres[truth] + rng.normal(0, 0.1, (200, 6))
    values, classes = knn_shortlist(model, Q, 4, candidates=8)
    assert values.shape == classes.shape == (200, 4)
    assert np.all(np.diff(classes, axis=1) > 0)
    best = np.take_along_axis(classes, np.argmax(values, axis=1)[:, None], axis=1)[:, 0]
    np.testing.assert_array_equal(best, truth)
    np.testing.assert_array_equal(best, np.argmax(model.predict_proba(Q), axis=1))
    assert np.all(values.sum(axis=1) <= 1.0 + 1e-12)


# -- screening by place ------------------------------------------------------------------------------------


def _alike_felt(seed=7):
    """Ten objects of one shape that feel alike, place-free: each holds the same descriptors at its places, in
    another order.  A touch alone cannot tell them apart; a touch at a known place can."""
    rng = np.random.default_rng(seed)
    positions = rng.normal(size=(PLACES, 3)) * 50.0
    base = rng.normal(size=(PLACES, 42)) * 2.0
    training, feels = {}, {}
    for j in range(OBJECTS):
        feels[j] = base[rng.permutation(PLACES)]
        for i in (1, 2):
            book = (feels[j][:, None] + 0.5 * rng.normal(size=(PLACES, 6, 42))).astype(np.float32)
            imprints = rng.random((1, PLACES, 16, 16)).astype(np.float32)
            training[f"object{j:02d}", i] = PlaceSample(_places(positions, rng), imprints, book)
    return training, feels


@pytest.fixture(scope="module")
def alike():
    training, feels = _alike_felt()
    by = {s: fit_place_knowledge(training, {"place": {"shortlist": 3, "screening": s}}) for s in ("touch", "place")}
    return training, feels, by


def _touches(feels, rng):
    """Four touches of each object at its places 8-11, and their objects."""
    X = np.concatenate([feels[j][8:12] + 0.5 * rng.normal(size=(4, 42)) for j in range(OBJECTS)])
    truth = np.repeat(np.arange(OBJECTS), 4)
    return X, truth


def test_screening_by_place_keeps_the_object_a_touch_alone_drops(alike):
    training, feels, by = alike
    X, truth = _touches(feels, np.random.default_rng(8))
    places = training["object00", 2].places  # every object has this shape
    rows = np.arange(len(X))
    G = np.tile(signatures(places)[8:12], (OBJECTS, 1))
    right = {}
    for screening, knowledge in by.items():
        ll = knowledge.model.log_likelihood(X, G)
        right[screening] = np.mean(ll.argmax(axis=1) == truth)
        # the true object's rank among the scores (0: first)
        if screening == "touch":
            d2, _ = knowledge.model.free_.nearest(knowledge.model._standardized(X), np.full(len(X), -1))
            dropped = np.mean((d2 < d2[rows, truth][:, None]).sum(axis=1) >= 3)
    assert dropped > 0.5  # the stimulus: a touch alone leaves the true object off its shortlist of three
    assert right["touch"] < 0.5 and right["place"] > 0.8


def test_screening_by_place_scores_every_object_and_registers_the_most_likely(alike):
    training, feels, by = alike
    knowledge = by["place"]
    model = copy.copy(knowledge.model)
    model.exact_places = 2
    X, truth = _touches(feels, np.random.default_rng(9))
    X, truth = X[::4], truth[::4]  # one touch of each object
    places = training["object00", 2].places
    own = np.tile(signatures(places)[8:9], (len(X), 1))
    # Registration is stood in for by a place a little off the instance's own: what the two-stage choice reads.
    moved = own + 0.05
    asked = []

    def where(c, rows, exact):
        asked.append((c, rows.copy(), None if exact is None else exact.copy()))
        if c is None:  # the place under every object, located on the instance's own landmarks
            return own[rows]
        return np.where(exact[:, None], moved[rows], own[rows])

    ll = model.log_likelihood(X, where)
    first = model.log_likelihood(X, own)  # every object at the instance's own place
    again = model.log_likelihood(X, moved)
    likely = np.argsort(-first, axis=1, kind="stable")[:, :2]
    # Every touch is located cheaply once, for every object, and by registration under its two most likely.
    cheap = np.concatenate([rows for c, rows, _ in asked if c is None])
    np.testing.assert_array_equal(np.sort(cheap), np.arange(len(X)))
    assert all(exact.all() for c, _, exact in asked if c is not None)
    for r in range(len(X)):
        registered = {c for c, rows, _ in asked if c is not None and r in rows}
        assert registered == set(likely[r].tolist())
        for c in range(OBJECTS):
            want = again[r, c] if c in registered else first[r, c]
            np.testing.assert_allclose(ll[r, c], want, rtol=1e-9, atol=1e-9)
    assert np.mean(ll.argmax(axis=1) == truth) > 0.9


def test_screening_by_place_registers_onto_no_object_by_default(alike):
    # Registration lets the test instance's shape in (it keeps the true object's place and moves the others'), so
    # by default the place screening locates every touch on the instance's own landmarks alone.
    training, feels, by = alike
    X, _ = _touches(feels, np.random.default_rng(10))
    own = np.tile(signatures(training["object00", 2].places)[8:12], (OBJECTS, 1))
    asked = []

    def where(c, rows, exact):
        asked.append(c)
        return own[rows]

    assert by["place"].model.exact_places is None
    np.testing.assert_array_equal(by["place"].model.log_likelihood(X, where), by["place"].model.log_likelihood(X, own))
    assert asked == [None]


def test_screening_by_place_fits_on_every_object_and_is_the_full_model_up_to_the_shortlist(alike, fitted):
    alike_training, _, by = alike
    every = fit_place_knowledge(alike_training, {"place": {"shortlist": 16}}).model
    # Past the shortlist the fit scores its held-out touches under every object: the full model's choice.
    for name in ("bandwidth_", "mixture_", "temperature_", "fit_loss_"):
        assert getattr(by["place"].model, name) == getattr(every, name)
    assert by["touch"].model.fit_loss_ != every.fit_loss_
    # Up to the shortlist the screening changes nothing, bit for bit.
    training, _, full, _ = fitted
    same = fit_place_knowledge(training, {"place": {"shortlist": 16, "screening": "place"}})
    X = training["object03", 2].codebook[8:12, 0]
    G = signatures(training["object03", 2].places)[8:12]
    np.testing.assert_array_equal(same.model.log_likelihood(X, G), full.model.log_likelihood(X, G))
    assert same.model.fit_loss_ == full.model.fit_loss_


def test_screening_by_place_scores_every_object_at_once_as_each_in_turn():
    # Objects of unequal banks: 2 to 6 places (some fewer than the 4 matched neighbours), 1 to 3 touches per place
    # and instance, two or three instances.  Scored all at once (places the same under every object) or object
    # by object (the same places given per object), the terms agree, left-out instances and -inf included.
    rng = np.random.default_rng(21)
    X, y, sig, inst, keys = [], [], [], [], []
    for c in range(12):
        for i in range(1, 3 + c % 2):
            for p in range(2 + c % 5):
                k = 1 + (c + p + i) % 3
                X.append(rng.normal(c % 4, 1.0, (k, 5)))
                sig.append(np.tile(np.array([p, c % 3, 1.0]) + 0.01 * i, (k, 1)))
                y += [c] * k
                inst += [i] * k
                keys += [p] * k
    X, sig = np.concatenate(X), np.concatenate(sig)
    model = PlaceAware(shortlist=4, screening="place", exact_places=0, fit_sets=5).fit(
        X, np.array(y), signatures=sig, instances=np.array(inst), places=np.array(keys)
    )
    Q, G = rng.normal(1.5, 1.5, (40, 5)), rng.uniform(0, 6, (40, 3))
    exclude = np.where(np.arange(40) % 3 == 0, 1, -1)
    at_once = model.log_likelihood(Q, G, exclude=exclude)
    in_turn = model.log_likelihood(Q, np.repeat(G[:, None], 12, axis=1), exclude=exclude)
    assert at_once.shape == (40, 12) and np.all(np.isfinite(at_once))
    np.testing.assert_allclose(at_once, in_turn, rtol=1e-12, atol=1e-12)
    assert all(np.shares_memory(bank.samples, model._stack().samples) for bank in model.banks_)  # held once
    # A function of the places is asked once, for every object (c None).
    asked = []

    def where(c, rows, exact):
        asked.append(c)
        return G[rows]

    np.testing.assert_array_equal(model.log_likelihood(Q, where, exclude=exclude), at_once)
    assert set(asked) == {None}
    # Each object's own places (as the surface frames lay them), given by the function at once, are scored as
    # the same places given object by object.
    H = G[:, None] + rng.uniform(-1.0, 1.0, (40, 12, 3))
    at_once = model.log_likelihood(Q, lambda c, rows, exact: H[rows], exclude=exclude)
    np.testing.assert_allclose(at_once, model.log_likelihood(Q, H, exclude=exclude), rtol=1e-12, atol=1e-12)
    assert not np.allclose(at_once, in_turn)


def test_a_bank_stack_lends_its_banks_their_samples_unchanged():
    # Banks of unequal sizes (entries, samples per entry, place-free samples): once stacked, each reads its
    # arrays from views of the stack's, its own let go, so the samples are held once, and every value and
    # distance is the same.
    import weakref

    from classify.recognizers.banks import Bank, BankStack, free_d2, sample_d2

    rng = np.random.default_rng(5)
    banks = []
    for c, (e, s, f) in enumerate([(3, 2, 4), (5, 4, 2), (1, 3, 3)]):
        inst = np.where(rng.random((e, s)) < 0.3, -1, rng.integers(0, 3, (e, s)))
        banks.append(
            Bank(
                np.arange(e),
                rng.normal(size=(e, 3)),
                rng.normal(size=(e, s, 4)),
                inst,
                rng.normal(size=(f, 4)),
                rng.integers(0, 3, f),
                0.5 + c,
            )
        )
    before = copy.deepcopy(banks)
    own = [weakref.ref(b.samples) for b in banks] + [weakref.ref(b.free) for b in banks]
    Z, exclude = rng.normal(size=(6, 4)), np.array([-1, 0, 1, 2, -1, 1])
    stack = BankStack(banks, lend=True)
    assert all(ref() is None for ref in own)
    for bank, old in zip(banks, before):
        for name in ("samples", "sq", "instances", "free", "free_sq", "free_instances"):
            mine, base = getattr(bank, name), getattr(stack, name)
            assert np.shares_memory(mine, base), name
            np.testing.assert_array_equal(mine, getattr(old, name))
        idx = rng.integers(0, len(old.keys), (6, 2))
        np.testing.assert_array_equal(sample_d2(bank, Z, idx, exclude), sample_d2(old, Z, idx, exclude))
        np.testing.assert_array_equal(free_d2(bank, Z, exclude), free_d2(old, Z, exclude))
    # Without lending, the banks keep their own arrays.
    kept = copy.deepcopy(before)
    BankStack(kept)
    assert all(np.array_equal(k.samples, b.samples) and k.samples.base is None for k, b in zip(kept, before))


_LENDING = """
import sys
import numpy as np, psutil
from classify.runtime.cluster import _set_malloc_thresholds
import classify.recognizers.banks as bk

_set_malloc_thresholds()  # a Dask worker's: arrays up to 32 MB from the heap
if sys.argv[1] == "kept":
    bk.release_free_memory = lambda: None
rng = np.random.default_rng(0)
banks = []
for c in range(400):
    E, S = 60, 24
    banks.append(bk.Bank(np.arange(E), rng.normal(size=(E, 3)), rng.normal(size=(E, S, 42)), np.ones((E, S), np.int64),
                         rng.normal(size=(8, 42)), np.ones(8, np.int64), 1.0))
samples = sum(b.samples.nbytes for b in banks)
before = psutil.Process().memory_info().rss
stack = bk.BankStack(banks, lend=True)
print((psutil.Process().memory_info().rss - before) / samples)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's heap")
def test_a_bank_stack_hands_back_its_banks_pages_as_it_lends_them_their_samples():
    # Each bank's samples (a few hundred kB, from the heap in a Dask worker) go as they are copied into the stack;
    # their pages stay resident unless handed back, and a thousand objects' banks are hundreds of megabytes.
    import subprocess

    grown = {
        how: float(
            subprocess.run([sys.executable, "-c", _LENDING, how], capture_output=True, text=True, check=True).stdout
        )
        for how in ("released", "kept")
    }
    assert grown["released"] < 0.35 and grown["kept"] > 0.8, grown


def test_the_knowledge_lets_its_training_touches_go_before_the_fit_reads_its_session_and_chooses(monkeypatch):
    # A thousand objects' codebook touches are hundreds of megabytes per worker; the choice of the fit, screened
    # by place, scores under every object, so the touches must not lie beside it.  The same fit, bit for bit.
    import weakref

    import classify.policies.place_knowledge as pk

    training, _ = _training()
    made, alive = [], []
    touches, choose = pk.place_touches, PlaceAware._choose

    def traced(*args, **kwargs):
        out = touches(*args, **kwargs)
        made.append(weakref.ref(out[0]))
        return out

    def checked(self, session):
        alive.append(made[-1]() is not None)
        return choose(self, session)

    def session_read(*args):
        alive.append(made[-1]() is not None)
        return session(*args)

    session = pk._session_touches
    monkeypatch.setattr(pk, "place_touches", traced)
    monkeypatch.setattr(pk, "_session_touches", session_read)
    monkeypatch.setattr(PlaceAware, "_choose", checked)
    params = {"shortlist": 3, "screening": "place"}
    knowledge = fit_place_knowledge(training, {"place": params})
    assert alive == [False, False]  # gone before the held-out session is read, and before the choice
    X, y, sig, inst, keys = touches(training, knowledge.names, dtype=np.float64)
    whole = PlaceAware(**params).fit(
        X, y, signatures=sig, instances=inst, places=keys, session=session(training, knowledge.names)
    )
    got = (knowledge.model.fit_loss_, knowledge.model.bandwidth_, knowledge.model.mixture_)
    assert got == (whole.fit_loss_, whole.bandwidth_, whole.mixture_)


def test_place_touches_copies_the_codebooks_into_one_array_and_holds_no_second_copy():
    # A thousand objects' codebooks are hundreds of megabytes: gathered in pieces and then joined they would lie
    # twice in memory (the pieces, float32, and the float64 whole, with the signatures' pieces: 0.8 of X here).
    import tracemalloc

    import classify.policies.place_knowledge as pk
    from meshsal.points.places import signatures

    training, _ = _training()
    names = tuple(sorted({name for name, _ in training}))
    tracemalloc.start()
    try:
        X, y, sig, inst, keys = pk.place_touches(training, names, dtype=np.float64)
        held, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak - held < 0.25 * X.nbytes, (peak - held) / X.nbytes
    order = [(c, name, i) for c, name in enumerate(names) for i in (1, 2)]
    draws = training[names[0], 1].codebook.shape[1]
    np.testing.assert_array_equal(X, np.concatenate([training[n, i].codebook.reshape(-1, 42) for _, n, i in order]))
    np.testing.assert_array_equal(y, np.repeat([c for c, _, _ in order], PLACES * draws))
    np.testing.assert_array_equal(inst, np.repeat([i for _, _, i in order], PLACES * draws))
    where = [signatures(training[n, i].places.positions, training[n, i].landmarks) for _, n, i in order]
    np.testing.assert_array_equal(sig, np.repeat(np.concatenate(where), draws, axis=0))
    np.testing.assert_array_equal(keys, np.repeat(pk.place_keys(np.concatenate(where)), draws))
    assert X.dtype == np.float64 and pk.place_touches(training, names)[0].dtype == np.float32


def test_screening_is_touch_or_place():
    X = np.random.default_rng(0).normal(size=(8, 3))
    with pytest.raises(ValueError, match=r"screening must be one of \('place', 'touch'\), got 'sight'"):
        PlaceAware(screening="sight").fit(
            X, np.repeat([0, 1], 4), signatures=np.zeros((8, 2)), instances=np.tile([1, 2], 4), places=np.zeros(8, int)
        )
    assert PlaceAware().get_params()["screening"] == "place"
