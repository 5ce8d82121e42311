"""Triangle meshes: the record (``record``), derived geometry (``geometry``), mesh files (``formats``
checks them for what pymeshlab misreads and reads OFF, ``io`` loads and writes them, ``texture`` reads
their material libraries and images), what loading repairs
(``repair``), sizing (``transform``), curvature and mesh saliency (``curvature``) and the Embree scene
that every ray caster shares (``embree``)."""

from meshsal.mesh.geometry import (
    bounding_sphere,
    closed_orientation,
    face_areas,
    face_normals,
    half_edges,
    normal_defined,
    ring_max,
    surface_distance,
    vertex_adjacency,
    vertex_normals,
)
from meshsal.mesh.record import Mesh, MeshError, Similarity

__all__ = [
    "Mesh",
    "MeshError",
    "Similarity",
    "face_normals",
    "face_areas",
    "vertex_normals",
    "normal_defined",
    "bounding_sphere",
    "closed_orientation",
    "surface_distance",
    "half_edges",
    "vertex_adjacency",
    "ring_max",
]
