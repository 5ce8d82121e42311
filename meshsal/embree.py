"""The Embree ray-casting scene shared by the renderer, point projection and tactile imprints."""

from __future__ import annotations

import numpy as np

from .mesh import Mesh


def embree_scene(mesh: Mesh):
    """An Embree scene of the mesh's triangles, built and ready for concurrent queries.

    ``scene.run(origins, directions, output=1)`` takes (k, 3) float32 arrays
    and returns a dict with ``primID`` (-1 on a miss), ``u``, ``v`` (the hit's
    barycentrics on the triangle's 2nd and 3rd corners), ``tfar`` and ``Ng``.
    Embree releases the GIL while tracing, so threads may share one scene.

    Examples
    --------
    >>> tri = Mesh(vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0]], faces=[[0, 1, 2]])
    >>> hit = embree_scene(tri).run(np.array([[0.2, 0.2, 1]], np.float32),
    ...                             np.array([[0, 0, -1]], np.float32), output=1)
    >>> int(hit["primID"][0]), float(hit["tfar"][0])
    (0, 1.0)
    """
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    scene = rtcs.EmbreeScene()
    TriangleMesh(scene, np.ascontiguousarray(mesh.vertices, dtype=np.float32),
                 np.ascontiguousarray(mesh.faces, dtype=np.int32))
    # The first query commits (builds) the scene: do it before threads share it.
    scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), output=0)
    return scene
