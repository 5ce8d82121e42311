"""The triangle mesh record and the similarity transform back to its file's frame."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Mesh", "MeshError", "Similarity"]


class MeshError(ValueError):
    """A mesh file or array cannot be used; the message names the file and the problem."""


@dataclass(frozen=True)
class Similarity:
    """A rotation, a uniform scale, then a translation: ``current = scale * R source + offset``.

    It maps a mesh's current frame back to the frame and units of the file it
    was loaded from, so any result (points, normals, lengths) can be reported
    in the user's own coordinates.  ``rotation`` is the identity unless the
    mesh was turned (as the instances of :mod:`meshsal.objects.instances` are).

    Parameters
    ----------
    scale : float
    offset : (3,) float64
    rotation : (3, 3) float64, a proper rotation (default identity)

    Examples
    --------
    >>> s = Similarity(scale=2.0, offset=np.array([1.0, 0.0, 0.0]))
    >>> s.to_source(np.array([[3.0, 0.0, 0.0]]))
    array([[1., 0., 0.]])
    >>> turn = Similarity(rotation=[[0, -1, 0], [1, 0, 0], [0, 0, 1]])   # 90 degrees about z
    >>> turn.apply([[1.0, 0.0, 0.0]]), turn.direction_to_source([[0.0, 1.0, 0.0]])
    (array([[0., 1., 0.]]), array([[1., 0., 0.]]))
    """

    scale: float = 1.0
    offset: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))

    def __post_init__(self):
        offset = np.asarray(self.offset, dtype=np.float64).reshape(3)
        R = np.asarray(self.rotation, dtype=np.float64)
        if not (np.isfinite(self.scale) and self.scale > 0):
            raise ValueError(f"similarity scale must be finite and positive, got {self.scale}")
        if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-9) or np.linalg.det(R) <= 0:
            raise ValueError(f"similarity rotation must be a proper 3x3 rotation matrix, got {R.tolist()}")
        object.__setattr__(self, "scale", float(self.scale))
        object.__setattr__(self, "offset", offset)
        object.__setattr__(self, "rotation", R)

    def then(self, other: Similarity) -> Similarity:
        """The transform that applies ``self`` first, then ``other``."""
        return Similarity(
            other.scale * self.scale,
            other.scale * (other.rotation @ self.offset) + other.offset,
            other.rotation @ self.rotation,
        )

    def inverse(self) -> Similarity:
        """The transform back: ``inverse().apply(apply(p)) == p``."""
        return Similarity(1.0 / self.scale, -(self.rotation.T @ self.offset) / self.scale, self.rotation.T)

    def apply(self, points) -> np.ndarray:
        """Map (k,3) points from the source frame into the current frame."""
        return self.scale * (np.asarray(points, dtype=np.float64) @ self.rotation.T) + self.offset

    def to_source(self, points) -> np.ndarray:
        """Map (k,3) points from the current frame back to the source frame."""
        return ((np.asarray(points, dtype=np.float64) - self.offset) / self.scale) @ self.rotation

    def apply_direction(self, directions) -> np.ndarray:
        """Turn (k,3) directions (normals) from the source frame into the current frame."""
        return np.asarray(directions, dtype=np.float64) @ self.rotation.T

    def direction_to_source(self, directions) -> np.ndarray:
        """Turn (k,3) directions (normals) from the current frame back into the source frame."""
        return np.asarray(directions, dtype=np.float64) @ self.rotation

    def length_to_source(self, length):
        """Map a length (or array of lengths) back to source units."""
        return np.asarray(length, dtype=np.float64) / self.scale


def check_face_indices(faces: np.ndarray, n_vertices: int, label: str) -> None:
    """Refuse face indices outside ``[0, n_vertices)``: every stage indexes vertices by them, and Embree reads
    out of range unchecked.

    Raises
    ------
    MeshError
        Led by ``label`` (a file, a mesh's name), with the indices' range.
    """
    if np.size(faces) and (faces.min() < 0 or faces.max() >= n_vertices):
        raise MeshError(f"{label}: face index out of range ({faces.min()}..{faces.max()} for {n_vertices} vertices)")


@dataclass(frozen=True, eq=False)
class Mesh:
    """A triangle mesh with optional per-vertex colors and a texture.

    Parameters
    ----------
    vertices : (n, 3) float64, finite
    faces : (m, 3) int32
        Vertex indices in ``[0, n)``, counter-clockwise seen from outside.
    vertex_colors : (n, 3) float32 in [0, 1], optional
    uv : (m, 3, 2) float32, optional
        Texture coordinates of each face corner, origin at the image's bottom left.
    texture : (H, W, 3) uint8, optional
        RGB texture image, first row at the top.
    name : str
    transform : Similarity
        Maps ``vertices`` back to the source file's frame and units
        (identity for a mesh made in memory).

    Raises
    ------
    MeshError
        An array of the wrong shape, a face index out of range or a
        non-finite vertex: every stage would fail on it, or read memory it
        does not own.

    Examples
    --------
    >>> m = Mesh(vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0]], faces=[[0, 1, 2]])
    >>> m.vertices.dtype, m.faces.dtype, m.vertex_colors
    (dtype('float64'), dtype('int32'), None)
    """

    vertices: np.ndarray
    faces: np.ndarray
    vertex_colors: np.ndarray | None = None
    uv: np.ndarray | None = None
    texture: np.ndarray | None = None
    name: str = ""
    transform: Similarity = field(default_factory=Similarity)

    def __post_init__(self):
        V = np.ascontiguousarray(self.vertices, dtype=np.float64)
        given = np.asarray(self.faces)
        label = f"mesh {self.name!r}" if self.name else "mesh"
        if V.ndim != 2 or V.shape[1] != 3:
            raise MeshError(f"{label}: vertices must have shape (n, 3), got {V.shape}")
        if given.ndim != 2 or given.shape[1] != 3:
            raise MeshError(f"{label}: faces must have shape (m, 3), got {given.shape}")
        # On the indices as given: int32 would wrap a larger one into range.
        check_face_indices(given, len(V), label)
        F = np.ascontiguousarray(given, dtype=np.int32)
        finite = np.isfinite(V).all(axis=1)
        if not finite.all():
            raise MeshError(f"{label}: vertex {int(np.argmin(finite))} has non-finite coordinates")
        object.__setattr__(self, "vertices", V)
        object.__setattr__(self, "faces", F)
        if self.vertex_colors is not None:
            C = np.ascontiguousarray(self.vertex_colors, dtype=np.float32)
            if C.shape != V.shape:
                raise MeshError(f"{label}: vertex_colors must have shape {V.shape}, got {C.shape}")
            object.__setattr__(self, "vertex_colors", np.clip(C, 0.0, 1.0))
        if self.uv is not None:
            UV = np.ascontiguousarray(self.uv, dtype=np.float32)
            if UV.shape != (F.shape[0], 3, 2):
                raise MeshError(f"{label}: uv must have shape {(F.shape[0], 3, 2)}, got {UV.shape}")
            object.__setattr__(self, "uv", UV)
        if self.texture is not None:
            T = np.ascontiguousarray(self.texture, dtype=np.uint8)
            if T.ndim != 3 or T.shape[2] != 3:
                raise MeshError(f"{label}: texture must have shape (H, W, 3), got {T.shape}")
            object.__setattr__(self, "texture", T)

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])

    def replace(self, **changes) -> Mesh:
        """A copy with some fields changed (``dataclasses.replace``)."""
        return dataclasses.replace(self, **changes)
