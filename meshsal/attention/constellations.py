"""Loy & Eklundh's symmetric feature constellations (:func:`symmetries`): where and how an image is symmetric.

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

The attention pipeline's symmetry channel no longer uses this (it is
:mod:`meshsal.attention.symmetry`); it stays, public, as the method the paper
cites and as the reference the channel's pop-out tests were measured
against.  About 500 lines: the paper's two symmetries (mirror, rotation),
matching and voting, which only read well together.

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

import dataclasses
from dataclasses import dataclass

import cv2
import numpy as np

from meshsal.attention.images import check_image
from meshsal.attention.local import luma

__all__ = ["symmetries", "ConstellationOptions", "Symmetries", "Keypoints", "sift_keypoints", "mirror_descriptors"]

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


@dataclass(frozen=True)
class ConstellationOptions:
    """How :func:`symmetries` matches features and keeps symmetries.

    Attributes
    ----------
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

    """

    n_features: int = 200
    work_scale: float = 0.5
    k: int = 5
    match_ratio: float = 0.5
    sigma_s: float = 1.0
    sigma_d: float | None = 0.25
    min_distance: float = 0.02
    min_rotation_deg: float = 15.0
    n_axes: int = 3
    n_centres: int = 3
    min_strength: float = 0.25
    min_pairs: int = 2

    def __post_init__(self):
        if int(self.n_features) < 2:
            raise ValueError(f"symmetry: n_features must be at least 2, got {self.n_features}")
        if not 0.0 < self.work_scale <= 1.0:
            raise ValueError(f"symmetry: work_scale must be in (0, 1], got {self.work_scale}")
        if int(self.k) < 1:
            raise ValueError(f"symmetry: k must be at least 1, got {self.k}")
        if not self.match_ratio > 0.0:
            raise ValueError(f"symmetry: match_ratio must be positive, got {self.match_ratio}")
        if not self.sigma_s > 0.0:
            raise ValueError(f"symmetry: sigma_s must be positive, got {self.sigma_s}")
        if self.sigma_d is not None and not self.sigma_d > 0.0:
            raise ValueError(f"symmetry: sigma_d must be positive or None, got {self.sigma_d}")
        if int(self.n_axes) < 0 or int(self.n_centres) < 0:
            raise ValueError(f"symmetry: n_axes and n_centres must be >= 0, got {self.n_axes}, {self.n_centres}")
        if not 0.0 <= self.min_strength <= 1.0:
            raise ValueError(f"symmetry: min_strength must be in [0, 1], got {self.min_strength}")
        if int(self.min_pairs) < 1:
            raise ValueError(f"symmetry: min_pairs must be at least 1, got {self.min_pairs}")


def symmetries(img: np.ndarray, options: ConstellationOptions | None = None, **changes) -> Symmetries:
    """Strongest bilateral axes and rotation centres of an image (Loy & Eklundh 2006).

    Parameters
    ----------
    img : (H, W, 3) float32 in [0, 1]
    options : ConstellationOptions, optional
        Default ``ConstellationOptions()``, changed by any ``**changes``
        named as its fields (``sigma_d=None``...).

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
    o = dataclasses.replace(options or ConstellationOptions(), **changes)
    h, w = img.shape[:2]
    gray = luma(img)
    kp = sift_keypoints(gray, o.n_features, o.work_scale)
    none = np.zeros((0, 3))
    if len(kp.xy) < 2:
        return Symmetries(kp, none, (), none, ())
    diag = float(np.hypot(h, w))
    sd = None if o.sigma_d is None else o.sigma_d * diag
    allowed = _allowed_pairs(kp, max(o.min_distance * diag, 1.0))
    loc = np.unique(np.rint(kp.xy[:, 1]) * (w + 1) + np.rint(kp.xy[:, 0]), return_inverse=True)[1]
    mirror_pairs = _matches(kp.descriptors, mirror_descriptors(kp.descriptors), allowed, o.k, o.match_ratio)
    axes, axis_pairs = none, ()
    if len(mirror_pairs) and o.n_axes:
        centre = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
        axes, axis_pairs = _bilateral(kp, mirror_pairs, loc, centre, diag, o.sigma_s, sd, o.n_axes, o.min_pairs)
    rotation_pairs = _matches(kp.descriptors, kp.descriptors, allowed, o.k, o.match_ratio)
    centres, centre_pairs = none, ()
    if len(rotation_pairs) and o.n_centres:
        min_rotation = np.radians(o.min_rotation_deg)
        centres, centre_pairs = _rotational(
            kp, rotation_pairs, loc, (h, w), diag, o.sigma_s, sd, min_rotation, o.n_centres, o.min_pairs
        )
    top = max(axes[:, 2].max(initial=0.0), centres[:, 2].max(initial=0.0))
    if top <= 0:
        return Symmetries(kp, none, (), none, ())
    keep_a = np.flatnonzero(axes[:, 2] >= o.min_strength * top)
    keep_a = keep_a[np.argsort(-axes[keep_a, 2], kind="stable")]
    keep_c = np.flatnonzero(centres[:, 2] >= o.min_strength * top)
    keep_c = keep_c[np.argsort(-centres[keep_c, 2], kind="stable")]
    return Symmetries(
        kp,
        axes[keep_a],
        tuple(axis_pairs[i] for i in keep_a),
        centres[keep_c],
        tuple(centre_pairs[i] for i in keep_c),
    )
