"""Reference imprints from exact plane-mesh sections, to validate and benchmark the fast path.

For each pad, the mesh is expressed in the pad frame ``(x, y, z)`` =
``(right, up, normal)`` about the touched point.  The first contact is the
highest front-facing surface over the pad's sample grid (at most
``sensor.reach_mm`` above the point), found by rasterizing the front-facing
triangles into a z-buffer with exact barycentric heights.  Contour mode
cuts every triangle over the pad with the four planes ``z = contact - k d/4``
(vectorized triangle/plane intersection), clips the segments to the pad and
draws them into the supersampled grid; pressure mode fills the penetration
of the rasterized surface.  Both then share :mod:`tactile.image`'s
conventions with :mod:`tactile.raycast`.

Unlike the rays, the planes also cut surfaces the pad cannot reach: faces
turned away from it and surfaces hidden below others (the far wall of a
thin part, the floor under an overhang).  That is where the two paths differ.
"""

from __future__ import annotations

import numpy as np

from meshsal.mesh import Mesh
from tactile.image import PLANES, finish_contours, plane_depths, pressure_image
from tactile.sensor import Poses, Sensor, check_points, sensor_poses

__all__ = ["imprint_exact", "imprints_exact", "imprints_exact_at"]


def _to_grid(xy: np.ndarray, sensor: Sensor) -> np.ndarray:
    """Pad-plane (x, y) in mm -> (column, row) sample coordinates (sample centres at integers)."""
    step = sensor.pitch_mm / sensor.supersample
    W, H = sensor.cols * sensor.supersample, sensor.rows * sensor.supersample
    return np.stack([xy[..., 0] / step + W / 2.0 - 0.5, -xy[..., 1] / step + H / 2.0 - 0.5], axis=-1)


def _zbuffer(uv: np.ndarray, z: np.ndarray, sensor: Sensor, top: float) -> np.ndarray:
    """Highest surface height at each sample, rasterizing triangles given as (m,3,2) grid coords
    and (m,3) heights; heights above ``top`` are out of reach.  -inf where no triangle covers."""
    W, H = sensor.cols * sensor.supersample, sensor.rows * sensor.supersample
    zbuf = np.full(H * W, -np.inf)
    lo = np.ceil(uv.min(axis=1) - 1e-9).astype(np.int64)
    hi = np.floor(uv.max(axis=1) + 1e-9).astype(np.int64)
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, [W - 1, H - 1])
    width = hi[:, 0] - lo[:, 0] + 1
    count = np.where((width > 0) & (hi[:, 1] >= lo[:, 1]), width * (hi[:, 1] - lo[:, 1] + 1), 0)
    total = int(count.sum())
    if total == 0:
        return zbuf.reshape(H, W)
    tri = np.repeat(np.arange(uv.shape[0]), count)
    local = np.arange(total) - np.repeat(np.cumsum(count) - count, count)
    col = lo[tri, 0] + local % width[tri]
    row = lo[tri, 1] + local // width[tri]
    a, b, c = uv[tri, 0], uv[tri, 1], uv[tri, 2]
    ab, ac = b - a, c - a
    qa = np.stack([col, row], axis=1) - a
    area = ab[:, 0] * ac[:, 1] - ab[:, 1] * ac[:, 0]
    beta = (qa[:, 0] * ac[:, 1] - qa[:, 1] * ac[:, 0]) / area
    gamma = (ab[:, 0] * qa[:, 1] - ab[:, 1] * qa[:, 0]) / area
    alpha = 1.0 - beta - gamma
    zt = z[tri]
    height = alpha * zt[:, 0] + beta * zt[:, 1] + gamma * zt[:, 2]
    eps = 1e-9
    keep = (alpha >= -eps) & (beta >= -eps) & (gamma >= -eps) & (height <= top)
    np.maximum.at(zbuf, row[keep] * W + col[keep], height[keep])
    return zbuf.reshape(H, W)


def _segments(xyz: np.ndarray, level: float) -> np.ndarray:
    """Exact intersection segments of triangles (m,3,3) with the plane z = level, as (s,2,2) xy."""
    above = xyz[:, :, 2] >= level
    crossing = above.any(axis=1) & ~above.all(axis=1)
    tri = xyz[crossing]
    if tri.shape[0] == 0:
        return np.zeros((0, 2, 2))
    a, b = tri, np.roll(tri, -1, axis=1)  # edges 01, 12, 20
    cut = (a[:, :, 2] >= level) != (b[:, :, 2] >= level)
    t = (level - a[:, :, 2]) / np.where(cut, b[:, :, 2] - a[:, :, 2], 1.0)
    points = a[:, :, :2] + t[:, :, None] * (b[:, :, :2] - a[:, :, :2])
    # Each crossing triangle has exactly two cut edges; nonzero lists them row by row.
    return points[cut].reshape(-1, 2, 2)


def _draw(segments_by_plane: list[np.ndarray], sensor: Sensor) -> np.ndarray:
    import cv2

    W, H = sensor.cols * sensor.supersample, sensor.rows * sensor.supersample
    lines = np.zeros((H, W), dtype=np.float32)
    shift = 4
    # Shallow planes first, so a deeper (brighter) contour wins where they overlap.
    for k, segments in enumerate(segments_by_plane, start=1):
        if segments.shape[0] == 0:
            continue
        pts = np.round(_to_grid(segments, sensor) * (1 << shift)).astype(np.int32)
        cv2.polylines(lines, list(pts), False, float(k) / PLANES, thickness=1, lineType=cv2.LINE_8, shift=shift)
    return lines


def _one(V: np.ndarray, F: np.ndarray, center, normal, up, right, sensor: Sensor) -> np.ndarray:
    R = np.stack([right, up, normal])
    X = (V - center) @ R.T
    T = X[F]
    half = np.array([sensor.width_mm, sensor.height_mm]) / 2.0
    over = ((T[:, :, :2].min(axis=1) <= half) & (T[:, :, :2].max(axis=1) >= -half)).all(axis=1)
    T = T[over]
    e1, e2 = T[:, 1, :2] - T[:, 0, :2], T[:, 2, :2] - T[:, 0, :2]
    front = (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]) > 0
    reach = sensor.reach_mm
    front &= T[:, :, 2].min(axis=1) <= reach
    zbuf = _zbuffer(_to_grid(T[front, :, :2], sensor), T[front, :, 2], sensor, reach)
    contact = zbuf.max()
    empty = np.zeros((sensor.rows, sensor.cols), dtype=np.float32)
    if not np.isfinite(contact):
        return empty
    if sensor.mode == "pressure":
        depth = contact - zbuf
        depth[depth > sensor.depth_mm] = np.inf
        return pressure_image(depth[None], sensor)[0]
    segments = [_segments(T, contact - d) for d in plane_depths(sensor)]
    return finish_contours(_draw(segments, sensor)[None], sensor)[0]


def imprints_exact_at(mesh: Mesh, poses: Poses, sensor: Sensor) -> np.ndarray:
    """Reference imprints of pads at given poses, (k, rows, cols) float32 in [0, 1]."""
    if mesh.n_faces == 0:
        raise ValueError(f"mesh {mesh.name!r} has no faces")
    out = np.zeros((len(poses), sensor.rows, sensor.cols), dtype=np.float32)
    for i in range(len(poses)):
        out[i] = _one(
            mesh.vertices, mesh.faces, poses.centers[i], poses.normals[i], poses.ups[i], poses.rights[i], sensor
        )
    return out


def imprints_exact(mesh: Mesh, positions, normals, sensor: Sensor | None = None, angles_deg=None) -> np.ndarray:
    """Reference imprints at k points: the pad poses of :func:`tactile.imprints`, sliced exactly.

    Same parameters and result as :func:`tactile.imprints`; it loops over the
    points in numpy and is meant for validation and benchmarks, not bulk use.
    """
    sensor = Sensor() if sensor is None else sensor
    P, N, A = check_points(positions, normals, angles_deg)
    if P.shape[0] == 0:
        return np.zeros((0, sensor.rows, sensor.cols), dtype=np.float32)
    return imprints_exact_at(mesh, sensor_poses(mesh, P, N, sensor, A), sensor)


def imprint_exact(mesh: Mesh, position, normal, sensor: Sensor | None = None, angle_deg: float = 0.0) -> np.ndarray:
    """The reference imprint at one point, (rows, cols) float32 in [0, 1]; see :func:`imprints_exact`.

    Examples
    --------
    >>> from meshsal.mesh import Mesh
    >>> plane = Mesh(vertices=[[-50, 0, -50], [50, 0, -50], [50, 0, 50], [-50, 0, 50]],
    ...              faces=[[0, 2, 1], [0, 3, 2]])
    >>> img = imprint_exact(plane, [0, 0, 0], [0, 1, 0], Sensor(mode="pressure"))
    >>> img.shape, float(img.min())
    ((16, 16), 1.0)
    """
    return imprints_exact(mesh, np.reshape(position, (1, 3)), np.reshape(normal, (1, 3)), sensor, [angle_deg])[0]
