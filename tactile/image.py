"""From depths under the pad to taxel images: the conventions both imprint paths share.

Depth ``h`` is measured along the pad normal from the pad's first contact
(the highest surface point it meets), on the supersampled grid of
:func:`tactile.sensor.sample_grid`; ``inf`` marks samples where the pad meets
nothing (no surface, a surface facing away, or one beyond the deepest plane).

The paper's four slicing planes sit at depths ``d/4, 2d/4, 3d/4, d``
(``d = sensor.depth_mm``).  In contour mode plane k (1..4) is drawn with gray
level ``k/4``: the deeper the plane, the brighter its contour.
"""

from __future__ import annotations

import numpy as np

from tactile.sensor import Sensor

__all__ = ["PLANES", "plane_depths", "pressure_image", "contour_lines", "finish_contours", "area_average"]

PLANES = 4


def plane_depths(sensor: Sensor) -> np.ndarray:
    """Depths of the four slicing planes below first contact, (4,) float64, deepest last."""
    return sensor.depth_mm * np.arange(1, PLANES + 1) / PLANES


def area_average(images: np.ndarray, sensor: Sensor) -> np.ndarray:
    """Average each ``supersample x supersample`` block: (k, H, W) -> (k, rows, cols) float32.

    Examples
    --------
    >>> area_average(np.arange(16.0).reshape(1, 4, 4), Sensor(rows=2, cols=2, supersample=2)).tolist()
    [[[2.5, 4.5], [10.5, 12.5]]]
    """
    s = sensor.supersample
    # Strided slice sums: far cheaper than a mean over the short block axes.
    cols = np.asarray(images, dtype=np.float64)[:, :, 0::s].copy()
    for j in range(1, s):
        cols += images[:, :, j::s]
    total = cols[:, 0::s].copy()
    for j in range(1, s):
        total += cols[:, j::s]
    return (total / (s * s)).astype(np.float32)


def pressure_image(depth: np.ndarray, sensor: Sensor) -> np.ndarray:
    """Penetration ``max(0, d - h) / d`` area-averaged to taxels, (k, rows, cols) float32 in [0, 1].

    Examples
    --------
    >>> s = Sensor(rows=1, cols=1, supersample=2, depth_mm=2.0)
    >>> pressure_image(np.array([[[0.0, 1.0], [np.inf, 3.0]]]), s).tolist()
    [[[0.375]]]
    """
    d = sensor.depth_mm
    return area_average(np.clip((d - np.asarray(depth, dtype=np.float64)) / d, 0.0, 1.0), sensor)


def contour_lines(depth: np.ndarray, sensor: Sensor) -> np.ndarray:
    """Iso-lines of the depth field at the four plane depths, on the supersampled grid.

    A sample lies on the contour of plane k when it is reached by that plane
    (``h <= k d/4``) and one of its four neighbours is not; samples beyond the
    grid are treated as copies of the edge, so the pad's border draws nothing.
    Where contours coincide the deeper (brighter) one wins.

    Returns
    -------
    (k, H, W) float32 with values in {0, 1/4, 2/4, 3/4, 1}.

    Examples
    --------
    >>> h = np.array([[[0.0, 0.0, 2.0, np.inf]]])
    >>> (contour_lines(h, Sensor(depth_mm=4.0)) * 4).astype(int).tolist()
    [[[0, 1, 4, 0]]]
    """
    h = np.asarray(depth)
    # Planes that miss each sample: plane k reaches it when ``k > above``.
    above = np.zeros(h.shape, dtype=np.uint8)
    for level in plane_depths(sensor):
        above += h > level
    # The deepest plane a neighbour escapes; beyond the grid the neighbour is
    # the sample itself, which never makes a contour, so 0 stands in for it.
    escape = np.zeros_like(above)
    np.maximum(escape[:, 1:], above[:, :-1], out=escape[:, 1:])
    np.maximum(escape[:, :-1], above[:, 1:], out=escape[:, :-1])
    np.maximum(escape[:, :, 1:], above[:, :, :-1], out=escape[:, :, 1:])
    np.maximum(escape[:, :, :-1], above[:, :, 1:], out=escape[:, :, :-1])
    plane = np.where(above < escape, escape, 0)
    return plane.astype(np.float32) / np.float32(PLANES)


def _dilate(images: np.ndarray, width: int) -> np.ndarray:
    """Gray-level dilation of (k, H, W) images by a ``width`` x ``width`` square (odd), zero outside."""
    out = images.copy()
    for axis in (1, 2):
        src = out.copy()
        for o in range(1, width // 2 + 1):
            lo = [slice(None)] * 3
            hi = [slice(None)] * 3
            lo[axis], hi[axis] = slice(None, -o), slice(o, None)
            np.maximum(out[tuple(hi)], src[tuple(lo)], out=out[tuple(hi)])
            np.maximum(out[tuple(lo)], src[tuple(hi)], out=out[tuple(lo)])
    return out


def finish_contours(lines: np.ndarray, sensor: Sensor) -> np.ndarray:
    """Widen one-sample contour lines to about a taxel, then area-average to taxels.

    A line as wide as a taxel makes a crossed taxel read close to its
    plane's gray level instead of ``1/supersample`` of it.  The widening is
    a gray-level dilation with an odd square (``2 * (supersample // 2) + 1``
    samples), symmetric so that turning the pad permutes the image exactly.
    """
    w = 2 * (sensor.supersample // 2) + 1
    return area_average(_dilate(np.asarray(lines, dtype=np.float32), w), sensor)
