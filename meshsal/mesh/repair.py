"""Find, repair and report what real meshes get wrong, before any work is done on them.

Meshes from a lab's drive are rarely clean: composite objects made of
several interpenetrating parts, triangles written twice (once per side),
parts facing inwards, fins and pinches, slivers.  :func:`repair_arrays`
(and :func:`repair_mesh` on a :class:`~meshsal.mesh.Mesh`) finds each
defect, repairs what can be repaired without changing the shape, and
returns a :class:`MeshReport` of what it found and did; ``load_mesh`` runs it
on every file it loads.  In order:

=========================  =============================================  ==============================================
defect                     found                                          done
=========================  =============================================  ==============================================
duplicate vertices         equal positions (and colours)                  merged; the first in file order is kept
zero-area faces            area <= ``ZERO_AREA`` * diagonal**2            dropped
sliver faces               height (twice the area over the longest        dropped, and the slit closed: a needle's short
                           edge) < ``SLIVER`` * diagonal                  edge is collapsed, a cap's vertex is inserted
                                                                          into the face across its long edge
duplicate faces            the same three vertices, the same way round    one kept
double-sided faces         the same three vertices, the other way round   one kept: the copy whose edges agree with its
                                                                          neighbours'
unreferenced vertices      no face uses them                              removed
inconsistent orientation   two faces run the same way along an edge       libigl ``bfs_orient`` on each patch joined by
                                                                          two-face edges; each patch keeps the
                                                                          orientation of most of its area
non-manifold edges         more than two faces on one edge                the faces are cut apart there: each fan of
and vertices               the faces at a vertex form several fans        faces gets its own copy of the vertex (what
                                                                          libigl ``split_nonmanifold`` does, keeping the
                                                                          file's vertex order)
inward closed components   closed, negative enclosed volume               turned outward, unless the component lies
                                                                          inside another closed one (a cavity: libigl
                                                                          ``fast_winding_number``)
inward open components     rays from the back escape the mesh more        turned outward (ray casting, as libigl's
                           often than rays from the front                 ``reorient_facets_raycast``:
                                                                          :mod:`meshsal.mesh.outward`)
several components         faces joined by two-face edges                 kept, counted, closed ones counted
open boundaries            edges with one face                            kept, counted (edges and loops)
vertices without a normal  :func:`~meshsal.mesh.geometry.normal_defined`  kept, counted: never interest points
=========================  =============================================  ==============================================

Every repair keeps the surface where it was: dropped faces are zero-area or
thinner than float32 resolves at the object's size (Embree traces in
float32), collapsed edges are shorter than that, and cuts, flips and
copies change the connectivity only.  ``SLIVER`` is 1e-7 of the bounding-box
diagonal; the thinnest face of the six toys, the ten YCB scans and the
public test meshes is 2e-5 of it, 200 times thicker.  pymeshlab's
repair filters were not used: ``meshing_repair_non_manifold_edges`` removes
faces (or splits vertices with no control of the order),
``meshing_remove_t_vertices`` measures slivers by their own aspect ratio,
which would eat thin but real triangles, and each call costs a copy of the
mesh into a MeshSet and back.  A mesh with no usable face left is a
:class:`~meshsal.mesh.MeshError`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshsal.mesh import topology
from meshsal.mesh.geometry import normal_defined
from meshsal.mesh.outward import orient_outward
from meshsal.mesh.record import Mesh, MeshError, check_face_indices

__all__ = ["MeshRepairWarning", "MeshReport", "repair_arrays", "repair_mesh", "ZERO_AREA", "SLIVER"]

#: Faces whose area is at most this fraction of the squared bounding-box diagonal are zero up to
#: rounding (collinear or coincident corners).
ZERO_AREA = 1e-14
#: Faces thinner than this fraction of the bounding-box diagonal are slivers: flat at the precision
#: of float32, in which Embree renders and casts rays.
SLIVER = 1e-7


class MeshRepairWarning(UserWarning):
    """A mesh file was repaired, or part of it (a texture) left out, while loading.

    The message names the file and gives the counts of each repair.
    """


@dataclass(frozen=True)
class MeshReport:
    """What a mesh's repair found and did (:func:`repair_arrays`, ``load_mesh(..., report=True)``).

    Attributes
    ----------
    source : str
        The file (or the mesh's name).
    vertices, faces : int
        As read (faces as triangles, before any was dropped).
    merged_vertices : int
        Duplicates merged into an equal vertex.
    unreferenced_vertices : int
        Vertices no face used (after the faces below were dropped), removed.
    zero_area_faces, sliver_faces : int
        Degenerate faces dropped (a face repeating a vertex has zero area).
    collapsed_vertices : int
        Vertices merged into a neighbour along a sliver's short edge.
    split_faces : int
        Faces split at the vertex of a cap (a sliver with one vertex on its long edge) across it.
    duplicate_faces, double_sided_faces : int
        Copies dropped of a face written again the same way round, and the other way round.
    flipped_faces : int
        Faces turned to agree with their patch's orientation.
    nonmanifold_edges : int
        Edges with more than two faces.
    nonmanifold_vertices : int
        Vertices whose faces formed several fans, split.
    added_vertices : int
        Copies the split made.
    outward_components : int
        Closed components turned outward.
    outward_open_components : int
        Open components turned outward (:mod:`meshsal.mesh.outward`: more of their back than of their front
        is seen from outside).
    components, closed_components : int
        Connected components of the repaired mesh, and how many of them are closed.
    boundary_edges, boundary_loops : int
        Open boundaries of the repaired mesh.
    normalless_vertices : int
        Vertices of the repaired mesh without a normal (:func:`~meshsal.mesh.geometry.normal_defined`).
    notes : tuple of str
        What else was left out (a texture, a material library), each with why.
    """

    source: str = ""
    vertices: int = 0
    faces: int = 0
    merged_vertices: int = 0
    unreferenced_vertices: int = 0
    zero_area_faces: int = 0
    sliver_faces: int = 0
    collapsed_vertices: int = 0
    split_faces: int = 0
    duplicate_faces: int = 0
    double_sided_faces: int = 0
    flipped_faces: int = 0
    nonmanifold_edges: int = 0
    nonmanifold_vertices: int = 0
    added_vertices: int = 0
    outward_components: int = 0
    outward_open_components: int = 0
    components: int = 0
    closed_components: int = 0
    boundary_edges: int = 0
    boundary_loops: int = 0
    normalless_vertices: int = 0
    notes: tuple = ()

    @property
    def repaired(self) -> bool:
        """Whether anything was changed or left out."""
        return bool(self.repairs() or self.notes)

    @property
    def noteworthy(self) -> bool:
        """Whether :meth:`message` has anything to say: a repair, a note or a defect kept."""
        return self.repaired or bool(self.findings())

    def repairs(self) -> list[str]:
        """What was done, one phrase per kind of repair, in the order they ran."""
        done = [
            f"{verb} {count} {noun}"
            for verb, count, noun in (
                ("merged", self.merged_vertices, "duplicate vertices"),
                ("removed", self.unreferenced_vertices, "unreferenced vertices"),
                ("dropped", self.zero_area_faces, "zero-area faces"),
            )
            if count
        ]
        if self.sliver_faces:
            how = [
                f"{k} {what}"
                for k, what in (
                    (self.collapsed_vertices, "vertices collapsed"),
                    (self.split_faces, "faces split at a cap's vertex"),
                )
                if k
            ]
            done.append(f"dropped {self.sliver_faces} sliver faces" + (f" ({', '.join(how)})" if how else ""))
        if self.duplicate_faces:
            done.append(f"dropped {self.duplicate_faces} duplicate faces")
        if self.double_sided_faces:
            done.append(f"dropped {self.double_sided_faces} double-sided twin faces")
        if self.flipped_faces:
            done.append(f"flipped {self.flipped_faces} faces to orient their components consistently")
        if self.nonmanifold_vertices:
            edges = f" on {self.nonmanifold_edges} non-manifold edges" if self.nonmanifold_edges else ""
            done.append(
                f"split {self.nonmanifold_vertices} non-manifold vertices{edges} ({self.added_vertices} vertices added)"
            )
        if self.outward_components:
            done.append(f"turned {self.outward_components} closed components outward")
        if self.outward_open_components:
            done.append(f"turned {self.outward_open_components} open components outward (ray casting)")
        return done

    def findings(self) -> list[str]:
        """Defects kept that a caller should know of (vertices without a normal)."""
        if not self.normalless_vertices:
            return []
        return [f"{self.normalless_vertices} vertices have no normal (their faces cancel)"]

    def message(self) -> str:
        """The one line that names the source and every repair (the warning ``load_mesh`` gives)."""
        parts = list(self.notes) + [", ".join(p) for p in (self.repairs(), self.findings()) if p]
        return f"{self.source}: " + "; ".join(parts)

    def __str__(self) -> str:
        kept = (
            f"{self.components} components ({self.closed_components} closed), {self.boundary_edges} boundary "
            f"edges in {self.boundary_loops} loops"
        )
        return self.message() + ("; " if self.noteworthy else "") + kept


def repair_mesh(mesh: Mesh) -> tuple[Mesh, MeshReport]:
    """:func:`repair_arrays` on a mesh in memory: the repaired mesh and the report.

    Name, texture and transform are kept; ``report.source`` is the mesh's name.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    >>> tetra = Mesh(vertices=V, faces=[[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3], [1, 3, 2]], name="t")
    >>> fixed, report = repair_mesh(tetra)       # the last face is the fourth's flipped twin
    >>> fixed.n_faces, report.double_sided_faces, report.closed_components
    (4, 1, 1)
    """
    V, F, C, UV, report = repair_arrays(mesh.vertices, mesh.faces, mesh.vertex_colors, mesh.uv, source=mesh.name)
    return mesh.replace(vertices=V, faces=F, vertex_colors=C, uv=UV), report


def repair_arrays(vertices, faces, vertex_colors=None, uv=None, source: str = ""):
    """Find and repair a mesh's defects (see the module's table); report them.

    Parameters
    ----------
    vertices : (n, 3) float64, finite
    faces : (m, 3) int, indices into ``vertices``
    vertex_colors : (n, 3) optional
        Kept with their vertices (duplicates with different colours are not merged).
    uv : (m, 3, 2) optional
        Kept with their face corners.
    source : str
        Names the mesh in the report and in errors.

    Returns
    -------
    vertices : (n', 3) float64
    faces : (m', 3) int64
    vertex_colors : (n', 3) or None
    uv : (m', 3, 2) or None
    report : MeshReport

    Raises
    ------
    MeshError
        Non-finite vertices, no faces, a face index out of range, or no
        face with a non-zero area left; the message names ``source``.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    >>> V2, F2, _, _, report = repair_arrays(V, [[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]], source="t")
    >>> report.outward_components, report.message()   # every face pointed in
    (1, 't: turned 1 closed components outward')
    """
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    C = None if vertex_colors is None else np.asarray(vertex_colors)
    UV = None if uv is None else np.asarray(uv)
    if V.ndim != 2 or V.shape[1] != 3 or not np.isfinite(V).all():
        raise MeshError(f"{source}: vertices must be finite, of shape (n, 3), got shape {V.shape}")
    if len(F) == 0:
        raise MeshError(f"{source}: no faces")
    check_face_indices(F, len(V), source)
    counts = {"source": source, "vertices": len(V), "faces": len(F)}
    V, F, C, counts["merged_vertices"] = _merge_duplicates(V, F, C)
    F, UV, degenerate = _drop_degenerate(V, F, UV)
    counts.update(degenerate)
    if len(F) == 0:
        raise MeshError(f"{source}: no non-degenerate face left (all {counts['faces']} faces have zero area)")
    edges = topology.Edges(F, len(V))
    if edges.maybe_duplicated():
        F, UV, counts["duplicate_faces"], counts["double_sided_faces"] = topology.drop_duplicate_faces(F, UV, len(V))
        edges = topology.Edges(F, len(V))
    V, F, C, removed = _remove_unreferenced(V, F, C)
    counts["unreferenced_vertices"] = removed - counts["collapsed_vertices"]
    if removed:
        edges = topology.Edges(F, len(V))
    if not edges.consistent().all():
        F, UV, counts["flipped_faces"] = topology.orient_patches(V, F, UV)
        edges = topology.Edges(F, len(V))
    counts["nonmanifold_edges"] = int(np.count_nonzero(edges.counts > 2))
    split = topology.split_fans(V, F, C, edges)
    if split is not None:
        V, F, C, counts["nonmanifold_vertices"], counts["added_vertices"] = split
        edges = topology.Edges(F, len(V))
    F, UV, components = orient_outward(V, F, UV, edges)
    counts.update(components)
    counts["normalless_vertices"] = int(np.count_nonzero(~normal_defined(V, F)))
    return V, F, C, UV, MeshReport(**counts)


# --------------------------------------------------------------------------- vertices


def _unique_rows(key: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """First index and group of each distinct row of a float array, or None when all rows differ.

    Rows are hashed and the hashes sorted, several times faster than
    ``np.unique(axis=0)``'s lexicographic sort of whole rows; equal hashes
    are confirmed on the rows themselves (on a collision, ``np.unique`` decides).
    """
    bits = np.ascontiguousarray(key, dtype=np.float64).view(np.uint64)
    h = np.zeros(len(bits), dtype=np.uint64)
    for column in bits.T:
        x = h ^ column
        x ^= x >> np.uint64(30)
        x *= np.uint64(0xBF58476D1CE4E5B9)
        x ^= x >> np.uint64(27)
        x *= np.uint64(0x94D049BB133111EB)
        h = x ^ (x >> np.uint64(31))
    order = np.argsort(h, kind="stable")
    hs = h[order]
    same_hash = hs[1:] == hs[:-1]
    if not same_hash.any():
        return None
    rows = bits[order]
    same = same_hash & (rows[1:] == rows[:-1]).all(axis=1)
    if np.any(same_hash & ~same):
        _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
        return (first, inverse.reshape(-1)) if len(first) < len(key) else None
    if not same.any():
        return None
    start = np.concatenate([[True], ~same])
    inverse = np.empty(len(key), dtype=np.int64)
    inverse[order] = np.cumsum(start) - 1
    return order[start], inverse


def _merge_duplicates(V, F, C):
    """Merge vertices with equal positions (and colours); the first in file order is kept."""
    # + 0.0 turns -0.0 into 0.0 so both merge.
    key = V + 0.0 if C is None else np.hstack([V + 0.0, C.astype(np.float64)])
    groups = _unique_rows(key)
    if groups is None:
        return V, F, C, 0
    first, inverse = groups
    order = np.argsort(first)  # keep vertices in file order
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    keep = first[order]
    return V[keep], rank[inverse][F], None if C is None else C[keep], len(V) - len(first)


def _remove_unreferenced(V, F, C):
    used = np.zeros(len(V), dtype=bool)
    used[F.reshape(-1)] = True
    removed = int(np.count_nonzero(~used))
    if removed:
        rank = np.cumsum(used) - 1
        F = rank[F]
        V, C = V[used], None if C is None else C[used]
    return V, F, C, removed


# --------------------------------------------------------------------------- degenerate faces


def _drop_degenerate(V, F, UV):
    """Drop zero-area and sliver faces; collapse needles' short edges, split the faces across caps."""
    counts = {"zero_area_faces": 0, "sliver_faces": 0, "collapsed_vertices": 0, "split_faces": 0}
    diagonal = float(np.linalg.norm(V.T.max(axis=1) - V.T.min(axis=1))) if len(V) else 0.0
    X = np.ascontiguousarray(V.T)
    (xa, xb, xc), (ya, yb, yc), (za, zb, zc) = (X[d][F.T] for d in range(3))
    ux, uy, uz, vx, vy, vz = xb - xa, yb - ya, zb - za, xc - xa, yc - ya, zc - za
    nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    area = 0.5 * np.sqrt(nx * nx + ny * ny + nz * nz)
    zero = ~(area > ZERO_AREA * diagonal**2)
    # Squared length of edge k, the one opposite corner k.
    squared = (
        (xc - xb) ** 2 + (yc - yb) ** 2 + (zc - zb) ** 2,
        vx * vx + vy * vy + vz * vz,
        ux * ux + uy * uy + uz * uz,
    )
    longest = np.maximum(np.maximum(squared[0], squared[1]), squared[2])
    sliver = ~zero & ((2.0 * area) ** 2 < (SLIVER * diagonal) ** 2 * longest)
    bad = zero | sliver
    counts["zero_area_faces"] = int(np.count_nonzero(zero))
    counts["sliver_faces"] = int(np.count_nonzero(sliver))
    if not bad.any():
        return F, UV, counts
    tolerance = SLIVER * diagonal
    F = F.copy()
    lengths = np.sqrt(np.stack(squared, axis=1))
    F, counts["collapsed_vertices"] = _collapse(F, np.flatnonzero(bad), lengths, tolerance, len(V))
    distinct = (F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 2] != F[:, 0])
    # A face that only a chain of collapses made degenerate is a sliver too.
    later = ~bad & ~distinct
    counts["sliver_faces"] += int(np.count_nonzero(later))
    bad |= later
    caps = np.flatnonzero(bad & distinct)
    F, UV, keep, counts["split_faces"] = _split_caps(V, F, UV, caps, np.argmax(lengths[caps], axis=1), bad)
    return F[keep], None if UV is None else UV[keep], counts


def _collapse(F, bad_faces, lengths, tolerance, n):
    """Merge the ends of every edge shorter than ``tolerance`` of a degenerate face (the smaller index is kept)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    ends = []
    for k in range(3):
        short = bad_faces[lengths[bad_faces, k] < tolerance]
        ends.append(F[short][:, [(k + 1) % 3, (k + 2) % 3]])
    ends = np.concatenate(ends)
    ends = ends[ends[:, 0] != ends[:, 1]]
    if len(ends) == 0:
        return F, 0
    graph = coo_matrix((np.ones(len(ends), dtype=np.int8), (ends[:, 0], ends[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    representative = np.full(label.max() + 1, n, dtype=np.int64)
    np.minimum.at(representative, label, np.arange(n))
    target = representative[label]
    return target[F], int(np.count_nonzero(target != np.arange(n)))


def _split_caps(V, F, UV, caps, opposite, bad):
    """Insert each cap's flat vertex into the face across its long edge, so that dropping the cap leaves no slit.

    A cap ``(a, b, c)`` has ``c`` within ``SLIVER`` of its long edge ``ab``;
    the one face ``(b, a, d)`` across that edge becomes ``(b, c, d)`` and
    ``(c, a, d)``, which cover what it covered.  Where no single face lies
    across (an open edge, a non-manifold one), the cap is dropped alone.
    Returns the faces, their uv, which to keep and how many were split.
    """
    keep = ~bad
    if len(caps) == 0:
        return F, UV, keep, 0
    faces = F.tolist()
    corners = None if UV is None else list(UV)
    owner = {}
    for f in np.flatnonzero(keep).tolist():
        x = faces[f]
        for i in range(3):
            owner.setdefault((x[i], x[(i + 1) % 3]), []).append(f)
    split = 0
    for f, k in zip(caps.tolist(), opposite.tolist()):
        c, a, b = faces[f][k], faces[f][(k + 1) % 3], faces[f][(k + 2) % 3]
        across = owner.get((b, a), [])
        if len(across) != 1 or len(owner.get((a, b), [])) > 0:
            continue
        g = across[0]
        j = next(i for i in range(3) if faces[g][i] == b and faces[g][(i + 1) % 3] == a)
        d = faces[g][(j + 2) % 3]
        for edge in ((b, a), (a, d), (d, b)):
            owner[edge].remove(g)
        faces[g] = [b, c, d]
        faces.append([c, a, d])
        h = len(faces) - 1
        for face, edges in ((g, ((b, c), (c, d), (d, b))), (h, ((c, a), (a, d), (d, c)))):
            for edge in edges:
                owner.setdefault(edge, []).append(face)
        if corners is not None:
            uv_b, uv_a, uv_d = corners[g][j], corners[g][(j + 1) % 3], corners[g][(j + 2) % 3]
            along = V[a] - V[b]
            t = float(np.clip(np.dot(V[c] - V[b], along) / max(np.dot(along, along), 1e-300), 0.0, 1.0))
            uv_c = uv_b + t * (uv_a - uv_b)
            corners[g] = np.stack([uv_b, uv_c, uv_d])
            corners.append(np.stack([uv_c, uv_a, uv_d]))
        split += 1
    if split == 0:
        return F, UV, keep, 0
    keep = np.concatenate([keep, np.ones(split, dtype=bool)])
    UV = None if corners is None else np.asarray(corners, dtype=UV.dtype)
    return np.asarray(faces, dtype=np.int64), UV, keep, split
