"""CPU ray-cast renderer on Embree: views with exact pixel-to-surface maps.

Every pixel of a :class:`~meshsal.views.cameras.View` knows the face it sees
(``face_id``) and where on that face (``bary``), so later stages map any
pixel back onto the surface exactly, with no approximate geometry.  The
cameras, the 72-view rig and their framing are in :mod:`meshsal.views.cameras`.

Casting and shading
-------------------
One ray per pixel centre, answered as Embree's robust traversal answers it
(no ray slips between two triangles sharing an edge) by a
:class:`~meshsal.views.tracer.Tracer`: on closed meshes Embree's faster traversal
traces every ray and the few that slip are traced again robustly.  Rays are
cast only inside the image of the mesh's convex hull, which holds its
silhouette under both projections, and in Z-order, which keeps neighbouring
rays together.  Shading is Lambert from a headlight plus ambient, evaluated
at the vertices and interpolated (Gouraud), times the texture, the
interpolated vertex colours or light gray.
"""

from __future__ import annotations

import os
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass

import cv2
import numpy as np

from meshsal.mesh import Mesh, bounding_sphere, vertex_normals
from meshsal.views.cameras import Camera, View, camera_rays, eye_position, image_coords, pixel_size
from meshsal.views.tracer import Tracer, tracer

__all__ = ["render", "render_views", "surface_points"]

AMBIENT = 0.3
DEFAULT_GRAY = 0.8


def _hull_points(vertices: np.ndarray) -> np.ndarray:
    """Points whose convex hull holds the mesh, (h, 3) float64: its hull's vertices, or its box's corners."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        return vertices[ConvexHull(vertices).vertices]
    except (QhullError, ValueError):  # flat or tiny meshes have no 3-D hull
        lo, hi = vertices.min(axis=0), vertices.max(axis=0)
        return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


@dataclass(frozen=True, eq=False)
class _PixelGrid:
    """The pixels of a square image in Z-order (Morton order).

    Embree traces neighbouring rays faster one after another (their BVH
    nodes are still in cache), and a Z-order keeps more neighbours together
    than rows do.

    Attributes
    ----------
    size : int
    pixels : (size*size,) int64, flat (row-major) indices in Z-order
    xy1 : (size*size, 3) float32, their centres on the image plane in [-1, 1] (x right, y up) and a 1
    """

    size: int
    pixels: np.ndarray
    xy1: np.ndarray


def _pixel_grid(size: int) -> _PixelGrid:
    side = 1 << int(size - 1).bit_length()
    key = np.arange(side * side)
    rows, cols = np.zeros_like(key), np.zeros_like(key)
    for bit in range(int(side - 1).bit_length()):
        cols |= ((key >> (2 * bit)) & 1) << bit
        rows |= ((key >> (2 * bit + 1)) & 1) << bit
    inside = (rows < size) & (cols < size)
    rows, cols = rows[inside], cols[inside]
    offsets = ((np.arange(size) + 0.5) / size * 2.0 - 1.0).astype(np.float32)
    xy1 = np.stack([offsets[cols], -offsets[rows], np.ones(rows.size, np.float32)], axis=1)
    return _PixelGrid(size=size, pixels=rows * size + cols, xy1=xy1)


def _candidates(camera: Camera, center: np.ndarray, radius: float, grid: _PixelGrid, hull: np.ndarray) -> np.ndarray:
    """Positions in ``grid`` of the pixels whose ray can meet the mesh, (k,) int64, in Z-order.

    Both projections keep convexity, so the mesh's silhouette lies inside the
    image of its convex hull: on a bust only a third of the frame's rays are
    cast.  The filled polygon grows by a pixel to be safe at its rim.
    """
    rc = image_coords(camera, center, radius, grid.size, hull)
    # OpenCV puts pixel centres at integers; 4 fractional bits keep the vertices' sub-pixel positions.
    xy = np.round(rc[:, ::-1] * 16.0 - 8.0).astype(np.int32)
    mask = np.zeros((grid.size, grid.size), np.uint8)
    cv2.fillConvexPoly(mask, cv2.convexHull(xy), 1, lineType=cv2.LINE_8, shift=4)
    inside = cv2.dilate(mask, np.ones((3, 3), np.uint8)).reshape(-1).view(bool)
    return np.flatnonzero(np.take(inside, grid.pixels))


def _sample_texture(texture: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear lookup of (k, 2) uv (repeating, origin bottom-left) in an (H, W, 3) uint8 texture.

    Returns (k, 3) float32 in [0, 1].
    """
    H, W = texture.shape[:2]
    k = len(uv)
    if k == 0:
        return np.zeros((0, texture.shape[2]), np.float32)
    # cv2.remap takes maps of fewer than 32767 rows: lay the k lookups out in rows of 1024.
    rows = -(-k // 1024)
    maps = np.zeros((2, rows * 1024), np.float32)
    maps[0, :k] = np.mod(uv[:, 0], 1.0) * W - 0.5
    maps[1, :k] = (1.0 - np.mod(uv[:, 1], 1.0)) * H - 0.5
    out = cv2.remap(
        texture, maps[0].reshape(rows, 1024), maps[1].reshape(rows, 1024), cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP
    )
    return out.reshape(-1, texture.shape[2])[:k].astype(np.float32) / np.float32(255.0)


@dataclass(frozen=True, eq=False)
class _Stage:
    """What every view of one mesh shares: its tracer, normals, framing sphere, hull and pixel grid.

    ``normals`` is the future (n, 3) float32 vertex normals: the first views
    trace while a worker computes them.
    """

    mesh: Mesh
    tracer: Tracer
    normals: Future
    center: np.ndarray
    radius: float
    hull: np.ndarray
    grid: _PixelGrid


def _vertex_light(stage: _Stage, camera: Camera, eye: np.ndarray) -> np.ndarray:
    """Lambert light of a headlight plus ambient at every vertex, (n,) float32."""
    if camera.projection == "orthographic":
        cosine = stage.normals.result() @ -camera.direction.astype(np.float32)
    else:
        towards_eye = (eye - stage.mesh.vertices).astype(np.float32)
        towards_eye /= np.maximum(np.linalg.norm(towards_eye, axis=1, keepdims=True), 1e-12)
        cosine = np.einsum("nd,nd->n", stage.normals.result(), towards_eye)
    # Open meshes show their inside: light both sides rather than render them black.
    light = np.abs(cosine, out=cosine)
    light *= np.float32(1.0 - AMBIENT)
    light += np.float32(AMBIENT)
    return light


def _interpolate(corner_values: np.ndarray, w: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Barycentric interpolation of values at the three corners, (k, 3, ...) -> (k, ...)."""
    w, u, v = (b.reshape(b.shape + (1,) * (corner_values.ndim - 2)) for b in (w, u, v))
    out = corner_values[:, 0] * w
    out += corner_values[:, 1] * u
    out += corner_values[:, 2] * v
    return out


def _shade(
    stage: _Stage,
    camera: Camera,
    eye: np.ndarray,
    faces: np.ndarray,
    corners: np.ndarray,
    w: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
) -> np.ndarray:
    """Colours of the hits at barycentrics (w, u, v), (k, 3) float32, or (k,) for a gray surface.

    Gouraud shading: the vertex light interpolated, times the surface colour.
    """
    mesh = stage.mesh
    light = _vertex_light(stage, camera, eye)
    if mesh.texture is not None and mesh.uv is not None:
        albedo = _sample_texture(mesh.texture, _interpolate(np.take(mesh.uv, faces, axis=0), w, u, v))
        rgb = albedo * _interpolate(np.take(light, corners), w, u, v)[:, None]
    elif mesh.vertex_colors is not None:
        rgb = _interpolate(np.take(mesh.vertex_colors * light[:, None], corners, axis=0), w, u, v)
    else:
        rgb = _interpolate(np.take(light, corners), w, u, v) * np.float32(DEFAULT_GRAY)
    return np.clip(rgb, 0.0, 1.0, out=rgb).astype(np.float32, copy=False)


@dataclass(frozen=True, eq=False)
class _Images:
    """The output images of all views, one block per kind: each view's arrays are slices of them.

    Fresh memory costs a page fault per page touched, and large blocks get
    huge pages: scattering one kind of output of 72 views takes 18 ms into one
    block against 31 ms into 72 fresh arrays.
    """

    rgb: np.ndarray  # (views, size*size, 3) float32, zeros
    bary: np.ndarray  # (views, size*size, 3) float32, zeros
    depth: np.ndarray  # (views, size*size) float32, uninitialized
    face_id: np.ndarray  # (views, size*size) int32, uninitialized

    @classmethod
    def allocate(cls, views: int, size: int) -> _Images:
        n = size * size
        return cls(
            rgb=np.zeros((views, n, 3), np.float32),
            bary=np.zeros((views, n, 3), np.float32),
            depth=np.empty((views, n), np.float32),
            face_id=np.empty((views, n), np.int32),
        )


def _scatter(out: np.ndarray, index: np.ndarray, columns) -> None:
    """Write the three (k,) ``columns`` into rows ``index`` of the (n, 3) ``out``."""
    # Column by column: NumPy scatters whole rows about twice as slowly.
    for j, column in enumerate(columns):
        out[index, j] = column


def _render_one(stage: _Stage, camera: Camera, images: _Images, k: int) -> View:
    grid = stage.grid
    cast = _candidates(camera, stage.center, stage.radius, grid, stage.hull)
    pixels = grid.pixels[cast]
    origins, directions, depth_factor = camera_rays(camera, stage.center, stage.radius, np.take(grid.xy1, cast, axis=0))
    # Misses keep tfar = inf, which is the background's depth.
    hit = stage.tracer.first_hits(origins, directions)
    depth, face_id = images.depth[k], images.face_id[k]
    depth.fill(np.inf)
    depth[pixels] = hit["tfar"] if depth_factor is None else hit["tfar"] * depth_factor
    face_id.fill(-1)
    face_id[pixels] = hit["primID"]
    hits = hit["primID"] >= 0
    seen = pixels[hits]
    face = hit["primID"][hits]
    u, v = hit["u"][hits], hit["v"][hits]
    w = 1.0 - u - v
    eye = eye_position(camera, stage.center, stage.radius)
    rgb = _shade(stage, camera, eye, face, np.take(stage.mesh.faces, face, axis=0), w, u, v)
    if rgb.ndim == 1:  # gray: scatter one channel, copy it densely to the others
        images.rgb[k][seen, 0] = rgb
        images.rgb[k][:, 1] = images.rgb[k][:, 2] = images.rgb[k][:, 0]
    else:
        _scatter(images.rgb[k], seen, rgb.T)
    _scatter(images.bary[k], seen, (w, u, v))
    shape = (grid.size, grid.size)
    return View(
        rgb=images.rgb[k].reshape(shape + (3,)),
        depth=depth.reshape(shape),
        face_id=face_id.reshape(shape),
        bary=images.bary[k].reshape(shape + (3,)),
        faces=stage.mesh.faces,
        camera=camera,
        center=stage.center,
        radius=stage.radius,
        eye=eye,
        pixel_size=pixel_size(camera, stage.radius, grid.size),
    )


def _check_size(size) -> int:
    if int(size) != size or size < 1:
        raise ValueError(f"image size must be a positive integer, got {size!r}")
    return int(size)


def render(mesh: Mesh, camera: Camera, size: int = 256) -> View:
    """Render one square view of ``size`` x ``size`` pixels.

    Colour comes from the texture (bilinear at the hit's UV), else the
    interpolated vertex colours, else light gray; Lambert shading from a
    headlight plus ambient at the vertices, interpolated (Gouraud).

    Examples
    --------
    >>> from meshsal.mesh import Mesh
    >>> tri = Mesh(vertices=[[-1, -1, 0], [1, -1, 0], [0, 1, 0]], faces=[[0, 1, 2]])
    >>> from meshsal.views.cameras import view_rig
    >>> view = render(tri, view_rig()[0][0], size=32)
    >>> view.rgb.shape, bool(view.mask[16, 16])
    ((32, 32, 3), True)
    """
    return render_views(mesh, [camera], size=size, threads=1)[0]


def render_views(mesh: Mesh, cameras, size: int = 256, threads: int | None = None, scene=None) -> list[View]:
    """Render many views of one mesh, sharing one Embree scene across threads.

    Parameters
    ----------
    mesh : Mesh
    cameras : sequence of Camera (e.g. ``[c for s in view_rig() for c in s]``)
    size : int
    threads : int, optional
        Worker threads (default: the CPU count); Embree releases the GIL.
    scene : optional
        What to cast the rays against, reused across calls:
        ``meshsal.views.tracer.tracer(mesh)`` of this very mesh, which also keeps
        what it checked of the mesh; or an Embree scene of it,
        ``meshsal.mesh.embree.embree_scene(mesh, robust=False)`` (building one
        takes about 15 ms per 100k faces).  A robust scene
        (``embree_scene(mesh)``) answers every ray itself: slower, and the
        answer to have on a closed mesh that passes through itself (see
        :mod:`meshsal.views.tracer`).

    Raises
    ------
    ValueError
        If the mesh has no faces, or ``scene`` is a tracer of another mesh.

    Returns
    -------
    list of View, in the order of ``cameras``
    """
    size = _check_size(size)
    cameras = list(cameras)
    if mesh.n_faces == 0:
        raise ValueError(f"cannot render {mesh.name or 'mesh'}: it has no faces")
    workers = threads or os.cpu_count() or 1
    with ThreadPoolExecutor(max_workers=workers) as pool:
        # Qhull and most of NumPy release the GIL: the hull, the pixel grid, the
        # normals, the mesh's orientation and the scene build run side by side.
        hull = pool.submit(_hull_points, mesh.vertices)
        normals = pool.submit(lambda: vertex_normals(mesh.vertices, mesh.faces).astype(np.float32))
        grid = pool.submit(_pixel_grid, size)
        if isinstance(scene, Tracer):
            if scene.mesh is not mesh:
                raise ValueError(
                    f"scene is a tracer of mesh {scene.mesh.name!r}, not of the mesh to render "
                    f"{mesh.name!r}: build it with meshsal.views.tracer.tracer(mesh)"
                )
            trace = scene
        else:
            trace = tracer(mesh, scene, executor=pool)
        center, radius = bounding_sphere(mesh.vertices)
        stage = _Stage(
            mesh=mesh,
            tracer=trace,
            normals=normals,
            center=center,
            radius=max(radius, 1e-12),
            hull=hull.result(),
            grid=grid.result(),
        )
        images = _Images.allocate(len(cameras), size)
        if workers == 1:
            return [_render_one(stage, c, images, k) for k, c in enumerate(cameras)]
        return list(pool.map(lambda k: _render_one(stage, cameras[k], images, k), range(len(cameras))))


def surface_points(mesh: Mesh, view: View, rows, cols) -> np.ndarray:
    """The exact surface points seen at pixels ``(rows, cols)``, (k, 3) float64.

    Raises ValueError if a pixel shows background.
    """
    rows = np.atleast_1d(np.asarray(rows, dtype=np.int64))
    cols = np.atleast_1d(np.asarray(cols, dtype=np.int64))
    faces = view.face_id[rows, cols]
    if np.any(faces < 0):
        raise ValueError("some pixels show the background, not the surface")
    corners = mesh.vertices[mesh.faces[faces]]
    return np.einsum("kc,kcd->kd", view.bary[rows, cols].astype(np.float64), corners)
