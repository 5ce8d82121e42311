"""Where to touch: interest points by visual attention, the baselines and the learned method.

The modules follow a method's steps: the options every method takes and the
rules they resolve to on a mesh (``rules``); the methods by name and the
dispatcher (``methods``); the paper's attention pipeline (``attend``), the
baselines (``baselines``) and the learned touch saliency (``learned``); the
selection they share: spacing, the touch check, the fill (``select``, on
``sampling`` and ``touch``); the record of chosen points and its files
(``record``); the record of a mesh being worked on, which every stage
shares (``workpiece``).
"""

from meshsal.attention.rig import ViewChannels, attention_maps, saliency_maps, view_channels
from meshsal.points.attend import attention_points, best_view_set, map_peaks
from meshsal.points.learned import learned_points
from meshsal.points.methods import (
    ATTENTION_METHODS,
    METHODS,
    MODEL_METHODS,
    POINT_METHODS,
    PointMethod,
    attention_combination,
    interest_points,
    method_points,
    points_by_method,
)
from meshsal.points.record import InterestPoints
from meshsal.points.rules import COMBINATIONS, PointOptions, Rules, default_min_spacing
from meshsal.points.workpiece import Workpiece
from meshsal.views.paper_projection import project_pixel_paper

__all__ = [
    "METHODS",
    "POINT_METHODS",
    "PointMethod",
    "PointOptions",
    "Rules",
    "InterestPoints",
    "interest_points",
    "default_min_spacing",
    "saliency_maps",
    "best_view_set",
    "map_peaks",
    "attention_points",
    "project_pixel_paper",
    "COMBINATIONS",
    "ATTENTION_METHODS",
    "MODEL_METHODS",
    "attention_combination",
    "ViewChannels",
    "view_channels",
    "attention_maps",
    "learned_points",
    "points_by_method",
    "method_points",
    "Workpiece",
]
