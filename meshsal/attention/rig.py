"""Attention on a mesh's 72 views: render the rig once, compute the channels once, combine as needed.

:func:`view_channels` renders the 72 views of :func:`meshsal.views.cameras.view_rig`
and computes each one's eight channel maps; :func:`attention_maps` combines
them into saliency maps with any combination, so several point methods share
one rendering.  :func:`saliency_maps` does both in one call.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshsal.attention.combine import combine_maps, saliency_views
from meshsal.mesh import Mesh

__all__ = ["ViewChannels", "view_channels", "attention_maps", "saliency_maps"]


@dataclass(frozen=True, eq=False)
class ViewChannels:
    """A mesh's 72 rendered views and their eight channel maps: render once, combine as each method needs.

    ``views`` list of 72 View in rig order; ``results`` the matching
    ``meshsal.attention.SaliencyResult`` as :func:`view_channels` computes
    them: their ``channels``, and their ``map`` the channels' equal-weight
    combination without N(.), which :func:`attention_maps` returns for
    "equal".
    """

    views: list
    results: list


def _rig_views(mesh: Mesh, size: int, threads: int | None, scene=None) -> list:
    from meshsal.views.cameras import view_rig
    from meshsal.views.render import render_views

    return render_views(mesh, [c for s in view_rig() for c in s], size=size, threads=threads, scene=scene)


def view_channels(
    mesh: Mesh, size: int = 128, vertex_saliency=None, threads: int | None = None, quiet: bool = True, scene=None
) -> ViewChannels:
    """Render the rig's 72 views and compute each one's channels (arguments as in :func:`saliency_maps`;
    ``scene`` as in :func:`meshsal.views.render.render_views`)."""
    views = _rig_views(mesh, size, threads, scene)
    return ViewChannels(
        views,
        saliency_views(views, mesh, vertex_saliency=vertex_saliency, threads=threads, quiet=quiet, normalize=False),
    )


def attention_maps(seen: ViewChannels, combination: str = "equal", weights=None) -> np.ndarray:
    """(72, H, W) float32 saliency maps combined from channels already computed.

    The same maps as :func:`saliency_maps` with that ``combination`` and
    ``weights`` ("learned" is a weighted sum with the given weights).
    """
    if combination == "equal" and weights is None:
        # Combined so already, view by view.
        return np.stack([r.map for r in seen.results]).astype(np.float32)
    return np.stack(
        [
            combine_maps(r.channels, v.mask, weights, normalize=combination == "itti")
            for v, r in zip(seen.views, seen.results)
        ]
    ).astype(np.float32)


def saliency_maps(
    mesh: Mesh,
    size: int = 128,
    vertex_saliency=None,
    quiet: bool = True,
    weights=None,
    threads: int | None = None,
    combination: str = "equal",
):
    """Render the 72 views of the rig and compute each one's saliency map.

    Parameters
    ----------
    mesh : Mesh
    size : int
        Image size in pixels.
    vertex_saliency : (n,) float64, optional
        Mesh saliency for the curvature channel (computed when omitted).
    quiet : bool
        No progress bar on stderr.
    weights : dict, optional
        Channel weights of :func:`meshsal.attention.saliency`.
    threads : int, optional
        Worker threads (default: the CPU count).
    combination : {"equal", "itti"}
        The paper's weighted sum, or each channel weighted by N(.) too.

    Returns
    -------
    views : list of 72 View, in rig order (view ``4 * s + k`` is camera ``k`` of set ``s``)
    maps : (72, size, size) float32 in [0, 1]
    """
    views = _rig_views(mesh, size, threads)
    results = saliency_views(
        views,
        mesh,
        weights=weights,
        vertex_saliency=vertex_saliency,
        threads=threads,
        quiet=quiet,
        normalize=combination == "itti",
    )
    return views, np.stack([r.map for r in results]).astype(np.float32)
