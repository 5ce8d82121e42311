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


def codebook_descriptors(mesh, books: list, settings: Settings, scene) -> list:
    """Polar descriptors of touch codebooks at points of a training instance, one (k, draws, d) float32 per book.

    ``books`` holds ``(positions, normals, rng, where)`` per book: its k
    points, the source of its draws and what names them in errors.  Each
    point gets ``settings.codebook_draws`` touches (``tactile.touch_codebook``:
    each its own device, roll, jitter and tilt, under ``settings.perturbation``),
    and every book's touches are cast together (``tactile.acquire_all``).
    """
    import tactile
    from tactile.features import polar_fourier

    draws = settings.codebook_draws
    requests = []
    for positions, normals, rng, where in books:
        positions = np.asarray(positions, np.float64).reshape(-1, 3)
        if len(positions) == 0:
            raise ValueError(f"{where}: no touchable place, so no touch codebook can be built")
        requests.append(tactile.Acquisition(positions, normals, settings.perturbation, rng, draws))
    read = tactile.acquire_all(mesh, requests, settings.sensor, scene=scene)
    return [polar_fourier(b.reshape(-1, *b.shape[2:])).reshape(len(b), draws, -1).astype(np.float32) for b in read]


def training_codebooks(task, places, by_method: dict, instance, places_key, keys: dict):
    """A training instance's codebooks at its touchable places and at every method's points, from the cache or
    simulated (each on a stream of its own, so a method's codebook does not depend on the others).

    Parameters
    ----------
    task : classify.experiment.samples.SampleTask, a training instance's
    places : classify.policies.PlaceSample or None, its places
    by_method : dict method -> classify.experiment.samples.TouchSample, its points
    instance : callable giving the instance's ``meshsal.points.Workpiece``, built on first need
    places_key, keys : the cache keys of the places' codebook and of each method's

    Returns
    -------
    places, by_method : with their ``codebook`` set
    """
    settings = task.settings
    where = f"{task.name}, replicate {task.replicate}, training instance {task.index}"

    def rng(*more):
        return instance_rng(settings.seed, task.name, task.replicate, task.index, Stream.CODEBOOK, *more)

    wanted = {}
    if places is not None:
        ok = places.places.touchable
        wanted[places_key] = (
            places.places.positions[ok],
            places.places.normals[ok],
            rng(0),
            f"{where}: candidate places",
        )
    for m, sample in by_method.items():
        if len(sample.positions) == 0:
            raise ValueError(f"{where}: method {m} found no touchable point, so no touch codebook can be built")
        wanted[keys[m]] = (sample.positions, sample.normals, rng(1, name_seed(m)), f"{where}: {m} points")
    books = {key: cache_mod.load(task.cache_dir, key) for key in wanted}
    missing = [key for key, stored in books.items() if stored is None]
    if missing:
        piece = instance()
        made = codebook_descriptors(piece.mesh, [wanted[key] for key in missing], settings, piece.scene)
        for key, codebook in zip(missing, made):
            books[key] = {"codebook": codebook}
            cache_mod.store(task.cache_dir, key, books[key])
    if places is not None:
        touched = books[places_key]["codebook"]
        full = np.zeros((len(ok), *touched.shape[1:]), np.float32)
        full[ok] = touched
        places = dataclasses.replace(places, codebook=full)
    out = {m: dataclasses.replace(sample, codebook=books[keys[m]]["codebook"]) for m, sample in by_method.items()}
    return places, out
