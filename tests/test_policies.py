"""Touch by touch: the policies see what they may, choose where objects differ, and places carry across instances."""

import warnings

import numpy as np
import pytest
import shapes

from classify.experiment.config import Settings
from classify.experiment.samples import SampleTask, instance_samples, instance_spec, nominal_mesh
from classify.policies import (
    POLICIES,
    Forecast,
    InfoGainPolicy,
    RandomPolicy,
    TouchPolicy,
    expected_entropy,
    fit_knowledge,
    run_episode,
    stopping_curve,
)
from classify.recognizers.touches import Recognizer
from meshsal.mesh import Similarity
from meshsal.points.places import POOL_FACTOR

SETTINGS = Settings(n_points=3, view_size=32, train_instances=2, train_sessions=1)


@pytest.fixture(scope="module")
def world():
    """Both objects' instances 0 (test), 1, 2 (training) of replicate 0 with their places, and the knowledge."""
    nominal = {m.name: nominal_mesh(m, SETTINGS) for m in shapes.ball_and_domed()}
    samples = {
        (name, j): instance_samples(SampleTask(mesh, name, (), SETTINGS, 0, j, places=True)).places
        for name, mesh in nominal.items()
        for j in range(3)
    }
    knowledge = fit_knowledge({k: v for k, v in samples.items() if k[1] >= 1}, Recognizer("knn", features="polar"))
    return nominal, samples, knowledge


def test_info_gain_touches_where_the_objects_differ_within_two_touches(world):
    nominal, samples, knowledge = world
    apex = nominal["domed"].vertices[np.argmax(nominal["domed"].vertices @ shapes.DOME_APEX)]
    d = knowledge.names.index("domed")  # its places are located on its shape as the ball's are on the ball

    def under_domed(episode, name):
        """Distances to the apex of the places touched, as the hypothesis "domed" locates them."""
        ranked = knowledge.match(d, samples[name, 0].places)[episode.touched]
        return np.linalg.norm(nominal["domed"].vertices[knowledge.place_ids[d][ranked]] - apex, axis=1)

    for name in knowledge.names:
        episode = run_episode(InfoGainPolicy(), samples[name, 0], knowledge, 2, 8.0, np.random.default_rng(0))
        assert under_domed(episode, name).min() < 25.0, name  # "if domed, on the dome" (about 25 mm across)
    # On the domed instance itself the touch is on its dome (its vertex ids are the nominal mesh's).
    episode = run_episode(InfoGainPolicy(), samples["domed", 0], knowledge, 2, 8.0, np.random.default_rng(0))
    assert np.linalg.norm(nominal["domed"].vertices[episode.vertex_ids] - apex, axis=1).min() < 25.0
    # Control: touches drawn at random rarely find the dome within two (pool rank 0, the farthest vertex from
    # the centroid, is the apex itself, so a fixed pool plan would not be one).
    hits = [
        under_domed(
            run_episode(RandomPolicy(), samples[name, 0], knowledge, 2, 8.0, np.random.default_rng(s)), name
        ).min()
        < 25.0
        for name in knowledge.names
        for s in range(20)
    ]
    assert np.mean(hits) < 0.5, np.mean(hits)


def test_a_place_on_a_turned_resized_copy_matches_the_same_place_of_the_object(world):
    nominal, samples, knowledge = world
    # A ball's places are defined only up to its symmetry (its pool starts anywhere): the domed object has none.
    j, name = knowledge.names.index("domed"), "domed"
    test = samples[name, 0].places
    spec = instance_spec(SETTINGS, name, 0, 0)
    assert not np.allclose(spec.rotation, np.eye(3)) and spec.scale != 1.0  # a turned, resized copy
    back = Similarity(spec.scale, np.zeros(3), spec.rotation).inverse().apply(test.positions)
    matched = nominal[name].vertices[knowledge.place_ids[j][knowledge.match(j, test)]]
    distance = np.linalg.norm(matched - back, axis=1)
    # The pool is found exactly, and so is every mesh-saliency peak training touched too, in whatever order the
    # instance ranks them; a peak of this instance's own (a resized tessellation) is matched to the nearest one.
    assert len(test) > POOL_FACTOR * SETTINGS.n_points and distance[: POOL_FACTOR * SETTINGS.n_points].max() < 1e-6
    assert np.median(distance) < 1e-6 and distance.max() < 0.5 * SETTINGS.sensor.width_mm


def test_a_policy_never_sees_the_label_or_an_imprint_it_did_not_touch(world):
    _, samples, knowledge = world
    seen = []

    class Spy(TouchPolicy):
        def choose(self, state, rng):
            seen.append(state)
            return int(np.flatnonzero(state.available)[-1])

    test = samples["domed", 0]
    episode = run_episode(Spy(), test, knowledge, 4, 16.0, np.random.default_rng(0))
    assert len(seen) == len(episode.touched) == 4
    for k, state in enumerate(seen):
        assert state.touched == tuple(episode.touched[:k])
        np.testing.assert_array_equal(state.imprints, test.imprints[0, list(state.touched)])
        assert not state.available[list(state.touched)].any()
        assert not any("label" in f or "name" == f for f in vars(state))
        positions = test.places.positions
        if state.touched:
            near = np.linalg.norm(positions[:, None] - positions[list(state.touched)][None], axis=2).min(axis=1)
            assert np.all(near[state.available] >= 16.0)
    assert np.allclose(seen[0].belief, 0.5) and np.isclose(episode.beliefs.sum(axis=1), 1.0).all()


def test_every_built_in_policy_runs_an_episode(world):
    _, samples, knowledge = world
    for name in POLICIES.names():
        episode = run_episode(POLICIES.get(name)(), samples["ball", 0], knowledge, 3, 16.0, np.random.default_rng(2))
        assert len(episode.touched) == 3 and len(set(episode.touched.tolist())) == 3, name


def test_expected_entropy_is_the_belief_entropy_where_no_hypothesis_knows_the_place():
    posteriors = np.full((2, 3, 1, 2), 0.5)
    posteriors[0, 0, 0], posteriors[1, 0, 0] = [0.99, 0.01], [0.01, 0.99]
    weights = np.ones((2, 3, 1))
    weights[:, 2] = 0.0  # place 2: nothing known
    h = expected_entropy(np.array([0.5, 0.5]), Forecast(posteriors, weights))
    assert h[0] < 0.1 and h[1] == pytest.approx(np.log(2)) and h[2] == pytest.approx(np.log(2))


def test_expected_entropy_takes_posteriors_and_beliefs_rounded_to_zero_at_their_limit():
    # Sharp posteriors underflow to exactly 0: 0 log 0 is 0, as the limit of a posterior that shrinks to it.
    # (J=3, P=2, S=1, C=3): place 0 tells every object apart, place 1 little.
    sure = np.stack([np.stack([np.eye(3)[j], np.where(np.arange(3) == j, 0.4, 0.3)])[:, None] for j in range(3)])
    tiny = np.where(sure > 0, sure, 1e-300)
    weights = np.ones((3, 2, 1))
    belief = np.array([0.5, 0.5, 0.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        h = expected_entropy(belief, Forecast(sure, weights))
    np.testing.assert_allclose(h, expected_entropy(belief, Forecast(tiny, weights)), rtol=1e-12, atol=1e-12)
    assert h[0] == pytest.approx(0.0) and h[1] > 0.6
    # A touch whose posterior shares no object with the belief leaves the belief as it is: here sure of object 0,
    # a touch that hypothesis 0 forecasts as surely object 1.
    disjoint = sure.copy()
    disjoint[0, 0, 0] = [0.0, 1.0, 0.0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        h = expected_entropy(np.array([1.0, 0.0, 0.0]), Forecast(disjoint, weights))
    assert np.isfinite(h).all() and h[0] == 0.0


def test_the_stopping_rule_stops_at_the_first_touch_whose_belief_reaches_the_level():
    beliefs = [np.array([[0.6, 0.4], [0.9, 0.1], [0.99, 0.01]]), np.array([[0.3, 0.7], [0.96, 0.04]])]
    correct, used = stopping_curve(
        beliefs, np.array([0, 0]), (0.5, 0.95, 0.999), [np.random.default_rng(e) for e in range(2)]
    )
    assert used.tolist() == [[1, 1], [3, 2], [3, 2]]
    assert correct.tolist() == [[1, 0], [1, 1], [1, 1]]


def test_a_place_sample_packs_an_adc_s_readings_as_codes_and_unpacks_them_bit_for_bit():
    import pickle

    from classify.policies import PackedPlaceSample, PlaceSample
    from classify.policies.knowledge import Places

    rng = np.random.default_rng(0)
    places = Places(
        np.arange(6), rng.normal(size=(6, 3)), rng.normal(size=(6, 3)), rng.random((6, 4)), np.ones(6, bool)
    )
    read = (np.round(rng.random((1, 6, 16, 16)) * 255) / 255).astype(np.float32)  # an 8-bit ADC's readings
    codebook = rng.random((6, 8, 42)).astype(np.float32)
    for imprints, packs in ((read, True), (rng.random((1, 6, 16, 16)).astype(np.float32), False), (read * 2, False)):
        sample = PlaceSample(places, imprints, codebook)
        packed = sample.packed()
        assert isinstance(packed, PackedPlaceSample) == packs and (packed is sample) != packs
        # Through a pickle, as a job takes it to a worker.
        back = pickle.loads(pickle.dumps(packed)).unpacked()
        assert isinstance(back, PlaceSample) and back.imprints.dtype == np.float32
        np.testing.assert_array_equal(back.imprints.view(np.int32), imprints.view(np.int32))
        np.testing.assert_array_equal(back.codebook, codebook)
        np.testing.assert_array_equal(packed.landmarks, sample.landmarks)
        for name, a in sample.to_arrays().items():
            np.testing.assert_array_equal(packed.to_arrays()[name], a)
        if packs:  # a byte a taxel where float32 takes four
            assert packed.codes.dtype == np.uint8 and packed.codes.nbytes * 4 == imprints.nbytes
