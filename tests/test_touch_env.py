"""TouchEnv: Gymnasium's checker passes, our policies touch through it what they touch outside, it never tells the label
before the answer, and the reward is what the documentation says."""

import warnings

import gymnasium
import numpy as np
import pytest
import shapes
from gymnasium.utils.env_checker import check_env, data_equivalence

from classify.experiment.config import Settings
from classify.experiment.env import ENV_ID, TouchEnv, run_policy, touch_state
from classify.experiment.samples import SampleTask, instance_samples, instance_spec, nominal_mesh
from classify.policies import InfoGainPolicy, fit_knowledge, run_episode
from classify.recognizers.touches import Recognizer

SETTINGS = Settings(n_points=3, view_size=32, train_instances=2, train_sessions=1)
KEYS = {"features", "positions", "normals", "valid", "available", "touched", "imprints", "belief", "touches"}


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("touch_env_cache")


@pytest.fixture(scope="module")
def env(cache):
    return TouchEnv(list(shapes.ball_and_domed()), SETTINGS, test_replicates=range(3), cache_dir=cache)


def _sample(name, replicate, cache):
    """The test instance an episode touched, built apart from the env."""
    mesh = {m.name: m for m in shapes.ball_and_domed()}[name]
    return instance_samples(
        SampleTask(nominal_mesh(mesh, SETTINGS), name, (), SETTINGS, replicate, 0, places=True, cache_dir=cache)
    ).places


def _touch_first_available(env, observation):
    return env.step(int(np.flatnonzero(observation["available"])[0]))


def test_gymnasiums_checker_passes_without_a_warning(env):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, skip_render_check=True)
    assert not [str(w.message) for w in caught if "WARN" in str(w.message)]
    assert env.max_places == 66 and env.action_space.n == 67 and env.max_touches == 3  # (20 + 2) * 3 places


def test_the_env_made_by_id_is_the_env(env, cache):
    made = gymnasium.make(
        ENV_ID, objects=list(shapes.ball_and_domed()), settings=SETTINGS, test_replicates=range(3), cache_dir=cache
    )
    assert data_equivalence(made.reset(seed=5)[0], env.reset(seed=5)[0], exact=True)


def test_info_gain_through_the_env_touches_what_run_episode_touches(env, cache):
    run = run_policy(env, "info_gain", episodes=6, seed=3)
    assert set(run.objects) == {"ball", "domed"} and run.touches.tolist() == [3] * 6
    # The knowledge fitted apart, on instances 1 and 2 of replicate 0 as the sequential protocol fits it: the
    # place-aware recognizer on their codebooks.
    nominal = {m.name: nominal_mesh(m, SETTINGS) for m in shapes.ball_and_domed()}
    training = {
        (name, j): instance_samples(
            SampleTask(mesh, name, (), SETTINGS, 0, j, places=True, codebook=True, cache_dir=cache)
        ).places
        for name, mesh in nominal.items()
        for j in (1, 2)
    }
    knowledge = fit_knowledge(training, Recognizer("place"))
    for e, (name, replicate) in enumerate(zip(run.objects, run.replicates)):
        episode = run_episode(
            InfoGainPolicy(),
            _sample(name, replicate, cache),
            knowledge,
            SETTINGS.n_points,
            0.5 * SETTINGS.sensor.width_mm,
            np.random.default_rng(0),
        )
        assert run.touched[e].tolist() == episode.touched.tolist(), (name, replicate)
        np.testing.assert_array_equal(run.beliefs[e], episode.beliefs[-1])
        assert run.correct[e] == (knowledge.names[int(np.argmax(episode.beliefs[-1]))] == name)


def test_the_stopping_rule_and_random_run_through_the_env(env):
    at_once = run_policy(env, "random", episodes=4, seed=0, stop=0.5)  # two objects: any belief reaches 0.5
    assert at_once.touches.tolist() == [1] * 4
    assert np.allclose(at_once.rewards, at_once.correct - env.touch_cost)
    full = run_policy(env, "random", episodes=4, seed=0)
    assert full.touches.tolist() == [3] * 4 and [len(t) for t in full.touched] == [3] * 4
    # Every episode draws alike from the env's generator, whatever the agent does: the same seed, the same episodes.
    assert full.objects.tolist() == at_once.objects.tolist()
    assert full.replicates.tolist() == at_once.replicates.tolist()


def test_the_observation_shows_only_what_was_touched_and_info_the_truth_only_at_the_end(env, cache):
    observation, info = env.reset(seed=11)
    assert set(observation) == KEYS and set(info) == {"touches", "replicate"}
    assert not observation["imprints"].any() and not observation["touched"].any()
    assert np.allclose(observation["belief"], 0.5) and observation["touches"] == 0
    p = len(env.places)
    assert observation["valid"][:p].all() and not observation["valid"][p:].any()
    assert not observation["available"][p:].any() and not observation["features"][p:].any()
    first = int(np.flatnonzero(observation["available"])[0])
    observation, reward, over, truncated, info = env.step(first)
    assert not over and not truncated and reward == -env.touch_cost and set(info) == {"touches"}
    assert observation["touched"][first] == 1 and observation["touched"].sum() == 1
    assert not observation["available"][first] and observation["touches"] == 1
    assert not observation["imprints"][1:].any()
    second = int(np.flatnonzero(observation["available"])[0])
    observation, _, over, _, info = env.step(second)
    assert not over and "object" not in info
    # Which instance it was, read back only now, from outside the env: the imprints are the touched places'.
    observation, _, over, _, info = env.step(env.max_places)
    assert over and set(info) == {"touches", "object", "answer", "correct"}
    sample = _sample(info["object"], env.unwrapped._episode.replicate, cache)
    np.testing.assert_array_equal(observation["imprints"][:2], sample.imprints[0, [first, second]])
    state = touch_state(env, observation)
    assert state.touched == (first, second) and np.array_equal(state.imprints, sample.imprints[0, [first, second]])
    touched = [first, second]
    felt = env.knowledge.posterior_at(sample.imprints[0, touched], sample.places.positions[touched], sample.places)
    felt = felt.prod(axis=0)
    assert np.allclose(observation["belief"], felt / felt.sum())


def test_the_reward_an_unavailable_place_and_the_automatic_answer(env):
    observation, _ = env.reset(seed=2)
    _, reward, over, _, info = env.step(env.max_places)  # answer before any touch
    assert over and reward == float(info["correct"]) and info["touches"] == 0
    assert (info["answer"] == info["object"]) == info["correct"]
    with pytest.raises(RuntimeError, match="reset"):
        env.step(0)
    observation, _ = env.reset(seed=2)
    touched, _, _, _, _ = _touch_first_available(env, observation)
    wasted = int(np.flatnonzero(touched["touched"])[0])  # touching it again feels nothing
    again, reward, over, _, info = env.step(wasted)
    assert reward == -env.touch_cost and not over and info["touches"] == again["touches"] == 2
    assert not again["imprints"][1].any() and np.array_equal(again["touched"], touched["touched"])
    assert np.array_equal(again["belief"], touched["belief"])
    _, reward, over, _, info = _touch_first_available(env, again)  # the third and last touch answers
    assert over and info["touches"] == 3 and reward == pytest.approx(float(info["correct"]) - env.touch_cost)
    env.reset(seed=2)
    with pytest.raises(ValueError, match="action"):
        env.step(env.max_places + 1)


def test_resets_are_seeded_and_draw_test_instances_training_never_saw(env, cache):
    first, info = env.reset(seed=7)
    assert data_equivalence(first, env.reset(seed=7)[0], exact=True)
    fresh = TouchEnv(list(shapes.ball_and_domed()), SETTINGS, test_replicates=range(3), seed=7, cache_dir=cache)
    with pytest.raises(gymnasium.error.ResetNeeded):
        fresh.step(0)
    assert data_equivalence(first, fresh.reset()[0], exact=True)  # an unseeded first reset: seed=7
    drawn = set()
    for seed in range(12):
        env.reset(seed=seed)
        drawn.add((env.unwrapped._episode.truth, env.unwrapped._episode.replicate))
    assert {t for t, _ in drawn} == {0, 1} and {r for _, r in drawn} == {0, 1, 2}
    for name in env.names:
        # Training saw instances 1 and 2 of replicate 0; tests are instance 0 of a replicate: other poses.
        trained = [instance_spec(SETTINGS, name, 0, j).rotation for j in (1, 2)]
        assert not any(np.allclose(instance_spec(SETTINGS, name, r, 0).rotation, R) for r in range(3) for R in trained)


def test_bad_arguments_are_refused_before_any_work():
    with pytest.raises(ValueError, match="touch_cost"):
        TouchEnv(list(shapes.ball_and_domed()), SETTINGS, touch_cost=-0.1)
    with pytest.raises(ValueError, match="test_replicates"):
        TouchEnv(list(shapes.ball_and_domed()), SETTINGS, test_replicates=[])
    with pytest.raises(ValueError, match="nope"):
        TouchEnv(list(shapes.ball_and_domed()), SETTINGS, classifier="nope")
    with pytest.raises(ValueError, match="two objects"):
        TouchEnv(list(shapes.ball_and_domed())[:1], SETTINGS)
