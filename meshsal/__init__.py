"""meshsal: meshes, objects, rendering, visual attention and interest points.

The sub-packages follow the data: ``mesh`` (the record, its files and
geometry) -> ``objects`` (the embedded objects and fresh instances of any
object) -> ``views`` (the 72-view renderer) -> ``attention`` (conspicuity
maps) -> ``points`` (where to touch).  ``util`` holds the toolkit's
infrastructure (atomic writes, progress bars, registries).  Public names are
loaded on first use (``lazy_loader``), so that ``import meshsal`` stays cheap
for the command line.  Modules moved in 0.2 are listed in ``CHANGELOG.md``.
"""

import lazy_loader

_EXPORTS = {
    "Mesh": "mesh",
    "MeshError": "mesh",
    "Similarity": "mesh",
    "face_normals": "mesh",
    "face_areas": "mesh",
    "vertex_normals": "mesh",
    "normal_defined": "mesh",
    "bounding_sphere": "mesh",
    "closed_orientation": "mesh",
    "vertex_adjacency": "mesh",
    "load_mesh": "mesh.io",
    "save_ply": "mesh.io",
    "MeshRepairWarning": "mesh.io",
    "MeshReport": "mesh.repair",
    "repair_mesh": "mesh.repair",
    "scale_to": "mesh.transform",
    "normalize": "mesh.transform",
    "scale_to_principal": "mesh.transform",
    "UnitsWarning": "mesh.transform",
    "mean_curvature": "mesh.curvature",
    "mesh_saliency": "mesh.curvature",
    "Camera": "views.cameras",
    "View": "views.cameras",
    "view_rig": "views.cameras",
    "render_views": "views.render",
    "InterestPoints": "points",
    "interest_points": "points",
    "points_by_method": "points",
    "TouchModel": "points.learned",
    "fit_touch_model": "points.learned",
    "project_pixel_paper": "views.paper_projection",
    "write_png": "util.atomic",
}
_SUBMODULES = {"util", "mesh", "objects", "views", "attention", "points", "cli"}

__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__, _SUBMODULES, {m: [n for n, where in _EXPORTS.items() if where == m] for m in set(_EXPORTS.values())}
)
