"""Pictures of imprints for people: a labelled grid with visible taxels."""

from __future__ import annotations

import numpy as np

__all__ = ["imprint_grid"]


def imprint_grid(images, captions=None, scale: int = 8, columns: int = 5) -> np.ndarray:
    """Tile imprints into one RGB picture, each enlarged and captioned.

    Each taxel becomes a ``scale x scale`` block (nearest neighbour, so
    taxels stay visible); gray level = reading (0 black, 1 white).  Each tile
    has a thin frame and its caption above it.

    Parameters
    ----------
    images : (k, rows, cols) float in [0, 1]
    captions : sequence of k str, optional
        Defaults to ``"#0"``, ``"#1"``, ... (points are numbered from 0 everywhere).
    scale : int
        Pixels per taxel side.
    columns : int
        Tiles per row of the grid.

    Returns
    -------
    (H, W, 3) uint8 RGB

    Examples
    --------
    >>> imprint_grid(np.zeros((3, 16, 16)), scale=4, columns=2).shape
    (184, 148, 3)
    """
    import cv2

    images = np.asarray(images, dtype=np.float64)
    if images.ndim != 3 or images.shape[0] == 0:
        raise ValueError(f"images must have shape (k, rows, cols) with k >= 1, got {images.shape}")
    k, rows, cols = images.shape
    captions = [f"#{i}" for i in range(k)] if captions is None else [str(c) for c in captions]
    if len(captions) != k:
        raise ValueError(f"need one caption per image ({k}), got {len(captions)}")
    scale, columns = max(1, int(scale)), max(1, min(int(columns), k))
    pad, bar = 4, 20
    tile_w, tile_h = cols * scale + 2, rows * scale + 2
    cell_w, cell_h = tile_w + 2 * pad, tile_h + bar + pad
    grid_rows = -(-k // columns)
    canvas = np.full((grid_rows * cell_h + pad, columns * cell_w, 3), 32, dtype=np.uint8)
    for i in range(k):
        top, left = (i // columns) * cell_h + pad, (i % columns) * cell_w + pad
        gray = np.round(np.clip(images[i], 0.0, 1.0) * 255).astype(np.uint8)
        big = np.repeat(np.repeat(gray, scale, axis=0), scale, axis=1)
        y0 = top + bar
        canvas[y0 : y0 + tile_h, left : left + tile_w] = 110
        canvas[y0 + 1 : y0 + tile_h - 1, left + 1 : left + tile_w - 1] = big[:, :, None]
        cv2.putText(
            canvas, captions[i], (left, top + bar - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 220, 90), 1, cv2.LINE_AA
        )
    return canvas
