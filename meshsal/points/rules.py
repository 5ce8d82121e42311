"""The options of every point method, and the rules they resolve to on one mesh.

:class:`PointOptions` gathers everything a caller may choose (how many
points, the pad, the spacing, the touch check, how views are rendered and
attended, the seed); :meth:`PointOptions.rules` resolves the lengths that
default to the mesh's size and checks everything once, giving the
:class:`Rules` every method obeys.

``pad_width`` is the tactile pad's width in mesh units, millimetres by
default: 32 mm, a 16 x 16 pad at 2 mm pitch, as on the command line, which
first scales a mesh to a 150 mm principal-frame box diagonal
(``meshsal.scale_to_principal``).  ``min_spacing`` defaults to half of it,
so that neighbouring touches do not share most of their contact.  A mesh
whose size disagrees with the pad's (one in metres, loaded as it is) gets a
:class:`~meshsal.mesh.transform.UnitsWarning` naming both sizes.
"""

from __future__ import annotations

import dataclasses
import numbers
from dataclasses import dataclass

import numpy as np

from meshsal.mesh import Mesh
from meshsal.mesh.transform import check_pad_size
from meshsal.points.touch import PAD_WIDTH

__all__ = ["COMBINATIONS", "MIN_VIEW_SIZE", "PointOptions", "Rules", "default_min_spacing"]

#: How the attention channels are combined: the paper's equal weights, Itti's N(.) on each, or
#: weights learned from touches (``meshsal.points.learned``; given as ``weights``).
COMBINATIONS = ("equal", "itti", "learned")
#: The smallest rendered view (pixels) that the commands, the batch and the experiment take.
MIN_VIEW_SIZE = 16


def default_min_spacing(pad_width: float | None = None) -> float:
    """Half the pad's width (default :data:`meshsal.points.touch.PAD_WIDTH`, 32 mm), in mesh units."""
    return 0.5 * (PAD_WIDTH if pad_width is None else float(pad_width))


@dataclass(frozen=True)
class Rules:
    """What every method obeys on one mesh, lengths in its units (:meth:`PointOptions.rules`).

    ``n`` points at most, no two closer than ``min_spacing``; salient pixels
    and peaks above ``threshold`` times their map's maximum; with ``touch``,
    only points a pad of ``pad_width`` pressed along the normal meets first,
    within ``touch_tolerance`` (None: ``pad_width / 32``).
    """

    n: int
    min_spacing: float
    pad_width: float
    threshold: float = 0.5
    touch: bool = True
    touch_tolerance: float | None = None


@dataclass(frozen=True)
class PointOptions:
    """How points are chosen, for :func:`meshsal.points.interest_points` and its relatives.

    Attributes
    ----------
    n : int
        How many points (fewer only if the mesh cannot hold ``n`` at ``min_spacing``).
    seed : int or numpy Generator
        Seeds the random baselines (the attention pipeline is deterministic).
    min_spacing : float, optional
        No two points closer than this (mesh units); default half of ``pad_width``.
    pad_width : float, optional
        The tactile pad's width, mesh units (default :data:`meshsal.points.touch.PAD_WIDTH`, 32 mm).
    threshold : float in [0, 1)
        Peak and salient-pixel threshold relative to each map's maximum.
    touch : bool
        Skip candidates the pad, pressed along their normal, would not meet
        first (:func:`meshsal.points.touch.touchable`); a result's
        ``untouchable`` counts them.
    touch_tolerance : float, optional
        How far above the point the first contact may lie (default ``pad_width / 32``: 1 mm of a 32 mm pad).
    size : int
        Rendered view size in pixels (the methods that look).
    threads : int, optional
        Rendering and attention threads (default: the CPU count).  The points do not depend on it.
    quiet : bool
        No progress bar on stderr.
    combination : {"equal", "itti", "learned"}
        Deprecated (0.3 removes it): each attention method has its own
        combination ("attention" the paper's equal-weight sum of the
        channels, "attention_itti" each channel weighted by Itti's N(.) as
        well, "attention_learned" weights learned from touches).  Until then
        it changes "attention"'s, unless the method of that combination is
        asked for too.
    weights : dict, optional
        Channel weights of the "learned" combination, without a touch model.
    """

    n: int = 15
    seed: object = 0
    min_spacing: float | None = None
    pad_width: float | None = None
    threshold: float = 0.5
    touch: bool = True
    touch_tolerance: float | None = None
    size: int = 128
    threads: int | None = None
    quiet: bool = True
    combination: str = "equal"
    weights: dict | None = None

    def replace(self, **changes) -> PointOptions:
        """A copy with some fields changed; an unknown field is a TypeError naming it."""
        return dataclasses.replace(self, **changes)

    def rules(self, mesh: Mesh) -> Rules:
        """The rules on ``mesh``: every option checked, the pad's size against the mesh's
        (:func:`~meshsal.mesh.transform.check_pad_size` warns when they disagree).

        Examples
        --------
        >>> from meshsal.mesh import Mesh
        >>> square = Mesh(vertices=[[0, 0, 0], [150, 0, 0], [0, 150, 0]], faces=[[0, 1, 2]])
        >>> r = PointOptions().rules(square)
        >>> r.n, r.min_spacing, r.pad_width
        (15, 16.0, 32.0)
        """
        n = self.n
        if int(n) != n or n < 1:
            raise ValueError(f"n must be a positive integer, got {n!r}")
        if mesh.n_faces == 0:
            raise ValueError(f"mesh {mesh.name!r} has no faces: no surface to put points on")
        if isinstance(self.seed, numbers.Integral) and self.seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {self.seed}")
        if not 0.0 <= self.threshold < 1.0:
            raise ValueError(f"threshold must lie in [0, 1), got {self.threshold}")
        if self.combination not in COMBINATIONS:
            raise ValueError(f"unknown combination {self.combination!r}; expected one of {COMBINATIONS}")
        pad = PAD_WIDTH if self.pad_width is None else float(self.pad_width)
        if not (np.isfinite(pad) and pad > 0):
            raise ValueError(f"pad_width must be a positive length, got {self.pad_width}")
        check_pad_size(mesh, pad, stacklevel=3)
        spacing = default_min_spacing(pad) if self.min_spacing is None else float(self.min_spacing)
        if not (np.isfinite(spacing) and spacing >= 0):
            raise ValueError(f"min_spacing must be a finite length >= 0, got {self.min_spacing}")
        return Rules(int(n), spacing, pad, float(self.threshold), bool(self.touch), self.touch_tolerance)
