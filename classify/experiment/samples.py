"""The per-object stage of the experiment: instances, their interest points, their imprints.

Everything here is a pure function of an object's mesh, its name, a
replicate number, an instance number and :class:`Settings`: no seed ever
comes from the position of an object in a list, so splitting or reordering
the objects changes nothing.  Each result is cached on disk under a key of
those inputs, the code of ``meshsal``, ``tactile`` and this module, and the
versions of the libraries that compute it (:mod:`classify.runtime.cache`).

An object's *nominal* mesh is the file (or toy) scaled so that its
principal-frame box diagonal is ``size_mm``, centroid at the origin
(``meshsal.mesh.transform.scale_to_principal``: a size that does not depend on
how the object was turned in its file).  Its *instances*
(``meshsal.objects.instances``) are turned uniformly over SO(3), resized within
±5 % and repainted.  Instance 0 of a replicate is the test instance;
instances 1..``train_instances`` train.

Every acquisition session is one call of ``tactile.acquire`` under
``Settings.perturbation``: its own device (gain map, dead taxels) and a
free roll per touch, drawn from a generator seeded with (seed, object name,
replicate, instance, session).  None of those draws depends on the point
method, so every method meets the same instances and devices (paired).

The learned methods also need each instance's *touch survey*
(:func:`touch_survey`): a candidate pool with its visual features and, on
training instances only, one touch of every candidate.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

from classify.runtime import cache as cache_mod

__all__ = ["Settings", "name_seed", "nominal_mesh", "mesh_hash", "instance_spec", "paper_sample",
           "instance_samples", "touch_survey"]


def _typical():
    import tactile

    return tactile.Perturbation.typical()


def _sensor():
    import tactile

    return tactile.Sensor()


@dataclass(frozen=True)
class Settings:
    """Everything the per-object stage depends on besides the mesh, its name and the draw.

    Attributes
    ----------
    n_points : int
        Interest points per instance.
    size_mm : float
        Nominal principal-frame box diagonal.
    view_size : int or None
        Rendered view size for the attention method (None: its default).
    sensor : tactile.Sensor
    perturbation : tactile.Perturbation
        Of every acquisition session (default ``Perturbation.typical()``).
    train_instances : int
        Training instances per object and replicate.
    train_sessions : int
        Acquisition sessions per training instance (the test instance has one).
    scale_spread, hue_deg, brightness_spread : float
        Instance variation (``meshsal.objects.instances.draw_instance``).
    seed : int
        Base seed of every draw.
    """

    n_points: int = 15
    size_mm: float = 150.0
    view_size: int | None = None
    sensor: object = field(default_factory=_sensor)
    perturbation: object = field(default_factory=_typical)
    train_instances: int = 3
    train_sessions: int = 2
    scale_spread: float = 0.05
    hue_deg: float = 30.0
    brightness_spread: float = 0.15
    seed: int = 0

    def __post_init__(self):
        if int(self.n_points) != self.n_points or self.n_points < 1:
            raise ValueError(f"n_points must be a positive integer, got {self.n_points!r}")
        if self.train_instances < 2:
            raise ValueError(f"train_instances must be at least 2 (calibration holds one out), "
                             f"got {self.train_instances}")
        if self.train_sessions < 1:
            raise ValueError(f"train_sessions must be at least 1, got {self.train_sessions}")
        if not self.size_mm > 0:
            raise ValueError(f"size_mm must be positive, got {self.size_mm}")

    def key(self) -> str:
        """A canonical text of every field, for cache keys."""
        return repr([self.n_points, float(self.size_mm), self.view_size, self.sensor, self.perturbation,
                     self.train_instances, self.train_sessions, float(self.scale_spread), float(self.hue_deg),
                     float(self.brightness_spread), int(self.seed)])


def name_seed(name: str) -> int:
    """A 63-bit integer from an object's name (SHA-256), the root of its random draws.

    Examples
    --------
    >>> name_seed("cow") == name_seed("cow"), name_seed("cow") == name_seed("cup")
    (True, False)
    """
    return int.from_bytes(hashlib.sha256(name.encode()).digest()[:8], "little") >> 1


def _rng(settings: Settings, name: str, *stream: int) -> np.random.Generator:
    return np.random.default_rng([int(settings.seed), name_seed(name), *stream])


def nominal_mesh(mesh, settings: Settings):
    """The object at its nominal size, centroid at the origin, as loaded otherwise."""
    from meshsal.mesh.transform import scale_to_principal

    return scale_to_principal(mesh, settings.size_mm)


def mesh_hash(mesh) -> str:
    """SHA-256 of a mesh's arrays (vertices, faces, colours, texture coordinates, texture)."""
    return cache_mod.hash_arrays(mesh.vertices, mesh.faces, mesh.vertex_colors, mesh.uv, mesh.texture)


def instance_spec(settings: Settings, name: str, replicate: int, index: int):
    """The pose, size and paint of instance ``index`` of replicate ``replicate`` of object ``name``."""
    from meshsal.objects.instances import draw_instance

    return draw_instance(_rng(settings, name, replicate, index, 0), settings.scale_spread, settings.hue_deg,
                         settings.brightness_spread)


def _rule_kwargs(settings: Settings, threads) -> dict:
    # The pad's real width: instances differ in size, the sensor does not.
    kwargs = {"n": settings.n_points, "quiet": True, "threads": threads, "pad_width": settings.sensor.width_mm}
    if settings.view_size is not None:
        kwargs["size"] = settings.view_size
    return kwargs


def _key(kind, nominal, name, method, settings, *parts):
    code = cache_mod.code_fingerprint("meshsal", "tactile") + cache_mod.file_fingerprint(__file__)
    return cache_mod.cache_key(kind, mesh_hash(nominal), name, method, settings.key(), list(parts), code,
                               cache_mod.library_versions())


def _point_seed(settings: Settings, name: str, replicate: int, index: int) -> int:
    return int(_rng(settings, name, replicate, index, 2).integers(2**31 - 1))


def paper_sample(nominal, name: str, method: str, settings: Settings, cache_dir=None, threads=None) -> dict:
    """The paper's data for one object: n points on the nominal mesh, one clean imprint each.

    ``threads`` (rendering and attention threads, default the CPU count)
    changes nothing in the result.

    Returns
    -------
    dict with ``positions``, ``normals`` (k, 3) float64 and ``imprints``
    (k, rows, cols) float32 (k <= n_points: fewer when the mesh cannot hold
    n points at the method's spacing).
    """
    import tactile

    def compute():
        import meshsal

        pts = meshsal.interest_points(nominal, method=method, seed=_point_seed(settings, name, 0, 0),
                                      **_rule_kwargs(settings, threads))
        images = tactile.imprints(nominal, pts.positions, pts.normals, settings.sensor)
        return {"positions": np.asarray(pts.positions, np.float64), "normals": np.asarray(pts.normals, np.float64),
                "imprints": np.asarray(images, np.float32)}

    return cache_mod.cached(cache_dir, _key("paper", nominal, name, method, settings), compute)


def _sessions(mesh, pts, settings: Settings, name: str, replicate: int, index: int, scene) -> dict:
    """The acquisition sessions of one instance at its points: the same devices and rolls for every method."""
    import tactile

    sessions = 1 if index == 0 else settings.train_sessions
    stack = [tactile.acquire(mesh, pts.positions, pts.normals, settings.sensor, settings.perturbation,
                             _rng(settings, name, replicate, index, 1, s), scene=scene)
             for s in range(sessions)]
    return {"positions": np.asarray(pts.positions, np.float64), "normals": np.asarray(pts.normals, np.float64),
            "imprints": np.asarray(stack, np.float32).reshape(sessions, len(pts), *stack[0].shape[1:])}


def _model_hash(model) -> str:
    return cache_mod.hash_arrays(model.mean, model.scale, model.coef, np.array([model.intercept]),
                                 np.array(list(model.channel_weights.values())))


def instance_samples(nominal, name: str, methods, settings: Settings, replicate: int, index: int,
                     survey: bool = False, cache_dir=None, threads=None, model=None, surveyed=None) -> dict:
    """Instance ``index`` of replicate ``replicate``: each method's points and the imprints of its sessions.

    Instance 0 is the test instance (one session), the others train
    (``settings.train_sessions`` sessions each).  The instance is built,
    rendered and its mesh saliency computed once for all ``methods``
    (``meshsal.points_by_method``); each method's sample is cached on its
    own, so adding a method later reuses the others.  ``threads``
    (rendering and attention threads, default the CPU count) changes
    nothing in the result.

    With ``survey``, also the instance's touch survey for the learned
    methods (:func:`touch_survey`), under key ``"survey"``.  The model
    methods take the replicate's ``model`` (``meshsal.points.learned.TouchModel``);
    "learned" chooses from the instance's ``surveyed`` pool without
    rendering, "attention_learned" renders with the model's channel weights.

    Returns
    -------
    dict method -> dict with ``positions``, ``normals`` (k, 3) float64 in
    the instance's frame and ``imprints`` (sessions, k, rows, cols) float32
    """
    import meshsal
    from meshsal.mesh.embree import embree_scene
    from meshsal.objects.instances import make_instance

    methods = list(dict.fromkeys(methods))
    model_part = [] if model is None else [_model_hash(model)]
    keys = {m: _key("instance", nominal, name, m, settings, replicate, index,
                    *(model_part if m in meshsal.points.MODEL_METHODS else [])) for m in methods}
    if survey:
        keys["survey"] = _key("survey", nominal, name, "", settings, replicate, index)
    out = {m: cache_mod.load(cache_dir, key) for m, key in keys.items()}
    missing = [m for m in methods if out[m] is None]
    if not missing and (not survey or out["survey"] is not None):
        return out
    mesh = make_instance(nominal, instance_spec(settings, name, replicate, index))
    vertex_saliency = meshsal.mesh_saliency(mesh)
    attention = [m for m in missing if m in meshsal.points.ATTENTION_METHODS]
    seen = None
    if attention or (survey and out["survey"] is None):
        seen = meshsal.points.view_channels(mesh, size=settings.view_size or 128, vertex_saliency=vertex_saliency,
                                            threads=threads)
    scene = embree_scene(mesh)
    rules = _rule_kwargs(settings, threads)
    picked = meshsal.points_by_method(mesh, [m for m in missing if m != "learned"], vertex_saliency=vertex_saliency,
                                      seed=_point_seed(settings, name, replicate, index), seen=seen, model=model,
                                      **rules)
    if "learned" in missing:
        picked["learned"] = meshsal.points.learned_points(mesh, surveyed["pool"], surveyed["features"], model,
                                                          vertex_saliency, n=rules["n"], pad_width=rules["pad_width"])
    for m in missing:
        out[m] = _sessions(mesh, picked[m], settings, name, replicate, index, scene)
        cache_mod.store(cache_dir, keys[m], out[m])
    if survey and out["survey"] is None:
        out["survey"] = touch_survey(mesh, seen, vertex_saliency, settings, name, replicate, index, scene)
        cache_mod.store(cache_dir, keys["survey"], out["survey"])
    return out


def touch_survey(mesh, seen, vertex_saliency, settings: Settings, name: str, replicate: int, index: int,
                 scene) -> dict:
    """What the learned methods need of one instance: its candidate pool and their visual features.

    On a training instance (``index >= 1``) the pool is also touched once
    (its own device and rolls) and the imprints' roll-invariant polar
    descriptors kept: the distinctiveness of each candidate is measured on
    those (``classify.experiment.survey``).  The test instance is never touched here.

    Returns
    -------
    dict with ``pool`` (P,) int64 vertex ids, ``features`` (P, len(meshsal.points.learned.FEATURES))
    float64 and, for a training instance, ``descriptors`` (P, d) float32
    """
    import tactile
    from meshsal.points.learned import candidate_pool, point_features
    from meshsal.mesh import vertex_normals
    from meshsal.points import attention_maps
    from tactile.features import describe

    pool = candidate_pool(mesh, settings.n_points)
    features = point_features(mesh, seen.views, seen.results, attention_maps(seen, "equal"), vertex_saliency, pool,
                              0.5 * settings.sensor.width_mm)
    out = {"pool": pool.astype(np.int64), "features": features}
    if index >= 1:
        vn = vertex_normals(mesh.vertices, mesh.faces)
        images = tactile.acquire(mesh, mesh.vertices[pool], vn[pool], settings.sensor, settings.perturbation,
                                 _rng(settings, name, replicate, index, 7), scene=scene)
        out["descriptors"] = describe(np.asarray(images, np.float32), "polar").astype(np.float32)
    return out
