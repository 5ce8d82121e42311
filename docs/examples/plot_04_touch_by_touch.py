"""
Touch by touch: an episode
==========================

:class:`classify.TouchEnv` puts touching behind Gymnasium's API.  Each episode draws an object and a
test instance that training never saw (turned, resized, repainted, another device); the agent sees
the candidate places vision offers and what each touch so far has felt, and chooses where to touch
next or stops.  The answer is the belief's most probable object; the return is 1 for a right answer,
less 0.01 per touch.

Small settings keep this quick (3 touches, 32-pixel views, two training instances, one session each);
``TouchEnv(["cow", "cup", "glasses"])`` alone uses the experiment's defaults.
"""

import matplotlib.pyplot as plt
import numpy as np

import classify
from classify.experiment import Settings
from classify.experiment.env import run_policy, touch_state
from classify.policies import TouchPolicy
from tactile.picture import imprint_grid

settings = Settings(n_points=3, view_size=32, train_instances=2, train_sessions=1)
env = classify.TouchEnv(["cow", "cup", "glasses"], settings, test_replicates=range(4), cache_dir=None)
print(f"objects {env.names}; {env.max_places} places at most, {env.max_touches} touches at most")

# %%
# A policy of one's own
# ---------------------
# A :class:`~classify.policies.TouchPolicy` has one method: ``choose(state, rng)`` returns the next
# place.  This one touches the place vision ranks first, then the available place farthest from
# every place touched so far.


class Farthest(TouchPolicy):
    def choose(self, state, rng):
        available = np.flatnonzero(state.available)
        if not state.touched:
            return int(available[0])
        positions = state.places.positions
        gaps = np.linalg.norm(positions[available, None] - positions[None, list(state.touched)], axis=2)
        return int(available[np.argmax(gaps.min(axis=1))])


# %%
# One episode, step by step through Gymnasium's API (any agent can drive it so, trained or not).
policy, rng = Farthest(), np.random.default_rng(0)
observation, info = env.reset(seed=0)
beliefs = [observation["belief"]]
terminated = False
while not terminated:
    place = policy.choose(touch_state(env, observation), rng)
    observation, reward, terminated, truncated, info = env.step(place)
    beliefs.append(observation["belief"])
touches = int(observation["touches"])
print(f"{touches} touches; the object was {info['object']!r}, the answer {info['answer']!r}")

# %%
# What each touch felt, and the belief after it (the single-touch posteriors multiplied).
fig, axes = plt.subplots(1, 2, figsize=(10, 3.4), gridspec_kw={"width_ratios": [3, 2]})
felt = observation["imprints"][:touches]
axes[0].imshow(imprint_grid(felt, captions=[f"touch {i + 1}" for i in range(touches)], scale=6))
axes[0].axis("off")
steps = np.arange(len(beliefs))
for c, name in enumerate(env.names):
    axes[1].plot(steps, [b[c] for b in beliefs], marker="o", label=name)
axes[1].set_xticks(steps)
axes[1].set_xlabel("touches")
axes[1].set_ylabel("belief")
axes[1].legend()
fig.tight_layout()

# %%
# Against ours, on the same episodes
# ----------------------------------
# :func:`~classify.experiment.env.run_policy` plays a policy through the same API, with a stopping
# rule: answer once the top belief reaches 0.999.  Policies started from the same seed meet the same
# objects and instances, so their comparison is paired.  Three toys are easy for touch: one touch
# mostly settles which it is; the experiment's tables compare policies on harder sets.
for name, chosen in (("farthest", Farthest()), ("random", "random"), ("info_gain", "info_gain")):
    run = run_policy(env, chosen, episodes=6, seed=1, stop=0.999)
    print(f"{name}: {run.correct.mean():.0%} right, {run.touches.mean():.1f} touches, return {run.rewards.mean():.3f}")
