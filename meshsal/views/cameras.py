"""Cameras and what they see: the 72-view rig, the framing of a mesh, views and projection.

The view rig
------------
18 sets of 4 cameras.  Set ``i`` turns around an axis ``a_i``; its 4 cameras
sit on the great circle perpendicular to ``a_i``, 90 degrees apart, and look
at the centre.  The axes follow a golden-angle spiral over the upper
hemisphere with ``a_i . y`` falling evenly from 1 (set 0: the turntable
around +y, first camera on +z) to 0 (axes in the horizontal plane, whose
circles pass over both poles), so the 72 views together see the top, the
bottom and every side.  Each set starts ``5 * i`` degrees further round its
circle, so no two sets repeat a viewpoint.  A camera's ``up`` is its set's
axis.

Framing
-------
Orthographic (default): the frame is a square of half-width
``radius * (1 + margin)`` around the bounding sphere (centre of the bounding
box, radius to the farthest vertex), the eye ``2 * radius`` before the centre.
Perspective (the paper's camera): view angle ``fov_deg``, the eye at the
distance where the bounding sphere plus the margin just fills the view.
``depth`` is the distance from the eye along the viewing direction.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "N_SETS",
    "VIEWS_PER_SET",
    "Camera",
    "View",
    "view_rig",
    "eye_position",
    "image_coords",
    "pixel_size",
    "camera_rays",
    "project",
]

N_SETS = 18
VIEWS_PER_SET = 4
_GOLDEN_ANGLE = np.pi * (3.0 - np.sqrt(5.0))


@dataclass(frozen=True, eq=False)
class Camera:
    """Where a view is taken from; the framing comes from the mesh at render time.

    Attributes
    ----------
    direction : (3,) float64
        Unit vector from the camera towards the object centre.
    up : (3,) float64
        Unit vector perpendicular to ``direction``; image rows run against it.
    projection : {"orthographic", "perspective"}
    fov_deg : float
        Full view angle of the perspective camera.
    margin : float
        Fraction of the bounding-sphere radius left free around it.
    set_index, view_index : int
        Position in :func:`view_rig` (-1 for a free camera).
    """

    direction: np.ndarray
    up: np.ndarray
    projection: str = "orthographic"
    fov_deg: float = 30.0
    margin: float = 0.05
    set_index: int = -1
    view_index: int = -1

    def __post_init__(self):
        d = np.asarray(self.direction, dtype=np.float64).reshape(3)
        u = np.asarray(self.up, dtype=np.float64).reshape(3)
        if np.linalg.norm(d) == 0:
            raise ValueError("camera direction must be a non-zero vector")
        d = d / np.linalg.norm(d)
        u = u - d * (u @ d)
        if np.linalg.norm(u) < 1e-9:
            raise ValueError("camera up must not be parallel to its direction")
        object.__setattr__(self, "direction", d)
        object.__setattr__(self, "up", u / np.linalg.norm(u))
        if self.projection not in ("orthographic", "perspective"):
            raise ValueError(f"projection must be 'orthographic' or 'perspective', got {self.projection!r}")
        if not 0 < self.fov_deg < 180:
            raise ValueError(f"fov_deg must lie in (0, 180), got {self.fov_deg}")
        if self.margin < 0:
            raise ValueError(f"margin must be >= 0, got {self.margin}")

    @property
    def right(self) -> np.ndarray:
        """Unit vector along image columns: ``cross(direction, up)``."""
        (dx, dy, dz), (ux, uy, uz) = self.direction.tolist(), self.up.tolist()
        # Spelled out: np.cross costs ten times more on 3-vectors, and every view asks several times.
        return np.array([dy * uz - dz * uy, dz * ux - dx * uz, dx * uy - dy * ux])


@dataclass(frozen=True, eq=False)
class View:
    """One rendered image with its exact pixel-to-surface map.

    Attributes
    ----------
    rgb : (H, W, 3) float32 in [0, 1]
    depth : (H, W) float32, distance from the eye along the view direction; inf on background
    face_id : (H, W) int32, the face seen at each pixel; -1 on background
    bary : (H, W, 3) float32, barycentric weights of that face's three vertices
    faces : (m, 3) int32, the rendered mesh's faces (shared, not copied)
    camera : Camera
    center : (3,) float64, centre of the framed bounding sphere
    radius : float, its radius
    eye : (3,) float64, the eye (perspective) or the centre of the image plane (orthographic)
    pixel_size : float, world units per pixel (orthographic; at the centre's depth for perspective)

    ``mask`` (pixels that see the object) and ``vertex_ids`` (the corners of
    the face each pixel sees) are derived from ``face_id`` on access.
    """

    rgb: np.ndarray
    depth: np.ndarray
    face_id: np.ndarray
    bary: np.ndarray
    faces: np.ndarray
    camera: Camera
    center: np.ndarray
    radius: float
    eye: np.ndarray
    pixel_size: float

    @property
    def size(self) -> int:
        return int(self.rgb.shape[0])

    @property
    def mask(self) -> np.ndarray:
        """(H, W) bool, the pixels that see the object."""
        return self.face_id >= 0

    @property
    def vertex_ids(self) -> np.ndarray:
        """(H, W, 3) int32, the three vertices (the face's corners) each pixel sees; -1 on background."""
        # By flat pixel index: half the time of indexing by the mask.
        face_id = self.face_id.ravel()
        seen = np.flatnonzero(face_id >= 0)
        out = np.full((face_id.size, 3), -1, np.int32)
        out[seen] = np.take(self.faces, face_id[seen], axis=0)
        return out.reshape(self.face_id.shape + (3,))


def view_rig() -> list[list[Camera]]:
    """The paper's 72 viewpoints: 18 sets of 4 cameras 90 degrees apart (see the module docstring).

    Returns
    -------
    list of 18 lists of 4 Camera

    Examples
    --------
    >>> rig = view_rig()
    >>> len(rig), len(rig[0])
    (18, 4)
    >>> bool(np.allclose(rig[0][0].direction, [0, 0, -1]))  # the first camera sits on +z
    True
    """
    rig = []
    for i in range(N_SETS):
        height = 1.0 - i / (N_SETS - 1)
        ring = np.sqrt(1.0 - height**2)
        azimuth = i * _GOLDEN_ANGLE
        axis = np.array([ring * np.sin(azimuth), height, ring * np.cos(azimuth)])
        reference = np.array([0.0, 0.0, 1.0]) if abs(axis[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
        e1 = reference - axis * (reference @ axis)
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(axis, e1)
        cameras = []
        for k in range(VIEWS_PER_SET):
            phi = np.deg2rad(5.0 * i + 90.0 * k)
            position = np.cos(phi) * e1 + np.sin(phi) * e2
            cameras.append(Camera(direction=-position, up=axis, set_index=i, view_index=VIEWS_PER_SET * i + k))
        rig.append(cameras)
    return rig


def eye_position(camera: Camera, center: np.ndarray, radius: float) -> np.ndarray:
    """The eye (perspective) or the centre of the image plane (orthographic)."""
    half = radius * (1.0 + camera.margin)
    if camera.projection == "orthographic":
        return center - camera.direction * 2.0 * radius
    return center - camera.direction * half / np.sin(np.deg2rad(camera.fov_deg) / 2.0)


def image_coords(camera: Camera, center: np.ndarray, radius: float, size: int, points: np.ndarray) -> np.ndarray:
    """Image coordinates (row, col), (k, 2) float64, of world points; pixel centres at half-integers."""
    P = np.atleast_2d(np.asarray(points, dtype=np.float64))
    x, y = ((P - center) @ np.stack([camera.right, camera.up], axis=1)).T
    if camera.projection == "perspective":
        z = (P - eye_position(camera, center, radius)) @ camera.direction
        scale = z * np.tan(np.deg2rad(camera.fov_deg) / 2.0)
    else:
        scale = radius * (1.0 + camera.margin)
    return np.stack([(1.0 - y / scale) * size / 2.0, (x / scale + 1.0) * size / 2.0], axis=1)


def camera_rays(camera: Camera, center: np.ndarray, radius: float, xy1: np.ndarray):
    """Rays through image-plane points, ``xy1`` (k, 3) float32 rows (x, y, 1) from :func:`_pixel_grid`.

    Returns ``origins`` (k, 3) float32, ``directions`` (k, 3) float32 or one
    shared (1, 3) row for the orthographic camera, and the factor turning a
    hit distance into depth along the view direction ((k,), or None when it
    is 1).
    """
    # One matrix takes (x, y, 1) to the ray's origin (orthographic) or direction (perspective).
    to_world = np.empty((3, 3), np.float32)
    to_world[0], to_world[1] = camera.right, camera.up
    eye = eye_position(camera, center, radius).astype(np.float32)
    if camera.projection == "orthographic":
        to_world[:2] *= radius * (1.0 + camera.margin)
        to_world[2] = eye
        return xy1 @ to_world, camera.direction.astype(np.float32)[None], None
    to_world[:2] *= np.tan(np.deg2rad(camera.fov_deg) / 2.0)
    to_world[2] = camera.direction
    directions = xy1 @ to_world
    depth_factor = 1.0 / np.linalg.norm(directions, axis=1)
    directions *= depth_factor[:, None]
    return np.broadcast_to(eye, directions.shape).copy(), directions, depth_factor


def pixel_size(camera: Camera, radius: float, size: int) -> float:
    """World units per pixel (at the centre's depth for a perspective camera)."""
    half = radius * (1.0 + camera.margin)
    if camera.projection == "orthographic":
        return 2.0 * half / size
    half_angle = np.deg2rad(camera.fov_deg) / 2.0
    return 2.0 * half / np.sin(half_angle) * np.tan(half_angle) / size


def project(view: View, points: np.ndarray) -> np.ndarray:
    """Image coordinates (row, col), (k, 2) float64, of world points; pixel centres at half-integers.

    Pixel ``(i, j)`` covers ``[i, i+1) x [j, j+1)``, so a point seen at the
    centre of pixel (i, j) projects to (i + 0.5, j + 0.5).
    """
    return image_coords(view.camera, view.center, view.radius, view.size, points)
