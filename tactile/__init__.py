"""tactile: simulated 16x16 tactile imprints at surface points, their realism and selection.

Points on a mesh (millimetres) -> a pad pressed at each point -> contour or
pressure images (fast Embree path :func:`imprints`, exact reference
:func:`imprint_exact`) -> perturbed acquisitions (:func:`acquire`) ->
similarity-based selection (:func:`select_by_similarity`) -> imprint sets on
disk (:class:`ImprintSet`).  To take imprints on one mesh over many calls,
build its Embree scene once (``meshsal.mesh.embree.embree_scene(mesh)``) and pass
it as ``scene=`` to :func:`imprints` or :func:`imprint`.  Public names are
loaded on first use, so that ``import tactile`` stays cheap for the command
line.
"""

import lazy_loader

_EXPORTS = {
    "Sensor": "sensor",
    "Poses": "sensor",
    "sensor_poses": "sensor",
    "imprint": "raycast",
    "imprints": "raycast",
    "imprint_exact": "section",
    "imprints_exact": "section",
    "Perturbation": "perturbation",
    "acquire": "perturbation",
    "touch_codebook": "perturbation",
    "Acquisition": "perturbation",
    "acquire_all": "perturbation",
    "select_by_similarity": "selection",
    "select_leaving_out": "selection",
    "ImprintSet": "imprint_set",
    "imprint_grid": "picture",
}

__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__, None, {m: [n for n, where in _EXPORTS.items() if where == m] for m in set(_EXPORTS.values())}
)
