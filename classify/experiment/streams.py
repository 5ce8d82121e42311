"""The experiment's random streams, by name.

Every random draw of the experiment comes from a generator seeded by the
base seed, the object's *name* (never its position in a list), and where the
draw belongs: which replicate and instance, and which :class:`Stream`.  So
splitting or reordering the objects changes nothing, and every point method
and classifier of a replicate meets the same instances, devices, rolls,
touch sets and tie breaks (paired comparisons rest on this).
"""

from __future__ import annotations

import hashlib
from enum import IntEnum

import numpy as np

__all__ = ["Stream", "name_seed", "instance_rng", "recognition_rng"]


class Stream(IntEnum):
    """What a generator is for; the values are part of every seed, so they never change."""

    #: An instance's pose, size and paint (``meshsal.objects.instances.draw_instance``).
    INSTANCE = 0
    #: An acquisition session's device and rolls (followed by the session's number).
    SESSION = 1
    #: The seed of the random point methods on an instance.
    POINTS = 2
    #: The touch sets a test instance is recognized from after k touches.
    TOUCH_SETS = 3
    #: Tie breaks of the fused decision.
    TIES = 4
    #: A touch policy's own draws on a test instance.
    EPISODE = 5
    #: Tie breaks of the decision after each touch of an episode (policies, and fixed plans in their order).
    EPISODE_TIES = 6
    #: The touch survey's device and rolls (learned methods).
    SURVEY = 7
    #: A training instance's touch codebooks (followed by 0 for its places, 1 and a method's name seed for its points).
    CODEBOOK = 8
    #: A control run's donors (``classify.experiment.controls``).
    CONTROL = 9


def name_seed(name: str) -> int:
    """A 63-bit integer from an object's name (SHA-256), the root of its random draws.

    Examples
    --------
    >>> name_seed("cow") == name_seed("cow"), name_seed("cow") == name_seed("cup")
    (True, False)
    """
    return int.from_bytes(hashlib.sha256(name.encode()).digest()[:8], "little") >> 1


def instance_rng(seed: int, name: str, replicate: int, index: int, stream: Stream, *more: int) -> np.random.Generator:
    """The generator of one ``stream`` of instance ``index`` of replicate ``replicate`` of object ``name``.

    Examples
    --------
    >>> a = instance_rng(0, "cow", 1, 2, Stream.SESSION, 0).random()
    >>> b = instance_rng(0, "cow", 1, 2, Stream.SESSION, 1).random()
    >>> a == instance_rng(0, "cow", 1, 2, Stream.SESSION, 0).random(), a == b
    (True, False)
    """
    return np.random.default_rng(
        [int(seed), name_seed(name), int(replicate), int(index), int(stream), *(int(m) for m in more)]
    )


def recognition_rng(
    seed: int, replicate: int, touches: int, name: str, stream: Stream, *more: int
) -> np.random.Generator:
    """The generator of one ``stream`` of the recognition of object ``name``'s test instance after ``touches``
    (0 for a whole episode)."""
    return np.random.default_rng(
        [int(seed), int(replicate), int(touches), name_seed(name), int(stream), *(int(m) for m in more)]
    )
