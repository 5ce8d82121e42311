"""Signed distance functions, smooth unions, and meshing a field into a closed mesh.

Every primitive takes points ``P`` (k, 3) float64 and returns (k,) float64
distances: negative inside, positive outside, zero on the surface.  The
exact primitives are 1-Lipschitz (``|grad d| = 1`` off the medial axis);
:func:`ellipsoid` is a close approximation.  Combining them with
:func:`smooth_union` keeps the field 1-Lipschitz, which is what lets
:func:`sample_grid` skip the far field and :func:`mesh_field` mesh fine
grids quickly.

Examples
--------
>>> f = lambda P: smooth_union(sphere(P, [0, 0, 0], 10.0), sphere(P, [15, 0, 0], 8.0), k=4.0)
>>> V, F = mesh_field(f, lo=[-12, -12, -12], hi=[25, 12, 12], spacing=1.0)
>>> V.shape[1], F.shape[1]
(3, 3)
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "sphere",
    "ellipsoid",
    "capsule",
    "round_cone",
    "cylinder",
    "round_box",
    "torus",
    "prism",
    "rounded_plate",
    "rounded_ring",
    "smooth_union",
    "smooth_subtract",
    "rotation",
    "sample_grid",
    "mesh_field",
]


def _points(P) -> np.ndarray:
    P = np.asarray(P, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise ValueError(f"points must have shape (k, 3), got {P.shape}")
    return P


def _vec(v) -> np.ndarray:
    return np.asarray(v, dtype=np.float64).reshape(3)


def _local(P, center, rot) -> np.ndarray:
    """Points in a part's frame: ``rot`` holds the part's axes as columns."""
    Q = _points(P) - _vec(center)
    return Q if rot is None else Q @ np.asarray(rot, dtype=np.float64)


def rotation(axis, angle_deg: float) -> np.ndarray:
    """(3, 3) rotation matrix about ``axis`` by ``angle_deg`` (right hand rule).

    Its columns are the rotated x, y, z axes, the form the ``rot`` argument of
    the primitives expects.

    Examples
    --------
    >>> rotation([0, 0, 1], 90.0).round(6) @ [1, 0, 0]
    array([0., 1., 0.])
    """
    a = _vec(axis)
    a = a / np.linalg.norm(a)
    t = np.deg2rad(angle_deg)
    K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + np.sin(t) * K + (1.0 - np.cos(t)) * (K @ K)


def sphere(P, center, radius: float) -> np.ndarray:
    """Exact distance to a sphere.

    Examples
    --------
    >>> sphere(np.array([[3.0, 0, 0]]), [0, 0, 0], 1.0)
    array([2.])
    """
    return np.linalg.norm(_points(P) - _vec(center), axis=1) - radius


def ellipsoid(P, center, radii, rot=None) -> np.ndarray:
    """Approximate distance to an ellipsoid with semi-axes ``radii`` (exact at the axes' ends).

    Outside and near the surface: the gradient-normalised implicit
    ``k0 (k0 - 1) / k1`` (Quilez), close to the true distance.  Deeper
    inside it eases towards ``-min(radii)`` at the centre, where that
    formula would jump, so the field stays continuous.

    Examples
    --------
    >>> ellipsoid(np.array([[0, 5.0, 0], [0, 0, 0]]), [0, 0, 0], [1, 2, 3]).round(6)
    array([ 3., -1.])
    """
    Q = _local(P, center, rot)
    r = _vec(radii)
    k0 = np.linalg.norm(Q / r, axis=1)
    k1 = np.linalg.norm(Q / (r * r), axis=1)
    # k0 / k1 is the semi-axis length in the point's direction, between min(r) and max(r).
    reach = np.divide(k0, k1, out=np.full_like(k0, r.min()), where=k1 > 0)
    return (k0 - 1.0) * (r.min() + (reach - r.min()) * np.minimum(k0, 1.0))


def capsule(P, a, b, radius: float) -> np.ndarray:
    """Exact distance to a capsule: the segment ``a``-``b`` thickened by ``radius``.

    Examples
    --------
    >>> capsule(np.array([[0, 3.0, 5.0]]), [0, 0, 0], [0, 0, 10], 1.0)
    array([2.])
    """
    return round_cone(P, a, b, radius, radius)


def round_cone(P, a, b, ra: float, rb: float) -> np.ndarray:
    """Exact distance to the convex hull of a sphere of radius ``ra`` at ``a`` and ``rb`` at ``b``.

    A tapered capsule (limbs, fingers, necks).  Requires ``|b - a| > |ra - rb|``.

    Examples
    --------
    >>> round_cone(np.array([[0, 0, -4.0]]), [0, 0, 0], [0, 0, 10], 2.0, 1.0)
    array([2.])
    """
    Q = _points(P) - _vec(a)
    ba = _vec(b) - _vec(a)
    l2 = float(ba @ ba)
    rr = ra - rb
    a2 = l2 - rr * rr
    if a2 <= 0:
        raise ValueError(f"round_cone: segment length {np.sqrt(l2):.4g} must exceed |ra - rb| = {abs(rr):.4g}")
    y = Q @ ba
    z = y - l2
    # |Q l2 - y ba|^2 expanded, as Q . ba = y.
    x2 = np.maximum(l2 * (l2 * np.einsum("ij,ij->i", Q, Q) - y * y), 0.0)
    y2 = y * y * l2
    z2 = z * z * l2
    k = np.sign(rr) * rr * rr * x2
    beyond_b = np.sign(z) * a2 * z2 > k
    before_a = np.sign(y) * a2 * y2 < k
    side = (np.sqrt(x2 * a2 / l2) + y * rr) / l2 - ra
    return np.where(beyond_b, np.sqrt(x2 + z2) / l2 - rb, np.where(before_a, np.sqrt(x2 + y2) / l2 - ra, side))


def cylinder(P, a, b, radius: float, rounding: float = 0.0) -> np.ndarray:
    """Exact distance to a capped cylinder from ``a`` to ``b``, edges rounded by ``rounding``.

    The rounded cylinder keeps the outer size: radius ``radius`` and the caps at ``a`` and ``b``.

    Examples
    --------
    >>> cylinder(np.array([[0, 0, 15.0], [5.0, 0, 5]]), [0, 0, 0], [0, 0, 10], 2.0)
    array([5., 3.])
    """
    Q = _points(P) - _vec(a)
    axis = _vec(b) - _vec(a)
    length = float(np.linalg.norm(axis))
    axis = axis / length
    h = Q @ axis - 0.5 * length
    rho = np.linalg.norm(Q - np.outer(Q @ axis, axis), axis=1)
    return _box2(rho - (radius - rounding), np.abs(h) - (0.5 * length - rounding)) - rounding


def _box2(dx, dy) -> np.ndarray:
    """Distance from per-axis excesses (2-D box / extrusion combinator)."""
    return np.minimum(np.maximum(dx, dy), 0.0) + np.hypot(np.maximum(dx, 0.0), np.maximum(dy, 0.0))


def round_box(P, center, half_size, rounding: float = 0.0, rot=None) -> np.ndarray:
    """Exact distance to a box of half extents ``half_size`` with edges rounded by ``rounding``.

    Examples
    --------
    >>> round_box(np.array([[0, 0, 4.0]]), [0, 0, 0], [1, 2, 3])
    array([1.])
    """
    q = np.abs(_local(P, center, rot)) - (_vec(half_size) - rounding)
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
    return outside + np.minimum(q.max(axis=1), 0.0) - rounding


def torus(P, center, major: float, minor: float, rot=None) -> np.ndarray:
    """Exact distance to a torus around the part's local y axis.

    Examples
    --------
    >>> torus(np.array([[10.0, 0, 0], [0, 0, 0]]), [0, 0, 0], 10.0, 2.0)
    array([-2.,  8.])
    """
    Q = _local(P, center, rot)
    return np.hypot(np.hypot(Q[:, 0], Q[:, 2]) - major, Q[:, 1]) - minor


def _polygon2(x, y, polygon) -> np.ndarray:
    """Exact signed distance to a simple polygon (k, 2) in the plane."""
    poly = np.asarray(polygon, dtype=np.float64)
    d2 = np.full(x.shape, np.inf)
    inside = np.zeros(x.shape, dtype=bool)
    for i in range(len(poly)):
        (x0, y0), (x1, y1) = poly[i], poly[i - 1]
        ex, ey = x1 - x0, y1 - y0
        wx, wy = x - x0, y - y0
        t = np.clip((wx * ex + wy * ey) / (ex * ex + ey * ey), 0.0, 1.0)
        d2 = np.minimum(d2, (wx - ex * t) ** 2 + (wy - ey * t) ** 2)
        # Even-odd crossing test of a ray along +x.
        crosses = (y0 > y) != (y1 > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xc = x0 + (y - y0) * ex / ey
        inside ^= crosses & (x < xc)
    return np.where(inside, -1.0, 1.0) * np.sqrt(d2)


def prism(P, polygon, center, half_thickness: float, rounding: float = 0.0, rot=None) -> np.ndarray:
    """Exact distance to a polygon in the local x-z plane extruded along local y, edges rounded.

    ``polygon`` (k, 2) lists local (x, z) corners; the outline and thickness
    shrink by ``rounding`` first so the rounded solid keeps the given outline.
    Wings, fins and plates.

    Examples
    --------
    >>> square = [[-1, -1], [1, -1], [1, 1], [-1, 1]]
    >>> prism(np.array([[0, 3.0, 0], [4.0, 0, 0]]), square, [0, 0, 0], 0.5)
    array([2.5, 3. ])
    """
    Q = _local(P, center, rot)
    d = _polygon2(Q[:, 0], Q[:, 2], polygon) + rounding
    return _box2(d, np.abs(Q[:, 1]) - (half_thickness - rounding)) - rounding


def _rounded_rect2(x, y, half_size, corner: float) -> np.ndarray:
    """Exact signed distance to a rectangle with corners rounded by ``corner``, in the plane."""
    hx, hy = half_size
    return _box2(np.abs(x) - hx + corner, np.abs(y) - hy + corner) - corner


def rounded_plate(
    P, center, half_size, corner: float, half_thickness: float, rounding: float = 0.0, rot=None
) -> np.ndarray:
    """Exact distance to a plate: a rounded rectangle in local x-y, thick along local z.

    ``half_size`` (2,) are the outline's half extents, ``corner`` its corner
    radius; ``rounding`` rounds the plate's edges without changing its size.

    Examples
    --------
    >>> rounded_plate(np.array([[0, 0, 3.0], [0, 12.0, 0]]), [0, 0, 0], [20, 10], 5.0, 1.0)
    array([2., 2.])
    """
    Q = _local(P, center, rot)
    d = _rounded_rect2(Q[:, 0], Q[:, 1], half_size, corner) + rounding
    return _box2(d, np.abs(Q[:, 2]) - (half_thickness - rounding)) - rounding


def rounded_ring(P, center, half_size, corner: float, tube: float, rot=None) -> np.ndarray:
    """Exact distance to a round tube of radius ``tube`` along a rounded rectangle in local x-y.

    Examples
    --------
    >>> rounded_ring(np.array([[20.0, 0, 0], [0, 0, 0]]), [0, 0, 0], [20, 10], 5.0, 2.0)
    array([-2.,  8.])
    """
    Q = _local(P, center, rot)
    return np.hypot(_rounded_rect2(Q[:, 0], Q[:, 1], half_size, corner), Q[:, 2]) - tube


def smooth_union(a, b, k: float) -> np.ndarray:
    """Polynomial smooth minimum of two distance fields with blend radius ``k``.

    Equal to ``min(a, b)`` where ``|a - b| >= k``, never above it and never
    below ``min(a, b) - k / 4``; continuous with a continuous gradient, and
    1-Lipschitz when ``a`` and ``b`` are.

    Examples
    --------
    >>> smooth_union(np.array([0.0, 0.0]), np.array([5.0, 0.0]), k=2.0)
    array([ 0. , -0.5])
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if k <= 0:
        return np.minimum(a, b)
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b + (a - b) * h - k * h * (1.0 - h)


def smooth_subtract(a, b, k: float) -> np.ndarray:
    """Field ``a`` with ``b`` carved out, the cut edge rounded over ``k`` (never below ``max(a, -b)``)."""
    return -smooth_union(-np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64), k)


def _grid_axes(lo, hi, spacing: float, stride: int) -> list[np.ndarray]:
    lo, hi = _vec(lo), _vec(hi)
    if not np.all(hi > lo):
        raise ValueError(f"grid bounds must satisfy hi > lo, got lo={lo}, hi={hi}")
    if not spacing > 0:
        raise ValueError(f"grid spacing must be positive, got {spacing}")
    # Cell counts are multiples of the coarse stride, so coarse nodes are fine nodes.
    cells = np.ceil((hi - lo) / (spacing * stride)).astype(int) * stride
    centre = 0.5 * (lo + hi)
    start = centre - 0.5 * cells * spacing
    return [start[i] + spacing * np.arange(cells[i] + 1) for i in range(3)]


def _grid_points(xs, ys, zs) -> np.ndarray:
    """Grid nodes (nx*ny*nz, 3) with x varying fastest, then y, then z."""
    Z, Y, X = np.meshgrid(zs, ys, xs, indexing="ij")
    return np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)


def sample_grid(field, lo, hi, spacing: float, levels: int = 3):
    """Sample ``field`` on a regular grid, exactly wherever the surface may pass.

    Coarse to fine: the grid at twice the spacing is sampled first (itself
    the same way, ``levels`` times), then a node is sampled exactly only if
    the nearest coarser node lies within a few cells of the surface;
    otherwise it keeps that coarser value, of the right sign and too far
    from zero to create a crossing.  Exact signs and exact values at every
    sign change for 1-Lipschitz fields, which smooth unions of the
    primitives here are; the band is wider than they need, which covers
    :func:`ellipsoid`'s small departures from a true distance near its surface.

    Parameters
    ----------
    field : callable (k, 3) float64 -> (k,) float64
    lo, hi : (3,) float
        Box that must contain the surface.
    spacing : float
        Fine grid step; the grid is centred on the box and may overhang it.
    levels : int
        Number of coarser grids (0 samples every node exactly).

    Returns
    -------
    values : (nz, ny, nx) float64
    axes : tuple of three 1-D arrays (xs, ys, zs)

    Examples
    --------
    >>> values, (xs, ys, zs) = sample_grid(lambda P: sphere(P, [0, 0, 0], 5.0), [-6] * 3, [6] * 3, 1.0)
    >>> values.shape, float(values[8, 8, 8])
    ((17, 17, 17), -5.0)
    """
    if levels < 0:
        raise ValueError(f"levels must be >= 0, got {levels}")
    axes = _grid_axes(lo, hi, spacing, 2**levels)
    return _sample(field, axes, spacing, levels), tuple(axes)


def _sample(field, axes, spacing: float, levels: int) -> np.ndarray:
    xs, ys, zs = axes
    if levels == 0:
        values = np.asarray(field(_grid_points(xs, ys, zs)), dtype=np.float64)
        return values.reshape(len(zs), len(ys), len(xs))
    coarse = _sample(field, [a[::2] for a in axes], 2.0 * spacing, levels - 1)
    # Nearest coarser node of every node, at most sqrt(3) * spacing away.
    iz, iy, ix = ((np.arange(len(a)) + 1) // 2 for a in (zs, ys, xs))
    values = coarse[np.ix_(iz, iy, ix)]
    # Copied values drift at most sqrt(3) * (spacing + 2 spacing + ...) from the exact
    # ones; this band keeps them clear of zero with margin to spare (see sample_grid).
    band = np.abs(values) < 2.0 * (np.sqrt(3.0) + 1.0) * spacing
    kz, ky, kx = np.nonzero(band)
    if len(kz):
        values[kz, ky, kx] = field(np.stack([xs[kx], ys[ky], zs[kz]], axis=1))
    return values


def mesh_field(field, lo, hi, spacing: float, levels: int = 3, snap: float = 0.05):
    """Mesh the zero set of a signed distance field by marching cubes into a closed surface.

    Parameters
    ----------
    field : callable (k, 3) float64 -> (k,) float64
        Negative inside.
    lo, hi : (3,) float
        Box containing the whole surface; the field must be positive on its border.
    spacing : float
        Grid step; parts thinner than about two steps may break up.
    levels : int
        See :func:`sample_grid`.
    snap : float
        Values within ``snap * spacing`` of zero are pushed out to
        ``+-snap * spacing`` (zero counts as outside) before meshing, in
        ``[0, 0.5)``.  Marching cubes puts a vertex where the field crosses
        zero on each grid edge; where the surface passes through or next
        to a grid node, the vertices on that node's edges meet and the
        triangles between them have (nearly) zero area.  Snapped, every
        vertex stays about ``snap * spacing`` or more from every node
        (the field changes by at most ``spacing`` along an edge), so the
        smallest triangles have area of order ``(snap * spacing)**2``; the
        surface moves by at most ``snap * spacing``.

    Returns
    -------
    V : (n, 3) float64
    F : (m, 3) int64
        Faces counter-clockwise seen from outside (positive signed volume).

    Raises
    ------
    ValueError
        If the surface reaches the grid border (it would be cut open) or is
        empty, or ``snap`` is out of range.

    Examples
    --------
    >>> from meshsal.mesh import face_areas
    >>> f = lambda P: capsule(P, [0, 0, -3], [0, 0, 3], 3.0)  # passes through grid nodes
    >>> V, F = mesh_field(f, [-7] * 3, [7] * 3, 1.0)
    >>> bool(face_areas(V, F).min() > 0.5 * 0.05**2)
    True
    """
    import igl

    if not 0.0 <= snap < 0.5:
        raise ValueError(f"snap must be in [0, 0.5), got {snap}")
    values, (xs, ys, zs) = sample_grid(field, lo, hi, spacing, levels)
    border = np.concatenate([values[[0, -1]].ravel(), values[:, [0, -1]].ravel(), values[:, :, [0, -1]].ravel()])
    if np.any(border <= 0):
        raise ValueError("mesh_field: the surface reaches the grid border; enlarge lo/hi")
    if not np.any(values < 0):
        raise ValueError("mesh_field: the field is positive everywhere on the grid; nothing to mesh")
    # snap = 0 still lifts exact zeros, which would put several vertices on one point.
    floor = max(snap * spacing, 1e-9 * spacing)
    values = np.where(np.abs(values) < floor, np.where(values < 0.0, -floor, floor), values)
    V, F, _ = igl.marching_cubes(values.ravel(), _grid_points(xs, ys, zs), len(xs), len(ys), len(zs), 0.0)
    return V, F.astype(np.int64)
