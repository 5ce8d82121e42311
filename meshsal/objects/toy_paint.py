"""The paint of the six toys: a colour per vertex from its part's name and its position.

Each paint is a function ``(V (n, 3) mm, labels (n,) part names, rng) ->
(n, 3) float64`` RGB in [0, 1]: a base colour per part (the parts of
:mod:`meshsal.objects.toy_shapes`), then details drawn where they are (the
cow's patches, the plane's windows, the cup's rim).  ``rng`` varies only the
paint: the cow's patches and the colours of frame, livery, cup, skin and
coat.

Examples
--------
>>> colors = hand(np.zeros((2, 3)), np.array(["skin", "nail"]), np.random.default_rng(0))
>>> colors.shape, bool(colors[1].tolist() == [0.98, 0.86, 0.84])
((2, 3), True)
"""

from __future__ import annotations

import numpy as np

from meshsal.objects.toy_shapes import CUP_HEIGHT

__all__ = ["cow", "glasses", "cup", "hand", "plane", "dromedary"]


def _rgb(*c) -> np.ndarray:
    return np.array(c, dtype=np.float64)


def _base_colors(labels: np.ndarray, palette: dict) -> np.ndarray:
    colors = np.zeros((len(labels), 3))
    for name, color in palette.items():
        colors[labels == name] = color
    return colors


def _jitter(rng, color, amount: float = 0.04) -> np.ndarray:
    return np.clip(np.asarray(color) + rng.uniform(-amount, amount, 3), 0.0, 1.0)


def _one_of(rng, choices, amount: float) -> np.ndarray:
    """One of the colours, drawn, then jittered by up to ``amount``."""
    return _jitter(rng, choices[rng.integers(len(choices))], amount)


def cow(V, labels, rng) -> np.ndarray:
    white, dark = _rgb(0.96, 0.95, 0.92), _rgb(0.12, 0.10, 0.09)
    colors = _base_colors(
        labels,
        {
            **dict.fromkeys(("body", "neck", "head", "ear", "leg", "tail"), white),
            **dict.fromkeys(("muzzle", "udder"), _rgb(0.93, 0.66, 0.68)),
            "eye": _rgb(0.04, 0.04, 0.04),
            "horn": _rgb(0.90, 0.85, 0.70),
            "hoof": _rgb(0.22, 0.20, 0.18),
            "tuft": dark,
        },
    )
    # Patches: random blobs over the coat, their edges wobbled by a few mm.
    n = 9
    centers = np.column_stack([rng.uniform(-35, 35, n), rng.uniform(45, 100, n), rng.uniform(-60, 90, n)])
    radii = rng.uniform(14, 26, n)
    phase = rng.uniform(0, 2 * np.pi, 3)
    W = V + 4.0 * np.sin(V[:, [1, 2, 0]] / 7.0 + phase)
    inside = (np.linalg.norm(W[:, None, :] - centers[None], axis=2) < radii).any(axis=1)
    coat = np.isin(labels, ["body", "neck", "head", "ear", "leg", "tail"])
    colors[coat & inside] = dark
    return colors


def glasses(V, labels, rng) -> np.ndarray:
    frame = _one_of(
        rng, [_rgb(0.75, 0.12, 0.10), _rgb(0.12, 0.30, 0.75), _rgb(0.45, 0.25, 0.10), _rgb(0.10, 0.55, 0.30)], 0.03
    )
    return _base_colors(
        labels,
        {
            "lens": _rgb(0.07, 0.09, 0.12),
            "frame": frame,
            "temple": frame,
            "pad": _rgb(0.80, 0.80, 0.78),
            "hinge": _rgb(0.62, 0.62, 0.64),
        },
    )


def cup(V, labels, rng) -> np.ndarray:
    body = _one_of(
        rng, [_rgb(0.15, 0.35, 0.70), _rgb(0.85, 0.30, 0.15), _rgb(0.20, 0.55, 0.35), _rgb(0.90, 0.75, 0.20)], 0.03
    )
    colors = _base_colors(
        labels, {"body": body, "handle": body, "rim": _rgb(0.97, 0.97, 0.95), "inside": 0.55 + 0.45 * body}
    )
    colors[(V[:, 1] > CUP_HEIGHT - 6.0) & (labels != "inside")] = _rgb(0.97, 0.97, 0.95)
    return colors


def hand(V, labels, rng) -> np.ndarray:
    skin = _jitter(rng, _rgb(0.93, 0.74, 0.60), 0.04)
    return _base_colors(labels, {"skin": skin, "nail": _rgb(0.98, 0.86, 0.84)})


def plane(V, labels, rng) -> np.ndarray:
    livery = _one_of(
        rng, [_rgb(0.10, 0.30, 0.75), _rgb(0.80, 0.12, 0.12), _rgb(0.10, 0.55, 0.45), _rgb(0.95, 0.55, 0.10)], 0.03
    )
    white, window = _rgb(0.96, 0.96, 0.97), _rgb(0.10, 0.14, 0.25)
    colors = _base_colors(
        labels,
        {
            "fuselage": white,
            "wing": livery,
            "tail": livery,
            "fin": livery,
            "pylon": _rgb(0.7, 0.7, 0.72),
            "engine": _rgb(0.62, 0.63, 0.66),
        },
    )
    x, y, z = V.T
    body = labels == "fuselage"
    cabin = body & (np.abs(x) > 6) & (y > 1.5) & (y < 6.5) & (z > -70) & (z < 50) & (np.mod(z, 8.0) < 4.5)
    cockpit = body & (z > 67) & (z < 77) & (y > 3) & (y < 10)
    colors[cabin | cockpit] = window
    colors[(labels == "engine") & (z > 27)] = _rgb(0.15, 0.15, 0.17)
    colors[body & (y < -8)] = 0.6 * livery + 0.4 * white
    return colors


def dromedary(V, labels, rng) -> np.ndarray:
    sand = _jitter(rng, _rgb(0.84, 0.68, 0.44), 0.03)
    return _base_colors(
        labels,
        {
            "coat": sand,
            "hump": 0.78 * sand,
            "muzzle": 0.85 * sand,
            "eye": _rgb(0.05, 0.04, 0.03),
            "ear": 0.8 * sand,
            "foot": 0.55 * sand,
            "tuft": 0.45 * sand,
        },
    )
