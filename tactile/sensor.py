"""The simulated tactile sensor and where it sits on the surface.

A :class:`Sensor` is a flat, rigid ``rows x cols`` pad of taxels.  A
:class:`Poses` record places k pads: each pad is centred on the line through a
touched point along the pad normal, and its image axes are the ``up`` (towards
row 0) and ``right`` (towards the last column) tangent vectors.  The pad
presses along ``-normal``.

Both imprint paths (:mod:`tactile.raycast`, fast; :mod:`tactile.section`,
exact) share these poses, the supersampled sample grid and the image
conventions of :mod:`tactile.image`, so they differ only in how they slice
the surface.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from meshsal.mesh import Mesh
from meshsal.mesh.geometry import tangent_frames, vertex_area_vectors
from meshsal.util.registry import Registry

__all__ = [
    "SENSOR_MODES",
    "SENSOR_PLANES",
    "Sensor",
    "Poses",
    "tangent_frames",
    "fit_normals",
    "poses_from_normals",
    "sensor_poses",
    "sample_grid",
    "check_points",
]

#: How a pad turns depth into taxel values.
SENSOR_MODES = Registry(
    "sensor mode",
    [
        ("contour", None, "the paper's depth-coded image of four plane sections"),
        ("pressure", None, "indentation depth, as a force-resistive array reads it"),
    ],
)
#: How the pad's plane is fitted at a point (:func:`fit_normals`).
SENSOR_PLANES = Registry(
    "sensor plane",
    [
        ("pca", None, "the area-weighted mean normal of the surface under the pad"),
        ("paper", None, "the plane through the three nearest vertices, as in the paper"),
    ],
)

# The in-plane frame follows world +y (meshes are y-up) unless the normal is
# within this angle of +-y, where the projection of y degenerates.


@dataclass(frozen=True)
class Sensor:
    """A flat ``rows x cols`` force-resistive taxel array pressed into a surface.

    Parameters
    ----------
    rows, cols : int
        Taxels per side (the paper's sensor is 16 x 16).
    pitch_mm : float
        Taxel spacing.  The default, 2.0 mm (a 32 mm square pad), is the
        spacing of fine piezoresistive (FSR) matrices of the Tekscan and
        Sensitronics kind sold as 16 x 16 grids; those products range from
        about 1.3 mm to well over 5 mm, so 2.0 mm is a representative
        figure, not the datasheet value of one part: set it to your sensor's.
    depth_mm : float
        How far the pad is pressed in beyond its first contact: the deepest
        of the paper's four slicing planes (the others are at 1/4, 2/4 and
        3/4 of it).  3 mm shows all four contours on toy-sized (100-250 mm)
        objects with curvature radii of a few centimetres.
    mode : {"contour", "pressure"}
        ``"contour"`` draws the four plane-surface intersection contours, the
        paper's image; ``"pressure"`` fills the penetration depth, what a real
        force-resistive array reports.
    supersample : int
        Samples per taxel side; images are area-averaged down to taxels.
    plane : {"pca", "paper"}
        How the pad orientation is found at a point; see :func:`fit_normals`.

    Examples
    --------
    >>> s = Sensor()
    >>> s.rows, s.cols, s.width_mm
    (16, 16, 32.0)
    >>> Sensor(mode="pressure", pitch_mm=1.5).height_mm
    24.0
    """

    rows: int = 16
    cols: int = 16
    pitch_mm: float = 2.0
    depth_mm: float = 3.0
    mode: str = "contour"
    supersample: int = 3
    plane: str = "pca"

    def __post_init__(self):
        for name in ("rows", "cols", "supersample"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"Sensor.{name} must be a positive integer, got {value!r}")
            object.__setattr__(self, name, int(value))
        if self.supersample > 16:
            raise ValueError(f"Sensor.supersample must be at most 16, got {self.supersample}")
        for name in ("pitch_mm", "depth_mm"):
            value = getattr(self, name)
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise ValueError(f"Sensor.{name} must be a number, got {value!r}") from None
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"Sensor.{name} must be finite and positive, got {value}")
            object.__setattr__(self, name, value)
        for name, registry in (("mode", SENSOR_MODES), ("plane", SENSOR_PLANES)):
            if getattr(self, name) not in registry:
                raise ValueError(f"Sensor.{name} must be one of {registry.names()}, got {getattr(self, name)!r}")

    @property
    def width_mm(self) -> float:
        """Extent of the pad along its columns (the ``right`` axis)."""
        return self.cols * self.pitch_mm

    @property
    def height_mm(self) -> float:
        """Extent of the pad along its rows (the ``up`` axis)."""
        return self.rows * self.pitch_mm

    @property
    def fit_radius_mm(self) -> float:
        """Radius of the disc inscribed in the pad: the neighbourhood of the ``"pca"`` fit."""
        return 0.5 * min(self.rows, self.cols) * self.pitch_mm

    @property
    def reach_mm(self) -> float:
        """How far above the touched point the pad can meet the surface first.

        Half the pad diagonal: surface rising more steeply than 45 degrees on
        average across the pad is out of reach and contributes nothing.
        """
        return 0.5 * self.pitch_mm * float(np.hypot(self.rows, self.cols))

    def to_dict(self) -> dict:
        """The fields as a JSON-ready dict (inverse of ``Sensor(**d)``)."""
        return asdict(self)


@dataclass(frozen=True)
class Poses:
    """Where k sensor pads sit.

    Attributes
    ----------
    centers : (k, 3) float64
        The touched points; each pad's axis passes through its point.
    normals : (k, 3) float64
        Unit pad normals pointing out of the surface; pads press along ``-normal``.
    ups : (k, 3) float64
        Unit tangent directions of image row 0 (the top of the image).
    rights : (k, 3) float64
        Unit tangent directions of increasing column; ``(right, up, normal)``
        is right-handed, so the image shows the surface as seen from outside.
    """

    centers: np.ndarray
    normals: np.ndarray
    ups: np.ndarray
    rights: np.ndarray

    def __len__(self) -> int:
        return int(self.centers.shape[0])


def check_points(positions, normals, angles_deg=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Validate touch points: (k,3) positions, (k,3) non-zero normals (unit on return), (k,) angles."""
    P = np.asarray(positions, dtype=np.float64)
    N = np.asarray(normals, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise ValueError(f"positions must have shape (k, 3), got {P.shape}")
    if N.shape != P.shape:
        raise ValueError(f"normals must have the shape of positions {P.shape}, got {N.shape}")
    if not (np.isfinite(P).all() and np.isfinite(N).all()):
        raise ValueError("positions and normals must be finite")
    length = np.linalg.norm(N, axis=1)
    if (length < 1e-12).any():
        raise ValueError(
            f"normals must be non-zero (zero normal at rows {np.flatnonzero(length < 1e-12)[:5].tolist()})"
        )
    A = np.zeros(P.shape[0]) if angles_deg is None else np.asarray(angles_deg, dtype=np.float64).reshape(-1)
    if A.shape != (P.shape[0],):
        raise ValueError(f"angles_deg must have shape ({P.shape[0]},), got {np.shape(angles_deg)}")
    if not np.isfinite(A).all():
        raise ValueError("angles_deg must be finite")
    return P, N / length[:, None], A


# The pca fit works on component-major (3, n) vertex arrays: on large meshes
# their contiguous rows make the gathers and reductions several times faster
# than on (n, 3) rows of three.


def _vertex_area_vectors(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Per vertex, a third of the area-weighted normals of its faces, (3, n) from (n, 3) vertices."""
    return np.ascontiguousarray(vertex_area_vectors(V, F).T) / 6.0


def _cells_near(cell: np.ndarray, P: np.ndarray, origin: np.ndarray, size: float, radius: float):
    """Mask of the vertices whose cell ((3, n) integer coordinates, side ``size``) comes within
    ``radius`` of a point; None when the points' cells outnumber half the vertices (most are near then).
    """
    reach = int(np.ceil(radius / size)) + 1
    steps = np.stack(np.meshgrid(*[np.arange(-reach, reach + 1)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    # A cell o steps away from the point's cell is at least (|o| - 1) sides away.
    steps = steps[np.linalg.norm(np.maximum(np.abs(steps) - 1, 0), axis=1) * size <= radius]
    if 2 * P.shape[0] * steps.shape[0] >= cell.shape[1]:
        return None
    span = cell.max(axis=1) + 1
    around = (np.floor((P - origin) / size).astype(np.int64)[:, None, :] + steps).reshape(-1, 3)
    around = around[((around >= 0) & (around < span)).all(axis=1)].T
    return np.isin(
        (cell[0] * span[1] + cell[1]) * span[2] + cell[2], (around[0] * span[1] + around[1]) * span[2] + around[2]
    )


def _surface_cells(Vt: np.ndarray, area: np.ndarray, cell: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertex area vectors summed per cell and per normal direction.

    ``Vt``, ``area`` and ``cell`` are (3, n): vertices, their area vectors
    and their integer cell coordinates (non-negative).  Within a cell,
    vertices are split by the dominant signed axis of their normal (six
    bins), so the two sides of a part thinner than a cell land in different
    bins instead of cancelling.

    Returns
    -------
    centroids : (c, 3) float64
        Area-weighted centre of each non-empty (cell, bin).
    vectors : (c, 3) float64
        Summed area vectors (area times unit normal).
    """
    ax, ay, az = np.abs(area)
    axis = np.where((ax >= ay) & (ax >= az), 0, np.where(ay >= az, 1, 2))
    direction = 2 * axis + (np.choose(axis, area) < 0)
    span = cell.max(axis=1) + 1
    key = ((cell[0] * span[1] + cell[1]) * span[2] + cell[2]) * 6 + direction
    _, group = np.unique(key, return_inverse=True)
    group = group.reshape(-1)
    weight = np.sqrt(np.einsum("in,in->n", area, area))
    mass = np.bincount(group, weights=weight)
    centroids = np.stack([np.bincount(group, weights=v * weight) for v in Vt], axis=1)
    vectors = np.stack([np.bincount(group, weights=a) for a in area], axis=1)
    return centroids / np.maximum(mass, 1e-300)[:, None], vectors


def _fit_pca(V, F, P, N, radius: float) -> np.ndarray:
    from scipy.spatial import cKDTree

    # Cells an eighth of the radius across keep the neighbourhood sums cheap
    # on dense meshes while blurring the disc's rim by well under a taxel.
    size = radius / 8.0
    Vt = np.ascontiguousarray(V.T)
    origin = Vt.min(axis=1)
    cell = np.floor((Vt - origin[:, None]) / size).astype(np.int64)
    # A cell's centroid lies in the cell, so only whole cells that come
    # within the radius of a point matter: a few points need only the
    # vertices near them, and get the result of the whole mesh.
    keep = _cells_near(cell, P, origin, size, radius)
    if keep is None:
        centroids, vectors = _surface_cells(Vt, _vertex_area_vectors(V, F), cell)
    elif keep.any():
        touching = keep[F[:, 0]] | keep[F[:, 1]] | keep[F[:, 2]]
        area = _vertex_area_vectors(V, F[touching])[:, keep]
        centroids, vectors = _surface_cells(Vt[:, keep], area, cell[:, keep])
    else:
        return N
    pairs = cKDTree(P).sparse_distance_matrix(cKDTree(centroids), radius, output_type="ndarray")
    i, a = pairs["i"], vectors[pairs["j"]]
    facing = (a * N[i]).sum(axis=1) > 0
    i, a = i[facing], a[facing]
    total = np.stack([np.bincount(i, weights=a[:, c], minlength=P.shape[0]) for c in range(3)], axis=1)
    length = np.linalg.norm(total, axis=1, keepdims=True)
    return np.where(length > 1e-12, total / np.maximum(length, 1e-300), N)


def _fit_paper(V, P, N) -> np.ndarray:
    from scipy.spatial import cKDTree

    k = min(8, V.shape[0])
    _, nearest = cKDTree(V).query(P, k=k)
    nearest = nearest.reshape(P.shape[0], k)
    a, b = V[nearest[:, 0]], V[nearest[:, 1]]
    fitted = N.copy()
    done = np.zeros(P.shape[0], dtype=bool)
    # The first non-collinear triple in order of distance: the nearest two and the next usable vertex.
    for c in range(2, k):
        e1, e2 = b - a, V[nearest[:, c]] - a
        n = np.cross(e1, e2)
        length = np.linalg.norm(n, axis=1)
        ok = ~done & (length > 1e-9 * np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1))
        fitted[ok] = n[ok] / length[ok, None]
        done |= ok
    return fitted * np.where((fitted * N).sum(1) < 0, -1.0, 1.0)[:, None]


def fit_normals(mesh: Mesh, positions, normals, sensor: Sensor) -> np.ndarray:
    """Pad normals at touch points, by the sensor's ``plane`` rule.

    ``"pca"``: the area-weighted mean normal of the surface within the
    sensor's footprint (the pad's inscribed disc, radius
    ``sensor.fit_radius_mm``, around the point), counting only surface that
    faces the same side as the given normal so the far side of a thin part
    does not cancel it: the orientation of the average plane a compliant pad
    settles on.  Each vertex carries a third of its faces' area-weighted
    normals; these are summed per cell an eighth of the radius across (and
    per dominant normal direction), and the cells whose centre lies in the
    disc are found with a KD-tree.  A few points on a large mesh only build
    the cells near them, with the same result.
    ``"paper"``: the normal of the plane through the three nearest mesh
    vertices (the paper's quasi-tangent plane; further vertices are tried when
    the nearest are collinear).  Both are oriented to agree with the given
    normal, which is kept where the rule has nothing to work on (no vertex in
    the disc on a very coarse mesh, or only collinear vertices).

    Parameters
    ----------
    mesh : Mesh
    positions, normals : (k, 3) float64
    sensor : Sensor

    Returns
    -------
    (k, 3) float64 unit normals.

    Examples
    --------
    >>> m = Mesh(vertices=[[0, 0, 0], [10, 0, 0], [0, 10, 0]], faces=[[0, 1, 2]])
    >>> fit_normals(m, [[1.0, 1.0, 0.0]], [[0.3, 0.0, 1.0]], Sensor()).round(6).tolist()
    [[0.0, 0.0, 1.0]]
    """
    P, N, _ = check_points(positions, normals)
    if mesh.n_faces == 0:
        raise ValueError(f"mesh {mesh.name!r} has no faces")
    if sensor.plane == "pca":
        return _fit_pca(mesh.vertices, mesh.faces, P, N, sensor.fit_radius_mm)
    return _fit_paper(mesh.vertices, P, N)


def poses_from_normals(positions, normals, angles_deg=None) -> Poses:
    """Poses centred on ``positions`` with the given pad normals, turned by ``angles_deg``."""
    P, N, A = check_points(positions, normals, angles_deg)
    up, right = tangent_frames(N, A)
    return Poses(centers=P, normals=N, ups=up, rights=right)


def sensor_poses(mesh: Mesh, positions, normals, sensor: Sensor, angles_deg=None) -> Poses:
    """Fit the pad plane at each point (:func:`fit_normals`) and lay out its image axes.

    Examples
    --------
    >>> m = Mesh(vertices=[[-50, 0, -50], [50, 0, -50], [0, 0, 50]], faces=[[0, 2, 1]])
    >>> p = sensor_poses(m, [[0.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]], Sensor())
    >>> p.normals.round(6).tolist(), p.ups.round(6).tolist()
    ([[0.0, 1.0, 0.0]], [[0.0, 0.0, -1.0]])
    """
    P, N, A = check_points(positions, normals, angles_deg)
    return poses_from_normals(P, fit_normals(mesh, P, N, sensor), A)


def sample_grid(sensor: Sensor) -> tuple[np.ndarray, np.ndarray]:
    """In-plane coordinates of the supersampled grid's sample centres.

    Returns
    -------
    xs : (cols * supersample,) float64
        Offset of each sample column along ``right``:
        ``(j + 0.5 - n/2) * pitch / supersample``.
    ys : (rows * supersample,) float64
        Offset of each sample row along ``up`` (row 0 at the top, positive).

    The grid is symmetric about the pad centre, so on a square pad a 90 degree
    turn permutes the samples exactly.

    Examples
    --------
    >>> xs, ys = sample_grid(Sensor(rows=2, cols=2, pitch_mm=2.0, supersample=1))
    >>> xs.tolist(), ys.tolist()
    ([-1.0, 1.0], [1.0, -1.0])
    """
    step = sensor.pitch_mm / sensor.supersample
    W, H = sensor.cols * sensor.supersample, sensor.rows * sensor.supersample
    return (np.arange(W) + 0.5 - W / 2.0) * step, -(np.arange(H) + 0.5 - H / 2.0) * step
