"""Small meshes with known geometry, built in memory for tests."""

import numpy as np

from meshsal.mesh import Mesh


def icosphere(radius: float = 1.0, subdivisions: int = 3, center=(0.0, 0.0, 0.0)) -> Mesh:
    """A closed sphere: an icosahedron split ``subdivisions`` times, vertices pushed to the sphere."""
    t = (1.0 + 5 ** 0.5) / 2.0
    V = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
         [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]
    F = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
         [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
         [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    for _ in range(subdivisions):
        edges = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
        unique, inverse = np.unique(edges, axis=0, return_inverse=True)
        mid = V.shape[0] + inverse.reshape(3, -1).T  # midpoints of edges 01, 12, 20 per face
        V = np.vstack([V, 0.5 * (V[unique[:, 0]] + V[unique[:, 1]])])
        a, b, c = F.T
        ab, bc, ca = mid.T
        F = np.concatenate([np.stack(x, 1) for x in ([a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca])])
    V = V / np.linalg.norm(V, axis=1, keepdims=True) * radius + np.asarray(center, dtype=np.float64)
    return Mesh(vertices=V, faces=F, name="icosphere")
