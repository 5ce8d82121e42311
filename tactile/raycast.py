"""Fast imprints: one Embree scene per mesh, supersampled parallel rays for every pad.

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

The pads are split into chunks that the calling thread and worker threads
cast and turn into images concurrently (Embree releases the GIL).  Building the
scene (the BVH of the mesh) costs more than casting a few dozen imprints:
callers that take many imprints on one mesh build it once with
``meshsal.mesh.embree.embree_scene(mesh)`` and pass it as ``scene``.
"""

from __future__ import annotations

import itertools
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from meshsal.mesh import Mesh
from tactile.image import contour_lines, finish_contours, pressure_image
from tactile.sensor import Poses, Sensor, check_points, sample_grid, sensor_poses

__all__ = ["imprint", "imprints", "imprints_at", "cast_depths", "depth_images", "mesh_scene"]

# Rays per chunk: enough to amortize the per-call overhead, small enough that
# a chunk's arrays stay in cache and that chunks spread evenly over the cores.
_CHUNK_RAYS = 1 << 15


def _holds_mesh(scene, mesh: Mesh) -> bool:
    """Probe a few large faces of the mesh: rays from just above each must hit at that distance.

    A ray that meets another face first, nearer than its own (a fold or an
    overlap of the surface, which decimation can make), says nothing, and
    the next largest face is probed instead: the scene holds the mesh when
    every probe that says something hits its face's distance (at most three
    of them asked, all of the 16 sampled faces tried).
    """
    picked = np.linspace(0, mesh.n_faces - 1, min(mesh.n_faces, 16)).astype(np.int64)
    T = mesh.vertices[mesh.faces[picked]]
    cross = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
    double_area = np.linalg.norm(cross, axis=1)
    best = np.argsort(double_area, kind="stable")[::-1]
    best = best[double_area[best] > 0]
    if best.size == 0:
        return True  # only degenerate faces sampled: nothing to probe
    # Well below the face size, well above float32 resolution at the face's coordinates.
    height = 0.01 * np.sqrt(double_area[best]) + 1e-4 * np.abs(T[best]).max(axis=(1, 2))
    normal = cross[best] / double_area[best, None]
    origins = T[best].mean(axis=1) + height[:, None] * normal
    hit = scene.run(origins.astype(np.float32), (-normal).astype(np.float32), output=1)
    held = (hit["primID"] >= 0) & (np.abs(hit["tfar"] - height) <= 0.25 * height)
    covered = (hit["primID"] >= 0) & (hit["primID"] != picked[best]) & (hit["tfar"] < 0.75 * height)
    telling = np.flatnonzero(~covered)[:3]
    return bool(held[telling].all())


def mesh_scene(mesh: Mesh, scene=None):
    """The Embree scene to cast against: ``scene`` after a sanity check, or a new one.

    Parameters
    ----------
    mesh : Mesh
    scene : embreex scene, optional
        From ``meshsal.mesh.embree.embree_scene(mesh)`` on this very mesh (after
        any scaling).  A few rays checked against a few of the mesh's faces
        catch a scene of another mesh or of the mesh before scaling; a scene
        of a slightly edited copy of the mesh may pass unnoticed.

    Raises
    ------
    ValueError
        If the mesh has no faces, or the scene does not hold the mesh.

    Examples
    --------
    >>> from meshsal.mesh.embree import embree_scene
    >>> tri = Mesh(vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0]], faces=[[0, 1, 2]])
    >>> mesh_scene(tri, embree_scene(tri)) is not None
    True
    >>> mesh_scene(tri.replace(vertices=tri.vertices * 3), embree_scene(tri))  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: scene does not hold mesh '': build it with meshsal.mesh.embree.embree_scene(mesh) from the same mesh...
    """
    from meshsal.mesh.embree import embree_scene

    if mesh.n_faces == 0:
        raise ValueError(f"mesh {mesh.name!r} has no faces")
    if scene is None:
        return embree_scene(mesh)
    if not callable(getattr(scene, "run", None)):
        raise ValueError(
            f"scene must be an Embree scene from meshsal.mesh.embree.embree_scene, got {type(scene).__name__}"
        )
    if not _holds_mesh(scene, mesh):
        raise ValueError(
            f"scene does not hold mesh {mesh.name!r}: build it with "
            "meshsal.mesh.embree.embree_scene(mesh) from the same mesh, after any scaling"
        )
    return scene


def _cast_chunk(scene, poses: Poses, sensor: Sensor, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    k, H, W = len(poses), ys.size, xs.size
    f32 = np.float32
    normals = poses.normals.astype(f32)
    start = (poses.centers + sensor.reach_mm * poses.normals).astype(f32)
    # (start + y * up) + x * right in float32: each row's start and each column's offset first, then their
    # sums a component at a time, whose loops run along a row of samples instead of over three components.
    rows = start[:, :, None] + ys.astype(f32)[None, None, :] * poses.ups.astype(f32)[:, :, None]
    cols = xs.astype(f32)[None, None, :] * poses.rights.astype(f32)[:, :, None]
    origins = np.empty((k, H, W, 3), f32)
    for c in range(3):
        np.add(rows[:, c, :, None], cols[:, c, None, :], out=origins[..., c])
    # First contact is no farther than any front-facing hit of the pad's own
    # rays, and hits deeper than depth_mm beyond contact are dropped: so one
    # probe ray per pad bounds how far all its rays need to travel, which
    # spares Embree the rest of the mesh (about a third of the time), with
    # the same result.  The margin covers float32 rounding.
    probe = scene.run(np.ascontiguousarray(origins[:, H // 2, W // 2]), -normals, output=1)
    front = (probe["primID"] >= 0) & ((probe["Ng"] * normals).sum(axis=1) > 0)
    travel = np.where(front, (probe["tfar"] + sensor.depth_mm) * (1 + 1e-4) + 1e-4, np.inf).astype(f32)
    hit = scene.run(
        origins.reshape(-1, 3), np.repeat(-normals, H * W, axis=0), dists=np.repeat(travel, H * W), output=1
    )
    facing = np.einsum("kpj,kj->kp", hit["Ng"].reshape(k, H * W, 3), normals) > 0
    t = np.where((hit["primID"].reshape(k, H * W) >= 0) & facing, hit["tfar"].reshape(k, H * W), np.inf)
    contact = t.min(axis=1, keepdims=True)
    depth = t - np.where(np.isfinite(contact), contact, 0.0).astype(f32)
    return np.where(depth <= sensor.depth_mm, depth, np.inf).reshape(k, H, W)


def _map_chunks(fn, poses: Poses, rays_per_pose: int, workers: int | None) -> list[np.ndarray]:
    """``fn(chunk_of_poses)`` over consecutive chunks of poses, on ``workers`` threads, in order."""
    k = len(poses)
    workers = (os.cpu_count() or 1) if workers is None else max(1, int(workers))
    # At least one chunk per worker, so that a few imprints use every core too.
    per_chunk = max(1, min(_CHUNK_RAYS // rays_per_pose, -(-k // workers)))
    chunks = [
        Poses(
            poses.centers[a : a + per_chunk],
            poses.normals[a : a + per_chunk],
            poses.ups[a : a + per_chunk],
            poses.rights[a : a + per_chunk],
        )
        for a in range(0, k, per_chunk)
    ]
    if workers == 1 or len(chunks) == 1:
        return [fn(chunk) for chunk in chunks]
    results = [None] * len(chunks)
    order = itertools.count()  # next() on it is atomic: each chunk goes to one thread

    def work() -> None:
        while (i := next(order)) < len(chunks):
            results[i] = fn(chunks[i])

    # The calling thread takes chunks too, instead of waiting for the pool's
    # threads to be scheduled.
    helpers_count = min(workers, len(chunks)) - 1
    with ThreadPoolExecutor(max_workers=helpers_count) as pool:
        helpers = [pool.submit(work) for _ in range(helpers_count)]
        work()
        for helper in helpers:
            helper.result()
    return results


def cast_depths(mesh: Mesh, poses: Poses, sensor: Sensor, workers: int | None = None, scene=None) -> np.ndarray:
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
    scene : embreex scene, optional
        ``meshsal.mesh.embree.embree_scene(mesh)``: pass the same mesh's scene to
        amortize the BVH build over calls (see :func:`mesh_scene`); built
        here when omitted.

    Returns
    -------
    (k, rows * supersample, cols * supersample) float32
        ``inf`` where the pad meets nothing within ``depth_mm``.
    """
    xs, ys = sample_grid(sensor)
    if len(poses) == 0:
        return np.zeros((0, ys.size, xs.size), dtype=np.float32)
    scene = mesh_scene(mesh, scene)
    parts = _map_chunks(lambda chunk: _cast_chunk(scene, chunk, sensor, xs, ys), poses, xs.size * ys.size, workers)
    return np.concatenate(parts)


def depth_images(depth: np.ndarray, sensor: Sensor) -> np.ndarray:
    """Contour or pressure imprints (by ``sensor.mode``) from depth fields, (k, rows, cols) float32."""
    if sensor.mode == "pressure":
        return pressure_image(depth, sensor)
    return finish_contours(contour_lines(depth, sensor), sensor)


def imprints_at(mesh: Mesh, poses: Poses, sensor: Sensor, workers: int | None = None, scene=None) -> np.ndarray:
    """Imprints of pads at given poses (no plane fitting), (k, rows, cols) float32 in [0, 1].

    Each worker thread casts its chunk of pads and turns it into images, so
    the image stage runs concurrently as well.  ``scene``: as in
    :func:`cast_depths`.
    """
    xs, ys = sample_grid(sensor)
    if len(poses) == 0:
        return np.zeros((0, sensor.rows, sensor.cols), dtype=np.float32)
    scene = mesh_scene(mesh, scene)

    def run(chunk: Poses) -> np.ndarray:
        return depth_images(_cast_chunk(scene, chunk, sensor, xs, ys), sensor)

    return np.concatenate(_map_chunks(run, poses, xs.size * ys.size, workers))


def imprints(
    mesh: Mesh,
    positions,
    normals,
    sensor: Sensor | None = None,
    angles_deg=None,
    workers: int | None = None,
    scene=None,
) -> np.ndarray:
    """Simulated tactile imprints at k surface points (fast path).

    Fits the pad plane at each point (``sensor.plane``), then casts all the
    rays of all pads against one Embree scene, in chunks over threads.

    Parameters
    ----------
    mesh : Mesh
        In millimetres (see ``meshsal.scale_to_principal``): a mesh whose size
        disagrees with the pad's (one in metres, smaller than a taxel) gets a
        ``meshsal.mesh.transform.UnitsWarning`` naming both sizes.
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
    scene : embreex scene, optional
        ``meshsal.mesh.embree.embree_scene(mesh)``: pass the same mesh's scene to
        amortize the BVH build when taking imprints on one mesh over several
        calls (building it costs more than a few dozen imprints).  It is
        checked against the mesh with a few rays (:func:`mesh_scene`); built
        here when omitted.  The result does not depend on it.

    Returns
    -------
    (k, rows, cols) float32 in [0, 1]

    Examples
    --------
    >>> from meshsal.mesh.embree import embree_scene
    >>> from meshsal.mesh import Mesh
    >>> plane = Mesh(vertices=[[-50, 0, -50], [50, 0, -50], [50, 0, 50], [-50, 0, 50]],
    ...              faces=[[0, 2, 1], [0, 3, 2]])
    >>> img = imprints(plane, [[0, 0, 0]], [[0, 1, 0]], Sensor(mode="pressure"))
    >>> img.shape, bool(np.allclose(img, 1.0, atol=1e-6))   # a flat plane presses every taxel fully
    ((1, 16, 16), True)
    >>> scene = embree_scene(plane)  # once per mesh, then for every call
    >>> bool((imprints(plane, [[0, 0, 0]], [[0, 1, 0]], Sensor(mode="pressure"), scene=scene) == img).all())
    True
    """
    from meshsal.mesh.transform import check_pad_size

    sensor = Sensor() if sensor is None else sensor
    P, N, A = check_points(positions, normals, angles_deg)
    if P.shape[0] == 0:
        return np.zeros((0, sensor.rows, sensor.cols), dtype=np.float32)
    check_pad_size(mesh, sensor.width_mm, sensor.pitch_mm)
    return imprints_at(mesh, sensor_poses(mesh, P, N, sensor, A), sensor, workers, scene)


def imprint(
    mesh: Mesh, position, normal, sensor: Sensor | None = None, angle_deg: float = 0.0, scene=None
) -> np.ndarray:
    """The imprint at one point: :func:`imprints` for k = 1, (rows, cols) float32 in [0, 1].

    Pass ``scene=meshsal.mesh.embree.embree_scene(mesh)`` when taking imprints one
    at a time on the same mesh, to build its BVH once.
    """
    return imprints(mesh, np.reshape(position, (1, 3)), np.reshape(normal, (1, 3)), sensor, [angle_deg], scene=scene)[0]
