"""meshsal: meshes, rendering, visual attention and interest points.

Mesh -> 72 rendered views -> eight-channel saliency per view -> interest
points fused on the mesh.  Public names are loaded on first use, so that
``import meshsal`` stays cheap for the command line.
"""

from .lazy import attach

_EXPORTS = {
    "Mesh": "mesh",
    "MeshError": "mesh",
    "Similarity": "mesh",
    "face_normals": "mesh",
    "face_areas": "mesh",
    "vertex_normals": "mesh",
    "bounding_sphere": "mesh",
    "closed_orientation": "mesh",
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
    "points_by_method": "points",
    "TouchModel": "learned",
    "fit_touch_model": "learned",
    "project_pixel_paper": "points",
}
_SUBMODULES = {"render", "tracer", "toys", "ycb", "objects", "instances", "reproducible", "registry", "sdf",
               "attention", "curvature", "points", "sampling", "overlay", "embree", "io", "transform", "progress",
               "atomic", "learned", "touch"}

__getattr__, __dir__, __all__ = attach(__name__, _EXPORTS, _SUBMODULES)
