"""The DKL color channel (Derrington, Krauskopf & Lennie, J. Physiol. 1984).

sRGB is linearized, taken to XYZ (sRGB primaries, D65 white) and to cone
space LMS with the Hunt-Pointer-Estevez matrix normalized to D65, so that
every gray has L = M = S.  The two chromatic DKL axes are then

* L - M            (the "red-green", parvocellular axis), and
* S - (L + M) / 2  (the "tritan", S-cone axis),

both zero on the achromatic axis: luminance changes alone do not drive this
channel.  Each axis goes through the center-surround pyramid and N(.).
"""

from __future__ import annotations

import cv2
import numpy as np

from meshsal.attention.images import ImageStack
from meshsal.attention.pyramid import conspicuity_maps

__all__ = ["RGB_TO_LMS", "srgb_to_linear", "rgb_to_lms", "dkl_axes", "dkl", "dkl_stack"]

_SRGB_TO_XYZ = np.array(
    [[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]], dtype=np.float64
)
_XYZ_TO_LMS_HPE_D65 = np.array(
    [[0.4002, 0.7076, -0.0808], [-0.2263, 1.1653, 0.0457], [0.0, 0.0, 0.9182]], dtype=np.float64
)
_M = _XYZ_TO_LMS_HPE_D65 @ _SRGB_TO_XYZ
# The published 4-digit matrices map white to (1, 1, 1) only up to rounding;
# making the rows sum to exactly 1 puts every gray exactly on the achromatic axis.
RGB_TO_LMS = (_M / _M.sum(axis=1, keepdims=True)).astype(np.float32)
"""(3, 3) linear sRGB -> LMS (Hunt-Pointer-Estevez, D65-normalized); rows sum to 1."""


# The chromatic DKL axes as rows applied to LMS: L - M and S - (L + M) / 2.
_LMS_TO_DKL = np.array([[1.0, -1.0, 0.0], [-0.5, -0.5, 1.0]], np.float32)
_RGB_TO_DKL = (_LMS_TO_DKL @ RGB_TO_LMS).astype(np.float32)


def srgb_to_linear(img: np.ndarray) -> np.ndarray:
    """Undo the sRGB transfer curve (IEC 61966-2-1); float32 in, float32 out."""
    img = np.ascontiguousarray(img, dtype=np.float32)
    out = img * np.float32(1.0 / 12.92)
    # The power only where it applies: most of a rendered view is black background.
    high = img > 0.04045
    # In float64, then rounded: SIMD power kernels differ by CPU in the last bits, which float32 absorbs.
    out[high] = np.power(img[high].astype(np.float64) / 1.055 + 0.055 / 1.055, 2.4).astype(np.float32)
    return out


def _transform(img: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    # cv2.transform applies a per-pixel matrix far faster than numpy's matmul on (H, W, 3).
    flat = np.ascontiguousarray(img.reshape(-1, 1, 3))
    return cv2.transform(flat, matrix).reshape(img.shape[:-1] + (matrix.shape[0],))


def rgb_to_lms(img: np.ndarray) -> np.ndarray:
    """sRGB image (..., 3) in [0, 1] -> cone excitations LMS (..., 3) float32."""
    return _transform(srgb_to_linear(img), RGB_TO_LMS)


def dkl_axes(img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The chromatic DKL axes of an sRGB image (..., 3), pixel by pixel.

    Returns
    -------
    l_minus_m, s_minus_lum : (...) float32 each, e.g. (H, W); zero for every gray.

    Examples
    --------
    >>> lm, s = dkl_axes(np.full((2, 2, 3), 0.5, np.float32))
    >>> bool(abs(lm).max() < 1e-3 and abs(s).max() < 1e-3)
    True
    """
    axes = _transform(srgb_to_linear(img), _RGB_TO_DKL)
    return np.ascontiguousarray(axes[..., 0]), np.ascontiguousarray(axes[..., 1])


def dkl(img: np.ndarray) -> np.ndarray:
    """DKL color conspicuity: center-surround on the L-M and S-(L+M) axes.

    Parameters
    ----------
    img : (H, W, 3) float32 sRGB in [0, 1]

    Returns
    -------
    (H, W) float32 in [0, 1]
    """
    return dkl_stack([img])[0]


def dkl_stack(imgs) -> np.ndarray:
    """:func:`dkl` of each image of a stack (n, H, W, 3) or :class:`ImageStack`, bit for bit: (n, H, W) float32."""
    # Image by image: the full-size arithmetic stays in cache.
    return conspicuity_maps(np.stack([np.stack(dkl_axes(img)) for img in ImageStack.of(imgs, "dkl").rgb]))
