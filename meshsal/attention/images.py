"""The images the channels read: checked once per stack, with the grey levels several channels share.

Five of the seven image channels start from a grey level of the same image:
intensity ``(r + g + b) / 3`` (intensity, color, orientation, entropy) or
Rec. 709 luma (symmetry, contrast), and orientation reads the finest levels
of intensity's own Gaussian pyramid.  An :class:`ImageStack` computes each
once for a stack of images, when a channel first asks for it.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np

from meshsal.attention.pyramid import gaussian_pyramid_stack

__all__ = ["ImageStack", "check_image", "check_images", "grey", "window_crop"]

#: ``(r + g + b) / 3`` and Rec. 709 luma, one row each for ``cv2.transform``.
MEAN = np.full((1, 3), 1.0 / 3.0, np.float32)
LUMA = np.array([[0.2126, 0.7152, 0.0722]], dtype=np.float32)


def grey(imgs: np.ndarray, row: np.ndarray) -> np.ndarray:
    """``row``-weighted sum of the channels of images (..., H, W, 3) float32: (..., H, W) float32.

    One ``cv2.transform``, two orders of magnitude faster than
    ``ndarray.mean(axis=-1)``; it weighs each pixel alone, so a stack gets the
    bits each image gets.  Image by image, the work stays in cache.
    """
    imgs = np.ascontiguousarray(imgs, np.float32)
    return cv2.transform(imgs.reshape(-1, imgs.shape[-2], 3), row).reshape(imgs.shape[:-1])


def window_crop(active: np.ndarray, reach: int):
    """The crop on which a window filter gives the pixels near the ``active`` ones their bits.

    A view's background is black, and a filter whose window reads no active
    (non-zero) pixel gives every such pixel one value: the filter need only
    run near the active pixels.

    Parameters
    ----------
    active : (h, w) array, non-zero where a pixel is active
    reach : int, how far the window reaches from its centre (4 for a 9 x 9 window)

    Returns
    -------
    ``(read, changed, inner)``, each a pair of slices, or None if no pixel is
    active: ``changed`` the box of the pixels whose window meets the active
    pixels' bounding box, ``read`` the crop to filter (``changed`` grown by
    the reach: what its windows read), ``inner`` where ``changed`` lies in
    the crop.  Where the crop's border is the image's, a reflected or
    replicated border is the image's own.

    Examples
    --------
    >>> active = np.zeros((20, 20)); active[10, 3] = 1
    >>> window_crop(active, 2)
    ((slice(6, 15, None), slice(0, 8, None)), (slice(8, 13, None), slice(1, 6, None)), (slice(2, 7, None), slice(1, 6, None)))
    """
    rows, cols = (np.flatnonzero(active.any(axis=axis)).tolist() for axis in (1, 0))
    if not rows:
        return None
    changed = [(max(i[0] - reach, 0), min(i[-1] + reach + 1, n)) for i, n in zip((rows, cols), active.shape)]
    read = [(max(lo - reach, 0), min(hi + reach, n)) for (lo, hi), n in zip(changed, active.shape)]
    return (
        tuple(slice(lo, hi) for lo, hi in read),
        tuple(slice(lo, hi) for lo, hi in changed),
        tuple(slice(lo - r, hi - r) for (lo, hi), (r, _) in zip(changed, read)),
    )


def check_image(img, name: str = "img") -> np.ndarray:
    """Validate an RGB image for the attention channels and return it as float32.

    Parameters
    ----------
    img : (H, W, 3) floating array with values in [0, 1]
    name : str
        The caller's name, used in the error message.

    Raises
    ------
    ValueError
        Wrong shape, non-floating dtype (e.g. uint8: divide by 255 first),
        NaN/inf, or values outside [0, 1].
    """
    arr = np.asarray(img)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise ValueError(f"{name}: expected an (H, W, 3) RGB image, got shape {arr.shape}")
    return check_images(arr[None], name)[0]


def check_images(imgs, name: str = "img") -> np.ndarray:
    """:func:`check_image` of each image of a stack, in one pass: (n, H, W, 3) float32.

    Parameters
    ----------
    imgs : (n, H, W, 3) array, or a sequence of n (H, W, 3) arrays of one shape
    name : str
        The caller's name, used in the error message.

    Examples
    --------
    >>> check_images([np.zeros((4, 4, 3), np.float32)] * 2).shape
    (2, 4, 4, 3)
    >>> check_images(np.full((1, 4, 4, 3), 2.0))
    Traceback (most recent call last):
    ...
    ValueError: img: image values must lie in [0, 1], got range [2, 2]
    """
    if isinstance(imgs, np.ndarray):
        arr = imgs
    else:
        shapes = {np.shape(img) for img in imgs}
        if len(shapes) != 1:
            raise ValueError(f"{name}: a stack needs images of one shape, got {sorted(shapes) or 'none'}")
        arr = np.stack([np.asarray(img) for img in imgs])
    if arr.ndim != 4 or arr.shape[3] != 3 or not arr.shape[0]:
        raise ValueError(f"{name}: expected a stack of (H, W, 3) RGB images, got shape {arr.shape}")
    if arr.shape[1] < 1 or arr.shape[2] < 1:
        raise ValueError(f"{name}: image is empty, shape {arr.shape[1:]}")
    if not np.issubdtype(arr.dtype, np.floating):
        raise ValueError(
            f"{name}: expected a float image with values in [0, 1], got dtype {arr.dtype}"
            " (convert uint8 images with img.astype(np.float32) / 255)"
        )
    arr = np.ascontiguousarray(arr, dtype=np.float32)
    lo, hi = float(arr.min()), float(arr.max())
    if not (np.isfinite(lo) and np.isfinite(hi)):
        raise ValueError(f"{name}: image contains NaN or infinite values")
    if lo < -1e-6 or hi > 1.0 + 1e-6:
        raise ValueError(f"{name}: image values must lie in [0, 1], got range [{lo:.4g}, {hi:.4g}]")
    return arr


@dataclass(frozen=True, eq=False)
class ImageStack:
    """RGB images of one shape, checked, and what several channels compute from them, computed once.

    Build it with :meth:`of`; one thread uses it at a time.

    Attributes
    ----------
    rgb : (n, H, W, 3) float32 in [0, 1]

    Examples
    --------
    >>> stack = ImageStack.of(np.full((2, 8, 8, 3), 0.5, np.float32))
    >>> stack.intensity.shape, [level.shape for level in stack.intensity_pyramid[:2]]
    ((2, 8, 8), [(2, 8, 8), (2, 4, 4)])
    """

    rgb: np.ndarray

    @classmethod
    def of(cls, imgs, name: str = "img") -> ImageStack:
        """The stack of ``imgs`` ((n, H, W, 3) or a sequence of (H, W, 3)), checked; an ImageStack as it is."""
        return imgs if isinstance(imgs, ImageStack) else cls(check_images(imgs, name))

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of every image."""
        return self.rgb.shape[1:3]

    @functools.cached_property
    def intensity(self) -> np.ndarray:
        """(n, H, W) float32, ``(r + g + b) / 3``."""
        return np.stack([grey(img, MEAN) for img in self.rgb])

    @functools.cached_property
    def luma(self) -> np.ndarray:
        """(n, H, W) float32, Rec. 709 luma."""
        return np.stack([grey(img, LUMA) for img in self.rgb])

    @functools.cached_property
    def intensity_pyramid(self) -> list[np.ndarray]:
        """The full Gaussian pyramid of :attr:`intensity`, a list of (n, h_k, w_k) float32."""
        return gaussian_pyramid_stack(self.intensity)
