"""Can a flat pad, pressed along the normal, touch a surface point first?

A tactile pad pressed onto a point along the point's normal meets the
surface wherever the surface rises highest under the pad.  When a
protrusion beside the point stands higher than the point itself, the pad
lands on the protrusion and the imprint shows a corner of it, not the point
(e.g. a few taxels where a whole patch was meant).  :func:`contact_gap` is
how far the pad stops short of the point; :func:`touchable` says whether
that is within a tolerance.

The pad may be rolled about the normal in any way, so the test covers the
disc it sweeps: radius half its diagonal.  Rays start beyond the whole
mesh, so anything in the pad's way along the normal counts, as it would for
a real finger coming from outside.
"""

from __future__ import annotations

import numpy as np

from meshsal.mesh import Mesh
from meshsal.mesh.geometry import tangent_frames

__all__ = ["contact_gap", "touchable", "PAD_FRACTION", "default_pad_width"]

#: The default pad width as a fraction of the mesh's bounding-box diagonal: the
#: 32 mm of a 16 x 16 pad at 2 mm pitch on an object of 150 mm diagonal.
PAD_FRACTION = 32.0 / 150.0


def default_pad_width(mesh: Mesh) -> float:
    """``PAD_FRACTION`` times the bounding-box diagonal, in mesh units."""
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    return PAD_FRACTION * float(np.linalg.norm(hi - lo))


def contact_gap(mesh: Mesh, positions: np.ndarray, normals: np.ndarray, pad_width: float,
                samples: int = 16, scene=None) -> np.ndarray:
    """How far above each point a pad pressed along its normal first meets the surface.

    Parameters
    ----------
    mesh : Mesh
    positions : (k, 3) float64
        Points on the surface.
    normals : (k, 3) float64
        Outward normals (need not be unit).
    pad_width : float > 0
        Width of the square pad, mesh units; the disc of radius
        ``pad_width / sqrt(2)`` (any roll) is tested.
    samples : int
        Rays across the pad's width (``samples / 2`` per half width).
    scene : Embree scene of ``mesh``, optional
        Built when omitted (:func:`meshsal.mesh.embree.embree_scene`).

    Returns
    -------
    (k,) float64
        0 where the point itself is the first contact; positive: the
        height of the first contact above the point's tangent plane.

    Examples
    --------
    >>> from meshsal.mesh import Mesh
    >>> plane = Mesh(vertices=[[-50, -50, 0], [50, -50, 0], [50, 50, 0], [-50, 50, 0.]],
    ...              faces=[[0, 1, 2], [0, 2, 3]])
    >>> float(contact_gap(plane, [[0, 0, 0]], [[0, 0, 1]], 32.0)[0]) < 1e-4
    True
    """
    from meshsal.mesh.embree import embree_scene

    P = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    N = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    if P.shape != N.shape:
        raise ValueError(f"positions {P.shape} and normals {N.shape} differ in shape")
    length = np.linalg.norm(N, axis=1)
    if np.any(length < 1e-12):
        raise ValueError(f"normals must be non-zero (zero at rows {np.flatnonzero(length < 1e-12)[:5].tolist()})")
    if not (np.isfinite(pad_width) and pad_width > 0):
        raise ValueError(f"pad_width must be a positive length, got {pad_width}")
    N = N / length[:, None]
    radius = pad_width / np.sqrt(2.0)
    # An odd count keeps the centre and the disc's rim on the grid.
    grid = np.linspace(-radius, radius, 2 * int(np.ceil(radius * samples / pad_width)) + 1)
    a, b = np.meshgrid(grid, grid)
    inside = a * a + b * b <= radius * radius
    a, b = a[inside], b[inside]
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    height = 2.0 * float(np.linalg.norm(hi - lo)) + radius
    scene = embree_scene(mesh) if scene is None else scene
    U, V = tangent_frames(N)
    origins = (P + height * N)[:, None] + a[None, :, None] * U[:, None] + b[None, :, None] * V[:, None]
    hit = scene.run(np.ascontiguousarray(origins.reshape(-1, 3), np.float32),
                    np.ascontiguousarray(np.repeat(-N, a.size, axis=0), np.float32), output=1)
    travel = np.where(hit["primID"] >= 0, hit["tfar"], np.inf).reshape(P.shape[0], a.size).min(axis=1)
    return np.where(np.isfinite(travel), np.maximum(0.0, height - travel), 0.0)


def touchable(mesh: Mesh, positions: np.ndarray, normals: np.ndarray, pad_width: float,
              tolerance: float | None = None, scene=None) -> np.ndarray:
    """Whether the pad pressed along each normal meets the surface first within ``tolerance`` of the point.

    Parameters
    ----------
    mesh, positions, normals, pad_width, scene : as in :func:`contact_gap`
    tolerance : float, optional
        Allowed gap, mesh units; default ``pad_width / 32`` (1 mm for a 32 mm pad).

    Returns
    -------
    (k,) bool

    Examples
    --------
    A point at the bottom of a step 10 units high, 5 units from the wall:
    the pad lands on the step's top.

    >>> from meshsal.mesh import Mesh
    >>> V = [[-50, -50, 0], [0, -50, 0], [0, 50, 0], [-50, 50, 0],
    ...      [0, -50, 10], [50, -50, 10], [50, 50, 10], [0, 50, 10.]]
    >>> F = [[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7], [1, 4, 7], [1, 7, 2]]
    >>> touchable(Mesh(vertices=V, faces=F), [[-5, 0, 0], [-40, 0, 0]], [[0, 0, 1], [0, 0, 1]], 32.0).tolist()
    [False, True]
    """
    gaps = contact_gap(mesh, positions, normals, pad_width, scene=scene)
    limit = pad_width / 32.0 if tolerance is None else float(tolerance)
    if not (np.isfinite(limit) and limit >= 0):
        raise ValueError(f"tolerance must be a finite length >= 0, got {tolerance}")
    return gaps <= limit
