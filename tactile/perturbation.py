"""Acquisition realism: a robot places the pad imperfectly and an ADC reads it.

:func:`acquire` turns clean simulated imprints into plausible sensor
readings.  Placement errors act on the geometry before slicing (position
jitter in the tangent plane, tilt of the fitted pad normal, in-plane
rotation); reading errors act on the image (the elastic cover's blur,
per-taxel gain spread, additive noise, dead taxels, ADC quantization), in
that order.  Gains and dead taxels belong to the device, so they are drawn
once per call and shared by all its imprints.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

import numpy as np

from meshsal.mesh import Mesh
from tactile.raycast import imprints_at
from tactile.sensor import Poses, Sensor, check_points, poses_from_normals, sensor_poses, tangent_frames

__all__ = ["Perturbation", "Acquisition", "acquire", "touch_codebook", "acquire_all"]


@dataclass(frozen=True)
class Perturbation:
    """How far an acquisition departs from the clean simulation.  All zero = clean.

    Parameters
    ----------
    jitter_mm : float
        Standard deviation of the pad position error along each tangent axis.
    tilt_deg : float
        Standard deviation of the pad normal's tilt away from the fitted
        normal (the tilt direction is uniform).
    rotation_deg : float
        Standard deviation of the in-plane rotation (ignored when
        ``uniform_rotation``).
    uniform_rotation : bool
        Draw the in-plane rotation uniformly over 360 degrees: the robot does
        not control the pad's roll.
    gain_spread : float
        Relative standard deviation of each taxel's gain (a fixed map per device).
    noise : float
        Standard deviation of additive noise per reading, in full-scale units.
    dead_fraction : float
        Fraction of taxels reading zero, in [0, 1).
    adc_bits : int
        Resolution of the converter; 0 keeps readings continuous.
    blur_mm : float
        Standard deviation of the Gaussian spread of force through the
        elastic cover.

    Examples
    --------
    >>> Perturbation.none().is_clean
    True
    >>> Perturbation(noise=0.02, adc_bits=8).is_clean
    False
    """

    jitter_mm: float = 0.0
    tilt_deg: float = 0.0
    rotation_deg: float = 0.0
    uniform_rotation: bool = False
    gain_spread: float = 0.0
    noise: float = 0.0
    dead_fraction: float = 0.0
    adc_bits: int = 0
    blur_mm: float = 0.0

    def __post_init__(self):
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "uniform_rotation":
                if not isinstance(value, (bool, np.bool_)):
                    raise ValueError(f"Perturbation.uniform_rotation must be a bool, got {value!r}")
                object.__setattr__(self, f.name, bool(value))
            elif f.name == "adc_bits":
                if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 0 <= value <= 24:
                    raise ValueError(f"Perturbation.adc_bits must be an integer in [0, 24], got {value!r}")
                object.__setattr__(self, f.name, int(value))
            else:
                try:
                    value = float(value)
                except (TypeError, ValueError):
                    raise ValueError(f"Perturbation.{f.name} must be a number, got {value!r}") from None
                if not (np.isfinite(value) and value >= 0):
                    raise ValueError(f"Perturbation.{f.name} must be finite and non-negative, got {value}")
                object.__setattr__(self, f.name, value)
        if self.dead_fraction >= 1:
            raise ValueError(f"Perturbation.dead_fraction must be below 1, got {self.dead_fraction}")

    @classmethod
    def none(cls) -> Perturbation:
        """No perturbation: :func:`acquire` returns exactly the clean imprints."""
        return cls()

    @classmethod
    def typical(cls) -> Perturbation:
        """Plausible figures for a robot-held FSR pad (assumed, not measured).

        1 mm placement error, 3 degree tilt, free roll, 10 % gain spread,
        2 % noise, 1 % dead taxels, an 8-bit ADC and a 1 mm elastic cover blur.
        """
        return cls(
            jitter_mm=1.0,
            tilt_deg=3.0,
            uniform_rotation=True,
            gain_spread=0.1,
            noise=0.02,
            dead_fraction=0.01,
            adc_bits=8,
            blur_mm=1.0,
        )

    @property
    def is_clean(self) -> bool:
        """True when every field is zero (or off)."""
        return self == Perturbation()

    def to_dict(self) -> dict:
        """The fields as a JSON-ready dict (inverse of ``Perturbation(**d)``)."""
        return asdict(self)


def _rng(rng) -> np.random.Generator:
    if isinstance(rng, np.random.Generator):
        return rng
    if rng is None or isinstance(rng, (int, np.integer)):
        return np.random.default_rng(rng)
    raise ValueError(f"rng must be a numpy Generator, an integer seed or None, got {type(rng).__name__}")


def _tilt(normals: np.ndarray, sd_deg: float, rng: np.random.Generator) -> np.ndarray:
    up, right = tangent_frames(normals)
    theta = np.deg2rad(sd_deg * rng.standard_normal(normals.shape[0]))[:, None]
    phi = rng.uniform(0.0, 2.0 * np.pi, normals.shape[0])[:, None]
    return np.cos(theta) * normals + np.sin(theta) * (np.cos(phi) * right + np.sin(phi) * up)


def acquire(
    mesh: Mesh,
    positions,
    normals,
    sensor: Sensor | None = None,
    perturb: Perturbation | None = None,
    rng=0,
    workers: int | None = None,
    scene=None,
    exact: bool = False,
) -> np.ndarray:
    """Simulated sensor readings at k points, with placement and reading errors.

    Parameters
    ----------
    mesh : Mesh
        In millimetres.
    positions, normals : (k, 3) float64
        Where the robot is told to touch, and the outward normals there.
    sensor : Sensor, optional
        Defaults to ``Sensor()``.
    perturb : Perturbation, optional
        Defaults to ``Perturbation.none()``, which gives exactly
        ``tactile.imprints(mesh, positions, normals, sensor)``.
    rng : numpy.random.Generator or int or None
        Source of every random draw; an integer seeds a new generator, so
        equal seeds give equal readings (the default seed is 0).  None
        draws fresh entropy from the operating system.  The device (gain map,
        dead taxels) comes first and from a stream of its own, so one
        generator state gives one device whatever points are touched.
    workers : int, optional
        Ray-casting threads.
    scene : optional
        ``meshsal.mesh.embree.embree_scene(mesh)``: pass the same mesh's scene to
        amortize the BVH build over many acquisitions.
    exact : bool
        Slice the surface exactly (``tactile.imprints_exact_at``) instead of
        ray casting: the same poses and draws, another simulator of the
        contact, for checking what a model fitted on ray-cast touches makes of
        touches it did not simulate.

    Returns
    -------
    (k, rows, cols) float32 in [0, 1]

    Examples
    --------
    >>> from meshsal.mesh import Mesh
    >>> plane = Mesh(vertices=[[-50, 0, -50], [50, 0, -50], [50, 0, 50], [-50, 0, 50]],
    ...              faces=[[0, 2, 1], [0, 3, 2]])
    >>> s = Sensor(mode="pressure")
    >>> noisy = acquire(plane, [[0, 0, 0]], [[0, 1, 0]], s, Perturbation(noise=0.05, adc_bits=4), rng=1)
    >>> bool((noisy == acquire(plane, [[0, 0, 0]], [[0, 1, 0]], s, Perturbation(noise=0.05, adc_bits=4), rng=1)).all())
    True
    """
    request = Acquisition(positions, normals, Perturbation.none() if perturb is None else perturb, rng)
    return acquire_all(mesh, [request], sensor, workers, scene, exact)[0]


def touch_codebook(
    mesh: Mesh,
    positions,
    normals,
    sensor: Sensor | None = None,
    perturb: Perturbation | None = None,
    draws: int = 8,
    rng=0,
    workers: int | None = None,
    scene=None,
) -> np.ndarray:
    """Many simulated touches at each of k places: what a touch there can feel like, (k, draws, rows, cols).

    Every touch is an acquisition of its own (:func:`acquire`'s model): its
    own device (gain map, dead taxels), roll, position jitter and tilt, and
    its own reading noise.  So the touches of a place spread over what one
    robot and pad can read there, whichever device it turns out to be.

    Parameters
    ----------
    mesh : Mesh, in millimetres
    positions, normals : (k, 3) float64, the places and their outward normals
    sensor : Sensor, optional
    perturb : Perturbation, optional (default ``Perturbation.typical()``)
    draws : int, touches per place (>= 1)
    rng : numpy.random.Generator or int or None, the source of every draw
    workers, scene : as for :func:`acquire`

    Returns
    -------
    (k, draws, rows, cols) float32 in [0, 1]

    Examples
    --------
    >>> from meshsal.mesh import Mesh
    >>> plane = Mesh(vertices=[[-50, 0, -50], [50, 0, -50], [50, 0, 50], [-50, 0, 50]],
    ...              faces=[[0, 2, 1], [0, 3, 2]])
    >>> book = touch_codebook(plane, [[0, 0, 0], [10, 0, 0]], [[0, 1, 0]] * 2, Sensor(mode="pressure"), draws=4)
    >>> book.shape, len({b.tobytes() for b in book[0]})     # four devices: four different readings
    ((2, 4, 16, 16), 4)
    """
    request = Acquisition(positions, normals, Perturbation.typical() if perturb is None else perturb, rng, draws)
    return acquire_all(mesh, [request], sensor, workers, scene)[0]


@dataclass(frozen=True, eq=False)
class Acquisition:
    """One request to :func:`acquire_all`: an acquisition session, or a touch codebook.

    Attributes
    ----------
    positions, normals : (k, 3) float64
        Where the robot is told to touch, and the outward normals there.
    perturb : Perturbation
    rng : numpy.random.Generator or int or None
        The source of this request's draws, as in :func:`acquire`.
    draws : int or None
        None: one session on one device, as :func:`acquire` reads it,
        (k, rows, cols).  An integer: that many touches per point, each its
        own device, as :func:`touch_codebook` reads them, (k, draws, rows, cols).
    """

    positions: object
    normals: object
    perturb: Perturbation = Perturbation()
    rng: object = 0
    draws: int | None = None


@dataclass(frozen=True, eq=False)
class _Placed:
    """A request's pads after its placement draws (jitter, roll), with its device and what is left of its stream."""

    perturb: Perturbation
    rng: np.random.Generator
    gain: np.ndarray
    dead: np.ndarray
    positions: np.ndarray
    normals: np.ndarray
    angles: np.ndarray
    shape: tuple


def acquire_all(
    mesh: Mesh, requests, sensor: Sensor | None = None, workers: int | None = None, scene=None, exact: bool = False
) -> list:
    """Many acquisitions on one mesh, their pads fitted and cast together.

    Each request reads exactly what :func:`acquire` (or, with ``draws``,
    :func:`touch_codebook`) reads alone: its draws come from its own
    stream, and a pad's imprint does not depend on the other pads.  Casting
    every pad of every request in one call keeps the Embree threads busy
    and walks the mesh once.

    Parameters
    ----------
    mesh : Mesh, in millimetres
    requests : sequence of Acquisition
    sensor : Sensor, optional
    workers, scene, exact : as for :func:`acquire`

    Returns
    -------
    list of float32 arrays in [0, 1], one per request, in order

    Examples
    --------
    >>> from meshsal.mesh import Mesh
    >>> plane = Mesh(vertices=[[-50, 0, -50], [50, 0, -50], [50, 0, 50], [-50, 0, 50]],
    ...              faces=[[0, 2, 1], [0, 3, 2]])
    >>> s, p = Sensor(mode="pressure"), Perturbation.typical()
    >>> both = acquire_all(plane, [Acquisition([[0, 0, 0]], [[0, 1, 0]], p, 1), Acquisition([[5, 0, 0]], [[0, 1, 0]], p, 2, 3)], s)
    >>> [b.shape for b in both], bool((both[0] == acquire(plane, [[0, 0, 0]], [[0, 1, 0]], s, p, 1)).all())
    ([(1, 16, 16), (1, 3, 16, 16)], True)
    """
    sensor = Sensor() if sensor is None else sensor
    placed = [_place(r, sensor) for r in requests]
    live = [p for p in placed if p.positions.shape[0]]
    clean = iter(_touch(mesh, live, sensor, workers, scene, exact) if live else ())
    out = []
    for p in placed:
        if p.positions.shape[0] == 0:
            out.append(np.zeros(p.shape, dtype=np.float32))
        else:
            out.append(_read(next(clean), p.gain, p.dead, sensor, p.perturb, p.rng).reshape(p.shape))
    return out


def _place(request: Acquisition, sensor: Sensor) -> _Placed:
    """Validate a request, draw its device(s), then its pads' jitter and roll."""
    if not isinstance(request, Acquisition):
        raise ValueError(f"requests must be tactile.Acquisition records, got {type(request).__name__}")
    perturb, draws = _checked(request.perturb), request.draws
    if draws is not None and (isinstance(draws, bool) or not isinstance(draws, (int, np.integer)) or draws < 1):
        raise ValueError(f"draws must be a positive integer, got {draws!r}")
    P, N, _ = check_points(request.positions, request.normals)
    k = P.shape[0]
    # The device (gain map, dead taxels) comes from its own stream: one session's device is the same
    # whatever points it touches, so methods touching other places meet the same device.
    device, rng = _rng(request.rng).spawn(2)
    gain, dead = _devices(device, perturb, sensor, () if draws is None else (k * draws,))
    shape = (k, sensor.rows, sensor.cols) if draws is None else (k, draws, sensor.rows, sensor.cols)
    if draws is not None:
        P, N = np.repeat(P, draws, axis=0), np.repeat(N, draws, axis=0)
    if k and perturb.jitter_mm > 0:
        up, right = tangent_frames(N)
        step = perturb.jitter_mm * rng.standard_normal((len(P), 2))
        P = P + step[:, :1] * right + step[:, 1:] * up
    if not k:
        angles = np.zeros(0)
    elif perturb.uniform_rotation:
        angles = rng.uniform(0.0, 360.0, len(P))
    else:
        angles = perturb.rotation_deg * rng.standard_normal(len(P)) if perturb.rotation_deg > 0 else np.zeros(len(P))
    return _Placed(perturb, rng, gain, dead, P, N, angles, shape)


def _checked(perturb) -> Perturbation:
    perturb = Perturbation.none() if perturb is None else perturb
    if not isinstance(perturb, Perturbation):
        raise ValueError(f"perturb must be a Perturbation, got {type(perturb).__name__}")
    return perturb


def _devices(device: np.random.Generator, perturb: Perturbation, sensor: Sensor, count: tuple):
    """Gain maps and dead-taxel masks, ``(*count, rows, cols)``: one device, or one per touch."""
    shape = (*count, sensor.rows, sensor.cols)
    gain = 1.0 + perturb.gain_spread * device.standard_normal(shape)
    dead = device.random(shape) < perturb.dead_fraction
    return gain, dead


def _touch(mesh, placed: list, sensor: Sensor, workers, scene, exact: bool) -> list:
    """Clean images of every request's pads, tilted by its draws: one pose fit and one cast for all."""
    cuts = np.cumsum([len(p.positions) for p in placed])[:-1]
    P, A = np.concatenate([p.positions for p in placed]), np.concatenate([p.angles for p in placed])
    # The same pose chain as tactile.imprints, so a clean acquisition is bit-identical.
    fitted = sensor_poses(mesh, P, np.concatenate([p.normals for p in placed]), sensor, A)
    parts = []
    for p, part in zip(placed, _split(fitted, cuts)):
        if p.perturb.tilt_deg > 0:
            part = poses_from_normals(p.positions, _tilt(part.normals, p.perturb.tilt_deg, p.rng), p.angles)
        parts.append(part)
    poses = Poses(*(np.concatenate([getattr(q, f) for q in parts]) for f in ("centers", "normals", "ups", "rights")))
    if exact:
        from tactile.section import imprints_exact_at

        images = imprints_exact_at(mesh, poses, sensor)
    else:
        images = imprints_at(mesh, poses, sensor, workers, scene=scene)
    return np.split(images, cuts)


def _split(poses: Poses, cuts) -> list:
    fields = [np.split(getattr(poses, f), cuts) for f in ("centers", "normals", "ups", "rights")]
    return [Poses(*f) for f in zip(*fields)]


def _read(images, gain, dead, sensor: Sensor, perturb: Perturbation, rng) -> np.ndarray:
    """What the device reads of clean images: cover blur, gains, noise, clipping, dead taxels, the ADC."""
    if perturb.blur_mm > 0:
        from scipy.ndimage import gaussian_filter

        sigma = perturb.blur_mm / sensor.pitch_mm
        images = gaussian_filter(images, sigma=(0.0, sigma, sigma), mode="constant", cval=0.0)
    if perturb.gain_spread > 0:
        images = images * np.maximum(gain, 0.0)
    if perturb.noise > 0:
        images = images + perturb.noise * rng.standard_normal(images.shape)
    images = np.clip(images, 0.0, 1.0)
    if perturb.dead_fraction > 0:
        images = np.where(dead, 0.0, images)
    if perturb.adc_bits > 0:
        levels = float(2**perturb.adc_bits - 1)
        images = np.round(images * levels) / levels
    return images.astype(np.float32)
