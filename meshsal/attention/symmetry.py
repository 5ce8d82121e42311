"""Symmetry channel: local mirror symmetry; plus Loy & Eklundh's symmetric feature constellations.

The channel, :func:`symmetry`
-----------------------------
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
orientations would double the cost of a view.  Oblique axes and rotation
centres are found by the feature-based analysis below.

Feature constellations, :func:`symmetries`
------------------------------------------
Loy & Eklundh, "Detecting Symmetry and Symmetric Constellations of Features",
ECCV 2006.  Symmetric structures are found as pairs of local features:

Matching: each keypoint's descriptor is compared with the (mirrored or
plain) descriptors of all other keypoints at least ``min_distance`` away; of
its ``k`` nearest, those closer than ``match_ratio`` times its median
distance to all of them are matches.  Lowe's second-nearest ratio test is not
used: it rejects exactly what symmetry produces, a feature repeated round a
centre matching all its copies equally well.

* **Bilateral (mirror) symmetry.**  Each keypoint's descriptor is matched
  against the *mirrored* descriptors of the others.  A matched pair
  ``(p_i, p_j)`` votes for the axis it implies, the perpendicular bisector of
  ``p_i p_j``, written ``x cos(theta) + y sin(theta) = r`` where ``theta`` is
  the direction of the line joining the pair.  The vote carries the paper's
  symmetry magnitude ``M_ij = Phi_ij * S_ij * D_ij``:

  - angular symmetry ``Phi_ij = 1 - cos(phi_i + phi_j - 2 theta_ij)`` (the
    orientations of true mirror partners satisfy ``phi_j = pi + 2 theta - phi_i``,
    which gives the maximum 2); halved here so that it lies in [0, 1];
  - scale agreement ``S_ij = exp(-|s_i - s_j| / (sigma_s (s_i + s_j)))**2``;
  - distance weighting ``D_ij = exp(-d_ij**2 / (2 sigma_d**2))`` (the paper's
    optional term favouring local symmetries; ``sigma_d=None`` drops it).

  Votes are accumulated in a (theta, r) Hough space, blurred (respecting that
  ``(theta, r)`` and ``(theta + pi, -r)`` are the same line); its strongest
  local maxima are the symmetry axes, each refined to the weighted mean of
  the votes that support it.

* **Rotational symmetry.**  Keypoints are matched against the (unmirrored)
  descriptors of the others.  A pair related by a rotation ``beta = phi_j -
  phi_i`` about a centre ``c`` satisfies ``p_j - c = R(beta) (p_i - c)``, so
  ``c = (I - R(beta))^-1 (p_j - R(beta) p_i)``: the point on the perpendicular
  bisector from which the pair subtends the angle ``beta``.  Pairs with almost
  equal orientations (translations, centre at infinity) do not vote.  The
  magnitude is ``S_ij * D_ij``; votes go to a 2-D accumulator over the image,
  blurred, and its strongest local maxima are the centres (refined likewise).

Mirrored descriptors are obtained by **permuting the SIFT descriptor bins**,
not by describing a flipped image: for OpenCV's layout (4 x 4 spatial cells,
row-major, times 8 orientation bins) mirroring the image left-right maps cell
``(row, col, o)`` to ``(3 - row, col, -o mod 8)`` in the keypoint's own frame
(the keypoint's orientation ``phi`` becomes ``pi - phi``; in the rotated
frame that reflects the cell rows and negates gradient angles).  This is
exact up to pixel rounding and costs nothing, where describing the flipped
image would double the SIFT time (:func:`mirror_descriptors`; the tests
compare it with descriptors of the flipped image).

An axis or centre is kept when it gathers at least ``min_pairs`` pairs (at
distinct keypoint locations) and ``min_strength`` of the strongest
symmetry's votes: a single pair always defines some axis, two agreeing pairs
are evidence.

This was the channel until the local mirror correlation replaced it: a
constellation of SIFT pairs singled out a symmetric textured patch among
asymmetric ones with the same texture statistics in only one or two of four
trials.  It stays as an analysis of where and how an image is symmetric.

Coordinates are pixels, ``x`` = column, ``y`` = row (row 0 at the top);
angles are radians in that frame (OpenCV keypoint angles, clockwise on
screen).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from meshsal.attention.pyramid import center_surround_map, check_image, gaussian_pyramid, upsample

__all__ = ["symmetry", "symmetries", "Symmetries", "Keypoints", "sift_keypoints", "mirror_descriptors"]

# Hough space of bilateral axes: 2-degree theta bins, r bins of 1% of the
# image diagonal; the blur spreads a vote over about its localisation error.
_N_THETA = 90
_R_BIN = 0.01
_AXIS_BLUR = 1.5
# Rotation centres: accumulator cells of 1% of the diagonal, same blur.
_CENTRE_BIN = 0.01
_CENTRE_BLUR = 1.5
# A pair supports a peak when its vote falls within this many bins of it.
_SUPPORT = 3.0
# SIFT margin (pixels at its working scale) around the non-flat part of the image.
_CROP_MARGIN = 8


@dataclass(frozen=True, eq=False)
class Keypoints:
    """SIFT keypoints in input-image pixels.

    Attributes
    ----------
    xy : (n, 2) float64, (x = column, y = row)
    angle : (n,) float64, orientation in radians
    size : (n,) float64, OpenCV keypoint size (twice the feature scale)
    descriptors : (n, 128) float32
    """

    xy: np.ndarray
    angle: np.ndarray
    size: np.ndarray
    descriptors: np.ndarray


@dataclass(frozen=True, eq=False)
class Symmetries:
    """The strongest symmetries of an image (see :func:`symmetries`).

    Attributes
    ----------
    keypoints : Keypoints
    axes : (a, 3) float64
        Bilateral axes as ``(theta, r, strength)``: the line
        ``(x - cx) cos(theta) + (y - cy) sin(theta) = r`` with ``(cx, cy)`` the
        image centre ``((W - 1) / 2, (H - 1) / 2)``, ``theta`` in [0, pi) the
        direction normal to the axis; strongest first.
    axis_pairs : tuple of (k, 2) int arrays
        Keypoint index pairs supporting each axis.
    centres : (c, 3) float64
        Rotation centres as ``(x, y, strength)``, strongest first.
    centre_pairs : tuple of (k, 2) int arrays
        Keypoint index pairs supporting each centre.

    Strengths are sums of the supporting pairs' symmetry magnitudes, so axes
    and centres compare on one scale.
    """

    keypoints: Keypoints
    axes: np.ndarray
    axis_pairs: tuple
    centres: np.ndarray
    centre_pairs: tuple


def mirror_descriptors(descriptors: np.ndarray) -> np.ndarray:
    """Descriptors of the mirror images of the described patches.

    Permutes OpenCV SIFT bins: spatial cell ``(row, col)`` goes to
    ``(3 - row, col)`` and orientation bin ``o`` to ``-o mod 8``, which is the
    descriptor the keypoint mirrored left-right (``x -> W - 1 - x``,
    ``angle -> pi - angle``) gets in the left-right flipped image.

    Parameters
    ----------
    descriptors : (n, 128) array

    Returns
    -------
    (n, 128) array of the same dtype

    Examples
    --------
    >>> d = np.arange(128, dtype=np.float32)[None]
    >>> bool((mirror_descriptors(mirror_descriptors(d)) == d).all())
    True
    """
    d = np.asarray(descriptors)
    if d.ndim != 2 or d.shape[1] != 128:
        raise ValueError(f"mirror_descriptors expects (n, 128) SIFT descriptors, got shape {d.shape}")
    cells = d.reshape(-1, 4, 4, 8)[:, ::-1, :, (-np.arange(8)) % 8]
    return np.ascontiguousarray(cells.reshape(-1, 128))


def _no_keypoints() -> Keypoints:
    return Keypoints(np.zeros((0, 2)), np.zeros(0), np.zeros(0), np.zeros((0, 128), np.float32))


def sift_keypoints(gray: np.ndarray, n_features: int = 200, work_scale: float = 0.5) -> Keypoints:
    """SIFT keypoints and descriptors of a grayscale image.

    Parameters
    ----------
    gray : (H, W) float array in [0, 1]
    n_features : int
        Keep at most this many (the strongest by contrast).
    work_scale : float in (0, 1]
        SIFT runs on the image resized by this factor (SIFT doubles its input
        first, so 0.5 still sees features of a pixel or two), cropped to the
        bounding box of the pixels that differ from the top-left one plus a
        margin (a rendered view's flat background holds no keypoints);
        positions and sizes are mapped back to input pixels.

    Returns
    -------
    Keypoints (possibly empty)
    """
    h, w = gray.shape
    g8 = np.clip(np.rint(gray * 255.0), 0, 255).astype(np.uint8)
    if work_scale != 1.0:
        size = (max(1, round(w * work_scale)), max(1, round(h * work_scale)))
        g8 = cv2.resize(g8, size, interpolation=cv2.INTER_AREA)
    sx, sy = g8.shape[1] / w, g8.shape[0] / h
    # Rendered views sit on a flat background where SIFT finds nothing: run it
    # on the bounding box of what differs from the corner pixel, plus a margin.
    differs = np.argwhere(g8 != g8[0, 0])
    if not len(differs):
        return _no_keypoints()
    (r0, c0), (r1, c1) = differs.min(0) - _CROP_MARGIN, differs.max(0) + _CROP_MARGIN + 1
    r0, c0 = max(r0, 0), max(c0, 0)
    # Precise upscaling: the default doubling shifts positions by a quarter pixel.
    sift = cv2.SIFT_create(nfeatures=n_features, enable_precise_upscale=True)
    kps, desc = sift.detectAndCompute(np.ascontiguousarray(g8[r0:r1, c0:c1]), None)
    if not kps:
        return _no_keypoints()
    pts = cv2.KeyPoint_convert(kps).astype(np.float64) + (c0, r0)
    xy = np.column_stack([(pts[:, 0] + 0.5) / sx - 0.5, (pts[:, 1] + 0.5) / sy - 0.5])
    angle = np.radians([k.angle for k in kps])
    size = np.array([k.size for k in kps]) / np.sqrt(sx * sy)
    return Keypoints(xy, angle, size, np.asarray(desc, np.float32))


def _allowed_pairs(kp: Keypoints, min_dist: float) -> np.ndarray:
    """(n, n) uint8, 1 where two keypoints may pair: distinct and at least min_dist apart."""
    dx = kp.xy[:, 0, None] - kp.xy[None, :, 0]
    dy = kp.xy[:, 1, None] - kp.xy[None, :, 1]
    allowed = dx * dx + dy * dy >= min_dist**2
    np.fill_diagonal(allowed, False)
    return allowed.astype(np.uint8)


def _matches(a: np.ndarray, b: np.ndarray, allowed: np.ndarray, k: int, ratio: float) -> np.ndarray:
    """Pairs (i, j), i < j, where b[j] is among a[i]'s k nearest and stands out from the crowd.

    A candidate is kept when its distance is at most ``ratio`` times the
    median distance from a[i] to all allowed b[j] (see the module notes).
    """
    n = len(a)
    # OpenCV's brute-force search runs in OpenCV's own thread pool, right
    # after SIFT, instead of waking BLAS threads that fight it for cores.
    dist, idx = cv2.batchDistance(a, b, cv2.CV_32F, normType=cv2.NORM_L2, K=n, mask=allowed)
    valid = idx >= 0
    count = valid.sum(1)
    # Rows come sorted, the masked-out entries last: the (lower) median of the
    # valid ones sits at (count - 1) // 2.
    ref = np.where(count > 0, dist[np.arange(n), np.maximum(count - 1, 0) // 2], 0.0)
    k = min(k, n)
    keep = valid[:, :k] & (dist[:, :k] <= ratio * ref[:, None])
    i = np.broadcast_to(np.arange(n)[:, None], keep.shape)[keep]
    j = idx[:, :k][keep].astype(np.int64)
    code = np.unique(np.minimum(i, j) * n + np.maximum(i, j))
    return np.column_stack([code // n, code % n])


def _distinct_pairs(pairs: np.ndarray, loc: np.ndarray) -> int:
    """Number of pairs that differ in keypoint locations (SIFT repeats a location per orientation)."""
    if len(pairs) < 2:
        return len(pairs)
    a = np.sort(loc[pairs], axis=1)
    return len(np.unique(a[:, 0] * (loc.max() + 1) + a[:, 1]))


def _magnitude_terms(kp: Keypoints, pairs: np.ndarray, sigma_s: float, sigma_d: float | None) -> np.ndarray:
    si, sj = kp.size[pairs[:, 0]], kp.size[pairs[:, 1]]
    scale = np.exp(-np.abs(si - sj) / (sigma_s * (si + sj))) ** 2
    if sigma_d is None:
        return scale
    d2 = ((kp.xy[pairs[:, 0]] - kp.xy[pairs[:, 1]]) ** 2).sum(1)
    return scale * np.exp(-d2 / (2.0 * sigma_d**2))


def _blur(acc: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian blur of an accumulator, zero beyond its edges."""
    k = 2 * int(np.ceil(3.0 * sigma)) + 1
    return cv2.GaussianBlur(acc.astype(np.float32), (k, k), sigma, sigma, borderType=cv2.BORDER_CONSTANT)


def _peaks(acc: np.ndarray, n: int, crop: int = 0) -> np.ndarray:
    """(m, 2) indices of the n largest positive local maxima of acc, largest first.

    The first and last ``crop`` rows are context only (a wrapped axis): their
    maxima are not reported and row indices are relative to the rows in between.
    """
    acc = acc.astype(np.float32)
    is_max = (acc == cv2.dilate(acc, np.ones((5, 5), np.uint8), borderType=cv2.BORDER_REPLICATE)) & (acc > 0)
    if crop:
        acc, is_max = acc[crop:-crop], is_max[crop:-crop]
    idx = np.flatnonzero(is_max)
    idx = idx[np.argsort(-acc.ravel()[idx], kind="stable")][:n]
    return np.column_stack(np.unravel_index(idx, acc.shape))


def _bilateral(kp, pairs, loc, centre, diag, sigma_s, sigma_d, n_axes, min_pairs):
    pi, pj = kp.xy[pairs[:, 0]], kp.xy[pairs[:, 1]]
    delta = pj - pi
    theta_line = np.arctan2(delta[:, 1], delta[:, 0])
    angular = 0.5 * (1.0 - np.cos(kp.angle[pairs[:, 0]] + kp.angle[pairs[:, 1]] - 2.0 * theta_line))
    weight = angular * _magnitude_terms(kp, pairs, sigma_s, sigma_d)
    theta = np.mod(theta_line, np.pi)
    mid = 0.5 * (pi + pj) - centre
    r = mid[:, 0] * np.cos(theta) + mid[:, 1] * np.sin(theta)

    r_bin = _R_BIN * diag
    n_r = 2 * int(np.ceil(0.5 * diag / r_bin)) + 1
    ti = np.minimum((theta / np.pi * _N_THETA).astype(np.int64), _N_THETA - 1)
    ri = np.clip(np.rint(r / r_bin).astype(np.int64) + n_r // 2, 0, n_r - 1)
    acc = np.bincount(ti * n_r + ri, weights=weight, minlength=_N_THETA * n_r).reshape(_N_THETA, n_r)
    # theta wraps onto itself with r mirrored: pad with the flipped far end.
    pad = int(np.ceil(3 * _AXIS_BLUR))
    padded = np.concatenate([acc[-pad:, ::-1], acc, acc[:pad, ::-1]])
    acc = _blur(padded, _AXIS_BLUR)[pad:-pad]
    wrapped = np.concatenate([acc[-pad:, ::-1], acc, acc[:pad, ::-1]])

    def bins_to(t0, r0, t, r):
        # Distance in bins from (t0, r0) to (t, r) the shorter way round the
        # wrap, and whether that way crosses it.
        dt = t - t0
        direct = dt**2 + (r - r0) ** 2
        across = (dt - np.sign(dt) * _N_THETA) ** 2 + (n_r - 1 - r - r0) ** 2
        return np.sqrt(np.minimum(direct, across)), across < direct

    axes, support, taken = [], [], []
    for t0, r0 in _peaks(wrapped, 2 * n_axes + 2, crop=pad):
        # Equal maxima can sit on both sides of the wrap: one line, keep one.
        if len(axes) == n_axes or any(bins_to(t0, r0, t, r)[0] < _SUPPORT for t, r in taken):
            continue
        dist, crossed = bins_to(t0, r0, ti, ri)
        near = (dist <= _SUPPORT) & (weight > 0)
        if _distinct_pairs(pairs[near], loc) >= min_pairs:
            taken.append((t0, r0))
            # The weighted mean of the supporting votes, all written on the peak's side of the wrap.
            wn, flip = weight[near], crossed[near]
            t_near = theta[near] + np.where(flip, np.sign(t0 + 0.5 - _N_THETA / 2) * np.pi, 0.0)
            t_mean = np.average(t_near, weights=wn)
            r_mean = np.average(np.where(flip, -r[near], r[near]), weights=wn)
            if not 0.0 <= t_mean < np.pi:
                t_mean, r_mean = np.mod(t_mean, np.pi), -r_mean
            axes.append((t_mean, r_mean, wn.sum()))
            support.append(pairs[near])
    return np.array(axes).reshape(-1, 3), tuple(support)


def _rotational(kp, pairs, loc, shape, diag, sigma_s, sigma_d, min_rotation, n_centres, min_pairs):
    beta = np.angle(np.exp(1j * (kp.angle[pairs[:, 1]] - kp.angle[pairs[:, 0]])))
    turning = np.abs(beta) >= min_rotation
    pairs, beta = pairs[turning], beta[turning]
    pi, pj = kp.xy[pairs[:, 0]], kp.xy[pairs[:, 1]]
    cb, sb = np.cos(beta), np.sin(beta)
    # p_j - c = R (p_i - c)  =>  c = (I - R)^-1 (p_j - R p_i),
    # (I - R)^-1 = [[1 - cb, -sb], [sb, 1 - cb]] / (2 - 2 cb).
    bx = pj[:, 0] - (cb * pi[:, 0] - sb * pi[:, 1])
    by = pj[:, 1] - (sb * pi[:, 0] + cb * pi[:, 1])
    det = 2.0 - 2.0 * cb
    cx = ((1.0 - cb) * bx - sb * by) / det
    cy = (sb * bx + (1.0 - cb) * by) / det
    h, w = shape
    inside = (cx >= 0) & (cx <= w - 1) & (cy >= 0) & (cy <= h - 1)
    pairs, cx, cy = pairs[inside], cx[inside], cy[inside]
    if not len(pairs):
        return np.zeros((0, 3)), ()
    weight = _magnitude_terms(kp, pairs, sigma_s, sigma_d)

    cell = _CENTRE_BIN * diag
    gh, gw = int(np.ceil(h / cell)), int(np.ceil(w / cell))
    ci = np.minimum((cy / cell).astype(np.int64), gh - 1)
    cj = np.minimum((cx / cell).astype(np.int64), gw - 1)
    acc = np.bincount(ci * gw + cj, weights=weight, minlength=gh * gw).reshape(gh, gw)
    acc = _blur(acc, _CENTRE_BLUR)

    centres, support = [], []
    for i0, j0 in _peaks(acc, 2 * n_centres + 2):
        near = ((ci - i0) ** 2 + (cj - j0) ** 2 <= _SUPPORT**2) & (weight > 0)
        if len(centres) < n_centres and _distinct_pairs(pairs[near], loc) >= min_pairs:
            wn = weight[near]
            centres.append((np.average(cx[near], weights=wn), np.average(cy[near], weights=wn), wn.sum()))
            support.append(pairs[near])
    return np.array(centres).reshape(-1, 3), tuple(support)


def symmetries(
    img: np.ndarray,
    *,
    n_features: int = 200,
    work_scale: float = 0.5,
    k: int = 5,
    match_ratio: float = 0.5,
    sigma_s: float = 1.0,
    sigma_d: float | None = 0.25,
    min_distance: float = 0.02,
    min_rotation_deg: float = 15.0,
    n_axes: int = 3,
    n_centres: int = 3,
    min_strength: float = 0.25,
    min_pairs: int = 2,
) -> Symmetries:
    """Strongest bilateral axes and rotation centres of an image (Loy & Eklundh 2006).

    Parameters
    ----------
    img : (H, W, 3) float32 in [0, 1]
    n_features : int, default 200
        SIFT keypoints kept (strongest by contrast); bounds the cost.
    work_scale : float, default 0.5
        SIFT runs on the image resized by this factor.
    k : int, default 5
        Nearest (mirrored, resp. plain) descriptors considered per keypoint;
        a feature repeated round a centre has that many copies to match.
    match_ratio : float, default 0.5
        A candidate match is kept when its descriptor distance is at most
        this fraction of the keypoint's median distance to all others.
    sigma_s : float, default 1.0
        Width of the scale agreement term ``S_ij``.
    sigma_d : float or None, default 0.25
        Width of the distance weighting ``D_ij`` as a fraction of the image
        diagonal; None switches it off.
    min_distance : float, default 0.02
        Keypoints closer than this fraction of the diagonal never pair (SIFT
        reports one location with several orientations).
    min_rotation_deg : float, default 15
        Pairs whose orientations differ by less are treated as translated
        copies and cast no rotation vote.
    n_axes, n_centres : int, default 3
        At most this many axes and centres are kept.
    min_strength : float, default 0.25
        Axes and centres weaker than this fraction of the strongest symmetry
        (of either kind) are dropped.
    min_pairs : int, default 2
        An axis or centre needs at least this many supporting pairs (at
        distinct keypoint locations): a lone pair of look-alike features in
        clutter is no symmetry.

    Returns
    -------
    Symmetries

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> half = cv2.GaussianBlur(rng.random((128, 64)).astype(np.float32), (0, 0), 2)
    >>> half = (half - half.min()) / (half.max() - half.min())
    >>> img = np.repeat(np.hstack([half, half[:, ::-1]])[:, :, None], 3, axis=2)
    >>> sym = symmetries(img)
    >>> theta, r = sym.axes[0, :2]   # the vertical line through the image centre
    >>> bool(min(theta, np.pi - theta) < 0.1 and abs(r) < 3)
    True
    """
    img = check_image(img, "symmetry")
    _check_params(n_features, work_scale, k, match_ratio, sigma_s, sigma_d, n_axes, n_centres, min_strength, min_pairs)
    h, w = img.shape[:2]
    gray = img @ np.array([0.299, 0.587, 0.114], np.float32)
    kp = sift_keypoints(gray, n_features, work_scale)
    none = np.zeros((0, 3))
    if len(kp.xy) < 2:
        return Symmetries(kp, none, (), none, ())
    diag = float(np.hypot(h, w))
    sd = None if sigma_d is None else sigma_d * diag
    allowed = _allowed_pairs(kp, max(min_distance * diag, 1.0))
    loc = np.unique(np.rint(kp.xy[:, 1]) * (w + 1) + np.rint(kp.xy[:, 0]), return_inverse=True)[1]
    mirror_pairs = _matches(kp.descriptors, mirror_descriptors(kp.descriptors), allowed, k, match_ratio)
    axes, axis_pairs = none, ()
    if len(mirror_pairs) and n_axes:
        centre = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
        axes, axis_pairs = _bilateral(kp, mirror_pairs, loc, centre, diag, sigma_s, sd, n_axes, min_pairs)
    rotation_pairs = _matches(kp.descriptors, kp.descriptors, allowed, k, match_ratio)
    centres, centre_pairs = none, ()
    if len(rotation_pairs) and n_centres:
        min_rotation = np.radians(min_rotation_deg)
        centres, centre_pairs = _rotational(
            kp, rotation_pairs, loc, (h, w), diag, sigma_s, sd, min_rotation, n_centres, min_pairs
        )
    top = max(axes[:, 2].max(initial=0.0), centres[:, 2].max(initial=0.0))
    if top <= 0:
        return Symmetries(kp, none, (), none, ())
    keep_a = np.flatnonzero(axes[:, 2] >= min_strength * top)
    keep_a = keep_a[np.argsort(-axes[keep_a, 2], kind="stable")]
    keep_c = np.flatnonzero(centres[:, 2] >= min_strength * top)
    keep_c = keep_c[np.argsort(-centres[keep_c, 2], kind="stable")]
    return Symmetries(
        kp,
        axes[keep_a],
        tuple(axis_pairs[i] for i in keep_a),
        centres[keep_c],
        tuple(centre_pairs[i] for i in keep_c),
    )


def _check_params(n_features, work_scale, k, match_ratio, sigma_s, sigma_d, n_axes, n_centres, min_strength, min_pairs):
    if int(n_features) < 2:
        raise ValueError(f"symmetry: n_features must be at least 2, got {n_features}")
    if not 0.0 < work_scale <= 1.0:
        raise ValueError(f"symmetry: work_scale must be in (0, 1], got {work_scale}")
    if int(k) < 1:
        raise ValueError(f"symmetry: k must be at least 1, got {k}")
    if not match_ratio > 0.0:
        raise ValueError(f"symmetry: match_ratio must be positive, got {match_ratio}")
    if not sigma_s > 0.0:
        raise ValueError(f"symmetry: sigma_s must be positive, got {sigma_s}")
    if sigma_d is not None and not sigma_d > 0.0:
        raise ValueError(f"symmetry: sigma_d must be positive or None, got {sigma_d}")
    if int(n_axes) < 0 or int(n_centres) < 0:
        raise ValueError(f"symmetry: n_axes and n_centres must be >= 0, got {n_axes}, {n_centres}")
    if not 0.0 <= min_strength <= 1.0:
        raise ValueError(f"symmetry: min_strength must be in [0, 1], got {min_strength}")
    if int(min_pairs) < 1:
        raise ValueError(f"symmetry: min_pairs must be at least 1, got {min_pairs}")


# --- the channel: local mirror correlation ------------------------------------

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
_LUMA = np.array([0.299, 0.587, 0.114], np.float32)


def _gaussian_kernel(sigma: float) -> np.ndarray:
    radius = max(1, int(np.ceil(2.5 * sigma)))
    k = np.exp(-0.5 * (np.arange(-radius, radius + 1) / sigma) ** 2)
    return (k / k.sum()).astype(np.float32)


def _mirror_correlation(b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Correlation of each window of ``b`` with its mirror image about a vertical line.

    Returns ``(on, between)``: the line through pixel column ``c``, and the
    line half-way between columns ``c`` and ``c + 1``; both (h, w) float32
    in [-1, 1].  Pairs whose partner falls outside the image are missing,
    and the correlation is scaled down by the square of the fraction of the
    window's weight that is present: a window cut by the border has fewer
    pairs and a noisier correlation.
    """
    h, w = b.shape
    r = max(1, int(np.ceil(2.5 * _ACROSS)))
    m = np.arange(1, r + 1)
    # Partners at c -+ m (on a column) and at c + 1/2 -+ (m - 1/2) (between columns).
    k_on = np.exp(-0.5 * (m / _ACROSS) ** 2)
    k_between = np.exp(-0.5 * ((m - 0.5) / _ACROSS) ** 2)
    k_on, k_between = (k / k.sum() for k in (k_on, k_between))
    # Column j of the window of pixel c holds b[c + j - r], zero off the image.
    window = sliding_window_view(np.pad(b, ((0, 0), (r, r))), 2 * r + 1, axis=1)
    right = window[:, :, r + 1 :]
    num_on = (window[:, :, r - 1 :: -1] * right * k_on.astype(np.float32)).sum(-1)
    num_between = (window[:, :, r:0:-1] * right * k_between.astype(np.float32)).sum(-1)
    # The energy of the same pairs, (b(p)**2 + b(p')**2) / 2, is a plain filter of b**2.
    energy = b * b
    ker_on = (0.5 * np.concatenate([k_on[::-1], [0.0], k_on]))[None].astype(np.float32)
    ker_between = (0.5 * np.concatenate([k_between[::-1], k_between]))[None].astype(np.float32)
    den_on = cv2.filter2D(energy, -1, ker_on, borderType=cv2.BORDER_CONSTANT)
    den_between = cv2.filter2D(energy, -1, ker_between, anchor=(r - 1, 0), borderType=cv2.BORDER_CONSTANT)

    c = np.arange(w)
    present_on = np.concatenate([[0.0], np.cumsum(k_on)])[np.clip(np.minimum(c, w - 1 - c), 0, r)]
    present_between = np.concatenate([[0.0], np.cumsum(k_between)])[np.clip(np.minimum(c + 1, w - 1 - c), 0, r)]
    along = _gaussian_kernel(_ALONG)
    one = np.ones(1, np.float32)
    present_along = cv2.sepFilter2D(np.ones((h, 1), np.float32), -1, one, along, borderType=cv2.BORDER_CONSTANT)
    out = []
    for num, den, present in ((num_on, den_on, present_on), (num_between, den_between, present_between)):
        # A ratio of window sums, not a mean of per-row ratios: rows with
        # little texture must not weigh as much as the rest.
        num = cv2.sepFilter2D(np.ascontiguousarray(num, np.float32), -1, one, along, borderType=cv2.BORDER_CONSTANT)
        den = cv2.sepFilter2D(den, -1, one, along, borderType=cv2.BORDER_CONSTANT)
        coverage = present.astype(np.float32)[None, :] * present_along
        out.append(num / (den + np.float32(_FLOOR)) * coverage * coverage)
    return out[0], out[1]


def _beside(a: np.ndarray) -> np.ndarray:
    """Mean of ``max(a, 0)`` one column to the left and one to the right (edge columns repeated)."""
    pos = np.maximum(a, 0.0)
    left = np.concatenate([pos[:, :1], pos[:, :-1]], axis=1)
    right = np.concatenate([pos[:, 1:], pos[:, -1:]], axis=1)
    return 0.5 * (left + right)


def _axis_evidence(b: np.ndarray) -> np.ndarray:
    """(h, w) float32 in [0, 1]: evidence for a vertical mirror axis through (or next to) each pixel."""
    on, between = _mirror_correlation(b)
    # An axis is a ridge of the correlation, not a plateau (see the module notes).
    on = on - _beside(on)
    between = between - _beside(between)
    # A pixel is next to the lines half a pixel to its left and to its right.
    between_left = np.concatenate([between[:, :1], between[:, :-1]], axis=1)
    return np.clip(np.maximum(on, np.maximum(between, between_left)), 0.0, 1.0)


def _mirror_feature(gray: np.ndarray) -> np.ndarray:
    """(H, W) float32 in [0, 1]: the strongest axis evidence (to the 4th power) over levels and orientations."""
    h, w = gray.shape
    pyramid = gaussian_pyramid(gray, max(_LEVELS) + 1)
    feature = np.zeros((h, w), np.float32)
    for level in _LEVELS:
        if level >= len(pyramid):
            break
        g = pyramid[level]
        b = g - cv2.GaussianBlur(g, (0, 0), _BAND, borderType=cv2.BORDER_REFLECT)
        vertical = _axis_evidence(b)
        horizontal = _axis_evidence(np.ascontiguousarray(b.T)).T
        evidence = np.ascontiguousarray(np.maximum(vertical, horizontal) ** _POWER, dtype=np.float32)
        np.maximum(feature, upsample(evidence, 2**level, (h, w)), out=feature)
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
    img = check_image(img, "symmetry")
    feature = _mirror_feature(img @ _LUMA)
    top = float(feature.max())
    if not top > 0.0:
        return np.zeros(img.shape[:2], np.float32)
    return center_surround_map(feature) * np.float32(top)
