"""The per-object stage of the experiment: instances, their interest points, their imprints.

Everything here is a pure function of an object's mesh, its name, a
replicate number, an instance number and :class:`Settings`: every draw comes
from a named stream of :mod:`classify.experiment.streams`, so splitting or
reordering the objects changes nothing.  Each result is cached on disk under
a key of those inputs, the code of ``meshsal``, ``tactile`` and this module,
and the versions of the libraries that compute it (:mod:`classify.runtime.cache`).

An object's *nominal* mesh is the file (or toy) scaled so that its
principal-frame box diagonal is ``size_mm``, centroid at the origin
(``meshsal.mesh.transform.scale_to_principal``: a size that does not depend
on how the object was turned in its file).  Its *instances*
(``meshsal.objects.instances``) are turned uniformly over SO(3), resized
within ±5 % and repainted.  Instance 0 of a replicate is the test instance;
instances 1..``train_instances`` train.

Every acquisition session is one ``tactile.Acquisition`` under
``Settings.perturbation``: its own device (gain map, dead taxels) and a free
roll per touch, drawn from the session's stream.  None of those draws
depends on the point method, so every method meets the same instances and
devices (paired).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from classify.experiment import codebooks as codebooks_mod
from classify.experiment.codebooks import training_codebooks
from classify.experiment.config import Settings
from classify.experiment.streams import Stream, instance_rng
from classify.experiment.survey import Survey, touch_survey
from classify.policies.knowledge import Places, PlaceSample
from classify.runtime import cache as cache_mod

__all__ = [
    "Settings",
    "TouchSample",
    "PaperSampleTask",
    "SampleTask",
    "InstanceSamples",
    "nominal_mesh",
    "mesh_hash",
    "instance_spec",
    "point_options",
    "paper_sample",
    "candidate_places_at",
    "test_perturbation",
    "instance_mesh",
    "instance_samples",
]


@dataclass(frozen=True, eq=False)
class TouchSample:
    """One instance's points for one method and the imprints of its sessions.

    ``positions``, ``normals`` (k, 3) float64 in the instance's frame;
    ``imprints`` (sessions, k, rows, cols) float32, or (k, rows, cols) for the
    paper protocol's clean imprints (k <= n_points: fewer when the mesh cannot
    hold n points at the method's spacing).
    """

    positions: np.ndarray
    normals: np.ndarray
    imprints: np.ndarray
    #: (k, draws, d) float32, the polar descriptors of a touch codebook at the points (training instances of a
    #: run with the place-aware recognizer; stored apart from the rest).
    codebook: np.ndarray | None = None

    def to_arrays(self) -> dict:
        return {"positions": self.positions, "normals": self.normals, "imprints": self.imprints}

    @staticmethod
    def from_arrays(arrays: dict) -> TouchSample:
        return TouchSample(arrays["positions"], arrays["normals"], arrays["imprints"])


@dataclass(frozen=True, eq=False)
class PaperSampleTask:
    """One object's data for the paper protocol: ``method``'s points on the nominal mesh.

    ``threads`` (rendering and attention threads, None: the CPU count)
    changes nothing in the result.
    """

    nominal: object
    name: str
    method: str
    settings: Settings
    cache_dir: object = None
    threads: int | None = None


@dataclass(frozen=True, eq=False)
class SampleTask:
    """One instance of one object for some point methods (:func:`instance_samples`).

    Attributes
    ----------
    nominal : meshsal.Mesh, the object at its nominal size
    name : str
    methods : tuple of str
    settings : Settings
    replicate, index : int
        Instance ``index`` of replicate ``replicate`` (0: the test instance).
    survey : bool
        Also the instance's touch survey (:func:`classify.experiment.survey.touch_survey`).
    places : bool
        Also its candidate places and their imprints, for the touch policies
        and the place-aware recognizer (:func:`place_sample`).
    codebook : bool
        On a training instance, also a touch codebook (``settings.codebook_draws``
        touches) at every touchable place and at every method's points
        (:mod:`classify.experiment.codebooks`).
    model : meshsal.points.learned.TouchModel, optional
        The replicate's touch model, for the model methods.
    surveyed : Survey, optional
        The instance's survey, from which "learned" chooses without rendering.
    cache_dir : path or None
    threads : int or None (rendering and attention threads; changes nothing in the result)
    """

    nominal: object
    name: str
    methods: tuple
    settings: Settings
    replicate: int
    index: int
    survey: bool = False
    places: bool = False
    codebook: bool = False
    model: object = None
    surveyed: Survey | None = None
    cache_dir: object = None
    threads: int | None = None


@dataclass(frozen=True, eq=False)
class InstanceSamples:
    """What :func:`instance_samples` made of one instance: a :class:`TouchSample` per method, its survey and its
    places (when asked)."""

    by_method: dict
    survey: Survey | None = None
    places: PlaceSample | None = None


def nominal_mesh(mesh, settings: Settings, units_mm: float | None = None):
    """The object at its nominal size, centroid at the origin, as loaded otherwise.

    With ``settings.size_mm`` None, the object keeps its real size:
    ``units_mm`` (millimetres per unit of its coordinates) must be known.
    """
    from meshsal.mesh.transform import scale_to_principal, to_millimetres

    if settings.size_mm is not None:
        return scale_to_principal(mesh, settings.size_mm)
    if units_mm is None:
        raise ValueError(
            f"{mesh.name or 'mesh'}: its units are not known, so it has no real size; give a size (--size-mm) instead"
        )
    return to_millimetres(mesh, units_mm)


def mesh_hash(mesh) -> str:
    """SHA-256 of a mesh's arrays (vertices, faces, colours, texture coordinates, texture)."""
    return cache_mod.hash_arrays(mesh.vertices, mesh.faces, mesh.vertex_colors, mesh.uv, mesh.texture)


def instance_spec(settings: Settings, name: str, replicate: int, index: int):
    """The pose, size and paint of instance ``index`` of replicate ``replicate`` of object ``name``."""
    from meshsal.objects.instances import draw_instance

    return draw_instance(
        instance_rng(settings.seed, name, replicate, index, Stream.INSTANCE),
        settings.scale_spread,
        settings.hue_deg,
        settings.brightness_spread,
    )


def point_options(settings: Settings, seed: int, threads: int | None):
    """The ``meshsal.points.PointOptions`` of every method in the experiment."""
    from meshsal.points import PointOptions

    # The pad's real width: instances differ in size, the sensor does not.
    return PointOptions(
        n=settings.n_points,
        seed=seed,
        pad_width=settings.sensor.width_mm,
        size=settings.rendered_view_size,
        threads=threads,
        quiet=True,
    )


def _point_seed(settings: Settings, name: str, replicate: int, index: int) -> int:
    return int(instance_rng(settings.seed, name, replicate, index, Stream.POINTS).integers(2**31 - 1))


def _keys(nominal, name, settings):
    """``key(kind, method, *parts)``: the cache keys of an object's entries.

    The mesh, the settings, the code and the libraries are hashed once here,
    not once per key: the code's hash reads every source file of two packages.
    """
    code = cache_mod.code_fingerprint("meshsal", "tactile") + cache_mod.file_fingerprint(
        __file__, codebooks_mod.__file__
    )
    mesh, setting, libraries = mesh_hash(nominal), settings.key(), cache_mod.library_versions()

    def key(kind, method, *parts):
        return cache_mod.cache_key(kind, mesh, name, method, setting, list(parts), code, libraries)

    return key


def paper_sample(task: PaperSampleTask) -> TouchSample:
    """The paper's data for one object: n points on the nominal mesh, one clean imprint each."""
    import tactile

    settings = task.settings

    def compute():
        from meshsal.points import interest_points

        pts = interest_points(
            task.nominal,
            method=task.method,
            options=point_options(settings, _point_seed(settings, task.name, 0, 0), task.threads),
        )
        images = tactile.imprints(task.nominal, pts.positions, pts.normals, settings.sensor)
        return TouchSample(
            np.asarray(pts.positions, np.float64), np.asarray(pts.normals, np.float64), np.asarray(images, np.float32)
        ).to_arrays()

    return TouchSample.from_arrays(
        cache_mod.cached(task.cache_dir, _keys(task.nominal, task.name, settings)("paper", task.method), compute)
    )


def test_perturbation(settings: Settings, index: int):
    """The perturbation of instance ``index``'s sessions: the settings', but for a test instance (0) under a noise
    mismatch arm, whose reading noise and gain spread are halved or doubled."""
    import dataclasses

    factor = {"noise_half": 0.5, "noise_double": 2.0}
    p = settings.perturbation
    for m in settings.mismatch if index == 0 else ():
        if m in factor:
            p = dataclasses.replace(p, noise=p.noise * factor[m], gain_spread=p.gain_spread * factor[m])
    return p


def _session(positions, normals, task: SampleTask, session: int):
    """Acquisition session ``session`` of the instance at k points (``tactile.Acquisition``): its device and rolls
    come from the session's stream, so every method meets the same ones."""
    import tactile

    settings = task.settings
    return tactile.Acquisition(
        positions,
        normals,
        test_perturbation(settings, task.index),
        instance_rng(settings.seed, task.name, task.replicate, task.index, Stream.SESSION, session),
    )


def _acquired(piece, requests: dict, task: SampleTask) -> dict:
    """Every requested session of the instance, cast together: key -> (k, rows, cols) float32.  A test instance
    of the ``exact`` mismatch arm is sliced exactly instead."""
    import tactile

    settings = task.settings
    exact = task.index == 0 and "exact" in settings.mismatch
    read = tactile.acquire_all(piece.mesh, list(requests.values()), settings.sensor, scene=piece.scene, exact=exact)
    return dict(zip(requests, read))


def candidate_places_at(piece, ids, features, settings: Settings) -> Places:
    """An instance's candidate places (``ids``, (P,) vertex ids of ``meshsal.points.places.candidate_places``),
    what vision sees there (``features``, (P, len(FEATURES)) of ``point_features``) and which the pad can touch.

    Their imprints are session 0 of the instance (:func:`instance_samples`):
    the same streams as the methods' sessions, so the same devices.
    """
    from meshsal.points.frames import shape_frame
    from meshsal.points.touch import touchable

    positions, normals = piece.mesh.vertices[ids], piece.vertex_normals[ids]
    ok = touchable(piece.mesh, positions, normals, settings.sensor.width_mm, scene=piece.scene)
    return Places(ids, positions, normals, features, ok, shape_frame(piece.mesh.vertices, piece.mesh.faces))


def _looked_at(piece, settings: Settings, places: bool):
    """The candidate pool, the places to touch (the pool alone unless ``places``) and what vision sees at them.

    The survey's pool is the places' first rows, and a vertex's features do
    not depend on which others are asked for, so both are seen once.
    """
    from meshsal.attention.rig import attention_maps
    from meshsal.points.learned import point_features
    from meshsal.points.places import candidate_places, candidate_pool

    mesh, seen = piece.mesh, piece.seen
    pool = candidate_pool(mesh, settings.n_points)
    ids = candidate_places(mesh, piece.vertex_saliency, settings.n_points, pool=pool) if places else pool
    features = point_features(
        mesh,
        seen.views,
        seen.results,
        attention_maps(seen, "equal"),
        piece.vertex_saliency,
        ids,
        0.5 * settings.sensor.width_mm,
    )
    return pool, ids, features


def _model_hash(model) -> str:
    return cache_mod.hash_arrays(
        model.mean, model.scale, model.coef, np.array([model.intercept]), np.array(list(model.channel_weights.values()))
    )


def instance_mesh(task: SampleTask):
    """Instance ``task.index`` of ``task.replicate``: the nominal mesh turned, resized, repainted; a test instance
    of a re-tessellation mismatch arm is re-tessellated (``meshsal.objects.instances.retessellate``)."""
    from meshsal.objects.instances import TESSELLATIONS, make_instance, retessellate

    settings = task.settings
    mesh = make_instance(task.nominal, instance_spec(settings, task.name, task.replicate, task.index))
    for kind in settings.mismatch if task.index == 0 else ():
        if kind in TESSELLATIONS:
            mesh = retessellate(mesh, kind)
    return mesh


def instance_samples(task: SampleTask) -> InstanceSamples:
    """One instance: each method's points and the imprints of its sessions, its survey, places and codebooks if asked.

    Instance 0 is the test instance (one session), the others train
    (``settings.train_sessions`` sessions each).  The instance is one
    ``meshsal.points.Workpiece``, passed to every stage: its scene is built,
    its mesh saliency computed and its views rendered once, when first
    needed, for all methods (:func:`meshsal.points.method_points`), the
    survey, the places and the codebooks.  Every method's sessions and the
    places' are cast in one call (``tactile.acquire_all``).  Each method's
    sample is cached on its own, so adding a method later reuses the
    others.  The model methods take the replicate's ``model``: "learned"
    chooses from the instance's ``surveyed`` pool without rendering,
    "attention_learned" renders with the model's channel weights.  A training instance's codebooks (``task.codebook``)
    are cached apart, by the number of draws: they need the mesh, never its
    rendering.

    Returns
    -------
    InstanceSamples
    """
    from meshsal.points import MODEL_METHODS, method_points

    settings = task.settings
    methods = list(dict.fromkeys(task.methods))
    model_part = [] if task.model is None else [_model_hash(task.model)]
    # A test instance of a mismatch arm is another instance; training instances are the same in every arm.
    arm = [list(settings.mismatch)] if task.index == 0 and settings.mismatch else []
    keys_of = _keys(task.nominal, task.name, settings)

    def key(kind, method="", *more):
        return keys_of(kind, method, task.replicate, task.index, *arm, *more)

    keys = {m: key("instance", m, *(model_part if m in MODEL_METHODS else [])) for m in methods}
    survey_key, places_key = key("survey"), key("places")
    books = task.codebook and task.index >= 1
    draws = [settings.codebook_draws]
    book_keys = {m: key("codebook", m, *draws, *(model_part if m in MODEL_METHODS else [])) for m in methods}
    places_book_key = key("codebook", "", *draws)
    found = {m: cache_mod.load(task.cache_dir, k) for m, k in keys.items()}
    by_method = {m: TouchSample.from_arrays(a) for m, a in found.items() if a is not None}
    survey = None
    if task.survey:
        stored = cache_mod.load(task.cache_dir, survey_key)
        survey = None if stored is None else Survey.from_arrays(stored)
    places = None
    if task.places:
        stored = cache_mod.load(task.cache_dir, places_key)
        places = None if stored is None else PlaceSample.from_arrays(stored)
    missing = [m for m in methods if m not in by_method]
    want_survey, want_places = task.survey and survey is None, task.places and places is None
    built = []

    def instance():
        """The instance's workpiece (mesh, Embree scene, mesh saliency, views), built on first need; its mesh
        saliency is the survey's when the survey holds it."""
        from meshsal.points.workpiece import Workpiece

        if not built:
            known = None if task.surveyed is None else task.surveyed.vertex_saliency
            piece = Workpiece.of(
                instance_mesh(task), vertex_saliency=known, view_size=settings.rendered_view_size, threads=task.threads
            )
            built.append(piece)
        return built[0]

    if missing or want_survey or want_places:
        piece = instance()
        options = point_options(settings, _point_seed(settings, task.name, task.replicate, task.index), task.threads)
        picked = method_points(piece, missing, options, model=task.model, surveyed=task.surveyed)
        sessions = 1 if task.index == 0 else settings.train_sessions
        requests = {
            (m, s): _session(picked[m].positions, picked[m].normals, task, s) for m in missing for s in range(sessions)
        }
        if want_survey or want_places:
            pool, ids, features = _looked_at(piece, settings, want_places)
        if want_survey:
            # The test instance is never touched before the test.
            rng = (
                instance_rng(settings.seed, task.name, task.replicate, task.index, Stream.SURVEY)
                if task.index >= 1
                else None
            )
            survey = touch_survey(
                piece.mesh, pool, features[: pool.size], settings, piece.scene, rng, piece.vertex_saliency
            )
            cache_mod.store(task.cache_dir, survey_key, survey.to_arrays())
        if want_places:
            at = candidate_places_at(piece, ids, features, settings)
            requests["places", 0] = _session(at.positions, at.normals, task, 0)
        read = _acquired(piece, requests, task)
        for m in missing:
            pts = picked[m]
            by_method[m] = TouchSample(
                np.asarray(pts.positions, np.float64),
                np.asarray(pts.normals, np.float64),
                np.stack([read[m, s] for s in range(sessions)]).astype(np.float32),
            )
            cache_mod.store(task.cache_dir, keys[m], by_method[m].to_arrays())
        if want_places:
            places = PlaceSample(at, read["places", 0][None].astype(np.float32))
            cache_mod.store(task.cache_dir, places_key, places.to_arrays())
    if books:
        places, by_method = training_codebooks(task, places, by_method, instance, places_book_key, book_keys)
    return InstanceSamples({m: by_method[m] for m in methods}, survey, places)
