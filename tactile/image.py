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
    """Average each ``supersample x supersample`` block: (k, H, W) -> (k, rows, cols) float32."""
    s = sensor.supersample
    k = images.shape[0]
    blocks = images.reshape(k, sensor.rows, s, sensor.cols, s)
    return blocks.mean(axis=(2, 4), dtype=np.float64).astype(np.float32)


def pressure_image(depth: np.ndarray, sensor: Sensor) -> np.ndarray:
    """Penetration ``max(0, d - h) / d`` area-averaged to taxels, (k, rows, cols) float32 in [0, 1].

    Examples
    --------
    >>> s = Sensor(rows=1, cols=1, supersample=2, depth_mm=2.0)
    >>> pressure_image(np.array([[[0.0, 1.0], [np.inf, 3.0]]]), s).tolist()
    [[[0.375]]]
    """
    d = sensor.depth_mm
    with np.errstate(invalid="ignore"):
        p = np.clip((d - np.asarray(depth, dtype=np.float64)) / d, 0.0, 1.0)
    return area_average(np.nan_to_num(p, nan=0.0), sensor)


def contour_lines(depth: np.ndarray, sensor: Sensor) -> np.ndarray:
    """Iso-lines of the depth field at the four plane depths, on the supersampled grid.

    A sample lies on the contour of plane k when it is reached by that plane
    (``h <= k d/4``) and one of its four neighbours is not; samples beyond the
    grid are treated as copies of the edge, so the pad's border draws nothing.
    Where contours coincide the deeper (brighter) one wins.

    Returns
    -------
    (k, H, W) float32 with values in {0, 1/4, 2/4, 3/4, 1}.
    """
    h = np.asarray(depth)
    padded = np.pad(h, ((0, 0), (1, 1), (1, 1)), mode="edge")
    lines = np.zeros(h.shape, dtype=np.float32)
    for k, level in enumerate(plane_depths(sensor), start=1):
        inside = padded <= level
        core = inside[:, 1:-1, 1:-1]
        edge = core & ~(
            inside[:, :-2, 1:-1] & inside[:, 2:, 1:-1] & inside[:, 1:-1, :-2] & inside[:, 1:-1, 2:]
        )
        lines[edge] = k / PLANES
    return lines


def finish_contours(lines: np.ndarray, sensor: Sensor) -> np.ndarray:
    """Widen one-sample contour lines to about a taxel, then area-average to taxels.

    A line as wide as a taxel makes a crossed taxel read close to its
    plane's gray level instead of ``1/supersample`` of it.  The widening is
    a gray-level dilation with an odd square (``2 * (supersample // 2) + 1``
    samples), symmetric so that turning the pad permutes the image exactly.
    """
    from scipy.ndimage import maximum_filter

    w = 2 * (sensor.supersample // 2) + 1
    wide = maximum_filter(np.asarray(lines, dtype=np.float32), size=(1, w, w), mode="constant", cval=0.0)
    return area_average(wide, sensor)
