"""Visual attention: the eight conspicuity maps of a rendered view and their combination.

The improved attention model of Rouhafzay, Pedneault & Cretu (2017) extends
Itti, Koch & Niebur (1998) with symmetry, curvature, DKL color, entropy and
contrast channels.  Each image channel is a plain function
``(img (H, W, 3) float32 in [0, 1]) -> (H, W) float32 in [0, 1]``:

>>> import numpy as np
>>> from meshsal import attention
>>> img = np.full((64, 64, 3), 0.2, np.float32); img[10:20, 40:50] = 0.9
>>> attention.intensity(img).shape
(64, 64)

``curvature(view, vertex_saliency)`` renders per-vertex mesh saliency
into a view, ``saliency(view, mesh)`` combines the eight channels and
``saliency_views(views, mesh)`` does so for many views in a thread pool, in stacks
(``image_channels_stack``: the channels of many images at once, bit for bit each one's own);
``view_channels(mesh)`` renders a mesh's 72 views and computes their channels
once, ``attention_maps`` combines them as a method needs (``rig``).
"""

# Functions are bound after their modules, so ``attention.dkl`` and
# ``attention.symmetry`` are the channel functions, not the submodules.
from meshsal.attention.combine import (
    CHANNELS,
    IMAGE_CHANNELS,
    SaliencyResult,
    combine_maps,
    curvature,
    erode_mask,
    image_channels,
    image_channels_stack,
    plateau_fraction,
    saliency,
    saliency_views,
)
from meshsal.attention.dkl import dkl
from meshsal.attention.itti import color, intensity, orientation
from meshsal.attention.local import contrast, entropy
from meshsal.attention.pyramid import center_surround_map, gaussian_pyramid, normalize_map
from meshsal.attention.rig import ViewChannels, attention_maps, saliency_maps, view_channels
from meshsal.attention.symmetry import symmetry

__all__ = [
    "CHANNELS",
    "IMAGE_CHANNELS",
    "SaliencyResult",
    "center_surround_map",
    "color",
    "combine_maps",
    "plateau_fraction",
    "contrast",
    "curvature",
    "dkl",
    "entropy",
    "erode_mask",
    "gaussian_pyramid",
    "image_channels",
    "image_channels_stack",
    "intensity",
    "normalize_map",
    "orientation",
    "saliency",
    "saliency_views",
    "symmetry",
    "ViewChannels",
    "view_channels",
    "attention_maps",
    "saliency_maps",
]
