"""Imprint descriptors that ignore the sensor's roll.

A robot rarely controls the pad's rotation about its normal, so the same
patch of surface can leave its imprint at any in-plane angle.  The paper
classifies the raw 16 x 16 taxels, which change completely with that angle.
:func:`polar_fourier` resamples each imprint on rings around the pad's
centre (where the touched point lies) and keeps, per ring, the magnitudes of
the first Fourier harmonics along the ring: a rotation of the imprint
shifts each ring's samples, which leaves those magnitudes unchanged.  The
descriptor is a fixed function of one imprint (nothing is fitted), so it can
never learn from a test imprint.
"""

from __future__ import annotations

import numpy as np

__all__ = ["FEATURES", "polar_fourier", "describe"]

#: Descriptor names accepted by :func:`describe`.
FEATURES = ("raw", "polar")
#: Imprints :func:`polar_fourier` describes at once.
_ROWS = 4096


def polar_fourier(imprints, rings: int = 7, samples: int = 32, harmonics: int = 6) -> np.ndarray:
    """Roll-invariant descriptors, (N, rings * harmonics) float64.

    Parameters
    ----------
    imprints : (N, rows, cols) array_like
    rings : int
        Circles around the pad centre, evenly spaced from the centre out to
        the inscribed circle.
    samples : int
        Points per ring (bilinear interpolation).
    harmonics : int
        Fourier magnitudes kept per ring (0 is the ring's mean).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> img = rng.random((1, 16, 16))
    >>> a, b = polar_fourier(img), polar_fourier(np.rot90(img, 1, axes=(1, 2)))
    >>> a.shape, bool(np.allclose(a, b))
    ((1, 42), True)
    """
    X = np.asarray(imprints)
    if X.ndim != 3:
        raise ValueError(f"imprints must have shape (N, rows, cols), got {X.shape}")
    if not (1 <= harmonics <= samples // 2 + 1 and rings >= 1):
        raise ValueError(f"need rings >= 1 and 1 <= harmonics <= samples // 2 + 1, got {rings}, {harmonics}")
    n, rows, cols = X.shape
    radius = (min(rows, cols) - 1) / 2.0
    r = np.linspace(0.0, radius, rings)[:, None]
    t = 2.0 * np.pi * np.arange(samples)[None, :] / samples
    ys = ((rows - 1) / 2.0 + r * np.sin(t)).ravel()
    xs = ((cols - 1) / 2.0 + r * np.cos(t)).ravel()
    # Bilinear interpolation as one gather per corner: every sample lies inside the grid.
    y0 = np.clip(np.floor(ys).astype(int), 0, rows - 2)
    x0 = np.clip(np.floor(xs).astype(int), 0, cols - 2)
    wy, wx = ys - y0, xs - x0
    (i0, w0), (i1, w1), (i2, w2), (i3, w3) = (
        (y0 * cols + x0, (1 - wy) * (1 - wx)),
        (y0 * cols + x0 + 1, (1 - wy) * wx),
        ((y0 + 1) * cols + x0, wy * (1 - wx)),
        ((y0 + 1) * cols + x0 + 1, wy * wx),
    )
    out = np.empty((n, rings * harmonics))
    # A block of imprints at a time: each row's descriptor is its own, and the rings and spectra of a whole
    # training set (some kilobytes per imprint) would otherwise be held at once.
    for a in range(0, n, _ROWS):
        flat = np.asarray(X[a : a + _ROWS], dtype=np.float64).reshape(-1, rows * cols)
        ring = flat[:, i0] * w0 + flat[:, i1] * w1 + flat[:, i2] * w2 + flat[:, i3] * w3
        spectrum = np.abs(np.fft.rfft(ring.reshape(-1, rings, samples), axis=2))[:, :, :harmonics] / samples
        out[a : a + _ROWS] = spectrum.reshape(-1, rings * harmonics)
    return out


def describe(imprints, features: str = "raw") -> np.ndarray:
    """Imprints as descriptor rows: ``"raw"`` the flattened taxels (the paper's), ``"polar"`` :func:`polar_fourier`.

    Examples
    --------
    >>> describe(np.zeros((2, 16, 16))).shape, describe(np.zeros((2, 16, 16)), "polar").shape
    ((2, 256), (2, 42))
    """
    if features not in FEATURES:
        raise ValueError(f"unknown features {features!r}; choose from {', '.join(FEATURES)}")
    X = np.asarray(imprints, dtype=np.float64)
    if features == "raw":
        return X.reshape(len(X), -1)
    return polar_fourier(X)
