"""The paper's six toy objects, built procedurally: cow, glasses, cup, hand, plane, dromedary.

The paper touched scanned toys; these stand in for them with no download.
Each toy is a smooth union of signed-distance parts (:mod:`meshsal.objects.sdf`)
meshed by marching cubes and decimated, so it is one closed, edge-manifold
surface.  Units are millimetres at toy size (largest extent 100-250 mm),
y is up and the toy faces +z, so the turntable views of the first view set
show its profile.  Colors are painted per vertex from the part nearest to
each vertex and from its position (patches, windows, nails).

The toys differ where a 30 mm touch can tell: the cow and the dromedary are
soft, rounded bodies on round legs; the glasses are thin tubes and flat
lenses; the cup is a large gently curved wall with a sharp-ish rim and a
handle loop; the hand is a flat palm with finger cylinders and nails; the
plane is a long cylinder with thin flat wings and fins.

``seed`` varies only the paint (the cow's patches, the colors of frame,
livery, cup, skin and coat); the geometry of a toy never changes, so its
shape is its identity.

Over 500 lines because it holds six designs, each a page of parts and
paint, beside the one pipeline that builds them; a toy is changed by
reading its design next to the others.

Examples
--------
>>> from meshsal import toys
>>> cup = toys.make("cup")
>>> cup.name, cup.vertex_colors.shape == cup.vertices.shape
('cup', True)
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from meshsal.mesh import Mesh, face_areas
from meshsal.objects import sdf

__all__ = ["NAMES", "make", "repaint"]

NAMES = ("cow", "glasses", "cup", "hand", "plane", "dromedary")

# Marching cubes output is decimated to at most this many faces.
MAX_FACES = 40000

# Every face's area exceeds this fraction of the squared bounding-box diagonal:
# 10^4 times the 1e-14 below which meshsal.mesh.io.load_mesh drops a face as zero-area,
# so a toy saved as PLY loads back unchanged.  The toys' smallest faces sit near 6e-8 or above.
MIN_FACE_AREA = 1e-10


@dataclass(frozen=True)
class _Part:
    """One signed-distance part, smooth-unioned (or carved, ``carve=True``) into the parts before it."""

    name: str
    sdf: Callable[[np.ndarray], np.ndarray]
    blend: float = 0.0
    carve: bool = False


@dataclass(frozen=True)
class _Design:
    """A toy: its parts in union order, the marching-cubes grid step (mm) and its paint."""

    parts: tuple[_Part, ...]
    spacing: float
    # (vertices, part name per vertex, rng) -> (n, 3) colors
    paint: Callable[[np.ndarray, np.ndarray, np.random.Generator], np.ndarray]


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
    if name not in _DESIGNS:
        raise ValueError(f"unknown toy {name!r}; valid toys are: {', '.join(NAMES)}")
    design = _DESIGNS[name]()
    V, F = _mesh(design)
    labels = _labels(design.parts, V)
    colors = design.paint(V, labels, np.random.default_rng(seed))
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
    if mesh.name not in _DESIGNS:
        raise ValueError(f"mesh {mesh.name!r} is not a toy; valid toys are: {', '.join(NAMES)}")
    design = _DESIGNS[mesh.name]()
    V = mesh.transform.to_source(mesh.vertices)
    colors = design.paint(V, _labels(design.parts, V), np.random.default_rng(seed))
    return mesh.replace(vertex_colors=colors)


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


def _design_field(design: _Design):
    """The design's field as a function of points, with per-part culling, and a box holding its surface."""
    boxes = _part_boxes(design.parts)
    solid = boxes[[not part.carve for part in design.parts]]
    margin = 2.0 * max(part.blend for part in design.parts) + 4.0 * design.spacing
    return (lambda P: _field(design.parts, P, boxes, margin)), solid[:, 0].min(axis=0), solid[:, 1].max(axis=0)


def _mesh(design: _Design):
    import igl

    from meshsal.util.meshlab import import_pymeshlab

    pymeshlab = import_pymeshlab()
    field, lo, hi = _design_field(design)
    # mesh_field's snapping keeps marching cubes free of the slivers it leaves near grid nodes.
    V, F = sdf.mesh_field(field, lo, hi, design.spacing)
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


# Helpers for the designs ----------------------------------------------------------------------


def _mirror_x(fn):
    """The part and its mirror image across x = 0 (exact when the part lies in x > 0)."""

    def mirrored(P):
        Q = P.copy()
        Q[:, 0] = np.abs(Q[:, 0])
        return fn(Q)

    return mirrored


def _union(*fns):
    return lambda P: np.min([fn(P) for fn in fns], axis=0)


def _rgb(*c) -> np.ndarray:
    return np.array(c, dtype=np.float64)


def _base_colors(labels: np.ndarray, palette: dict) -> np.ndarray:
    colors = np.zeros((len(labels), 3))
    for name, color in palette.items():
        colors[labels == name] = color
    return colors


def _jitter(rng, color, amount: float = 0.04) -> np.ndarray:
    return np.clip(np.asarray(color) + rng.uniform(-amount, amount, 3), 0.0, 1.0)


# The cow ---------------------------------------------------------------------------------------


def _cow() -> _Design:
    S = sdf
    head_rot = S.rotation([1, 0, 0], 30)
    parts = (
        _Part("body", lambda P: S.round_box(P, [0, 72, 0], [30, 28, 58], 22)),
        _Part("body", lambda P: S.ellipsoid(P, [0, 68, 0], [33, 30, 56]), 10),
        _Part("neck", lambda P: S.round_cone(P, [0, 80, 40], [0, 90, 72], 20, 15), 8),
        _Part("head", lambda P: S.ellipsoid(P, [0, 92, 84], [15, 17, 22], head_rot), 6),
        _Part("muzzle", lambda P: S.ellipsoid(P, [0, 79, 99], [15.5, 12, 11]), 5),
        _Part("eye", _mirror_x(lambda P: S.sphere(P, [13, 94, 90], 4.6)), 1),
        _Part("ear", _mirror_x(lambda P: S.ellipsoid(P, [20, 101, 72], [9, 3, 5.5], S.rotation([0, 0, 1], 20))), 3),
        _Part("horn", _mirror_x(lambda P: S.round_cone(P, [8, 104, 80], [19, 114, 78], 3.8, 2.2)), 2),
        _Part(
            "leg",
            _mirror_x(
                _union(
                    lambda P: S.round_cone(P, [18, 62, 40], [18, 9, 41], 11, 7.5),
                    lambda P: S.round_cone(P, [18, 62, -40], [18, 9, -41], 12, 7.5),
                )
            ),
            6,
        ),
        _Part(
            "hoof",
            _mirror_x(
                _union(
                    lambda P: S.cylinder(P, [18, 0, 41], [18, 11, 41], 8.2, 2.0),
                    lambda P: S.cylinder(P, [18, 0, -41], [18, 11, -41], 8.2, 2.0),
                )
            ),
            2,
        ),
        _Part("udder", lambda P: S.sphere(P, [0, 46, -26], 13), 6),
        _Part(
            "udder",
            _mirror_x(
                _union(
                    lambda P: S.capsule(P, [5, 38, -21], [5.5, 30, -21], 2.8),
                    lambda P: S.capsule(P, [5, 38, -31], [5.5, 30, -31], 2.8),
                )
            ),
            2,
        ),
        _Part("tail", lambda P: S.capsule(P, [0, 90, -57], [0, 42, -66], 3.0), 3),
        _Part("tuft", lambda P: S.ellipsoid(P, [0, 38, -66], [5, 9, 5]), 2),
    )

    def paint(V, labels, rng):
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

    return _Design(parts, spacing=1.25, paint=paint)


# The glasses -----------------------------------------------------------------------------------


def _glasses() -> _Design:
    S = sdf
    lens_half, corner = [25.0, 18.0], 11.0
    parts = (
        _Part("lens", _mirror_x(lambda P: S.rounded_plate(P, [33, 0, 0], lens_half, corner, 1.5, 0.7))),
        _Part("frame", _mirror_x(lambda P: S.rounded_ring(P, [33, 0, 0], lens_half, corner, 2.8)), 1.0),
        _Part("frame", _mirror_x(lambda P: S.capsule(P, [9, 9, 0.5], [0, 12, 0.5], 2.6)), 1.5),
        _Part("pad", _mirror_x(lambda P: S.ellipsoid(P, [9.5, -5, -4], [2.2, 4.5, 3.2])), 1.5),
        _Part("hinge", _mirror_x(lambda P: S.round_box(P, [59, 7, -3], [4, 5, 5], 2)), 1.5),
        _Part("temple", _mirror_x(lambda P: S.capsule(P, [60, 7, -6], [63, 7, -110], 2.4)), 1.5),
        _Part("temple", _mirror_x(lambda P: S.round_cone(P, [63, 7, -110], [63, -14, -130], 2.4, 3.0)), 1.0),
    )

    def paint(V, labels, rng):
        frames = [_rgb(0.75, 0.12, 0.10), _rgb(0.12, 0.30, 0.75), _rgb(0.45, 0.25, 0.10), _rgb(0.10, 0.55, 0.30)]
        frame = _jitter(rng, frames[rng.integers(len(frames))], 0.03)
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

    return _Design(parts, spacing=0.9, paint=paint)


# The cup ---------------------------------------------------------------------------------------


def _cup() -> _Design:
    S = sdf
    radius, height, wall = 44.0, 100.0, 4.5

    def handle(P):
        loop = S.torus(P, [radius + 3, 50, 0], 22, 5.5, S.rotation([1, 0, 0], 90))
        # Keep the loop out of the cup's hollow: cut it at the wall's middle.
        return np.maximum(loop, radius - 0.5 * wall - np.hypot(P[:, 0], P[:, 2]))

    parts = (
        _Part("body", lambda P: S.cylinder(P, [0, 0, 0], [0, height, 0], radius, 5)),
        _Part("handle", handle, 4),
        _Part("rim", lambda P: S.torus(P, [0, height - 2.5, 0], radius - 0.5 * wall, 0.5 * wall + 1.0), 1.5),
        _Part("inside", lambda P: S.cylinder(P, [0, 8, 0], [0, height + 40, 0], radius - wall, 6), 1.5, carve=True),
    )

    def paint(V, labels, rng):
        bodies = [_rgb(0.15, 0.35, 0.70), _rgb(0.85, 0.30, 0.15), _rgb(0.20, 0.55, 0.35), _rgb(0.90, 0.75, 0.20)]
        body = _jitter(rng, bodies[rng.integers(len(bodies))], 0.03)
        colors = _base_colors(
            labels, {"body": body, "handle": body, "rim": _rgb(0.97, 0.97, 0.95), "inside": 0.55 + 0.45 * body}
        )
        colors[(V[:, 1] > height - 6.0) & (labels != "inside")] = _rgb(0.97, 0.97, 0.95)
        return colors

    return _Design(parts, spacing=1.4, paint=paint)


# The hand --------------------------------------------------------------------------------------

# Finger base x, length, base and tip radius, spread (degrees about z, + towards the pinky side).
_FINGERS = (
    (-26.0, 70.0, 9.5, 7.5, 8.0),
    (-8.5, 79.0, 10.0, 8.0, 2.0),
    (8.5, 74.0, 9.5, 7.5, -3.0),
    (25.0, 58.0, 8.5, 6.5, -10.0),
)


def _chain(start, direction, lengths, curl_deg, curl_axis) -> list[np.ndarray]:
    """Joint positions of a digit that bends by ``curl_deg`` about ``curl_axis`` at each joint."""
    joints = [np.asarray(start, dtype=np.float64)]
    d = np.asarray(direction, dtype=np.float64) / np.linalg.norm(direction)
    for length in lengths:
        joints.append(joints[-1] + length * d)
        d = sdf.rotation(curl_axis, curl_deg) @ d
    return joints


def _digit(joints, radii, blend: float) -> list[_Part]:
    """Tapered segments between consecutive joints; the first blends into the palm."""
    return [
        _Part(
            "skin",
            lambda P, a=joints[k], b=joints[k + 1], ra=radii[k], rb=radii[k + 1]: sdf.round_cone(P, a, b, ra, rb),
            blend if k == 0 else 1.0,
        )
        for k in range(len(joints) - 1)
    ]


def _hand() -> _Design:
    S = sdf
    parts = [
        _Part("skin", lambda P: S.round_box(P, [0, 45, 0], [40, 42, 13], 11)),
        _Part("skin", lambda P: S.round_box(P, [0, -22, 0], [27, 32, 17], 14), 12),
        _Part("skin", lambda P: S.ellipsoid(P, [-24, 28, -5], [17, 24, 13]), 8),
    ]
    nails = []
    curl_axis = [1.0, 0.0, 0.0]
    for x, length, r0, r1, spread in _FINGERS:
        direction = sdf.rotation([0, 0, 1], spread) @ np.array([0.0, 1.0, 0.0])
        joints = _chain([x, 80.0, 0.0], direction, [0.45 * length, 0.30 * length, 0.25 * length], 10.0, curl_axis)
        radii = np.linspace(r0, r1, 4)
        parts += _digit(joints, radii, 6.0)
        nails.append((joints[2], joints[3], radii[3]))
    joints = _chain([-30.0, 25.0, 3.0], [-0.45, 0.89, 0.15], [30.0, 25.0, 21.0], -8.0, [0.3, 0.0, 1.0])
    radii = (13.0, 11.0, 9.5, 8.5)
    parts += _digit(joints, radii, 7.0)
    nails.append((joints[2], joints[3], radii[3]))
    for a, b, r in nails:
        # A flat lens on the back (+z) of the last segment, ending just short of the tip.
        axis = (b - a) / np.linalg.norm(b - a)
        back = np.array([0.0, 0.0, 1.0]) - axis * axis[2]
        back /= np.linalg.norm(back)
        rot = np.column_stack([np.cross(axis, back), back, axis])
        center = b - 0.45 * r * axis + 0.85 * r * back
        radii = [0.75 * r, 0.25 * r, 1.2 * r]
        parts.append(_Part("nail", lambda P, c=center, radii=radii, rot=rot: S.ellipsoid(P, c, radii, rot), 1.0))

    def paint(V, labels, rng):
        skin = _jitter(rng, _rgb(0.93, 0.74, 0.60), 0.04)
        return _base_colors(labels, {"skin": skin, "nail": _rgb(0.98, 0.86, 0.84)})

    return _Design(tuple(parts), spacing=1.3, paint=paint)


# The plane -------------------------------------------------------------------------------------


def _plane() -> _Design:
    S = sdf
    fin_rot = np.column_stack([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    wing = [(0, 30), (100, -14), (100, -28), (0, -12), (-100, -28), (-100, -14)]
    stabilizer = [(0, -84), (38, -106), (38, -116), (0, -110), (-38, -116), (-38, -106)]
    fin = [(4, -76), (46, -106), (46, -118), (4, -114)]
    parts = (
        _Part("fuselage", lambda P: S.capsule(P, [0, 0, -80], [0, 0, 68], 13)),
        _Part("fuselage", lambda P: S.round_cone(P, [0, 0, -80], [0, 8, -114], 13, 4), 4),
        _Part("wing", lambda P: S.prism(P, wing, [0, -5, 0], 2.6, 1.2), 5),
        _Part("tail", lambda P: S.prism(P, stabilizer, [0, 7, 0], 2.0, 0.9), 3),
        _Part("fin", lambda P: S.prism(P, fin, [0, 0, 0], 2.2, 1.0, fin_rot), 3),
        _Part("pylon", _mirror_x(lambda P: S.round_box(P, [38, -10, 12], [2, 6, 12], 1.5)), 2),
        _Part("engine", _mirror_x(lambda P: S.cylinder(P, [38, -17, -4], [38, -17, 30], 8, 3)), 2),
    )

    def paint(V, labels, rng):
        liveries = [_rgb(0.10, 0.30, 0.75), _rgb(0.80, 0.12, 0.12), _rgb(0.10, 0.55, 0.45), _rgb(0.95, 0.55, 0.10)]
        livery = _jitter(rng, liveries[rng.integers(len(liveries))], 0.03)
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

    return _Design(parts, spacing=1.2, paint=paint)


# The dromedary ---------------------------------------------------------------------------------


def _dromedary() -> _Design:
    S = sdf
    head_rot = S.rotation([1, 0, 0], 12)
    legs = []
    for z in (38.0, -36.0):
        legs += [
            lambda P, z=z: S.round_cone(P, [14, 98, z], [14, 56, z + 1], 11, 6.5),
            lambda P, z=z: S.round_cone(P, [14, 56, z + 1], [14, 8, z], 6.5, 5),
            lambda P, z=z: S.sphere(P, [14, 56, z + 1], 7.2),
        ]
    parts = (
        _Part("coat", lambda P: S.ellipsoid(P, [0, 105, 0], [26, 27, 52])),
        _Part("hump", lambda P: S.ellipsoid(P, [0, 127, -3], [20, 26, 30]), 12),
        _Part("coat", lambda P: S.round_cone(P, [0, 108, 38], [0, 100, 66], 17, 11), 8),
        _Part("coat", lambda P: S.round_cone(P, [0, 100, 66], [0, 142, 90], 11, 9), 6),
        _Part("coat", lambda P: S.ellipsoid(P, [0, 148, 100], [10, 11, 20], head_rot), 5),
        _Part("muzzle", lambda P: S.ellipsoid(P, [0, 143, 114], [8.5, 8.5, 8]), 4),
        _Part("eye", _mirror_x(lambda P: S.sphere(P, [8.6, 152, 100], 2.8)), 1),
        _Part("ear", _mirror_x(lambda P: S.ellipsoid(P, [6.5, 158, 93], [2.5, 5, 3])), 1.5),
        _Part("coat", _mirror_x(_union(*legs)), 6),
        _Part(
            "foot",
            _mirror_x(
                _union(
                    lambda P: S.ellipsoid(P, [14, 4.5, 40], [8, 4.5, 10]),
                    lambda P: S.ellipsoid(P, [14, 4.5, -34], [8, 4.5, 10]),
                )
            ),
            3,
        ),
        _Part("coat", lambda P: S.capsule(P, [0, 112, -50], [0, 76, -58], 2.6), 3),
        _Part("tuft", lambda P: S.ellipsoid(P, [0, 73, -58], [4, 7, 4]), 2),
    )

    def paint(V, labels, rng):
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

    return _Design(parts, spacing=1.3, paint=paint)


_DESIGNS = {"cow": _cow, "glasses": _glasses, "cup": _cup, "hand": _hand, "plane": _plane, "dromedary": _dromedary}
