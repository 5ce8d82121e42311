"""The curvature channel and the combination of the eight channels into one saliency map."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import cv2
import numpy as np

from meshsal.attention.dkl import dkl, dkl_stack
from meshsal.attention.images import ImageStack
from meshsal.attention.itti import color, color_stack, intensity, intensity_stack, orientation, orientation_stack
from meshsal.attention.local import contrast, contrast_stack, entropy, entropy_stack
from meshsal.attention.pyramid import _stack_to_max, normalize_maps
from meshsal.attention.symmetry import symmetry, symmetry_stack
from meshsal.util.quantiles import percentiles
from meshsal.util.registry import Registry

__all__ = [
    "CHANNELS",
    "CHANNEL_REGISTRY",
    "IMAGE_CHANNELS",
    "SaliencyResult",
    "channel_function",
    "image_channels",
    "image_channels_stack",
    "curvature",
    "outline_radius",
    "erode_mask",
    "combine_maps",
    "plateau_fraction",
    "saliency",
    "saliency_views",
]

#: The eight conspicuity channels; an image channel's value maps (H, W, 3) float32 to (H, W) float32.
#: "curvature" (mesh saliency seen from the view) needs the mesh, so it has no image function.
CHANNEL_REGISTRY = Registry("attention channel")
CHANNEL_REGISTRY.register("intensity", intensity, "Itti's intensity")
CHANNEL_REGISTRY.register("color", color, "Itti's red-green and blue-yellow opponency")
CHANNEL_REGISTRY.register("orientation", orientation, "Gabor energy at four orientations")
CHANNEL_REGISTRY.register("dkl", dkl, "DKL colour contrast")
CHANNEL_REGISTRY.register("symmetry", symmetry, "local mirror symmetry (windowed mirror correlation)")
CHANNEL_REGISTRY.register("curvature", None, "mesh saliency (Lee et al.) seen from the view")
CHANNEL_REGISTRY.register("entropy", entropy, "local entropy")
CHANNEL_REGISTRY.register("contrast", contrast, "local contrast")
CHANNELS = CHANNEL_REGISTRY.names()
IMAGE_CHANNELS = tuple(e.name for e in CHANNEL_REGISTRY if e.value is not None)

# Channel functions that also run on an ImageStack -> (n, H, W), bit for bit image by image (see
# image_channels_stack).
_STACKED = {
    intensity: intensity_stack,
    color: color_stack,
    orientation: orientation_stack,
    dkl: dkl_stack,
    symmetry: symmetry_stack,
    entropy: entropy_stack,
    contrast: contrast_stack,
}
# Views a thread takes at once in saliency_views: enough to share the pyramids' per-call costs, few enough
# that two threads share 72 views evenly.  On the cow's 72 views (two threads at 256 px) 12, 18 and 36 are
# within the machine's noise of each other; on corpus meshes at 128 px (the batch's case) one thread spends
# 3 % less CPU on 36 than on 18 (120 meshes, each computed both ways in turn).
_VIEWS_PER_STACK = 36
# Python's switch interval while saliency_views' pool runs (its default is 5 ms).
_SWITCH_S = 0.0005


def channel_function(name: str):
    """The function ``(img (H, W, 3) float32) -> (H, W) float32`` of an image channel."""
    if name not in IMAGE_CHANNELS:
        raise ValueError(f"unknown image channel {name!r}; expected one of {IMAGE_CHANNELS}")
    return CHANNEL_REGISTRY.get(name)


@dataclass(frozen=True, eq=False)
class SaliencyResult:
    """Saliency of one view.

    Attributes
    ----------
    map : (H, W) float32 in [0, 1]
        Weighted combination of the channels, zero outside the eroded silhouette.
    channels : dict str -> (H, W) float32 in [0, 1]
        The eight conspicuity maps, keyed by the names of ``CHANNELS``, over the
        whole image (not masked).
    """

    map: np.ndarray
    channels: dict


def image_channels(img: np.ndarray, names: Sequence[str] = IMAGE_CHANNELS) -> dict[str, np.ndarray]:
    """Compute several image channels of one RGB image.

    Parameters
    ----------
    img : (H, W, 3) float32 in [0, 1]
    names : sequence of image channel names (all seven by default)

    Returns
    -------
    dict name -> (H, W) float32 in [0, 1]
    """
    return {name: channel_function(name)(img) for name in names}


def image_channels_stack(imgs, names: Sequence[str] = IMAGE_CHANNELS) -> dict[str, np.ndarray]:
    """:func:`image_channels` of a stack of images, bit for bit image by image.

    The images are checked once, each grey level and pyramid several
    channels read is computed once, and the center-surround pyramids are
    normalized for the whole stack at once; channels registered from
    outside run image by image.

    Parameters
    ----------
    imgs : (n, H, W, 3) float32 in [0, 1], or a sequence of n such images of one shape
    names : sequence of image channel names (all seven by default)

    Returns
    -------
    dict name -> (n, H, W) float32 in [0, 1]

    Examples
    --------
    >>> imgs = np.full((3, 64, 64, 3), 0.2, np.float32); imgs[1, 10:20, 40:50] = 0.9
    >>> m = image_channels_stack(imgs, ["intensity"])["intensity"]
    >>> m.shape, bool(m[1, 15, 45] > 0.5), bool(m[0].any())
    ((3, 64, 64), True, False)
    """
    if not len(imgs):
        raise ValueError("image_channels_stack needs at least one image")
    functions = {name: channel_function(name) for name in names}
    stack = ImageStack.of(imgs, ", ".join(names))
    out = {}
    for name, fn in functions.items():
        stacked = _STACKED.get(fn)
        out[name] = stacked(stack) if stacked is not None else np.stack([fn(img) for img in stack.rgb])
    return out


def curvature(view, vertex_saliency: np.ndarray) -> np.ndarray:
    """Render per-vertex saliency into a view (the curvature channel).

    Each object pixel interpolates the values of the three vertices of the
    face it sees with its barycentric weights; background pixels are zero.
    Values are min-max scaled over the whole mesh, not the view, so a vertex
    has the same value in every view and a view without salient geometry is
    not inflated.

    Parameters
    ----------
    view : View
        Uses ``view.face_id`` (H, W) int (-1 on background), ``view.faces`` and ``view.bary`` (H, W, 3).
    vertex_saliency : (n,) float, e.g. ``meshsal.mesh_saliency(mesh)``

    Returns
    -------
    (H, W) float32 in [0, 1]

    Examples
    --------
    >>> from types import SimpleNamespace  # what curvature reads of a View
    >>> v = SimpleNamespace(face_id=np.array([[0, -1]]), faces=np.array([[0, 1, 2]]),
    ...                     bary=np.array([[[0.5, 0.5, 0.0], [0, 0, 0]]]))
    >>> curvature(v, np.array([0.0, 1.0, 2.0])).tolist()
    [[0.25, 0.0]]
    """
    values = np.asarray(vertex_saliency, dtype=np.float64)
    if values.ndim != 1:
        raise ValueError(f"vertex_saliency must be a 1-D array with one value per vertex, got shape {values.shape}")
    if not np.isfinite(values).all():
        raise ValueError("vertex_saliency contains NaN or infinite values")
    # Pixels by flat index (indexing by a mask would take most of the channel's time), and the corners of the
    # faces the object's pixels see, not the whole image's.
    face_id = np.asarray(view.face_id).reshape(-1)
    pixels = np.flatnonzero(face_id >= 0)
    corners = np.take(view.faces, face_id[pixels], axis=0)
    if pixels.size and int(corners.max()) >= values.size:
        raise ValueError(f"vertex_saliency has {values.size} values but the view shows vertex {int(corners.max())}")
    out = np.zeros(np.shape(view.face_id), np.float32)
    if values.size == 0:
        return out
    lo, span = float(values.min()), float(np.ptp(values))
    if not span > 0:
        return out
    scaled = ((values - lo) / span).astype(np.float32)
    bary = np.asarray(view.bary, np.float32).reshape(-1, 3)[pixels]
    out.ravel()[pixels] = np.einsum("kc,kc->k", scaled[corners], bary)
    return np.clip(out, 0.0, 1.0)


def outline_radius(shape: tuple[int, int]) -> int:
    """Default silhouette erosion: 2% of the image's longer side (5 px at 256), at least 1."""
    return max(1, int(round(0.02 * max(shape[:2]))))


def erode_mask(mask: np.ndarray, radius: int | None = None) -> np.ndarray:
    """Shrink a silhouette by ``radius`` pixels (a disk), dropping the band along its outline.

    The paper removes the salient regions around the object's outline: the
    contrast between object and background is not a property of the object.

    Parameters
    ----------
    mask : (H, W) bool
    radius : int, optional
        Default :func:`outline_radius`; 0 returns the mask unchanged.

    Returns
    -------
    (H, W) bool
    """
    mask = np.asarray(mask, dtype=bool)
    if mask.ndim != 2:
        raise ValueError(f"mask must be (H, W), got shape {mask.shape}")
    r = outline_radius(mask.shape) if radius is None else int(radius)
    if r < 0:
        raise ValueError(f"erosion radius must be non-negative, got {radius}")
    if r == 0:
        return mask.copy()
    disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    # Outside the image counts as background, so the outline at the border is eroded too.
    eroded = cv2.erode(mask.astype(np.uint8), disk, borderType=cv2.BORDER_CONSTANT, borderValue=0)
    return eroded.astype(bool)


def _check_weights(weights: Mapping[str, float] | None) -> dict[str, float]:
    if weights is None:
        return dict.fromkeys(CHANNELS, 1.0)
    if not isinstance(weights, Mapping):
        raise ValueError(f"weights must be a dict channel name -> float, got {type(weights).__name__}")
    unknown = sorted(set(weights) - set(CHANNELS))
    if unknown:
        raise ValueError(f"unknown channel(s) in weights: {unknown}; expected names from {CHANNELS}")
    out = dict.fromkeys(CHANNELS, 0.0)
    for name, w in weights.items():
        w = float(w)
        if not (np.isfinite(w) and w >= 0):
            raise ValueError(f"weight of channel {name!r} must be finite and non-negative, got {w}")
        out[name] = w
    if not sum(out.values()) > 0:
        raise ValueError("weights are all zero: at least one channel needs a positive weight")
    return out


def combine_maps(
    channels: Mapping[str, np.ndarray],
    mask: np.ndarray,
    weights: Mapping[str, float] | None = None,
    erode: int | None = None,
    normalize: bool = True,
    floor: float | None = 50.0,
) -> np.ndarray:
    """Weighted combination of channel maps inside the eroded silhouette.

    Each channel is cut to the silhouette shrunk by ``erode`` pixels (see
    :func:`erode_mask`), scaled to [0, 1] and lowered by its ``floor``
    percentile there (clipped at 0); with ``normalize`` it is
    then multiplied by its N(.) amplitude, as Itti combines conspicuity maps
    (S = sum of N(conspicuity)): :func:`~meshsal.attention.pyramid.normalize_map`
    of the cut map averaged down to the resolution of scale 4 (1/16), so a
    channel with one outstanding region counts fully and a channel that
    responds everywhere on the object counts little.  The weighted sum is
    divided by its maximum.

    Parameters
    ----------
    channels : dict name -> (H, W) map; every channel with a positive weight must be present
    mask : (H, W) bool silhouette
    weights : dict name -> float, optional
        Equal weights for the eight channels by default; channels missing
        from a given dict weigh zero; unknown names raise ValueError.
    erode : int, optional
        Erosion radius in pixels (default :func:`outline_radius`).
    normalize : bool
        Apply N(.) to each channel before summing (default True).
    floor : float in [0, 100] or None
        Percentile of a channel's values inside the silhouette that is
        subtracted from it (default 50, the median).  A level that most of
        the object reaches says nothing about where to look: without it a
        channel high all over the object lifts the whole map into a plateau
        (on the ten YCB scans half the maximum covered a median 39% of the
        silhouette with equal weights and 63% with N(.); 13% and 16% with
        the median removed).  The remainder is not stretched back to
        [0, 1], so a channel whose peak barely clears its level counts
        little instead of having its ripples amplified.  Higher percentiles
        shrink the plateaus further by construction, since a channel then
        covers at most ``100 - floor`` percent of the object, and erase
        larger features.  None keeps the channels as they are.

    Returns
    -------
    (H, W) float32 in [0, 1], zero outside the eroded mask.
    """
    w = _check_weights(weights)
    if floor is not None and not 0.0 <= floor <= 100.0:
        raise ValueError(f"floor must be a percentile in [0, 100] or None, got {floor}")
    inside = erode_mask(mask, erode)
    # Picking the silhouette's pixels by index is faster than by mask, eight times over.
    pixels = np.flatnonzero(inside)
    h, wd = inside.shape
    small = (max(1, wd // 16), max(1, h // 16))
    names = [name for name, weight in w.items() if weight != 0]
    for name in names:
        if name not in channels:
            raise ValueError(f"channel {name!r} has weight {w[name]} but its map was not given")
        shape = np.shape(channels[name])
        if shape != inside.shape:
            raise ValueError(f"channel {name!r} has shape {shape}, the mask {inside.shape}")
    gains = [w[name] for name in names]
    # Every cut map is zero off the silhouette: work on its pixels only, each channel scaled to its maximum.
    cuts = np.empty((len(names), pixels.size), np.float32)
    for k, name in enumerate(names):
        cuts[k] = np.asarray(channels[name]).reshape(-1)[pixels]
    _stack_to_max(cuts)
    if floor is not None and pixels.size:
        # Not rescaled (see ``floor``).
        cuts -= percentiles(cuts, floor)[:, None]
        np.maximum(cuts, np.float32(0.0), out=cuts)
    if normalize:
        # N(.) of every channel that responds, in one pass.
        live = np.flatnonzero(cuts.any(axis=1))
        if live.size:
            image = np.zeros(h * wd, np.float32)
            shrunk = []
            for k in live:
                image[pixels] = cuts[k]
                shrunk.append(cv2.resize(image.reshape(h, wd), small, interpolation=cv2.INTER_AREA))
            for k, amplitude in zip(live, normalize_maps(np.stack(shrunk)).reshape(len(live), -1).max(axis=1)):
                gains[k] *= float(amplitude)
    total = np.zeros(pixels.size, np.float32)
    for cut, gain in zip(cuts, gains):
        total += np.float32(gain) * cut
    out = np.zeros(h * wd, np.float32)
    out[pixels] = _stack_to_max(total[None])[0]
    return out.reshape(h, wd)


def plateau_fraction(saliency_map: np.ndarray, mask: np.ndarray, erode: int | None = None) -> float:
    """Share of the (eroded) silhouette where the map reaches half its maximum there.

    A measure of peaks against plateaus: a map that singles out a few spots
    scores near 0, one that is high over the whole object near 1.

    Parameters
    ----------
    saliency_map : (H, W) float
    mask : (H, W) bool silhouette
    erode : int, optional
        As in :func:`combine_maps` (default :func:`outline_radius`).

    Returns
    -------
    float in [0, 1]; 0 for an empty silhouette or a zero map.

    Examples
    --------
    >>> m = np.zeros((64, 64), np.float32); m[30:34, 30:34] = 1.0
    >>> round(plateau_fraction(m, np.ones((64, 64), bool), erode=0), 4)
    0.0039
    """
    inside = erode_mask(mask, erode)
    values = np.asarray(saliency_map, dtype=np.float64)[inside]
    if values.size == 0 or not values.max() > 0:
        return 0.0
    return float(np.mean(values >= 0.5 * values.max()))


def _combined(view, channels: dict, vertex_saliency, weights, normalize: bool) -> SaliencyResult:
    """A view's :class:`SaliencyResult` from its image channels: adds the curvature channel, combines."""
    channels = {**channels, "curvature": curvature(view, vertex_saliency)}
    channels = {name: channels[name] for name in CHANNELS}
    return SaliencyResult(map=combine_maps(channels, view.mask, weights, normalize=normalize), channels=channels)


def saliency(
    view, mesh, weights: Mapping[str, float] | None = None, vertex_saliency=None, normalize: bool = True
) -> SaliencyResult:
    """The eight-channel saliency map of one rendered view.

    Parameters
    ----------
    view : View
        From :mod:`meshsal.views.render`; the image channels use ``view.rgb``, the
        curvature channel ``view.face_id`` and ``view.bary``.
    mesh : Mesh
        The rendered mesh.
    weights : dict name -> float, optional
        Equal weights by default (see :func:`combine_maps`).
    vertex_saliency : (n,) float, optional
        Per-vertex mesh saliency; computed with
        ``meshsal.mesh.curvature.mesh_saliency(mesh)`` when omitted.  Pass it when
        processing many views of one mesh.
    normalize : bool
        Weight each channel by Itti's N(.) too (see :func:`combine_maps`);
        False is the paper's plain weighted sum.

    Returns
    -------
    SaliencyResult
        ``map`` zero outside the silhouette eroded by :func:`outline_radius`
        pixels, so that the object-background edge does not dominate;
        ``channels`` the eight full-image maps.
    """
    w = _check_weights(weights)
    if vertex_saliency is None:
        from meshsal.mesh.curvature import mesh_saliency

        vertex_saliency = mesh_saliency(mesh)
    return _combined(view, image_channels(view.rgb), vertex_saliency, w, normalize)


def saliency_views(
    views: Sequence,
    mesh,
    weights: Mapping[str, float] | None = None,
    vertex_saliency=None,
    threads: int | None = None,
    quiet: bool = True,
    normalize: bool = True,
) -> list[SaliencyResult]:
    """:func:`saliency` of many views of one mesh, in a thread pool, bit for bit view by view.

    The mesh saliency is computed once.  Each thread takes up to ``_VIEWS_PER_STACK`` views
    of one size at once (:func:`image_channels_stack`): per view, the
    center-surround pyramids' hundreds of calls on small maps, each of which
    holds Python's lock and hands it over between threads, become a share of
    a few calls on the stack.

    Parameters
    ----------
    views : sequence of View
    mesh : Mesh
    weights, vertex_saliency, normalize : as in :func:`saliency`
    threads : int, optional, worker threads (default: the CPU count); with more than one, OpenCV's own
        threads are capped at one and Python's switch interval set to 0.5 ms for the call (both
        process-wide), then restored
    quiet : bool, no progress bar on stderr

    Returns
    -------
    list of SaliencyResult, in the order of ``views``
    """
    views = list(views)
    w = _check_weights(weights)
    if vertex_saliency is None:
        from meshsal.mesh.curvature import mesh_saliency

        vertex_saliency = mesh_saliency(mesh)
    stacks = _stacks(views, _VIEWS_PER_STACK)

    def one(stack):
        channels = image_channels_stack([v.rgb for v in stack])
        return [
            _combined(view, {name: maps[k] for name, maps in channels.items()}, vertex_saliency, w, normalize)
            for k, view in enumerate(stack)
        ]

    from meshsal.util.progress import progress

    workers = threads or os.cpu_count() or 1
    if workers == 1 or len(stacks) <= 1:
        done = progress(map(one, stacks), total=len(stacks), desc="saliency", quiet=quiet)
        return [r for results in done for r in results]
    from meshsal.util.threads import opencv_threads, switch_interval

    # The pool's threads fill the cores: OpenCV's own threads within each call would only contend with them.
    # The cap is process-wide, for the call's duration; every OpenCV call here gives the same bits either way.
    # A thread back from a C call waits for Python's lock less at a short switch interval (5 % of the wall
    # time on 72 views and 2 cores).
    with opencv_threads(1), switch_interval(_SWITCH_S), ThreadPoolExecutor(max_workers=workers) as pool:
        done = progress(pool.map(one, stacks), total=len(stacks), desc="saliency", quiet=quiet)
        return [r for results in done for r in results]


def _stacks(views: list, size: int) -> list[list]:
    """Consecutive runs of at most ``size`` views whose images have one shape, in order."""
    stacks = []
    for view in views:
        if stacks and len(stacks[-1]) < size and stacks[-1][0].rgb.shape == view.rgb.shape:
            stacks[-1].append(view)
        else:
            stacks.append([view])
    return stacks
