"""The paper's analytic projection of pixels onto the mesh, kept beside the exact one for comparison.

The renderer knows for every pixel the face and the barycentric point it
shows (:func:`meshsal.views.render.surface_points`), which is what the
interest points use.  The paper instead places each pixel on the image plane
from the camera's spherical coordinates and casts a ray from there:
:func:`project_pixel_paper` does that, so the two can be compared.
"""

from __future__ import annotations

import numpy as np

from meshsal.mesh import Mesh
from meshsal.mesh.embree import embree_scene

__all__ = ["project_pixel_paper"]


def _spherical(view):
    """The paper's camera parameters: azimuth, elevation (y up), distance, roll, pixels per unit."""
    cam = view.camera
    e = view.eye - view.center
    distance = float(np.linalg.norm(e))
    e = e / distance
    elevation = float(np.arcsin(np.clip(e[1], -1.0, 1.0)))
    azimuth = float(np.arctan2(e[0], e[2]))
    forward = -e
    up_s = np.array([-np.sin(elevation) * np.sin(azimuth), np.cos(elevation), -np.sin(elevation) * np.cos(azimuth)])
    roll = float(np.arctan2(np.cross(up_s, cam.up) @ forward, up_s @ cam.up))
    return azimuth, elevation, distance, roll, 1.0 / view.pixel_size


def project_pixel_paper(view, rows, cols, mesh: Mesh) -> np.ndarray:
    """The paper's analytic 2-D to 3-D projection of pixels onto the mesh.

    From the view's camera in spherical coordinates about the framed centre
    (azimuth about +y, elevation, distance, plus the roll of the camera's up
    vector about its axis) and the image scale in pixels per world unit, the
    pixel centre is placed on the image plane and a ray perpendicular to that
    plane (orthographic views; for perspective views, the ray from the eye
    through that point) is intersected with the mesh by Embree.  The exact
    alternative used by the pipeline is :func:`meshsal.views.render.surface_points`.

    Parameters
    ----------
    view : View
    rows, cols : int or (k,) int
        Pixel indices (row 0 at the top).
    mesh : Mesh
        The rendered mesh.

    Returns
    -------
    (k, 3) float64 surface points; NaN rows where the ray misses the mesh.
    """
    rows = np.atleast_1d(np.asarray(rows, dtype=np.float64))
    cols = np.atleast_1d(np.asarray(cols, dtype=np.float64))
    azimuth, elevation, distance, roll, ppu = _spherical(view)
    e = np.array([np.cos(elevation) * np.sin(azimuth), np.sin(elevation), np.cos(elevation) * np.cos(azimuth)])
    forward = -e
    up_s = np.array([-np.sin(elevation) * np.sin(azimuth), np.cos(elevation), -np.sin(elevation) * np.cos(azimuth)])
    up = np.cos(roll) * up_s + np.sin(roll) * np.cross(forward, up_s)
    right = np.cross(forward, up)
    eye = view.center + distance * e
    half = view.size / 2.0
    x = (cols + 0.5 - half) / ppu
    y = (half - rows - 0.5) / ppu
    if view.camera.projection == "orthographic":
        origins = eye + x[:, None] * right + y[:, None] * up
        directions = np.broadcast_to(forward, origins.shape)
    else:
        # The image plane through the centre, as the pixel size is measured there.
        on_plane = view.center + x[:, None] * right + y[:, None] * up
        origins = np.broadcast_to(eye, on_plane.shape)
        directions = on_plane - eye
        directions = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    hit = embree_scene(mesh).run(
        np.ascontiguousarray(origins, np.float32), np.ascontiguousarray(directions, np.float32), output=1
    )
    out = np.full((rows.size, 3), np.nan)
    ok = hit["primID"] >= 0
    f = hit["primID"][ok]
    u, v = hit["u"][ok].astype(np.float64), hit["v"][ok].astype(np.float64)
    corners = mesh.vertices[mesh.faces[f]]
    out[ok] = (1 - u - v)[:, None] * corners[:, 0] + u[:, None] * corners[:, 1] + v[:, None] * corners[:, 2]
    return out
