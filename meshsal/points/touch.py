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

What a mesh and a pad width share for any number of points (the Embree
scene, the height rays start from, the rays across the pad) is
:class:`PadRays`, built once by :func:`pad_rays`; :func:`pad_touches`
tests points with it, as a selection testing many candidates does
(:class:`meshsal.points.select.TouchFilter`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshsal.mesh import Mesh
from meshsal.mesh.geometry import tangent_frames

__all__ = ["contact_gap", "touchable", "PadRays", "pad_rays", "pad_touches", "PAD_WIDTH"]

#: The default pad width in millimetres: ``tactile.Sensor()``'s 16 x 16 taxels at 2 mm pitch, and the
#: command line's ``--pad-mm``.
PAD_WIDTH = 32.0


# The touch test first traces every COARSE-th ray of the grid in each direction (29 of 441 at the
# default 16 samples).  On the hand toy, a 124k-face hand, the plane and the bunny at 150 mm, where four
# vertices in five are refused, they alone refuse 88-97 % of them: a test traces 0.27-0.33 of the rays
# of the whole grid (0.65 on nefertiti, a relief).
COARSE = 4


@dataclass(frozen=True, eq=False)
class PadRays:
    """The rays of a pad pressed on one mesh, the same for every point: built once by :func:`pad_rays`.

    Attributes
    ----------
    scene : Embree scene of the mesh
    pad_width : float
        Width of the square pad, mesh units.
    height : float
        Rays start this far above each point along its normal: beyond the whole mesh.
    offsets : (r, 2) float64
        Each ray's place across the pad's disc, along the two tangent directions.
    coarse : (r,) bool
        The rays :func:`pad_touches` traces first.
    """

    scene: object
    pad_width: float
    height: float
    offsets: np.ndarray
    coarse: np.ndarray


def pad_rays(mesh: Mesh, pad_width: float, samples: int = 16, scene=None) -> PadRays:
    """The rays a pad of ``pad_width`` casts on ``mesh`` (arguments as in :func:`contact_gap`).

    Examples
    --------
    >>> from meshsal.mesh import Mesh
    >>> plane = Mesh(vertices=[[-50, -50, 0], [50, -50, 0], [50, 50, 0], [-50, 50, 0.]],
    ...              faces=[[0, 1, 2], [0, 2, 3]])
    >>> rays = pad_rays(plane, 32.0)
    >>> rays.offsets.shape, int(rays.coarse.sum())
    ((441, 2), 29)
    """
    from meshsal.mesh.embree import embree_scene

    if not (np.isfinite(pad_width) and pad_width > 0):
        raise ValueError(f"pad_width must be a positive length, got {pad_width}")
    radius = pad_width / np.sqrt(2.0)
    # An odd count keeps the centre and the disc's rim on the grid.
    steps = 2 * int(np.ceil(radius * samples / pad_width)) + 1
    grid = np.linspace(-radius, radius, steps)
    a, b = np.meshgrid(grid, grid)
    inside = a * a + b * b <= radius * radius
    on_coarse = (np.arange(steps) - steps // 2) % COARSE == 0
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    return PadRays(
        scene=embree_scene(mesh) if scene is None else scene,
        pad_width=float(pad_width),
        height=2.0 * float(np.linalg.norm(hi - lo)) + radius,
        offsets=np.column_stack([a[inside], b[inside]]),
        coarse=(on_coarse[None, :] & on_coarse[:, None])[inside],
    )


def _unit_normals(positions, normals) -> tuple[np.ndarray, np.ndarray]:
    P = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    N = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    if P.shape != N.shape:
        raise ValueError(f"positions {P.shape} and normals {N.shape} differ in shape")
    length = np.linalg.norm(N, axis=1)
    if np.any(length < 1e-12):
        raise ValueError(f"normals must be non-zero (zero at rows {np.flatnonzero(length < 1e-12)[:5].tolist()})")
    return P, N / length[:, None]


def _travel(rays: PadRays, P: np.ndarray, N: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """(k,) how far each point's rays at ``offsets`` travel before they first meet the surface (inf: never)."""
    U, V = tangent_frames(N)
    a, b = offsets[:, 0], offsets[:, 1]
    origins = (P + rays.height * N)[:, None] + a[None, :, None] * U[:, None] + b[None, :, None] * V[:, None]
    hit = rays.scene.run(
        np.ascontiguousarray(origins.reshape(-1, 3), np.float32),
        np.ascontiguousarray(np.repeat(-N, a.size, axis=0), np.float32),
        output=1,
    )
    return np.where(hit["primID"] >= 0, hit["tfar"], np.inf).reshape(P.shape[0], a.size).min(axis=1)


def _gap(rays: PadRays, travel: np.ndarray) -> np.ndarray:
    return np.where(np.isfinite(travel), np.maximum(0.0, rays.height - travel), 0.0)


def _verdicts(rays: PadRays, P: np.ndarray, N: np.ndarray, tolerance: float | None) -> np.ndarray:
    limit = rays.pad_width / 32.0 if tolerance is None else float(tolerance)
    if not (np.isfinite(limit) and limit >= 0):
        raise ValueError(f"tolerance must be a finite length >= 0, got {tolerance}")
    # The coarse rays first: where they already meet the surface too high, the whole pad does (its first
    # contact is the highest of all its rays).  The points still in doubt get the other rays, so their
    # gap is the minimum over the whole grid, as in contact_gap: the same verdicts, far fewer rays.
    travel = _travel(rays, P, N, rays.offsets[rays.coarse])
    doubt = np.flatnonzero(_gap(rays, travel) <= limit)
    if doubt.size:
        rest = _travel(rays, P[doubt], N[doubt], rays.offsets[~rays.coarse])
        travel[doubt] = np.minimum(travel[doubt], rest)
    return _gap(rays, travel) <= limit


def pad_touches(
    rays: PadRays, positions: np.ndarray, normals: np.ndarray, tolerance: float | None = None
) -> np.ndarray:
    """:func:`touchable` with the rays already built (:func:`pad_rays`)."""
    P, N = _unit_normals(positions, normals)
    return _verdicts(rays, P, N, tolerance)


def contact_gap(
    mesh: Mesh, positions: np.ndarray, normals: np.ndarray, pad_width: float, samples: int = 16, scene=None
) -> np.ndarray:
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
    P, N = _unit_normals(positions, normals)
    rays = pad_rays(mesh, pad_width, samples, scene)
    return _gap(rays, _travel(rays, P, N, rays.offsets))


def touchable(
    mesh: Mesh, positions: np.ndarray, normals: np.ndarray, pad_width: float, tolerance: float | None = None, scene=None
) -> np.ndarray:
    """Whether the pad pressed along each normal meets the surface first within ``tolerance`` of the point.

    Parameters
    ----------
    mesh, positions, normals, pad_width, scene : as in :func:`contact_gap`
    tolerance : float, optional
        Allowed gap, mesh units; default ``pad_width / 32`` (1 mm for a 32 mm pad).

    Returns
    -------
    (k,) bool, ``contact_gap(...) <= tolerance``

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
    P, N = _unit_normals(positions, normals)
    return _verdicts(pad_rays(mesh, pad_width, scene=scene), P, N, tolerance)
