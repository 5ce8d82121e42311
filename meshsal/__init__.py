"""meshsal: meshes, rendering, visual attention and interest points.

Mesh -> 72 rendered views -> eight-channel saliency per view -> interest
points fused on the mesh.  Public names are loaded on first use, so that
``import meshsal`` stays cheap for the command line.
"""

import importlib

_EXPORTS = {
    "Mesh": "mesh",
    "MeshError": "mesh",
    "Similarity": "mesh",
    "face_normals": "mesh",
    "face_areas": "mesh",
    "vertex_normals": "mesh",
    "bounding_sphere": "mesh",
    "vertex_adjacency": "mesh",
    "load_mesh": "io",
    "save_ply": "io",
    "MeshRepairWarning": "io",
    "scale_to": "transform",
    "normalize": "transform",
    "Camera": "render",
    "View": "render",
    "view_rig": "render",
    "render_views": "render",
    "mean_curvature": "curvature",
    "mesh_saliency": "curvature",
    "InterestPoints": "points",
    "interest_points": "points",
    "project_pixel_paper": "points",
}
_SUBMODULES = {"render", "toys", "sdf", "attention", "curvature", "points", "sampling", "overlay", "embree",
               "io", "transform", "progress", "atomic"}

__all__ = sorted(_EXPORTS) + sorted(_SUBMODULES)


def __getattr__(name):
    if name in _EXPORTS:
        value = getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
        globals()[name] = value
        return value
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return __all__
