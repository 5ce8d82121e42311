"""The three channels of Itti, Koch & Niebur (PAMI 1998): intensity, color, orientation.

Each is a function of an RGB image (H, W, 3) float32 in [0, 1] returning its
conspicuity map (H, W) float32 in [0, 1], built with the center-surround
machinery of :mod:`meshsal.attention.pyramid`.
"""

from __future__ import annotations

import cv2
import numpy as np

from meshsal.attention.images import ImageStack, window_crop
from meshsal.attention.pyramid import conspicuity_maps, conspicuity_of_pyramid, upsample_stack

__all__ = [
    "intensity",
    "color",
    "orientation",
    "intensity_stack",
    "color_stack",
    "orientation_stack",
    "orientation_energy",
    "opponency",
    "gabor_energy",
    "ORIENTATIONS_DEG",
]

ORIENTATIONS_DEG = (0.0, 45.0, 90.0, 135.0)

# Gabor filters applied at each pyramid level: 4-pixel period, envelope of
# half a period, elongated 2:1 along the stripes; they match a bar one or two
# pixels wide at that level (8-32 px wide at scales 2-4 of the input).
_GABOR_SIZE = 9
_GABOR_SIGMA = 2.0
_GABOR_PERIOD = 4.0
_GABOR_ASPECT = 0.5

# Rows giving Itti's broadly tuned R, G, B from r, g, b (before rectification).
_RGB_TUNED = np.array([[1.0, -0.5, -0.5], [-0.5, 1.0, -0.5], [-0.5, -0.5, 1.0]], np.float32)


def intensity(img: np.ndarray) -> np.ndarray:
    """Intensity conspicuity: center-surround of I = (r + g + b) / 3.

    Parameters
    ----------
    img : (H, W, 3) float32 in [0, 1]

    Returns
    -------
    (H, W) float32 in [0, 1]

    Examples
    --------
    >>> img = np.full((128, 128, 3), 0.2, np.float32); img[20:40, 90:110] = 0.9
    >>> m = intensity(img)
    >>> m.shape, bool(m[30, 100] > 0.5)
    ((128, 128), True)
    """
    return intensity_stack([img])[0]


def intensity_stack(imgs) -> np.ndarray:
    """:func:`intensity` of each image of a stack (n, H, W, 3) or :class:`ImageStack`, bit for bit: (n, H, W) float32."""
    stack = ImageStack.of(imgs, "intensity")
    return conspicuity_of_pyramid(stack.intensity_pyramid, 1, stack.shape)


def opponency(img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Itti's red-green and blue-yellow opponent features.

    r, g, b are divided by I = (r + g + b) / 3 where I exceeds a tenth of its
    maximum (elsewhere hue is not perceivable and the features are zero); the
    broadly tuned channels are R = r - (g + b)/2, G = g - (r + b)/2,
    B = b - (r + g)/2, Y = (r + g)/2 - |r - g|/2 - b, negatives set to zero.

    Returns
    -------
    RG = R - G, BY = B - Y : (H, W) float32 each
    """
    rg, by = _opponencies(ImageStack.of([img], "opponency"))[0]
    return rg, by


def _opponencies(stack: ImageStack) -> np.ndarray:
    """:func:`opponency` of each image of a stack: (n, 2, H, W) float32, RG and BY."""
    inten = stack.intensity
    # Hue normalization by I commutes with the rectified, degree-1 tuned
    # channels, so it is applied to the two differences only.
    scale = 1.0 / np.maximum(inten, np.float32(1e-6))
    tenth = (0.1 * inten.reshape(len(inten), -1).max(axis=1).astype(np.float64)).astype(np.float32)
    scale[inten <= tenth[:, None, None]] = 0.0
    out = np.empty((len(inten), 2, *stack.shape), np.float32)
    # Image by image: the full-size arithmetic stays in cache.
    for img, weight, (rg, by) in zip(stack.rgb, scale, out):
        tuned = np.maximum(cv2.transform(img, _RGB_TUNED), np.float32(0.0))
        # cv2.extractChannel, unlike cv2.split, is nearly free.
        red, green, blue = (cv2.extractChannel(tuned, k) for k in range(3))
        r, g, b = (cv2.extractChannel(img, k) for k in range(3))
        # (r + g)/2 - |r - g|/2 = min(r, g)
        yellow = np.maximum(np.minimum(r, g) - b, np.float32(0.0))
        np.multiply(red - green, weight, out=rg)
        np.multiply(blue - yellow, weight, out=by)
    return out


def color(img: np.ndarray) -> np.ndarray:
    """Color conspicuity: double opponency |RG(c) - RG(s)| and |BY(c) - BY(s)|.

    The two opponent features (see :func:`opponency`) are each taken through
    the center-surround pyramid, N(.)-normalized and summed.

    Takes and returns images as :func:`intensity` does.

    Examples
    --------
    >>> img = np.zeros((128, 128, 3), np.float32); img[..., 1] = 0.6
    >>> img[20:40, 90:110] = (0.8, 0.1, 0.1)
    >>> bool(color(img)[30, 100] > 0.5)
    True
    """
    return color_stack([img])[0]


def color_stack(imgs) -> np.ndarray:
    """:func:`color` of each image of a stack (n, H, W, 3) or :class:`ImageStack`, bit for bit: (n, H, W) float32."""
    return conspicuity_maps(_opponencies(ImageStack.of(imgs, "color")))


def _gabor_pair(theta_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Even (zero mean) and odd Gabor kernels; ``theta`` is the stripes' direction."""
    # cv2's theta is the direction of the carrier wave, normal to the stripes.
    theta = np.deg2rad(theta_deg + 90.0)
    size = (_GABOR_SIZE, _GABOR_SIZE)
    even = cv2.getGaborKernel(size, _GABOR_SIGMA, theta, _GABOR_PERIOD, _GABOR_ASPECT, 0.0, ktype=cv2.CV_32F)
    odd = cv2.getGaborKernel(size, _GABOR_SIGMA, theta, _GABOR_PERIOD, _GABOR_ASPECT, np.pi / 2, ktype=cv2.CV_32F)
    even -= even.mean()
    even.setflags(write=False)
    odd.setflags(write=False)
    return even, odd


_GABORS = {theta: _gabor_pair(theta) for theta in ORIENTATIONS_DEG}


def gabor_energy(level: np.ndarray, theta_deg: float) -> np.ndarray:
    """Phase-invariant Gabor energy sqrt(even^2 + odd^2) of one image at one orientation.

    Parameters
    ----------
    level : (h, w) float32
    theta_deg : float
        Orientation of the stripes the filter prefers, degrees counter-clockwise
        from vertical in image coordinates (0 = vertical bars, 90 = horizontal).

    Returns
    -------
    (h, w) float32, non-negative
    """
    theta_deg = float(theta_deg)
    even, odd = _GABORS[theta_deg] if theta_deg in _GABORS else _gabor_pair(theta_deg)
    e = cv2.filter2D(level, cv2.CV_32F, even, borderType=cv2.BORDER_REFLECT)
    o = cv2.filter2D(level, cv2.CV_32F, odd, borderType=cv2.BORDER_REFLECT)
    # Not cv2.magnitude: its result depends on the output buffer's alignment (seen: 5e-7 run to run).
    # In place: the same operations, without three full-size temporaries.
    e *= e
    o *= o
    e += o
    return np.sqrt(e, out=e)


def _gabor_energies(level: np.ndarray) -> np.ndarray:
    """:func:`gabor_energy` of one level (h, w) at the four orientations, (4, h, w) float32, the same bits.

    A filter that reads only zeros gives +0: the filters run on the
    :func:`~meshsal.attention.images.window_crop` of the non-zero pixels.
    """
    energy = np.zeros((len(ORIENTATIONS_DEG), *level.shape), np.float32)
    box = window_crop(level, _GABOR_SIZE // 2)
    if box is not None:
        read, changed, inner = box
        crop = np.ascontiguousarray(level[read])
        for k, theta in enumerate(ORIENTATIONS_DEG):
            energy[(k, *changed)] = gabor_energy(crop, theta)[inner]
    return energy


def _upsample_box(maps: np.ndarray, factor: int, shape: tuple[int, int]) -> np.ndarray:
    """:func:`~meshsal.attention.pyramid.upsample_stack` of maps (n, h, w) that are zero off a box, the same bits.

    Bilinear interpolation of zeros gives +0: only the box and a row and a
    column of zeros around it (the neighbours its edges are interpolated
    with) are interpolated, and placed where they go.
    """
    n, h, w = maps.shape
    out = np.zeros((n, *shape), np.float32)
    rows, cols = np.flatnonzero(maps.any(axis=(0, 2))), np.flatnonzero(maps.any(axis=(0, 1)))
    if not rows.size:
        return out
    (r0, r1), (c0, c1) = [
        (max(lo - 1, 0), min(hi + 2, extent)) for lo, hi, extent in ((rows[0], rows[-1], h), (cols[0], cols[-1], w))
    ]
    box = (slice(r0 * factor, min(r1 * factor, shape[0])), slice(c0 * factor, min(c1 * factor, shape[1])))
    size = (box[0].stop - box[0].start, box[1].stop - box[1].start)
    out[:, box[0], box[1]] = upsample_stack(np.ascontiguousarray(maps[:, r0:r1, c0:c1]), factor, size)
    return out


# Orientation energy is measured at the three finest levels, where the filters match
# bars 2-8 px wide, and compared across space by the usual center-surround pyramid.
_ENERGY_LEVELS = (0, 1, 2)


def orientation_energy(img: np.ndarray) -> np.ndarray:
    """Purity-weighted Gabor energy of each orientation at full resolution.

    The energy of each orientation is summed over the levels of
    ``_ENERGY_LEVELS`` (brought back to the input size), then weighted by
    its share of the energy of all four: ``E_t**2 / sum_t' E_t'``.  The
    weighting keeps what tells an oblique bar from a vertical one (its
    dominant orientation) and drops what they share (their ends and
    outline respond to every filter).

    Parameters
    ----------
    img : (H, W, 3) float32 in [0, 1]

    Returns
    -------
    (4, H, W) float32, non-negative, one map per angle of ``ORIENTATIONS_DEG``
    """
    return _orientation_energies(ImageStack.of([img], "orientation"))[0]


def _orientation_energies(stack: ImageStack) -> np.ndarray:
    """:func:`orientation_energy` of each image of a stack, (n, 4, H, W) float32, on intensity's own pyramid.

    Image by image: the full-size arithmetic stays in cache.
    """
    n, (h, w) = len(stack.rgb), stack.shape
    out = np.empty((n, len(ORIENTATIONS_DEG), h, w), np.float32)
    levels = stack.intensity_pyramid[: max(_ENERGY_LEVELS) + 1]
    for k, energy in enumerate(out):
        energy[:] = 0.0
        for level, maps in enumerate(levels):
            e = _gabor_energies(maps[k])
            energy += _upsample_box(e, 2**level, (h, w)) if level else e
        total = energy.sum(axis=0)
        floor = np.float32(1e-6 * max(float(total.max()), 1e-30))
        energy *= energy / np.maximum(total, floor)
    return out


def orientation(img: np.ndarray) -> np.ndarray:
    """Orientation conspicuity: orientation contrast across space, at 0, 45, 90 and 135 degrees.

    Each orientation's energy (:func:`orientation_energy`, measured at the
    bars' own scale) goes through the center-surround pyramid and N(.), as
    the color opponencies do, and the four are summed.  Itti's original
    applies the Gabor filters to the coarse levels themselves, where the
    bars of a search display are blobs: an odd oblique bar among vertical
    ones on a dense grid scored 1.2x inside/outside.  Here it pops out.

    Takes and returns images as :func:`intensity` does.

    Examples
    --------
    >>> img = np.full((256, 256, 3), 0.2, np.float32)
    >>> for r in range(16, 256, 32):
    ...     for c in range(16, 256, 32):
    ...         img[r - 9:r + 9, c - 1:c + 2] = 0.9
    >>> img[80 - 9:80 + 9, 144 - 1:144 + 2] = 0.2
    >>> for d in range(-7, 8):
    ...     img[80 + d - 1:80 + d + 2, 144 - d - 1:144 - d + 2] = 0.9
    >>> m = orientation(img)
    >>> r, c = np.unravel_index(np.argmax(m), m.shape)
    >>> bool(abs(r - 80) < 16 and abs(c - 144) < 16)
    True
    """
    return orientation_stack([img])[0]


def orientation_stack(imgs) -> np.ndarray:
    """:func:`orientation` of each image of a stack (n, H, W, 3) or :class:`ImageStack`, bit for bit: (n, H, W) float32."""
    return conspicuity_maps(_orientation_energies(ImageStack.of(imgs, "orientation")))
