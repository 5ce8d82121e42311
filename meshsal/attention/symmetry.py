"""Symmetry channel: local mirror symmetry (:func:`symmetry`).

For every pixel and for a vertical and a horizontal mirror line through it
(at pixel centres and half-way between pixels), the channel measures how well
the neighbourhood matches its own mirror image: the normalized correlation

    A = sum_pairs w * b(p) * b(p') / sum_pairs w * (b(p)**2 + b(p')**2) / 2

over the pairs of pixels ``(p, p')`` that the line swaps, where ``b`` is the
band-passed luminance (a level of the Gaussian pyramid minus its blur) and
the weights ``w`` are Gaussian in the partners' distance to the line (sigma
``_ACROSS``) and in their position along it (sigma ``_ALONG``).  ``A`` is 1
for an exact mirror image and near 0 for independent halves.  Being a
correlation, it does not grow with contrast: a busy texture scores no more
than a faint one, and regions below a contrast floor (``_FLOOR``) score
nothing.  The sums over pairs are weighted sums of shifted products followed
by one blur along the line, so the cost is linear in the window width.

A pattern that does not change along some direction (a straight edge, a
shading ramp) is its own mirror image about *every* line across it; that is
no symmetric object.  A true axis is a ridge: the evidence is the
correlation on the line minus the mean (positive) correlation on the
parallel lines one pixel to either side, which is exactly zero for such
patterns and keeps most of the value on a symmetric patch, whose
correlation falls off at once beside the axis.

The evidence is raised to the 4th power, so that the chance symmetries of
random texture (evidence mostly below 0.5, hence below 0.06) fade next to
real ones (above 0.8, hence above 0.4).  It is computed at pyramid levels 1
and 2 (mirror-symmetric regions from about 15 to 80 input pixels across), the
maximum over levels and the two line orientations is the feature, which goes
through Itti's center-surround machinery
(:func:`~meshsal.attention.pyramid.center_surround_map`) like the other
channels.  That map is scaled to [0, 1]; the channel multiplies it by the
feature's own maximum, so the map's peak says how symmetric the most
symmetric region is: 0.57 for a smooth random texture mirrored about the
image's centre line, up to 1 for a plain symmetric shape, a few hundredths
for random texture, 0 for a flat image.

Only vertical and horizontal axes are measured: they are the ones human
observers detect best (Wenderoth 1994, Perception 23), and oblique
orientations would double the cost of a view.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np
from numpy.lib.stride_tricks import as_strided

from meshsal.attention.images import ImageStack
from meshsal.attention.pyramid import conspicuity_maps, gaussian_pyramid_stack, upsample_stack

__all__ = ["symmetry", "symmetry_stack"]


# Pyramid levels measured: level 1 keeps texture of a pixel or two of the
# input, level 2 reaches regions of some 80 px; level 0 would double the cost.
_LEVELS = (1, 2)
# Band-pass: a level minus its blur of this sigma (level pixels), so shading
# ramps and the mean luminance do not correlate.
_BAND = 1.5
# Pair weights: Gaussian sigma of the partners' distance to the line, and of
# their position along it (level pixels).  The longer extent along the line
# averages more texture for the same resolution across it.
_ACROSS = 4.0
_ALONG = 8.0
# Mean band-passed energy (about a 1% contrast) below which a window counts as flat.
_FLOOR = 1e-4
# Evidence exponent: chance correlations of random texture fade, near-exact ones stay.
_POWER = 4


def _pair_weights():
    """The pair weights across a line, normalized: partners at ``c -+ m`` (a line on a column) and at
    ``c + 1/2 -+ (m - 1/2)`` (a line between columns), ``m = 1..r``."""
    m = np.arange(1, max(1, int(np.ceil(2.5 * _ACROSS))) + 1)
    k_on = np.exp(-0.5 * (m / _ACROSS) ** 2)
    k_between = np.exp(-0.5 * ((m - 0.5) / _ACROSS) ** 2)
    return k_on / k_on.sum(), k_between / k_between.sum()


# Built once: the channel runs these for every level and axis of every stack.
_K_ON, _K_BETWEEN = _pair_weights()
_R = _K_ON.size
# The same weights as filters of b**2 (the pairs' energy) and as (r, 1, 1, 1) factors of the products.
_KER_ON = (0.5 * np.concatenate([_K_ON[::-1], [0.0], _K_ON]))[None].astype(np.float32)
_KER_BETWEEN = (0.5 * np.concatenate([_K_BETWEEN[::-1], _K_BETWEEN]))[None].astype(np.float32)
_K_ON32 = _K_ON.astype(np.float32)[:, None, None, None]
_K_BETWEEN32 = _K_BETWEEN.astype(np.float32)[:, None, None, None]
# Fraction of a window's weight present, by the number of partners on the image (0..r).
_PRESENT_ON = np.concatenate([[0.0], np.cumsum(_K_ON)])
_PRESENT_BETWEEN = np.concatenate([[0.0], np.cumsum(_K_BETWEEN)])
_ALONG_KERNEL = cv2.getGaussianKernel(2 * max(1, int(np.ceil(2.5 * _ALONG))) + 1, _ALONG, cv2.CV_32F)
_ONE = np.ones(1, np.float32)
# Maps measured in one call: a stack's views at 64 x 64 at once (their products stay in cache),
# larger maps a few at a time.
_CHUNK_PIXELS = 80_000


def _sum_in_numpy_order(terms) -> np.ndarray:
    """Elementwise sum of a few float32 arrays, added in the order of NumPy's pairwise sum.

    The same bits as stacking them on a last axis and calling ``.sum(-1)``
    (eight running sums combined as a tree, the rest added one by one),
    without summing over a short last axis, which makes the channel slow.
    """
    if len(terms) < 8:
        total = terms[0]
        for t in terms[1:]:
            total = total + t
        return total
    if len(terms) > 128:
        raise ValueError(f"_sum_in_numpy_order reproduces NumPy's order for at most 128 terms, got {len(terms)}")
    blocks = len(terms) - len(terms) % 8
    r = list(terms[:8])
    for i in range(8, blocks, 8):
        r = [r[j] + terms[i + j] for j in range(8)]
    total = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    for t in terms[blocks:]:
        total = total + t
    return total


def _columns(padded: np.ndarray, first: int, step: int, w: int) -> np.ndarray:
    """(r, n, h, w) view of maps (n, h, W): plane j is ``padded[:, :, first + step * j : ... + w]`` (no copy)."""
    s0, s1, s2 = padded.strides
    return as_strided(
        padded[:, :, first:], shape=(_R, *padded.shape[:2], w), strides=(step * s2, s0, s1, s2), writeable=False
    )


@functools.lru_cache(maxsize=8)
def _present_along(h: int) -> np.ndarray:
    """(h, 1) float32: the fraction of the weight along a line that lies on an image ``h`` rows high."""
    present = cv2.sepFilter2D(np.ones((h, 1), np.float32), -1, _ONE, _ALONG_KERNEL, borderType=cv2.BORDER_CONSTANT)
    present.setflags(write=False)
    return present


def _along(maps: np.ndarray) -> np.ndarray:
    """Sums along vertical lines (the weights ``_ALONG_KERNEL``) of maps (n, h, c) float32, zero off the maps.

    The maps lie side by side in one image of ``n * c`` columns: the sums
    run down each column, so each map gets the bits a call on it alone gives
    (with the pinned kernels: OpenCV's baseline code treats every column alike).
    """
    n, h, c = maps.shape
    side = np.ascontiguousarray(maps.transpose(1, 0, 2)).reshape(h, n * c)
    sums = cv2.sepFilter2D(side, -1, _ONE, _ALONG_KERNEL, borderType=cv2.BORDER_CONSTANT)
    return sums.reshape(h, n, c).transpose(1, 0, 2)


def _mirror_correlation(b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Correlation of each window of band-passed maps ``b`` (n, h, w) with its mirror image about a vertical line.

    Returns ``(on, between)``: the line through pixel column ``c``, and the
    line half-way between columns ``c`` and ``c + 1``; both (n, h, w) float32
    in [-1, 1].  Pairs whose partner falls outside the image are missing,
    and the correlation is scaled down by the square of the fraction of the
    window's weight that is present: a window cut by the border has fewer
    pairs and a noisier correlation.

    A line has a non-zero product of partners only between the first and the
    last non-zero column of its map (a view's background is black): the
    products and the sums along the lines are taken on the columns and rows
    where some map of the stack is non-zero, as one array for the stack.
    Elsewhere the correlation is zero, as over the whole image, up to the sign
    of a zero, which the channel's evidence (a 4th power) drops: each map
    keeps the bits it gets alone.
    """
    n, h, w = b.shape
    r = _R
    on, between = np.zeros((n, h, w), np.float32), np.zeros((n, h, w), np.float32)
    rows, cols = np.flatnonzero(b.any(axis=(0, 2))), np.flatnonzero(b.any(axis=(0, 1)))
    if not rows.size:
        return on, between
    (r0, r1), (c0, c1) = (rows[0], rows[-1] + 1), (cols[0], cols[-1] + 1)
    part = b[:, r0:r1]
    # Column c + j of the padded rows holds b[..., c + j - r], zero off the image.
    padded = np.pad(part, ((0, 0), (0, 0), (r, r)))
    # Plane m - 1 holds the partners at distance m: c - m and c + m (on), c + 1 - m and c + m (between).
    right = _columns(padded, r + 1 + c0, 1, c1 - c0)
    products = (
        _sum_in_numpy_order(_columns(padded, r - 1 + c0, -1, c1 - c0) * right * _K_ON32),
        _sum_in_numpy_order(_columns(padded, r + c0, -1, c1 - c0) * right * _K_BETWEEN32),
    )
    # The energy of the same pairs, (b(p)**2 + b(p')**2) / 2, is a plain filter of b**2, row by row:
    # the maps' rows, one map under the other, make one image.
    energy = (part * part).reshape(-1, w)
    energies = (
        cv2.filter2D(energy, -1, _KER_ON, borderType=cv2.BORDER_CONSTANT),
        cv2.filter2D(energy, -1, _KER_BETWEEN, anchor=(r - 1, 0), borderType=cv2.BORDER_CONSTANT),
    )
    c = np.arange(c0, c1)
    present_on = _PRESENT_ON[np.clip(np.minimum(c, w - 1 - c), 0, r)]
    present_between = _PRESENT_BETWEEN[np.clip(np.minimum(c + 1, w - 1 - c), 0, r)]
    column = np.zeros((n, h, c1 - c0), np.float32)
    for out, num, den, present in (
        (on, products[0], energies[0], present_on),
        (between, products[1], energies[1], present_between),
    ):
        # A ratio of window sums, not a mean of per-row ratios: rows with
        # little texture must not weigh as much as the rest.  The sums run
        # down each column, over the zero rows too.
        column[:, r0:r1] = num
        num = _along(column)
        column[:, r0:r1] = den.reshape(n, -1, w)[:, :, c0:c1]
        den = _along(column)
        coverage = present.astype(np.float32)[None, :] * _present_along(h)
        out[:, :, c0:c1] = num / (den + np.float32(_FLOOR)) * coverage * coverage
    return on, between


def _beside(a: np.ndarray) -> np.ndarray:
    """Mean of ``max(a, 0)`` one column to the left and one to the right (edge columns repeated), maps (..., w)."""
    pos = np.maximum(a, 0.0)
    left = np.concatenate([pos[..., :1], pos[..., :-1]], axis=-1)
    right = np.concatenate([pos[..., 1:], pos[..., -1:]], axis=-1)
    return 0.5 * (left + right)


def _axis_evidence(b: np.ndarray) -> np.ndarray:
    """(n, h, w) float32 in [0, 1]: evidence for a vertical mirror axis through (or next to) each pixel of maps b."""
    on, between = _mirror_correlation(b)
    # An axis is a ridge of the correlation, not a plateau (see the module notes).
    on = on - _beside(on)
    between = between - _beside(between)
    # A pixel is next to the lines half a pixel to its left and to its right.
    between_left = np.concatenate([between[..., :1], between[..., :-1]], axis=-1)
    return np.clip(np.maximum(on, np.maximum(between, between_left)), 0.0, 1.0)


def _mirror_features(grays: np.ndarray) -> np.ndarray:
    """(n, H, W) float32 in [0, 1] of greys (n, H, W): the strongest axis evidence (to the 4th power) over
    levels and orientations."""
    n, h, w = grays.shape
    pyramid = gaussian_pyramid_stack(grays, max(_LEVELS) + 1)
    feature = np.zeros((n, h, w), np.float32)
    for level in _LEVELS:
        if level >= len(pyramid):
            break
        b = np.stack([g - cv2.GaussianBlur(g, (0, 0), _BAND, borderType=cv2.BORDER_REFLECT) for g in pyramid[level]])
        evidence = np.empty(b.shape, np.float32)
        step = max(1, _CHUNK_PIXELS // (b.shape[1] * b.shape[2]))
        for k in range(0, n, step):
            chunk = b[k : k + step]
            vertical = _axis_evidence(chunk)
            horizontal = _axis_evidence(np.ascontiguousarray(chunk.transpose(0, 2, 1))).transpose(0, 2, 1)
            evidence[k : k + step] = np.maximum(vertical, horizontal) ** _POWER
        np.maximum(feature, upsample_stack(evidence, 2**level, (h, w)), out=feature)
    return feature


def symmetry(img: np.ndarray) -> np.ndarray:
    """Mirror-symmetry conspicuity map of an RGB image.

    The local mirror correlation of the band-passed luminance about vertical
    and horizontal lines, kept where it forms an axis, at pyramid levels 1
    and 2 (see the module notes), through Itti's center-surround machinery
    and scaled by its own strongest value.

    Parameters
    ----------
    img : (H, W, 3) float32 in [0, 1]

    Returns
    -------
    (H, W) float32 in [0, 1]; its maximum is the 4th power of the strongest
    axis evidence (see the module notes): a few hundredths for random
    texture, all zeros for a flat image or one less than 2 pixels wide or
    high (it has no pyramid level 1).

    Raises
    ------
    ValueError
        If ``img`` is not an (H, W, 3) float array with finite values in [0, 1].

    Examples
    --------
    >>> float(symmetry(np.full((64, 64, 3), 0.5, np.float32)).max())
    0.0
    >>> rng = np.random.default_rng(0)
    >>> half = cv2.GaussianBlur(rng.random((128, 64)).astype(np.float32), (0, 0), 2)
    >>> half = (half - half.min()) / (half.max() - half.min())
    >>> def peak(gray):
    ...     return round(float(symmetry(np.repeat(gray[:, :, None], 3, axis=2)).max()), 2)
    >>> peak(np.hstack([half, half[:, ::-1]])), peak(np.hstack([half, half]))  # mirrored; repeated
    (0.57, 0.02)
    """
    return symmetry_stack([img])[0]


def symmetry_stack(imgs) -> np.ndarray:
    """:func:`symmetry` of each image of a stack (n, H, W, 3) or :class:`ImageStack`, bit for bit with the pinned
    kernels (``meshsal.util.reproducible``): (n, H, W) float32."""
    features = _mirror_features(ImageStack.of(imgs, "symmetry").luma)
    out = np.zeros(features.shape, np.float32)
    tops = features.reshape(len(features), -1).max(axis=1)
    some = np.flatnonzero(tops > 0.0)
    if some.size:
        # Scaled by the strongest axis evidence (see the module notes).
        out[some] = conspicuity_maps(features[some, None]) * tops[some, None, None]
    return out
