"""Pictures of saliency and interest points, drawn with OpenCV; all images are RGB uint8."""

from __future__ import annotations

import numpy as np

__all__ = ["colormap", "saliency_overlay", "draw_points", "visible_points", "tile", "views_picture", "contact_sheet"]


def colormap(values: np.ndarray) -> np.ndarray:
    """Map values in [0, 1] to RGB colours (OpenCV's 'turbo'), same shape plus a last axis of 3, uint8.

    Examples
    --------
    >>> colormap(np.array([0.0, 1.0])).shape
    (2, 3)
    """
    import cv2

    v = np.asarray(values, dtype=np.float64)
    u8 = (np.clip(np.nan_to_num(v), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8).reshape(-1, 1)
    bgr = cv2.applyColorMap(u8, cv2.COLORMAP_TURBO).reshape(-1, 3)
    return bgr[:, ::-1].reshape(*v.shape, 3).copy()


def saliency_overlay(
    rgb: np.ndarray, saliency_map: np.ndarray, mask: np.ndarray | None = None, alpha: float = 0.55
) -> np.ndarray:
    """Blend a colour-mapped saliency map over a rendered image, on the object only.

    Parameters
    ----------
    rgb : (H, W, 3) float in [0, 1]
    saliency_map : (H, W) float in [0, 1]
    mask : (H, W) bool, optional
        Where to blend (default everywhere).
    alpha : float
        Weight of the saliency colours.

    Returns
    -------
    (H, W, 3) uint8
    """
    base = np.clip(np.asarray(rgb, dtype=np.float64), 0.0, 1.0) * 255.0
    heat = colormap(saliency_map).astype(np.float64)
    out = base.copy()
    where = np.ones(base.shape[:2], bool) if mask is None else np.asarray(mask, bool)
    out[where] = (1.0 - alpha) * base[where] + alpha * heat[where]
    return (out + 0.5).astype(np.uint8)


def draw_points(image: np.ndarray, rows_cols: np.ndarray, labels, radius: int | None = None) -> np.ndarray:
    """Draw numbered markers at (row, col) positions (float pixel coordinates); returns a copy.

    Parameters
    ----------
    image : (H, W, 3) uint8
    rows_cols : (k, 2) float
    labels : sequence of str or int, one per point
    radius : int, optional
        Marker radius in pixels (default scales with the image).
    """
    import cv2

    img = np.ascontiguousarray(image, dtype=np.uint8).copy()
    h = img.shape[0]
    r = max(3, h // 60) if radius is None else int(radius)
    scale = max(0.35, h / 700.0)
    thick = max(1, h // 300)
    for (row, col), label in zip(np.asarray(rows_cols, dtype=np.float64).reshape(-1, 2), labels):
        c = (int(round(col)), int(round(row)))
        cv2.circle(img, c, r + thick, (0, 0, 0), -1, cv2.LINE_AA)
        cv2.circle(img, c, r, (255, 255, 255), -1, cv2.LINE_AA)
        text = str(label)
        org = (c[0] + r + 2, c[1] - r - 2)
        cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), thick + 2, cv2.LINE_AA)
        cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, (255, 255, 255), thick, cv2.LINE_AA)
    return img


def visible_points(view, points: np.ndarray, tolerance: float = 2.0):
    """Project points into a view and tell which ones the view actually sees.

    A point is visible when it projects inside the image onto the object and
    its depth is within ``tolerance`` pixel sizes of the rendered depth there.

    Returns
    -------
    rows_cols : (k, 2) float64
    visible : (k,) bool
    """
    from meshsal.views.cameras import project

    P = np.atleast_2d(np.asarray(points, dtype=np.float64))
    rc = project(view, P)
    i = np.floor(rc).astype(np.int64)
    inside = np.all((i >= 0) & (i < view.size), axis=1)
    visible = np.zeros(P.shape[0], bool)
    if np.any(inside):
        r, c = i[inside, 0], i[inside, 1]
        # Rendered depth is the distance from the eye along the viewing direction, in both projections.
        depth = (P[inside] - view.eye) @ view.camera.direction
        visible[inside] = np.abs(view.depth[r, c] - depth) <= tolerance * view.pixel_size
    return rc, visible


def tile(images, columns: int, gap: int = 2) -> np.ndarray:
    """Tile equally sized (H, W) or (H, W, 3) uint8 images row-major on a white sheet."""
    images = [np.repeat(im[..., None], 3, axis=2) if im.ndim == 2 else im for im in images]
    h, w = images[0].shape[:2]
    rows = -(-len(images) // columns)
    sheet = np.full((rows * (h + gap) + gap, columns * (w + gap) + gap, 3), 255, np.uint8)
    for k, im in enumerate(images):
        r, c = divmod(k, columns)
        y, x = gap + r * (h + gap), gap + c * (w + gap)
        sheet[y : y + h, x : x + w] = im
    return sheet


def _caption(image: np.ndarray, text: str) -> np.ndarray:
    import cv2

    img = image.copy()
    scale = max(0.3, img.shape[0] / 600.0)
    cv2.putText(img, text, (4, int(16 * scale / 0.5)), cv2.FONT_HERSHEY_SIMPLEX, scale, (255, 255, 255), 1, cv2.LINE_AA)
    return img


def views_picture(views, maps, view_indices, positions: np.ndarray, min_size: int = 384) -> np.ndarray:
    """The given views with saliency overlays and the visible points numbered from 1, in a 2-column grid.

    Parameters
    ----------
    views : list of View
    maps : (len(views), H, W) float saliency maps
    view_indices : sequence of int
        Which views to show (e.g. the best set's four).
    positions : (k, 3) float64
        Points in the views' frame, best first (labelled 1..k).
    min_size : int
        Each panel is enlarged to at least this many pixels for legible labels.
    """
    import cv2

    panels = []
    for k in view_indices:
        view = views[k]
        img = saliency_overlay(view.rgb, maps[k], view.mask)
        factor = max(1, -(-min_size // view.size))
        img = cv2.resize(img, None, fx=factor, fy=factor, interpolation=cv2.INTER_NEAREST)
        rc, visible = visible_points(view, positions)
        labels = np.flatnonzero(visible) + 1
        img = draw_points(img, rc[visible] * factor, labels.tolist())
        panels.append(_caption(img, f"view {k} (set {k // 4})"))
    return tile(panels, columns=2)


def contact_sheet(maps, masks=None, columns: int = 12) -> np.ndarray:
    """All saliency maps colour-mapped (background black), in a grid of ``columns``."""
    images = []
    for k, m in enumerate(maps):
        img = colormap(m)
        if masks is not None:
            img[~np.asarray(masks[k], bool)] = 0
        images.append(img)
    return tile(images, columns=columns)
