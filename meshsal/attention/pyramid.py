"""Gaussian pyramids, center-surround differences and Itti's map normalization.

The shared machinery of the Itti-Koch style channels (Itti, Koch & Niebur,
PAMI 1998; Itti & Koch, J. Electronic Imaging 2001): a dyadic Gaussian
pyramid of a feature, center-surround differences ``|F(c) - F(s)|`` for center
scales ``c in {2, 3, 4}`` and surround scales ``s = c + d, d in {3, 4}``,
each normalized by ``N(.)``, summed across scales at the resolution of scale 4,
normalized again and brought back to the input size.

N(.) is by default the global non-linear normalization ("maxima": scale to
[0, 1], multiply by ``(1 - mean of the rival local maxima)**2``) that Itti &
Koch (2001) compare with their iterative difference-of-Gaussians competition;
the latter is available as ``normalize_map(m, "iterative")``
(see :func:`normalize_map` for why it is not the default).

Every operation is written once, for a stack of maps (n, h, w) that
one call takes through it, bit for bit map by map: a single map is a
stack of one.  Coarse levels are brought back up with the pyramid's own geometry
(:func:`upsample`): ``cv2.pyrDown`` puts coarse pixel ``i`` on fine pixel
``2 i``, and resizing as if pixel centres were aligned would shift a scale-4
map by 7.5 input pixels.

Small images
------------
The full scheme needs nine pyramid levels (0..8), i.e. images of at least
256 pixels on their shorter side.  Smaller images get fewer levels (levels
are built while the shorter side is at least 2 pixels) and the (c, s) pairs
whose surround level does not exist are dropped; if no pair survives (shorter
side below 32 pixels) the finest center and the coarsest surround available
are used, ``(0, L - 1)``.  A single-pixel or constant feature gives a zero map.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np

__all__ = [
    "CENTERS",
    "DELTAS",
    "gaussian_pyramid",
    "gaussian_pyramid_stack",
    "normalize_map",
    "normalize_maps",
    "across_scale_sum",
    "conspicuity_map",
    "conspicuity_maps",
    "conspicuity_of_pyramid",
    "scale_pairs",
    "center_surround_map",
    "to_unit",
    "upsample",
    "upsample_stack",
    "scale_to_max",
]

CENTERS = (2, 3, 4)
DELTAS = (3, 4)
_LEVELS = max(CENTERS) + max(DELTAS) + 1

# Itti & Koch (2001), iterative N(.): excitatory and inhibitory Gaussians of
# 2% and 25% of the map width with gains 0.5 and 1.5, global inhibition 0.02.
_C_EX, _C_INH = 0.5, 1.5
_SIGMA_EX, _SIGMA_INH = 0.02, 0.25
_GLOBAL_INH = 0.02
# N(.) "maxima": local maxima (3x3) above 10% of the range count as peaks;
# those within 2 pixels (Chebyshev) of the global maximum belong to it.
_PEAK_FLOOR = 0.1
_PEAK_EXCLUSION = 2
# NumPy sums fewer values than this one after another, more pairwise.
_SEQUENTIAL_SUM = 8
# Maps whose value range is below this are flat: nothing to normalize.
_FLAT = 1e-6
_3X3 = np.ones((3, 3), np.uint8)
# Upsampling by a power of two takes two separable passes, one call for a whole stack, where they beat
# OpenCV's warp map by map: stacks of at least 4 maps, or 128 x 128 pixels and more by a factor of 8 or more.
_SEPARABLE_MAPS = 4
_SEPARABLE_PIXELS = 128 * 128
_SEPARABLE_FACTOR = 8


def gaussian_pyramid(img: np.ndarray, levels: int = _LEVELS) -> list[np.ndarray]:
    """Dyadic Gaussian pyramid (5x5 binomial filter, then subsampling by 2).

    Parameters
    ----------
    img : (H, W) or (H, W, C) array, level 0 (converted to float32)
    levels : int, wanted number of levels; a level is added only while the previous one's shorter side is >= 2

    Returns
    -------
    list of float32 arrays; level ``k`` has shape ``ceil(H / 2**k), ceil(W / 2**k)``.

    Examples
    --------
    >>> [p.shape for p in gaussian_pyramid(np.zeros((64, 48), np.float32), 4)]
    [(64, 48), (32, 24), (16, 12), (8, 6)]
    """
    return [level[0] for level in gaussian_pyramid_stack(np.asarray(img)[None], levels)]


def gaussian_pyramid_stack(maps: np.ndarray, levels: int = _LEVELS) -> list[np.ndarray]:
    """:func:`gaussian_pyramid` of each map of a stack (n, H, W[, C]), level by level: a list of (n, h_k, w_k[, C]).

    ``cv2.pyrDown`` map by map: one call on maps laid out as channels rounds otherwise.
    """
    if levels < 1:
        raise ValueError(f"gaussian_pyramid needs at least one level, got {levels}")
    pyramid = [np.ascontiguousarray(maps, dtype=np.float32)]
    while len(pyramid) < levels and min(pyramid[-1].shape[1:3]) >= 2:
        pyramid.append(_pyr_down_each(pyramid[-1]))
    return pyramid


def _pyr_down_each(maps: np.ndarray) -> np.ndarray:
    """``cv2.pyrDown`` of each map of a stack, written into the stack it returns (no list of maps to join)."""
    n, h, w = maps.shape[:3]
    out = np.empty((n, (h + 1) // 2, (w + 1) // 2, *maps.shape[3:]), np.float32)
    for m, level in zip(maps, out):
        done = cv2.pyrDown(m, dst=level)
        if done is not level:  # OpenCV allocates anew when it cannot use ``dst``
            level[...] = done
    return out


def _gaussian(m: np.ndarray, sigma: float) -> np.ndarray:
    k = 2 * max(1, math.ceil(3.0 * sigma)) + 1
    return cv2.GaussianBlur(m, (k, k), sigmaX=sigma, sigmaY=sigma, borderType=cv2.BORDER_REFLECT)


def upsample(m: np.ndarray, factor: int, shape: tuple[int, int]) -> np.ndarray:
    """Bilinear upsampling that respects the pyramid's geometry.

    ``cv2.pyrDown`` centres pixel ``i`` of the coarse level on pixel ``2 i`` of
    the finer one (not on ``2 i + 0.5`` as ``cv2.resize`` assumes), so a level-k
    pixel ``i`` sits at input pixel ``i * 2**k``; upsampling with that same map
    keeps features in place instead of drifting by up to ``2**k / 2`` pixels.

    ``m`` (h, w) float32 by ``factor`` (e.g. ``2**k``) to ``shape`` (H, W): (H, W) float32.

    Examples
    --------
    >>> upsample(np.array([[0.0, 1.0]], np.float32), 2, (1, 4)).tolist()
    [[0.0, 0.5, 1.0, 1.0]]
    """
    if m.ndim == 2 and m.dtype == np.float32:
        return upsample_stack(m[None], factor, shape)[0]
    return _warp_upsample(m, int(factor), shape)


def _warp_upsample(m: np.ndarray, factor: int, shape: tuple[int, int]) -> np.ndarray:
    """:func:`upsample` by OpenCV's affine warp (coarse pixel ``i`` read at fine pixel ``i * factor``)."""
    inv = 1.0 / factor
    warp = np.array([[inv, 0.0, 0.0], [0.0, inv, 0.0]], np.float32)
    return cv2.warpAffine(
        m,
        warp,
        (shape[1], shape[0]),
        flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
        borderMode=cv2.BORDER_REPLICATE,
    )


def _step_differences(m: np.ndarray, axis: int) -> np.ndarray:
    """``next - this`` along ``axis`` (-1 or -2), the last one against itself (the replicated border): float32."""
    d = np.empty_like(m)
    if axis == -1:
        np.subtract(m[..., 1:], m[..., :-1], out=d[..., :-1])
        np.subtract(m[..., -1], m[..., -1], out=d[..., -1])
    else:
        np.subtract(m[..., 1:, :], m[..., :-1, :], out=d[..., :-1, :])
        np.subtract(m[..., -1, :], m[..., -1, :], out=d[..., -1, :])
    return d


def _separable_upsample(m: np.ndarray, factor: int, shape: tuple[int, int]) -> np.ndarray:
    """:func:`upsample` of a stack of maps (..., h, w) by a power-of-two ``factor`` in one call, bit for bit
    what :func:`_warp_upsample` gives each map with the pinned kernels.

    The sample positions ``i / factor`` are exact in float32 and repeat with
    period ``factor``, so bilinear interpolation splits into a pass along
    rows and one along columns with ``factor`` fixed weights.  Each pass
    computes ``alpha * (next - this) + this`` in float32, rounding after
    the product and after the sum, in the order of OpenCV's own kernel
    (without fused multiply-add, which the pin turns off); the border is
    replicated.
    """
    *lead, h, w = m.shape
    weights = np.arange(factor, dtype=np.float32) / np.float32(factor)
    d = _step_differences(m, axis=-1)
    rows = np.empty((*lead, h, w, factor), np.float32)
    # Weight by weight: a pass along whole rows, not along the factor's few entries.
    for j, weight in enumerate(weights):
        np.multiply(d, weight, out=rows[..., j])
        rows[..., j] += m
    rows = rows.reshape(*lead, h, w * factor)[..., : shape[1]]
    out = np.empty((*lead, h, factor, rows.shape[-1]), np.float32)
    np.multiply(_step_differences(rows, axis=-2)[..., :, None, :], weights[:, None], out=out)
    out += rows[..., :, None, :]
    return out.reshape(*lead, h * factor, -1)[..., : shape[0], :]


def upsample_stack(maps: np.ndarray, factor: int, shape: tuple[int, int]) -> np.ndarray:
    """:func:`upsample` of each map of a stack (n, h, w) float32: (n, H, W) float32, bit for bit map by map."""
    factor = int(factor)
    n, h, w = maps.shape
    if (
        factor >= 2
        and factor & (factor - 1) == 0
        and (n >= _SEPARABLE_MAPS or (factor >= _SEPARABLE_FACTOR and n * shape[0] * shape[1] >= _SEPARABLE_PIXELS))
        and h * factor >= shape[0]
        and w * factor >= shape[1]
    ):
        return _separable_upsample(maps, factor, shape)
    out = np.empty((n, *shape), np.float32)
    for k in range(n):
        out[k] = _warp_upsample(maps[k], factor, shape)
    return out


def to_unit(m: np.ndarray) -> np.ndarray:
    """Min-max scale a map to [0, 1] as float32; a flat map becomes zeros."""
    m = np.asarray(m, dtype=np.float32)
    return _to_unit_stack(m.reshape(1, -1)).reshape(m.shape)


def scale_to_max(m: np.ndarray) -> np.ndarray:
    """Divide a non-negative map by its maximum (float32, [0, 1]); a zero map stays zero."""
    m = np.array(m, dtype=np.float32)
    return _stack_to_max(m.reshape(1, -1)).reshape(m.shape)


def _stack_to_max(maps: np.ndarray) -> np.ndarray:
    """:func:`scale_to_max` of each map of a stack (n, ...) float32, in place; returns ``maps``."""
    top = maps.reshape(len(maps), -1).max(axis=1, initial=0.0).astype(np.float64)
    scale = np.divide(1.0, top, out=np.zeros_like(top), where=top > _FLAT).astype(np.float32)
    maps *= scale.reshape((-1,) + (1,) * (maps.ndim - 1))
    maps[top <= _FLAT] = 0.0
    return maps


def normalize_map(m: np.ndarray, method: str = "maxima", iterations: int = 3) -> np.ndarray:
    """Itti's map normalization operator N(.).

    Both variants first scale the map to the fixed range [0, 1] (removing
    amplitude differences between modalities), then promote maps with a few
    strong peaks over maps with many comparable ones.

    Parameters
    ----------
    m : (h, w) array
    method : {"maxima", "iterative"}
        ``"maxima"`` (default; Itti, Koch & Niebur 1998, also the first form
        in Itti & Koch 2001): multiply by ``(1 - mean)**2``, ``mean`` the
        average of the rival peaks: 3x3 local maxima above 10% of the range,
        but those within 2 pixels of the global maximum (its own plateau).
        ``"iterative"``: Itti & Koch (2001), ``iterations`` rounds of
        ``M <- |M + M * DoG - C_inh|_{>=0}``, DoG the difference of an
        excitatory Gaussian (sigma 2% of the map width, gain 0.5**2) and an
        inhibitory one (sigma 25%, gain 1.5**2), C_inh = 0.02.  On our 16 x 16
        scale-4 maps it keeps the bar ends of orientation search displays
        alive, so it is not the default.
    iterations : int
        Rounds of the iterative variant.

    Returns
    -------
    (h, w) float32, non-negative, at most 1 for "maxima"; not rescaled: the
    surviving amplitude is what ranks maps when they are summed.

    Examples
    --------
    >>> one = np.zeros((16, 16), np.float32); one[8, 8] = 1.0
    >>> float(normalize_map(one).max())
    1.0
    >>> two = one.copy(); two[2, 2] = 0.8
    >>> round(float(normalize_map(two).max()), 2)
    0.04
    """
    m = np.asarray(m, dtype=np.float32)
    if m.ndim != 2:
        raise ValueError(f"normalize_map expects a 2-D map, got shape {m.shape}")
    if method == "maxima":
        return normalize_maps(m[None])[0]
    if method == "iterative":
        m = to_unit(m)
        if not m.any():
            return m
        width = max(m.shape)
        sigma_ex, sigma_inh = _SIGMA_EX * width, _SIGMA_INH * width
        for _ in range(iterations):
            dog = _C_EX**2 * _gaussian(m, sigma_ex) - _C_INH**2 * _gaussian(m, sigma_inh)
            m = np.maximum(m + dog - _GLOBAL_INH, 0.0, dtype=np.float32)
        return m
    raise ValueError(f"normalize_map method must be 'iterative' or 'maxima', got {method!r}")


def _to_unit_stack(maps: np.ndarray) -> np.ndarray:
    """:func:`to_unit` of each map of a stack (n, ...) float32: one over the float64 range, rounded to float32."""
    flat = maps.reshape(len(maps), -1)
    if not flat.shape[1]:
        return np.zeros(maps.shape, np.float32)
    lo = flat.min(axis=1)
    span = flat.max(axis=1).astype(np.float64) - lo.astype(np.float64)
    live = span > _FLAT
    scale = np.divide(1.0, span, out=np.zeros_like(span), where=live).astype(np.float32)
    shape = (-1,) + (1,) * (maps.ndim - 1)
    out = maps - lo.reshape(shape)
    out *= scale.reshape(shape)
    out[~live] = 0.0
    return out


def _dilate_3x3(maps: np.ndarray) -> np.ndarray:
    """Maximum over each pixel's 3 x 3 neighbourhood inside its map, for a stack (n, h, w) float32.

    One ``cv2.dilate`` of the maps laid one under the other, a row of -inf
    after each, so no neighbourhood reaches into the next map: what the
    dilation of each map alone gives (a maximum is exact).
    """
    n, h, w = maps.shape
    tall = np.empty((n, h + 1, w), np.float32)
    tall[:, :h] = maps
    tall[:, h] = -np.inf
    return cv2.dilate(tall.reshape(n * (h + 1), w), _3X3).reshape(n, h + 1, w)[:, :h]


def normalize_maps(maps: np.ndarray) -> np.ndarray:
    """Itti's N(.) ("maxima", see :func:`normalize_map`) of each map of a stack (n, h, w): (n, h, w) float32.

    One pass over the whole stack: N(.) runs some seventy times per view, on
    maps of a few hundred pixels, where each call's overhead counted.

    Examples
    --------
    >>> one = np.zeros((2, 16, 16), np.float32); one[:, 8, 8] = 1.0; one[1, 2, 2] = 0.8
    >>> [round(float(m.max()), 2) for m in normalize_maps(one)]
    [1.0, 0.04]
    """
    maps = np.asarray(maps, dtype=np.float32)
    if maps.ndim != 3:
        raise ValueError(f"normalize_maps expects a stack of 2-D maps (n, h, w), got shape {maps.shape}")
    n, h, w = maps.shape
    if not maps.size:
        return np.zeros(maps.shape, np.float32)
    m = _to_unit_stack(maps)
    # A flat map is all zeros now: no peaks.
    peaks = m == _dilate_3x3(m)
    peaks &= m > _PEAK_FLOOR
    top_r, top_c = np.divmod(m.reshape(n, -1).argmax(axis=1), w)
    # The global maximum's own plateau or shoulder is not a rival peak.
    e = _PEAK_EXCLUSION
    near_r = np.abs(np.arange(h) - top_r[:, None]) <= e
    near_c = np.abs(np.arange(w) - top_c[:, None]) <= e
    peaks &= ~(near_r[:, :, None] & near_c[:, None, :])
    counts = np.count_nonzero(peaks.reshape(n, -1), axis=1)
    # Each map's rivals in row-major order, as m[peaks] gives them.  Their float32 sum must be NumPy's
    # pairwise sum of that array, which below 8 values adds them one after another: so do all maps at
    # once, each padded with zeros (adding +0 changes no positive sum).  Maps with the same larger number
    # of rivals are summed as the rows of one array, which NumPy sums row by row in the order it sums
    # each (np.add.reduceat sums in another).
    rivals = np.append(m[peaks], np.float32(0.0))
    starts = np.cumsum(counts) - counts
    slots = np.arange(_SEQUENTIAL_SUM)
    padded = rivals[np.where(slots < counts[:, None], starts[:, None] + slots, rivals.size - 1)]
    sums = padded[:, 0].copy()
    for k in range(1, _SEQUENTIAL_SUM):
        sums += padded[:, k]
    many = counts >= _SEQUENTIAL_SUM
    if many.any():
        for count in set(counts[many].tolist()):
            which = np.flatnonzero(counts == count)
            sums[which] = np.add.reduce(rivals[starts[which, None] + np.arange(count)], axis=1)
    # The mean as ndarray.mean() takes it: the float32 sum divided in float64, rounded to float32.
    means = (sums.astype(np.float64) / np.maximum(counts, 1)).astype(np.float32).astype(np.float64)
    m *= ((1.0 - means) ** 2).astype(np.float32)[:, None, None]
    return m


def scale_pairs(levels: int) -> list[tuple[int, int]]:
    """The (center, surround) level pairs a pyramid of ``levels`` levels supports.

    ``(c, c + d)`` for ``c in CENTERS``, ``d in DELTAS`` whose surround exists;
    ``[(0, levels - 1)]`` if none does (shorter side below 32 px); ``[]`` for a
    single level.

    Examples
    --------
    >>> scale_pairs(9)
    [(2, 5), (2, 6), (3, 6), (3, 7), (4, 7), (4, 8)]
    >>> scale_pairs(4)
    [(0, 3)]
    """
    pairs = [(c, c + d) for c in CENTERS for d in DELTAS if c + d < levels]
    if not pairs and levels >= 2:
        pairs = [(0, levels - 1)]
    return pairs


def _across_scale(pyramid: Sequence[np.ndarray]) -> np.ndarray:
    """:func:`across_scale_sum` of a stack: ``pyramid`` a list of levels (n, h_k, w_k); (n, h, w) float32."""
    n = pyramid[0].shape[0]
    pairs = scale_pairs(len(pyramid))
    if not pairs:
        return np.zeros((n, 1, 1), np.float32)
    top = max(c for c, _ in pairs)
    total = np.zeros(pyramid[top].shape, np.float32)
    for c, s in pairs:
        center = pyramid[c]
        surround = upsample_stack(pyramid[s], 2 ** (s - c), center.shape[1:])
        # |F(c) - F(s)| rounds as cv2.absdiff does: one float32 difference, then its magnitude.
        fmap = normalize_maps(np.abs(center - surround))
        for _ in range(top - c):
            fmap = _pyr_down_each(fmap)
        total += fmap
    return total


def across_scale_sum(pyramid: Sequence[np.ndarray]) -> np.ndarray:
    """Sum of N(|F(c) - F(s)|) over the center-surround pairs of a :func:`gaussian_pyramid`, (h, w) float32.

    At the resolution of the coarsest center scale used (scale 4 for images
    of 256 pixels; see :func:`scale_pairs`); a (1, 1) zero map for a single level.
    """
    return _across_scale([np.asarray(level, np.float32)[None] for level in pyramid])[0]


def conspicuity_of_pyramid(pyramid: Sequence[np.ndarray], features: int, shape: tuple[int, int]) -> np.ndarray:
    """:func:`conspicuity_maps` of n images' features from their ready pyramid, levels (n * features, h_k, w_k)."""
    small = normalize_maps(_across_scale(pyramid))
    small = small.reshape(-1, features, *small.shape[1:])
    total = small[:, 0]
    for k in range(1, features):
        total = total + small[:, k]
    top = max((c for c, _ in scale_pairs(len(pyramid))), default=0)
    return _to_unit_stack(upsample_stack(normalize_maps(total), 2**top, shape))


def conspicuity_maps(features: np.ndarray, shape: tuple[int, int] | None = None) -> np.ndarray:
    """:func:`conspicuity_map` of many images at once, bit for bit image by image.

    Parameters
    ----------
    features : (n, k, H, W) float, ``k`` feature images of each of ``n`` images (e.g. 4 orientation energies)
    shape : (H, W), optional output size; the features' size by default

    Returns
    -------
    (n, H, W) float32 in [0, 1]

    Examples
    --------
    >>> f = np.zeros((2, 1, 64, 64), np.float32); f[0, 0, 8:16, 40:48] = f[1, 0, 40:48, 8:16] = 1.0
    >>> peaks = [np.unravel_index(int(m.argmax()), m.shape) for m in conspicuity_maps(f)]
    >>> [(int(r) // 8, int(c) // 8) for r, c in peaks]  # on each image's own square
    [(1, 5), (5, 1)]
    """
    features = np.asarray(features, dtype=np.float32)
    if features.ndim != 4 or not features.shape[1]:
        raise ValueError(f"conspicuity_maps expects features (n, k, H, W) with k >= 1, got shape {features.shape}")
    n, k, h, w = features.shape
    pyramid = gaussian_pyramid_stack(features.reshape(n * k, h, w))
    return conspicuity_of_pyramid(pyramid, k, shape or (h, w))


def conspicuity_map(features: Sequence[np.ndarray], shape: tuple[int, int] | None = None) -> np.ndarray:
    """Itti's conspicuity map of one channel made of several (H, W) feature images: (H, W) float32 in [0, 1].

    ``to_unit(resize(N(sum_f N(across_scale_sum(pyramid(f))))))``: e.g. the
    red-green and blue-yellow opponencies of the color channel, or the four
    Gabor orientations; ``shape`` as in :func:`conspicuity_maps`.
    """
    if len({np.shape(f) for f in features}) != 1:
        raise ValueError(f"conspicuity_map needs feature images of one shape, got {[np.shape(f) for f in features]}")
    return conspicuity_maps(np.stack(features)[None], shape)[0]


def center_surround_map(feature: np.ndarray) -> np.ndarray:
    """Itti's center-surround conspicuity of a single feature image.

    Gaussian pyramid, ``|F(c) - F(s)|`` for ``c in {2, 3, 4}``, ``s = c + d``,
    ``d in {3, 4}``, each N(.)-normalized and summed at the resolution of
    scale 4, N(.) again, resized back to the input size and scaled to [0, 1].

    Takes an (H, W) float array, returns (H, W) float32 in [0, 1].

    Examples
    --------
    >>> f = np.zeros((128, 128), np.float32); f[50:70, 80:100] = 1.0
    >>> m = center_surround_map(f)
    >>> bool(np.unravel_index(m.argmax(), m.shape)[1] > 64)
    True
    """
    feature = np.asarray(feature, dtype=np.float32)
    if feature.ndim != 2:
        raise ValueError(f"center_surround_map expects an (H, W) feature, got shape {feature.shape}")
    if not np.isfinite(feature).all():
        raise ValueError("center_surround_map: feature contains NaN or infinite values")
    return conspicuity_map([feature])
