"""Fresh instances of an object: turned, resized and repainted copies of one mesh.

An evaluation that trains on one copy of an object and tests on another
must not let the copies share anything but the object itself: pose, size
and paint vary between instances, as they would between two cups on a
table.  :func:`draw_instance` draws those variations from a generator;
:func:`make_instance` applies them to a mesh that
:func:`meshsal.mesh.transform.scale_to_principal` has brought to its nominal
size, centroid at the origin.

* pose: a rotation uniform over SO(3) (a uniform unit quaternion, ``scipy.spatial.transform.Rotation``);
* size: a scale factor uniform in ``1 ± scale_spread`` (5 % by default);
* paint: the toys of :mod:`meshsal.objects.toys` are repainted with a new paint
  seed; any other coloured mesh (vertex colours or a texture) has its hue
  turned about the grey axis and its brightness scaled; an uncoloured mesh
  stays uncoloured.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from meshsal.mesh import Mesh, Similarity

__all__ = ["InstanceSpec", "random_rotation", "draw_instance", "make_instance", "recolor"]


@dataclass(frozen=True, eq=False)
class InstanceSpec:
    """How one instance departs from the nominal object.

    Attributes
    ----------
    rotation : (3, 3) float64
        Proper rotation about the centroid.
    scale : float
        Size relative to the nominal one.
    paint_seed : int
        New paint seed (toys).
    hue_deg : float
        Hue turn about the grey axis (other coloured meshes).
    brightness : float
        Brightness factor (other coloured meshes).
    """

    rotation: np.ndarray
    scale: float
    paint_seed: int
    hue_deg: float
    brightness: float

    def key(self) -> list:
        """A JSON-ready description, for cache keys and reports."""
        return [
            np.round(self.rotation, 12).tolist(),
            round(self.scale, 12),
            self.paint_seed,
            round(self.hue_deg, 9),
            round(self.brightness, 12),
        ]


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A rotation matrix uniform over SO(3), (3, 3) float64.

    A unit quaternion from four standard normal draws is uniform on the
    3-sphere, hence its rotation is uniform over SO(3) (Shoemake 1992).

    Examples
    --------
    >>> R = random_rotation(np.random.default_rng(0))
    >>> bool(np.allclose(R @ R.T, np.eye(3))), bool(np.isclose(np.linalg.det(R), 1.0))
    (True, True)
    """
    w, x, y, z = rng.standard_normal(4)
    return Rotation.from_quat([x, y, z, w]).as_matrix()


def draw_instance(
    rng: np.random.Generator,
    scale_spread: float = 0.05,
    hue_deg: float = 30.0,
    brightness_spread: float = 0.15,
    rotate: bool = True,
) -> InstanceSpec:
    """Draw one instance's pose, size and paint.

    Parameters
    ----------
    rng : numpy.random.Generator
    scale_spread : float
        Scale uniform in ``[1 - scale_spread, 1 + scale_spread]``.
    hue_deg : float
        Hue turn uniform in ``[-hue_deg, hue_deg]``.
    brightness_spread : float
        Brightness factor uniform in ``[1 - brightness_spread, 1 + brightness_spread]``.
    rotate : bool
        False keeps the nominal pose (identity rotation).

    Examples
    --------
    >>> spec = draw_instance(np.random.default_rng(1))
    >>> 0.95 <= spec.scale <= 1.05, -30 <= spec.hue_deg <= 30
    (True, True)
    """
    if not 0 <= scale_spread < 1 or not 0 <= brightness_spread < 1 or hue_deg < 0:
        raise ValueError(
            f"spreads must be in [0, 1) and hue_deg >= 0, got scale_spread={scale_spread}, "
            f"brightness_spread={brightness_spread}, hue_deg={hue_deg}"
        )
    rotation = random_rotation(rng) if rotate else np.eye(3)
    scale = float(rng.uniform(1 - scale_spread, 1 + scale_spread))
    paint_seed = int(rng.integers(2**31 - 1))
    hue = float(rng.uniform(-hue_deg, hue_deg))
    brightness = float(rng.uniform(1 - brightness_spread, 1 + brightness_spread))
    return InstanceSpec(rotation, scale, paint_seed, hue, brightness)


def recolor(colors: np.ndarray, hue_deg: float, brightness: float) -> np.ndarray:
    """Turn RGB colours about the grey axis by ``hue_deg`` and scale them by ``brightness``.

    Parameters
    ----------
    colors : (..., 3) float in [0, 1] or uint8
    hue_deg, brightness : float

    Returns
    -------
    The same shape and dtype, clipped to the valid range.

    Examples
    --------
    >>> recolor(np.array([[0.5, 0.5, 0.5]]), 90.0, 1.0).round(6).tolist()   # grey has no hue
    [[0.5, 0.5, 0.5]]
    >>> recolor(np.array([[1.0, 0.0, 0.0]]), 120.0, 1.0).round(6).tolist()  # red -> green
    [[0.0, 1.0, 0.0]]
    """
    c = np.asarray(colors)
    t = np.deg2rad(hue_deg)
    cos, sin = np.cos(t), np.sin(t)
    # Rodrigues' rotation about (1, 1, 1) / sqrt(3).
    k = (1.0 - cos) / 3.0
    s = sin / np.sqrt(3.0)
    M = np.array([[cos + k, k - s, k + s], [k + s, cos + k, k - s], [k - s, k + s, cos + k]]) * brightness
    if c.dtype == np.uint8:
        out = (c.astype(np.float64) @ M.T).round()
        return np.clip(out, 0, 255).astype(np.uint8)
    return np.clip(c.astype(np.float64) @ M.T, 0.0, 1.0).astype(c.dtype)


def make_instance(mesh: Mesh, spec: InstanceSpec) -> Mesh:
    """Apply an instance's paint, size and pose to a nominal mesh (centroid at the origin).

    The returned mesh's ``transform`` composes the turn and the resize with
    the mesh's earlier steps, so ``transform.to_source`` still leads back to
    the file.

    Examples
    --------
    >>> m = Mesh(vertices=[[1.0, 0, 0], [0, 1, 0], [0, 0, 1]], faces=[[0, 1, 2]])
    >>> spec = InstanceSpec(np.eye(3), 2.0, 0, 0.0, 1.0)
    >>> make_instance(m, spec).vertices[0].tolist()
    [2.0, 0.0, 0.0]
    """
    from meshsal.objects import toys

    if mesh.name in toys.NAMES and mesh.vertex_colors is not None:
        mesh = toys.repaint(mesh, spec.paint_seed)
    else:
        if mesh.vertex_colors is not None:
            mesh = mesh.replace(vertex_colors=recolor(mesh.vertex_colors, spec.hue_deg, spec.brightness))
        if mesh.texture is not None:
            mesh = mesh.replace(texture=recolor(mesh.texture, spec.hue_deg, spec.brightness))
    step = Similarity(spec.scale, np.zeros(3), spec.rotation)
    return mesh.replace(vertices=step.apply(mesh.vertices), transform=mesh.transform.then(step))
