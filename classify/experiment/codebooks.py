"""Touch codebooks of training instances: many simulated touches at every place, for the place-aware recognizer.

At every touchable candidate place and at every fixed plan's point of a
training instance, ``settings.codebook_draws`` touches, each an acquisition
of its own (``tactile.touch_codebook``), kept as their roll-invariant polar
descriptors.  They are computed by the instance's task (its mesh and Embree
scene, never its rendering) and cached apart from the rest of the instance,
by the number of draws.  Test instances have none.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from classify.experiment.config import Settings
from classify.experiment.streams import Stream, instance_rng, name_seed
from classify.runtime import cache as cache_mod

__all__ = ["codebook_descriptors", "training_codebooks"]


def codebook_descriptors(mesh, positions, normals, settings: Settings, rng, scene, where: str) -> np.ndarray:
    """Polar descriptors of a touch codebook at k points of a training instance, (k, draws, d) float32.

    ``settings.codebook_draws`` touches per point (``tactile.touch_codebook``:
    each its own device, roll, jitter and tilt, under ``settings.perturbation``).
    ``where`` names the points in errors.
    """
    import tactile
    from tactile.features import polar_fourier

    positions = np.asarray(positions, np.float64).reshape(-1, 3)
    if len(positions) == 0:
        raise ValueError(f"{where}: no touchable place, so no touch codebook can be built")
    draws = settings.codebook_draws
    book = tactile.touch_codebook(
        mesh, positions, normals, settings.sensor, settings.perturbation, draws, rng, scene=scene
    )
    d = polar_fourier(book.reshape(-1, *book.shape[2:]))
    return d.reshape(len(positions), draws, -1).astype(np.float32)


def training_codebooks(task, places, by_method: dict, instance, places_key, keys: dict):
    """A training instance's codebooks at its touchable places and at every method's points, from the cache or
    simulated (each on a stream of its own, so a method's codebook does not depend on the others).

    Parameters
    ----------
    task : classify.experiment.samples.SampleTask, a training instance's
    places : classify.policies.PlaceSample or None, its places
    by_method : dict method -> classify.experiment.samples.TouchSample, its points
    instance : callable giving (mesh, vertex saliency, Embree scene), built on first need
    places_key, keys : the cache keys of the places' codebook and of each method's

    Returns
    -------
    places, by_method : with their ``codebook`` set
    """
    settings = task.settings
    where = f"{task.name}, replicate {task.replicate}, training instance {task.index}"

    def rng(*more):
        return instance_rng(settings.seed, task.name, task.replicate, task.index, Stream.CODEBOOK, *more)

    def book(key, positions, normals, draw, label):
        stored = cache_mod.load(task.cache_dir, key)
        if stored is None:
            mesh, _, scene = instance()
            stored = {"codebook": codebook_descriptors(mesh, positions, normals, settings, draw, scene, label)}
            cache_mod.store(task.cache_dir, key, stored)
        return stored["codebook"]

    if places is not None:
        ok = places.places.touchable
        touched = book(
            places_key, places.places.positions[ok], places.places.normals[ok], rng(0), f"{where}: candidate places"
        )
        full = np.zeros((len(ok), *touched.shape[1:]), np.float32)
        full[ok] = touched
        places = dataclasses.replace(places, codebook=full)
    out = {}
    for m, sample in by_method.items():
        if len(sample.positions) == 0:
            raise ValueError(f"{where}: method {m} found no touchable point, so no touch codebook can be built")
        out[m] = dataclasses.replace(
            sample,
            codebook=book(keys[m], sample.positions, sample.normals, rng(1, name_seed(m)), f"{where}: {m} points"),
        )
    return places, out
