"""The paper's six toy objects, built procedurally: cow, glasses, cup, hand, plane, dromedary.

The paper touched scanned toys; these stand in for them with no download.
Each toy is a smooth union of signed-distance parts
(:mod:`meshsal.objects.toy_shapes`, on :mod:`meshsal.objects.sdf`) meshed by
marching cubes and decimated, so it is one closed, edge-manifold surface,
then painted per vertex from the part nearest to each vertex and from its
position (:mod:`meshsal.objects.toy_paint`: patches, windows, nails).
Units are millimetres at toy size (largest extent 100-250 mm), y is up and
the toy faces +z, so the turntable views of the first view set show its
profile.

``seed`` varies only the paint (the cow's patches, the colors of frame,
livery, cup, skin and coat); the geometry of a toy never changes, so its
shape is its identity.

Examples
--------
>>> from meshsal.objects import toys
>>> cup = toys.make("cup")
>>> cup.name, cup.vertex_colors.shape == cup.vertices.shape
('cup', True)
"""

from __future__ import annotations

import numpy as np

from meshsal.mesh import Mesh, face_areas
from meshsal.objects import sdf, toy_paint, toy_shapes

__all__ = ["NAMES", "make", "repaint"]

#: Each toy's shape and paint, by name.
_TOYS = {
    "cow": (toy_shapes.cow, toy_paint.cow),
    "glasses": (toy_shapes.glasses, toy_paint.glasses),
    "cup": (toy_shapes.cup, toy_paint.cup),
    "hand": (toy_shapes.hand, toy_paint.hand),
    "plane": (toy_shapes.plane, toy_paint.plane),
    "dromedary": (toy_shapes.dromedary, toy_paint.dromedary),
}
NAMES = tuple(_TOYS)

# Marching cubes output is decimated to at most this many faces.
MAX_FACES = 40000

# Every face's area exceeds this fraction of the squared bounding-box diagonal:
# 10^4 times the 1e-14 below which meshsal.mesh.io.load_mesh drops a face as zero-area,
# so a toy saved as PLY loads back unchanged.  The toys' smallest faces sit near 6e-8 or above.
MIN_FACE_AREA = 1e-10


def make(name: str, seed: int = 0) -> Mesh:
    """Build one toy as a closed, colored mesh in millimetres (y up, facing +z).

    Parameters
    ----------
    name : str
        One of :data:`NAMES`.
    seed : int
        Seed of the paint's random details; the same seed gives identical arrays.

    Returns
    -------
    Mesh
        Closed, edge-manifold, outward oriented, with ``vertex_colors``.

    Raises
    ------
    ValueError
        For an unknown name.

    Examples
    --------
    >>> m = make("glasses", seed=1)
    >>> 5000 <= m.n_faces <= 60000
    True
    """
    shape, paint = _toy(name, f"unknown toy {name!r}")
    V, F = _mesh(shape)
    colors = paint(V, _labels(shape.parts, V), np.random.default_rng(seed))
    return Mesh(vertices=V, faces=F, vertex_colors=colors, name=name)


def repaint(mesh: Mesh, seed: int) -> Mesh:
    """The same toy painted with another paint seed, without meshing it again.

    Parameters
    ----------
    mesh : Mesh
        Made by :func:`make` (``mesh.name`` names the toy), possibly scaled,
        turned or moved since: the paint is computed on
        ``mesh.transform.to_source(mesh.vertices)``, the toy's millimetres.
    seed : int

    Returns
    -------
    Mesh
        Same vertices, faces and transform; the colours of ``make(name, seed)``.

    Examples
    --------
    >>> cup = make("cup")
    >>> bool((repaint(cup, 3).vertex_colors == make("cup", seed=3).vertex_colors).all())
    True
    """
    shape, paint = _toy(mesh.name, f"mesh {mesh.name!r} is not a toy")
    V = mesh.transform.to_source(mesh.vertices)
    colors = paint(V, _labels(shape.parts, V), np.random.default_rng(seed))
    return mesh.replace(vertex_colors=colors)


def _toy(name, unknown: str):
    """The toy's :class:`~meshsal.objects.toy_shapes.Shape` and paint; ValueError starting ``unknown`` if none."""
    if name not in _TOYS:
        raise ValueError(f"{unknown}; valid toys are: {', '.join(NAMES)}")
    shape, paint = _TOYS[name]
    return shape(), paint


def _field(parts, P: np.ndarray, boxes=None, margin: float = 0.0) -> np.ndarray:
    """The toy's signed distance at points P (k, 3).

    With ``boxes`` (one (2, 3) box around each part), a part is evaluated
    only within ``margin`` of its box; farther away ``margin`` stands in
    for its distance.  That is a lower bound, so the field there can only
    be underestimated and stays positive, and the surface and the values
    near it are unchanged when ``margin`` exceeds twice the largest blend
    plus a few grid steps.
    """
    columns = np.ascontiguousarray(P.T)
    d = None
    for i, part in enumerate(parts):
        if boxes is None or part.carve:
            s = part.sdf(P)
            d = s if d is None else (sdf.smooth_subtract if part.carve else sdf.smooth_union)(d, s, part.blend)
            continue
        lo, hi = boxes[i][0] - margin, boxes[i][1] + margin
        near = (columns[0] > lo[0]) & (columns[0] < hi[0])
        for axis in (1, 2):
            near &= (columns[axis] > lo[axis]) & (columns[axis] < hi[axis])
        if d is None:
            d = np.full(len(P), margin)
            d[near] = part.sdf(P[near])
            continue
        # Far from the part, the bound changes the field only where the field is about as large.
        touched = ~near & (d > margin - part.blend)
        d[touched] = sdf.smooth_union(d[touched], margin, part.blend)
        d[near] = sdf.smooth_union(d[near], part.sdf(P[near]), part.blend)
    return d


def _labels(parts, V: np.ndarray) -> np.ndarray:
    """Name of the part whose own surface passes closest to each vertex, (n,) str."""
    D = np.stack([np.abs(part.sdf(V)) for part in parts])
    return np.array([part.name for part in parts])[D.argmin(axis=0)]


def _part_boxes(parts, step: float = 8.0, reach: float = 160.0) -> np.ndarray:
    """(p, 2, 3) boxes holding each part, from a coarse scan of the +-``reach`` mm cube.

    Each point of a part's surface lies within half a cell diagonal of a
    node, where the part's distance is then at most that much.
    """
    axis = np.arange(-reach, reach + step, step)
    G = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    boxes = []
    for part in parts:
        near = G[part.sdf(G) <= step * np.sqrt(3.0)]
        if not len(near):
            raise RuntimeError(f"toy part {part.name!r} lies outside the +-{reach} mm design space")
        boxes.append([near.min(axis=0) - step, near.max(axis=0) + step])
    return np.array(boxes)


def _shape_field(shape: toy_shapes.Shape):
    """The shape's field as a function of points, with per-part culling, and a box holding its surface."""
    boxes = _part_boxes(shape.parts)
    solid = boxes[[not part.carve for part in shape.parts]]
    margin = 2.0 * max(part.blend for part in shape.parts) + 4.0 * shape.spacing
    return (lambda P: _field(shape.parts, P, boxes, margin)), solid[:, 0].min(axis=0), solid[:, 1].max(axis=0)


def _mesh(shape: toy_shapes.Shape):
    import igl

    from meshsal.util.meshlab import import_pymeshlab

    pymeshlab = import_pymeshlab()
    field, lo, hi = _shape_field(shape)
    # mesh_field's snapping keeps marching cubes free of the slivers it leaves near grid nodes.
    V, F = sdf.mesh_field(field, lo, hi, shape.spacing)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(V, F.astype(np.int32)))
    ms.meshing_decimation_quadric_edge_collapse(
        targetfacenum=min(MAX_FACES, int(0.8 * len(F))), preservetopology=True, preservenormal=True
    )
    ms.meshing_remove_unreferenced_vertices()
    V = np.ascontiguousarray(ms.current_mesh().vertex_matrix(), dtype=np.float64)
    F = np.ascontiguousarray(ms.current_mesh().face_matrix(), dtype=np.int64)
    if len(igl.boundary_facets(F)[0]) or not igl.is_edge_manifold(F)[0]:
        raise RuntimeError("toy mesh is not closed and edge-manifold after decimation")
    diagonal = np.linalg.norm(V.max(axis=0) - V.min(axis=0))
    if face_areas(V, F).min() <= MIN_FACE_AREA * diagonal**2:
        raise RuntimeError("toy mesh has a near-degenerate face after decimation")
    return V, F
