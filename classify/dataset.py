"""The per-object stage of the experiment: instances, their interest points, their imprints.

Everything here is a pure function of an object's mesh, its name, a
replicate number, an instance number and :class:`Settings`: no seed ever
comes from the position of an object in a list, so splitting or reordering
the objects changes nothing.  Each result is cached on disk under a key of
those inputs, the code of ``meshsal``, ``tactile`` and this module, and the
versions of the libraries that compute it (:mod:`classify.cache`).

An object's *nominal* mesh is the file (or toy) scaled so that its
principal-frame box diagonal is ``size_mm``, centroid at the origin
(``meshsal.transform.scale_to_principal``: a size that does not depend on
how the object was turned in its file).  Its *instances*
(``meshsal.instances``) are turned uniformly over SO(3), resized within
±5 % and repainted.  Instance 0 of a replicate is the test instance;
instances 1..``train_instances`` train.

Every acquisition session is one call of ``tactile.acquire`` under
``Settings.perturbation``: its own device (gain map, dead taxels) and a
free roll per touch, drawn from a generator seeded with (seed, object name,
replicate, instance, session).  None of those draws depends on the point
method, so every method meets the same instances and devices (paired).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

from classify import cache as cache_mod

__all__ = ["Settings", "name_seed", "nominal_mesh", "mesh_hash", "instance_spec", "paper_sample",
           "instance_sample"]


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
        Instance variation (``meshsal.instances.draw_instance``).
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
    from meshsal.transform import scale_to_principal

    return scale_to_principal(mesh, settings.size_mm)


def mesh_hash(mesh) -> str:
    """SHA-256 of a mesh's arrays (vertices, faces, colours, texture coordinates, texture)."""
    return cache_mod.hash_arrays(mesh.vertices, mesh.faces, mesh.vertex_colors, mesh.uv, mesh.texture)


def instance_spec(settings: Settings, name: str, replicate: int, index: int):
    """The pose, size and paint of instance ``index`` of replicate ``replicate`` of object ``name``."""
    from meshsal.instances import draw_instance

    return draw_instance(_rng(settings, name, replicate, index, 0), settings.scale_spread, settings.hue_deg,
                         settings.brightness_spread)


def _points(mesh, method, settings: Settings, seed: int, threads):
    import meshsal

    # The pad's real width: instances differ in size, the sensor does not.
    kwargs = {"n": settings.n_points, "method": method, "seed": seed, "quiet": True, "threads": threads,
              "pad_width": settings.sensor.width_mm}
    if settings.view_size is not None:
        kwargs["size"] = settings.view_size
    return meshsal.interest_points(mesh, **kwargs)


def _key(kind, nominal, name, method, settings, *parts):
    code = cache_mod.code_fingerprint("meshsal", "tactile") + cache_mod.file_fingerprint(__file__)
    return cache_mod.cache_key(kind, mesh_hash(nominal), name, method, settings.key(), list(parts), code,
                               cache_mod.library_versions())


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
        pts = _points(nominal, method, settings, int(_rng(settings, name, 0, 0, 2).integers(2**31 - 1)), threads)
        images = tactile.imprints(nominal, pts.positions, pts.normals, settings.sensor)
        return {"positions": np.asarray(pts.positions, np.float64), "normals": np.asarray(pts.normals, np.float64),
                "imprints": np.asarray(images, np.float32)}

    return cache_mod.cached(cache_dir, _key("paper", nominal, name, method, settings), compute)


def instance_sample(nominal, name: str, method: str, settings: Settings, replicate: int, index: int,
                    cache_dir=None, threads=None) -> dict:
    """Instance ``index`` of replicate ``replicate``: its points and the imprints of its sessions.

    Instance 0 is the test instance (one session), the others train
    (``settings.train_sessions`` sessions each).  ``threads`` as in
    :func:`paper_sample`.

    Returns
    -------
    dict with ``positions``, ``normals`` (k, 3) float64 in the instance's
    frame and ``imprints`` (sessions, k, rows, cols) float32.
    """
    import meshsal
    import tactile
    from meshsal.instances import make_instance

    sessions = 1 if index == 0 else settings.train_sessions

    def compute():
        mesh = make_instance(nominal, instance_spec(settings, name, replicate, index))
        pts = _points(mesh, method, settings, int(_rng(settings, name, replicate, index, 2).integers(2**31 - 1)),
                      threads)
        scene = meshsal.embree.embree_scene(mesh)
        stack = [tactile.acquire(mesh, pts.positions, pts.normals, settings.sensor, settings.perturbation,
                                 _rng(settings, name, replicate, index, 1, s), scene=scene)
                 for s in range(sessions)]
        return {"positions": np.asarray(pts.positions, np.float64), "normals": np.asarray(pts.normals, np.float64),
                "imprints": np.asarray(stack, np.float32).reshape(sessions, len(pts), *stack[0].shape[1:])}

    return cache_mod.cached(cache_dir, _key("instance", nominal, name, method, settings, replicate, index),
                            compute)
