"""Control runs: what must bring recognition down to chance, so that a high rate means what it seems to.

``shuffled`` (``--control shuffled``) gives each test instance the imprints
of another object's test instance, place for place (index for index, and
around again where the donor has fewer), while keeping everything else of
its own: its places, the points its plans touch, their positions.  Whatever
a recognizer then gets right it gets from where it touched, not from what it
felt, so every recognizer, place-aware or not, must fall to chance (below
it, when it recognizes the donor).  Place for place keeps one thing: a
plan's k-th point on the donor ranks where the test instance's k-th point
ranks (mesh saliency's first points are the sharpest features of every
object), so a place-aware recognizer may still find a sharp touch likelier
at a sharp place.  ``scrambled`` gives each test instance its donor's
imprints in a random order, which keeps no such rank.  Donors form a
derangement of the objects drawn from the replicate's stream, by the
objects' names, so the control does not depend on their order.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from classify.experiment.streams import Stream, recognition_rng

__all__ = ["donors", "shuffled_imprints", "shuffled_places"]

#: Place for place, or in a random order of the donor's (``scrambled``).
ORDERS = ("shuffled", "scrambled")


def donors(names, seed: int, replicate: int) -> dict:
    """Each object's donor: a derangement of ``names`` (no object its own donor), by name and replicate.

    Examples
    --------
    >>> d = donors(["cow", "cup", "hand"], 0, 1)
    >>> sorted(d) == sorted(d.values()) == ["cow", "cup", "hand"], any(k == v for k, v in d.items())
    (True, False)
    >>> d == donors(["hand", "cow", "cup"], 0, 1)
    True
    """
    ordered = sorted(names)
    if len(ordered) < 2:
        raise ValueError("a shuffled control needs at least two objects")
    rng = recognition_rng(seed, replicate, 0, "|".join(ordered), Stream.CONTROL)
    while True:
        perm = rng.permutation(len(ordered))
        if not np.any(perm == np.arange(len(ordered))):
            return {ordered[i]: ordered[p] for i, p in enumerate(perm)}


def _cycled(imprints: np.ndarray, count: int, order: np.random.Generator | None) -> np.ndarray:
    """``count`` imprints of a donor's (k, rows, cols), index for index (in a random order when ``order`` draws
    one), around again where it has fewer."""
    if len(imprints) == 0:
        raise ValueError("a shuffled control's donor has no imprints")
    if order is not None:
        imprints = imprints[order.permutation(len(imprints))]
    return imprints[np.arange(count) % len(imprints)]


def _orders(kind: str, names, seed: int, replicate: int) -> dict:
    """Each object's generator of the donor's order (None: place for place)."""
    if kind not in ORDERS:
        raise ValueError(f"unknown control {kind!r}; choose from {', '.join(ORDERS)}")
    if kind == "shuffled":
        return dict.fromkeys(names)
    return {n: recognition_rng(seed, replicate, 0, n, Stream.CONTROL) for n in names}


def shuffled_imprints(tests: tuple, names: tuple, seed: int, replicate: int, kind: str = "shuffled") -> tuple:
    """Test imprints (one (k_c, rows, cols) array per object of ``names``) swapped for their donors'."""
    give, order = donors(names, seed, replicate), _orders(kind, names, seed, replicate)
    by_name = dict(zip(names, tests))
    return tuple(_cycled(by_name[give[n]], len(t), order[n]) for n, t in zip(names, tests))


def shuffled_places(tests: tuple, names: tuple, seed: int, replicate: int, kind: str = "shuffled") -> tuple:
    """Test :class:`~classify.policies.PlaceSample` s with every session's imprints swapped for their donors'."""
    give, order = donors(names, seed, replicate), _orders(kind, names, seed, replicate)
    by_name = dict(zip(names, tests))
    out = []
    for n, t in zip(names, tests):
        donor = by_name[give[n]].imprints
        imprints = np.stack([_cycled(donor[s], t.imprints.shape[1], order[n]) for s in range(t.imprints.shape[0])])
        out.append(dataclasses.replace(t, imprints=imprints))
    return tuple(out)
