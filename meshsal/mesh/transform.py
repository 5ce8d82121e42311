"""Similarity transforms that bring a mesh to a standard size and place.

Each function returns a new mesh whose ``transform`` composes the step with
the mesh's earlier ones, so ``out.transform.to_source(out.vertices)`` is
always the source file's own coordinates.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from meshsal.mesh import Mesh, MeshError, Similarity, bounding_sphere

__all__ = [
    "scale_to",
    "normalize",
    "principal_diagonal",
    "scale_to_principal",
    "to_millimetres",
    "UnitsWarning",
    "check_pad_size",
    "MAX_PAD_WIDTHS",
]

#: A mesh more pad widths across than this is felt as a flat patch wherever it is pressed (a 150 mm object
#: in micrometres is 4,700 widths of a 32 mm pad; the toys and the YCB scans in millimetres, 2 to 8).
MAX_PAD_WIDTHS = 1000.0


class UnitsWarning(UserWarning):
    """A mesh's size and a pad's width disagree: the mesh is most likely not in millimetres.

    The message names the mesh, its size and the pad's width.
    """


def check_pad_size(mesh: Mesh, pad_width: float, pitch: float | None = None, stacklevel: int = 2) -> bool:
    """Warn (:class:`UnitsWarning`) when a pad of ``pad_width`` would miss the mesh, cover it, or feel it flat.

    Meshes are taken in millimetres, and so are the pad's width (32 mm by
    default) and its taxels' ``pitch``.  A mesh in metres, loaded as it is, is
    smaller than a taxel: its rays miss it and its imprints are all zero; a
    mesh smaller than the pad is covered by it; one more than
    :data:`MAX_PAD_WIDTHS` widths across is felt as a flat patch anywhere.

    Parameters
    ----------
    mesh : Mesh
    pad_width : float
        The pad's width, in the mesh's units.
    pitch : float, optional
        The distance between the pad's taxels, in the mesh's units.

    Returns
    -------
    bool
        Whether the sizes agree (no warning).

    Examples
    --------
    >>> import warnings
    >>> bunny = Mesh(vertices=[[0, 0, 0], [0.15, 0, 0], [0, 0.12, 0]], faces=[[0, 1, 2]], name="bunny")
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     check_pad_size(bunny, 32.0, pitch=2.0)
    False
    >>> print(caught[0].message)  # doctest: +ELLIPSIS
    bunny: 0.192 units across (its bounding-box diagonal), and the pad 32 wide: the pad's taxels, 2 apart, miss it...
    """
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    size = float(np.linalg.norm(hi - lo))
    if pitch is not None and size < pitch:
        problem = f"the pad's taxels, {pitch:g} apart, miss it"
    elif size <= pad_width:
        problem = "the pad covers it whole"
    elif size > MAX_PAD_WIDTHS * pad_width:
        problem = "the pad feels a flat patch of it anywhere"
    else:
        return True
    warnings.warn(
        f"{mesh.name or 'mesh'}: {size:.3g} units across (its bounding-box diagonal), and the pad {pad_width:g} "
        f"wide: {problem}. Sizes are taken in millimetres: scale the mesh first "
        "(meshsal.scale_to_principal(mesh, 150.0), or meshsal.mesh.transform.to_millimetres with its units) "
        "or give the pad's width in its units",
        UnitsWarning,
        stacklevel=stacklevel + 1,
    )
    return False


def _label(mesh: Mesh) -> str:
    return f"mesh {mesh.name!r}" if mesh.name else "mesh"


def _check_diagonal(diagonal_mm) -> float:
    try:
        diagonal_mm = float(diagonal_mm)
    except (TypeError, ValueError):
        raise ValueError(f"diagonal_mm must be a positive number, got {diagonal_mm!r}") from None
    if not (math.isfinite(diagonal_mm) and diagonal_mm > 0):
        raise ValueError(f"diagonal_mm must be positive and finite, got {diagonal_mm}")
    return diagonal_mm


def _apply(mesh: Mesh, step: Similarity) -> Mesh:
    return mesh.replace(vertices=step.apply(mesh.vertices), transform=mesh.transform.then(step))


def scale_to(mesh: Mesh, diagonal_mm: float = 150.0) -> Mesh:
    """Scale uniformly to a bounding-box diagonal and centre the box at the origin.

    Parameters
    ----------
    mesh : Mesh
    diagonal_mm : float
        Length of the axis-aligned bounding box's diagonal after scaling
        (millimetres by convention: the toys of the paper are 100-250 mm).

    Returns
    -------
    Mesh
        Same faces, colors and texture; ``vertices`` scaled and centred;
        ``transform`` extended so it still maps back to the source frame.

    Raises
    ------
    ValueError
        ``diagonal_mm`` is not a positive finite number.
    MeshError
        The mesh has no vertices or zero extent (all vertices coincide).

    Examples
    --------
    >>> m = Mesh(vertices=[[0, 0, 0], [3, 0, 0], [0, 4, 0]], faces=[[0, 1, 2]])
    >>> s = scale_to(m, diagonal_mm=10.0)
    >>> s.vertices.min(axis=0), s.vertices.max(axis=0)
    (array([-3., -4.,  0.]), array([3., 4., 0.]))
    >>> s.transform.to_source(s.vertices)[1]
    array([3., 0., 0.])
    """
    diagonal_mm = _check_diagonal(diagonal_mm)
    if mesh.n_vertices == 0:
        raise MeshError(f"{_label(mesh)}: cannot scale a mesh without vertices")
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    diagonal = float(np.linalg.norm(hi - lo))
    if not (math.isfinite(diagonal) and diagonal > 0):
        raise MeshError(f"{_label(mesh)}: cannot scale a mesh of zero extent (all vertices coincide)")
    scale = diagonal_mm / diagonal
    return _apply(mesh, Similarity(scale, -scale * 0.5 * (lo + hi)))


def normalize(mesh: Mesh) -> Mesh:
    """Move the bounding-sphere centre to the origin and scale the sphere to unit radius.

    The sphere is :func:`meshsal.mesh.bounding_sphere` (centred on the
    bounding box), so every vertex ends up within distance 1 of the origin
    and at least one at distance exactly 1.

    Parameters
    ----------
    mesh : Mesh

    Returns
    -------
    Mesh
        ``vertices`` normalized, ``transform`` extended so it still maps
        back to the source frame.

    Raises
    ------
    MeshError
        The mesh has no vertices or zero extent.

    Examples
    --------
    >>> m = Mesh(vertices=[[1, 1, 1], [3, 1, 1], [1, 1, 3]], faces=[[0, 1, 2]])
    >>> n = normalize(m)
    >>> round(float(np.linalg.norm(n.vertices, axis=1).max()), 12)
    1.0
    >>> n.transform.to_source(n.vertices)[1]
    array([3., 1., 1.])
    """
    if mesh.n_vertices == 0:
        raise MeshError(f"{_label(mesh)}: cannot normalize a mesh without vertices")
    center, radius = bounding_sphere(mesh.vertices)
    if not (math.isfinite(radius) and radius > 0):
        raise MeshError(f"{_label(mesh)}: cannot normalize a mesh of zero extent (all vertices coincide)")
    return _apply(mesh, Similarity(1.0 / radius, -center / radius))


def principal_diagonal(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, float]:
    """Area-weighted centroid and the bounding-box diagonal in the surface's principal frame.

    Both follow the mesh when it is turned, unlike the axis-aligned box of
    :func:`scale_to`, so two copies of one object turned differently in
    their files get the same size (up to the sign and order of the
    principal axes, which the diagonal ignores).

    Parameters
    ----------
    vertices, faces : (n, 3) float64 and (m, 3) int32

    Returns
    -------
    centroid : (3,) float64
    diagonal : float

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [4, 0, 0], [4, 3, 0], [0, 3, 0]], float)
    >>> c, d = principal_diagonal(V, np.array([[0, 1, 2], [0, 2, 3]]))
    >>> np.round(c, 6).tolist(), round(d, 6)
    ([2.0, 1.5, 0.0], 5.0)
    """
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces)
    corners = V[F]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    total = float(area.sum())
    if not (math.isfinite(total) and total > 0):
        raise MeshError("cannot find the principal frame of a surface of zero area")
    centroid = (area[:, None] * corners.mean(axis=1)).sum(axis=0) / total
    # Second moment of each triangle about the centroid (exact for a uniform density on it).
    D = corners - centroid
    S = D.sum(axis=1)
    second = np.einsum("f,fi,fj->ij", area, S, S) + np.einsum("f,fci,fcj->ij", area, D, D)
    _, axes = np.linalg.eigh(second / (12.0 * total))
    local = (V[np.unique(F)] - centroid) @ axes
    return centroid, float(np.linalg.norm(local.max(axis=0) - local.min(axis=0)))


def scale_to_principal(mesh: Mesh, diagonal_mm: float = 150.0) -> Mesh:
    """Scale uniformly so the principal-frame box diagonal is ``diagonal_mm``; centroid to the origin.

    The rotation-invariant counterpart of :func:`scale_to`: a mesh and a
    turned copy of it come out the same size (:func:`principal_diagonal`).
    No rotation is applied; ``transform`` still maps back to the source.

    Examples
    --------
    >>> m = Mesh(vertices=[[0, 0, 0], [4, 0, 0], [4, 3, 0], [0, 3, 0]], faces=[[0, 1, 2], [0, 2, 3]])
    >>> s = scale_to_principal(m, 10.0)
    >>> np.round(s.vertices.max(axis=0) - s.vertices.min(axis=0), 6).tolist()
    [8.0, 6.0, 0.0]
    """
    diagonal_mm = _check_diagonal(diagonal_mm)
    centroid, diagonal = _principal(mesh)
    scale = diagonal_mm / diagonal
    return _apply(mesh, Similarity(scale, -scale * centroid))


def _principal(mesh: Mesh) -> tuple[np.ndarray, float]:
    """:func:`principal_diagonal` of a mesh that has one, else a MeshError naming the mesh."""
    if mesh.n_faces == 0:
        raise MeshError(f"{_label(mesh)}: cannot size a mesh without faces")
    try:
        centroid, diagonal = principal_diagonal(mesh.vertices, mesh.faces)
    except MeshError as exc:
        raise MeshError(f"{_label(mesh)}: {exc}") from None
    if not (math.isfinite(diagonal) and diagonal > 0):
        raise MeshError(f"{_label(mesh)}: cannot size a mesh of zero extent (all vertices coincide)")
    return centroid, diagonal


def to_millimetres(mesh: Mesh, units_mm: float) -> Mesh:
    """The object at its real size in millimetres, area-weighted centroid at the origin.

    The counterpart of :func:`scale_to_principal` for objects whose files
    have real units (``units_mm``: millimetres per file unit, 1000 for
    metres), so a pad of 2 mm taxels meets the curvature the object has.

    Examples
    --------
    >>> m = Mesh(vertices=[[0, 0, 0], [0.04, 0, 0], [0.04, 0.03, 0], [0, 0.03, 0]], faces=[[0, 1, 2], [0, 2, 3]])
    >>> s = to_millimetres(m, 1000.0)
    >>> np.round(s.vertices.max(axis=0) - s.vertices.min(axis=0), 6).tolist()
    [40.0, 30.0, 0.0]
    """
    if not (math.isfinite(units_mm) and units_mm > 0):
        raise ValueError(f"units_mm must be positive and finite, got {units_mm}")
    centroid, _ = _principal(mesh)
    return _apply(mesh, Similarity(float(units_mm), -float(units_mm) * centroid))
