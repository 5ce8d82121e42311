"""A labelled set of tactile imprints, and its ``.npz`` file format.

The file is a NumPy ``.npz`` archive (no pickles) holding the arrays and a
``meta`` JSON string: ``{"format": "visuotactile.ImprintSet", "version": 1,
"object_names": [...], "sensor": {...}, "perturbation": {...} | null,
"seed": int | null, "source": str}``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tactile.perturbation import Perturbation
from tactile.sensor import Sensor

__all__ = ["FORMAT", "VERSION", "ImprintSet"]

FORMAT = "visuotactile.ImprintSet"
VERSION = 1
_ARRAYS = ("imprints", "labels", "point_ids", "positions", "normals")


@dataclass(frozen=True, eq=False)
class ImprintSet:
    """Imprints of one or more objects, with where and how they were taken.

    Attributes
    ----------
    imprints : (N, rows, cols) float32 in [0, 1]
    labels : (N,) int64
        Index into ``object_names``.
    object_names : tuple of str
    point_ids : (N,) int64
        Which interest point of its object each imprint was taken at.
    positions, normals : (N, 3) float64
        The touched points and their normals, in the scaled mesh frame (mm).
    sensor : Sensor
    perturbation : Perturbation or None
        None for clean simulations and for recorded hardware.
    seed : int or None
        Seed of the random draws, when there were any.
    source : str
        Free text: where the imprints came from (mesh file, device...).

    Examples
    --------
    >>> s = ImprintSet(imprints=np.zeros((2, 16, 16)), labels=[0, 1], object_names=("cup", "hand"),
    ...                point_ids=[0, 0], positions=np.zeros((2, 3)), normals=[[0, 1, 0]] * 2,
    ...                sensor=Sensor())
    >>> len(s), s.imprints.dtype, s.subset([False, True]).object_names
    (2, dtype('float32'), ('cup', 'hand'))
    """

    imprints: np.ndarray
    labels: np.ndarray
    object_names: tuple
    point_ids: np.ndarray
    positions: np.ndarray
    normals: np.ndarray
    sensor: Sensor
    perturbation: Perturbation | None = None
    seed: int | None = None
    source: str = ""

    def __post_init__(self):
        imprints = np.ascontiguousarray(self.imprints, dtype=np.float32)
        if imprints.ndim != 3:
            raise ValueError(f"imprints must have shape (N, rows, cols), got {imprints.shape}")
        n = imprints.shape[0]
        if not isinstance(self.sensor, Sensor):
            raise ValueError(f"sensor must be a Sensor, got {type(self.sensor).__name__}")
        if imprints.shape[1:] != (self.sensor.rows, self.sensor.cols):
            raise ValueError(
                f"imprints are {imprints.shape[1:]} but the sensor is {(self.sensor.rows, self.sensor.cols)}"
            )
        if self.perturbation is not None and not isinstance(self.perturbation, Perturbation):
            raise ValueError(f"perturbation must be a Perturbation or None, got {type(self.perturbation).__name__}")
        names = tuple(str(name) for name in self.object_names)
        arrays = {
            "labels": (np.asarray(self.labels), (n,), np.int64),
            "point_ids": (np.asarray(self.point_ids), (n,), np.int64),
            "positions": (np.asarray(self.positions), (n, 3), np.float64),
            "normals": (np.asarray(self.normals), (n, 3), np.float64),
        }
        for name, (value, shape, dtype) in arrays.items():
            if value.shape != shape:
                raise ValueError(f"{name} must have shape {shape}, got {value.shape}")
            if dtype is np.int64 and value.size and not np.issubdtype(value.dtype, np.integer):
                raise ValueError(f"{name} must be integers, got {value.dtype}")
            object.__setattr__(self, name, np.ascontiguousarray(value, dtype=dtype))
        if n and (self.labels.min() < 0 or self.labels.max() >= len(names)):
            raise ValueError(
                f"labels must index object_names (0..{len(names) - 1}), "
                f"got values {self.labels.min()}..{self.labels.max()}"
            )
        if self.seed is not None and (isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer))):
            raise ValueError(f"seed must be an integer or None, got {self.seed!r}")
        object.__setattr__(self, "imprints", imprints)
        object.__setattr__(self, "object_names", names)
        object.__setattr__(self, "seed", None if self.seed is None else int(self.seed))
        object.__setattr__(self, "source", str(self.source))

    def __len__(self) -> int:
        return int(self.imprints.shape[0])

    def subset(self, keep) -> ImprintSet:
        """The imprints selected by a boolean mask or an index array (object names unchanged)."""
        keep = np.asarray(keep)
        if keep.dtype == bool and keep.shape != (len(self),):
            raise ValueError(f"mask must have shape ({len(self)},), got {keep.shape}")
        return ImprintSet(
            imprints=self.imprints[keep],
            labels=self.labels[keep],
            object_names=self.object_names,
            point_ids=self.point_ids[keep],
            positions=self.positions[keep],
            normals=self.normals[keep],
            sensor=self.sensor,
            perturbation=self.perturbation,
            seed=self.seed,
            source=self.source,
        )

    def save(self, path) -> None:
        """Write the set to ``path`` (.npz), atomically."""
        from meshsal.util.atomic import atomic_path

        path = Path(path)
        if path.suffix != ".npz":
            raise ValueError(f"{path}: an imprint set is saved as .npz")
        meta = {
            "format": FORMAT,
            "version": VERSION,
            "object_names": list(self.object_names),
            "sensor": self.sensor.to_dict(),
            "perturbation": None if self.perturbation is None else self.perturbation.to_dict(),
            "seed": self.seed,
            "source": self.source,
        }
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as fh:
                np.savez_compressed(
                    fh, meta=np.array(json.dumps(meta)), **{name: getattr(self, name) for name in _ARRAYS}
                )

    @classmethod
    def load(cls, path) -> ImprintSet:
        """Read a set written by :meth:`save`; a clear ``ValueError`` naming the file if it is
        damaged, truncated, foreign, of another version, or larger than the caps of
        :func:`meshsal.util.npzfile.read_npz` (512 MiB in all, 256 MiB an array)."""
        from meshsal.util.jsonfile import parse_json
        from meshsal.util.npzfile import read_npz

        path = Path(path)
        try:
            arrays = read_npz(path, "imprint set")
        except FileNotFoundError:
            raise FileNotFoundError(f"{path}: no such imprint set file") from None
        if "meta" not in arrays:
            raise ValueError(
                f"{path}: not an imprint set (no 'meta' entry; arrays found: {', '.join(arrays) or 'none'})"
            )
        meta = parse_json(str(arrays["meta"]), path, "imprint set")
        if not isinstance(meta, dict) or meta.get("format") != FORMAT:
            raise ValueError(
                f"{path}: not an imprint set (format {meta.get('format') if isinstance(meta, dict) else meta!r})"
            )
        if meta.get("version") != VERSION:
            raise ValueError(
                f"{path}: imprint set version {meta.get('version')!r} is not supported "
                f"(this toolkit reads version {VERSION})"
            )
        missing = [name for name in _ARRAYS if name not in arrays]
        if missing:
            raise ValueError(f"{path}: damaged imprint set, missing {', '.join(missing)}")
        try:
            perturbation = meta.get("perturbation")
            return cls(
                sensor=Sensor(**meta["sensor"]),
                perturbation=None if perturbation is None else Perturbation(**perturbation),
                object_names=tuple(meta["object_names"]),
                seed=meta.get("seed"),
                source=meta.get("source", ""),
                **{name: arrays[name] for name in _ARRAYS},
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{path}: inconsistent imprint set ({exc})") from None
