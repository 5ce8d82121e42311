"""Fast imprints: one Embree scene per mesh, one supersampled ray batch for all points.

Each pad casts a grid of ``(rows * supersample) x (cols * supersample)``
parallel rays along ``-normal`` from a plane ``sensor.reach_mm`` above its
point.  The hit distances are the height field of the surface under the
pad; the smallest is the first contact, and depths are measured from it (the
pad is pressed ``depth_mm`` beyond first contact).  Like a robot's guarded
move, the pad travels along ``-normal`` until it meets the surface, so a
point slightly off the surface (a jittered placement) still gives the
imprint of the surface under it.  Hits on faces facing away
from the pad and hits deeper than the deepest plane contribute nothing.
:mod:`tactile.image` turns the depths into contour or pressure images.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from meshsal.mesh import Mesh
from tactile.image import contour_lines, finish_contours, pressure_image
from tactile.sensor import Poses, Sensor, check_points, sample_grid, sensor_poses

__all__ = ["imprint", "imprints", "imprints_at", "cast_depths", "depth_images"]

# Poses per ray chunk: about 10^5 rays at the default sampling, enough to
# keep Embree busy and few enough chunks to spread over the cores.
_CHUNK_RAYS = 1 << 17


def _scene(mesh: Mesh):
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    if mesh.n_faces == 0:
        raise ValueError(f"mesh {mesh.name!r} has no faces")
    scene = rtcs.EmbreeScene()
    TriangleMesh(scene, np.ascontiguousarray(mesh.vertices, dtype=np.float32),
                 np.ascontiguousarray(mesh.faces, dtype=np.int32))
    # The first query commits (builds) the scene; do it before threads share it.
    scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), output=0)
    return scene


def _cast_chunk(scene, poses: Poses, sensor: Sensor, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    k, H, W = len(poses), ys.size, xs.size
    reach = sensor.reach_mm
    start = poses.centers + reach * poses.normals
    origins = (start[:, None, None, :]
               + ys[None, :, None, None] * poses.ups[:, None, None, :]
               + xs[None, None, :, None] * poses.rights[:, None, None, :])
    origins = origins.reshape(-1, 3).astype(np.float32)
    normals = np.repeat(poses.normals.astype(np.float32), H * W, axis=0)
    hit = scene.run(origins, -normals, output=1)
    t = hit["tfar"].astype(np.float64)
    front = (hit["primID"] >= 0) & ((hit["Ng"] * normals).sum(axis=1) > 0)
    t = np.where(front, t, np.inf).reshape(k, H, W)
    contact = t.min(axis=(1, 2), keepdims=True)
    with np.errstate(invalid="ignore"):
        depth = t - contact
    depth[~np.isfinite(depth) | (depth > sensor.depth_mm)] = np.inf
    return depth


def cast_depths(mesh: Mesh, poses: Poses, sensor: Sensor, workers: int | None = None) -> np.ndarray:
    """Depth below first contact on each pad's supersampled grid, by ray casting.

    Parameters
    ----------
    mesh : Mesh
        In millimetres.
    poses : Poses
        k pads (see :func:`tactile.sensor.sensor_poses`).
    sensor : Sensor
    workers : int, optional
        Threads casting ray chunks concurrently (Embree releases the GIL);
        defaults to the number of CPUs.

    Returns
    -------
    (k, rows * supersample, cols * supersample) float64
        ``inf`` where the pad meets nothing within ``depth_mm``.
    """
    xs, ys = sample_grid(sensor)
    k = len(poses)
    if k == 0:
        return np.zeros((0, ys.size, xs.size))
    scene = _scene(mesh)
    per_chunk = max(1, _CHUNK_RAYS // (xs.size * ys.size))
    chunks = [slice(a, min(a + per_chunk, k)) for a in range(0, k, per_chunk)]

    def run(sl: slice) -> np.ndarray:
        part = Poses(poses.centers[sl], poses.normals[sl], poses.ups[sl], poses.rights[sl])
        return _cast_chunk(scene, part, sensor, xs, ys)

    workers = (os.cpu_count() or 1) if workers is None else int(workers)
    if workers <= 1 or len(chunks) == 1:
        return np.concatenate([run(sl) for sl in chunks])
    with ThreadPoolExecutor(max_workers=workers) as pool:
        return np.concatenate(list(pool.map(run, chunks)))


def depth_images(depth: np.ndarray, sensor: Sensor) -> np.ndarray:
    """Contour or pressure imprints (by ``sensor.mode``) from depth fields, (k, rows, cols) float32."""
    if sensor.mode == "pressure":
        return pressure_image(depth, sensor)
    return finish_contours(contour_lines(depth, sensor), sensor)


def imprints_at(mesh: Mesh, poses: Poses, sensor: Sensor, workers: int | None = None) -> np.ndarray:
    """Imprints of pads at given poses (no plane fitting), (k, rows, cols) float32 in [0, 1]."""
    return depth_images(cast_depths(mesh, poses, sensor, workers), sensor)


def imprints(mesh: Mesh, positions, normals, sensor: Sensor | None = None, angles_deg=None,
             workers: int | None = None) -> np.ndarray:
    """Simulated tactile imprints at k surface points (fast path).

    Fits the pad plane at each point (``sensor.plane``), then casts all the
    rays of all pads in one batch against one Embree scene.

    Parameters
    ----------
    mesh : Mesh
        In millimetres (see ``meshsal.scale_to``).
    positions : (k, 3) float64
        Touched points.
    normals : (k, 3) float64
        Outward normals there (need not be unit); they orient the fitted plane.
    sensor : Sensor, optional
        Defaults to ``Sensor()``.
    angles_deg : (k,) float64, optional
        In-plane pad rotations (see :func:`tactile.sensor.tangent_frames`).
    workers : int, optional
        Ray-casting threads; defaults to the number of CPUs.

    Returns
    -------
    (k, rows, cols) float32 in [0, 1]

    Examples
    --------
    >>> from meshsal.mesh import Mesh
    >>> plane = Mesh(vertices=[[-50, 0, -50], [50, 0, -50], [50, 0, 50], [-50, 0, 50]],
    ...              faces=[[0, 2, 1], [0, 3, 2]])
    >>> img = imprints(plane, [[0, 0, 0]], [[0, 1, 0]], Sensor(mode="pressure"))
    >>> img.shape, float(img.min()), float(img.max())
    ((1, 16, 16), 1.0, 1.0)
    """
    sensor = Sensor() if sensor is None else sensor
    P, N, A = check_points(positions, normals, angles_deg)
    if P.shape[0] == 0:
        return np.zeros((0, sensor.rows, sensor.cols), dtype=np.float32)
    return imprints_at(mesh, sensor_poses(mesh, P, N, sensor, A), sensor, workers)


def imprint(mesh: Mesh, position, normal, sensor: Sensor | None = None, angle_deg: float = 0.0) -> np.ndarray:
    """The imprint at one point: :func:`imprints` for k = 1, (rows, cols) float32 in [0, 1]."""
    return imprints(mesh, np.reshape(position, (1, 3)), np.reshape(normal, (1, 3)), sensor, [angle_deg])[0]
