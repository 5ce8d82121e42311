"""Local statistics channels: entropy and luminance contrast.

Unlike the center-surround channels these are direct neighbourhood
statistics at full resolution, computed with separable box filters.
Both maps are divided by their maximum, so zero keeps its meaning (a flat
neighbourhood) and the most entropic / most contrasted place is 1.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np

from meshsal.attention.images import LUMA, ImageStack, grey, window_crop
from meshsal.attention.pyramid import _stack_to_max

__all__ = [
    "entropy",
    "entropy_stack",
    "contrast",
    "contrast_stack",
    "local_entropy",
    "local_variance",
    "luma",
    "default_contrast_window",
]


def luma(img: np.ndarray) -> np.ndarray:
    """Rec. 709 luma of an RGB image, (H, W) float32."""
    return grey(img, LUMA)


def local_entropy(gray: np.ndarray, size: int = 9, bins: int = 16) -> np.ndarray:
    """Shannon entropy (bits) of the gray-level histogram in each size x size window.

    One normalized box filter per histogram bin gives every pixel's local
    bin frequencies p_b; the entropy is -sum_b p_b log2 p_b.  Borders are
    reflected.

    Parameters
    ----------
    gray : (H, W) float in [0, 1]
    size : odd int, window side in pixels
    bins : int, histogram bins over [0, 1]

    Returns
    -------
    (H, W) float32 in [0, log2(min(bins, size**2))]

    Examples
    --------
    >>> float(local_entropy(np.zeros((16, 16), np.float32)).max())
    0.0
    """
    if size < 1 or size % 2 == 0:
        raise ValueError(f"entropy window must be an odd positive size, got {size}")
    if bins < 2:
        raise ValueError(f"entropy needs at least 2 histogram bins, got {bins}")
    q = np.minimum((np.asarray(gray, np.float32) * bins).astype(np.int32), bins - 1)
    # Every window of bin 0 alone (a view's black background, its darkest pixels) has one entropy: the
    # windows are counted on the window_crop of the other bins only.
    out = np.full(q.shape, _flat_entropy(size, bins), np.float32)
    box = window_crop(q, size // 2)
    if box is not None:
        read, changed, inner = box
        out[changed] = _window_entropy(np.ascontiguousarray(q[read]), size, bins)[inner]
    return out


@functools.lru_cache(maxsize=16)
def _flat_entropy(size: int, bins: int) -> np.float32:
    """:func:`local_entropy` of a window whose pixels all fall in one bin."""
    return _window_entropy(np.zeros((size, size), np.int32), size, bins)[0, 0]


def _window_entropy(q: np.ndarray, size: int, bins: int) -> np.ndarray:
    """:func:`local_entropy` of the bin indices ``q`` (h, w) int32 in [0, bins)."""
    n = size * size
    # H = log2 n - (1/n) sum_b c_b log2 c_b over the bin counts c_b of the window.
    clog = np.zeros(q.shape, np.float32)
    if n <= 255:
        # Counts fit in uint8: unnormalized box sums in 8 bits, c log2 c by table lookup.
        table = np.zeros(256, np.float32)
        table[1:] = np.arange(1, 256) * np.log2(np.arange(1, 256))
        for b in range(bins):
            counts = cv2.boxFilter(
                (q == b).view(np.uint8), cv2.CV_8U, (size, size), normalize=False, borderType=cv2.BORDER_REFLECT
            )
            clog += cv2.LUT(counts, table)
    else:
        for b in range(bins):
            counts = cv2.boxFilter(
                (q == b).astype(np.float32), cv2.CV_32F, (size, size), normalize=False, borderType=cv2.BORDER_REFLECT
            )
            counts = np.rint(counts)
            clog += counts * np.log2(np.maximum(counts, 1.0))
    return np.maximum(np.float32(np.log2(n)) - clog * np.float32(1.0 / n), 0.0)


def entropy(img: np.ndarray, size: int = 9, bins: int = 16, median: int = 3) -> np.ndarray:
    """Entropy channel: local Shannon entropy of the median-filtered intensity.

    Parameters
    ----------
    img : (H, W, 3) float32 in [0, 1]
    size : odd int
        Neighbourhood side (9 in the paper).
    bins : int
        Histogram bins of the intensity.
    median : {1, 3, 5}
        Median filter aperture applied first (1 disables it); it removes
        isolated pixel noise, e.g. rendering aliasing, before counting.

    Returns
    -------
    (H, W) float32 in [0, 1], divided by its maximum.
    """
    return entropy_stack([img], size, bins, median)[0]


def entropy_stack(imgs, size: int = 9, bins: int = 16, median: int = 3) -> np.ndarray:
    """:func:`entropy` of each image of a stack (n, H, W, 3) or :class:`ImageStack`, bit for bit: (n, H, W) float32."""
    if median not in (1, 3, 5):
        raise ValueError(f"entropy median aperture must be 1, 3 or 5, got {median}")
    grays = ImageStack.of(imgs, "entropy").intensity
    return _stack_to_max(
        np.stack([local_entropy(cv2.medianBlur(g, median) if median > 1 else g, size, bins) for g in grays])
    )


def local_variance(gray: np.ndarray, window: int) -> np.ndarray:
    """Variance of ``gray`` in each window x window neighbourhood (reflected borders).

    Returns
    -------
    (H, W) float32, non-negative
    """
    g = np.asarray(gray, np.float32)
    g = g - np.float32(g.mean())  # centring keeps E[x^2] - E[x]^2 accurate in float32
    k = (window, window)
    mean = cv2.boxFilter(g, cv2.CV_32F, k, borderType=cv2.BORDER_REFLECT)
    mean_sq = cv2.boxFilter(g * g, cv2.CV_32F, k, borderType=cv2.BORDER_REFLECT)
    return np.maximum(mean_sq - mean * mean, 0.0)


def default_contrast_window(shape: tuple[int, int]) -> int:
    """80 pixels per 512 pixels of the image's longer side, at least 3, odd."""
    w = max(3, int(round(80.0 * max(shape[:2]) / 512.0)))
    return w + 1 if w % 2 == 0 else w


def contrast(img: np.ndarray, window: int | None = None) -> np.ndarray:
    """Contrast channel: local luminance variance.

    Parameters
    ----------
    img : (H, W, 3) float32 in [0, 1]
    window : int, optional
        Neighbourhood side in pixels.  The paper uses 80 x 80 on its views;
        ours are smaller, so by default the window scales with the image:
        80 px per 512 px of the longer side (41 px at 256), rounded to odd.

    Returns
    -------
    (H, W) float32 in [0, 1], divided by its maximum.

    Examples
    --------
    >>> img = np.full((64, 64, 3), 0.5, np.float32); img[::2, :32] = 1.0
    >>> m = contrast(img, window=9)
    >>> bool(m[32, 8] > 0.9 and m[32, 56] == 0.0)
    True
    """
    return contrast_stack([img], window)[0]


def contrast_stack(imgs, window: int | None = None) -> np.ndarray:
    """:func:`contrast` of each image of a stack (n, H, W, 3) or :class:`ImageStack`, bit for bit: (n, H, W) float32."""
    stack = ImageStack.of(imgs, "contrast")
    if window is None:
        window = default_contrast_window(stack.shape)
    if isinstance(window, bool) or not isinstance(window, (int, np.integer)) or window < 1:
        raise ValueError(f"contrast window must be a positive integer number of pixels, got {window!r}")
    return _stack_to_max(np.stack([local_variance(g, int(window)) for g in stack.luma]))
