"""Small meshes with known geometry, built in memory for tests (the tactile ones in millimetres)."""

import numpy as np

from meshsal.mesh import Mesh


def icosphere(radius: float = 1.0, subdivisions: int = 3, center=(0.0, 0.0, 0.0)) -> Mesh:
    """A closed sphere: an icosahedron split ``subdivisions`` times, vertices pushed to the sphere."""
    t = (1.0 + 5**0.5) / 2.0
    V = [
        [-1, t, 0],
        [1, t, 0],
        [-1, -t, 0],
        [1, -t, 0],
        [0, -1, t],
        [0, 1, t],
        [0, -1, -t],
        [0, 1, -t],
        [t, 0, -1],
        [t, 0, 1],
        [-t, 0, -1],
        [-t, 0, 1],
    ]
    F = [
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ]
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


def _grid(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit square split into n x n quads: (n+1)^2 (u, v) points and 2 n^2 triangles."""
    u, v = np.meshgrid(np.linspace(0.0, 1.0, n + 1), np.linspace(0.0, 1.0, n + 1), indexing="ij")
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    F = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return np.stack([u.ravel(), v.ravel()], 1), F


def _orient(V: np.ndarray, F: np.ndarray, outward) -> np.ndarray:
    """Flip faces whose normal disagrees with ``outward(centroids) -> (m,3)``."""
    T = V[F]
    n = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
    flip = (n * outward(T.mean(axis=1))).sum(axis=1) < 0
    F = F.copy()
    F[flip] = F[flip][:, ::-1]
    return F


def _weld(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    _, first, inverse = np.unique(np.round(V, 9), axis=0, return_index=True, return_inverse=True)
    return V[first], inverse.reshape(-1)[F]


def plane(size: float = 200.0, n: int = 10) -> Mesh:
    """The square |x|, |z| <= size/2 at y = 0, facing +y."""
    uv, F = _grid(n)
    V = np.stack([(uv[:, 0] - 0.5) * size, np.zeros(len(uv)), (uv[:, 1] - 0.5) * size], 1)
    return Mesh(vertices=V, faces=_orient(V, F, lambda c: np.array([0.0, 1.0, 0.0])), name="plane")


def _box_points(n: int) -> tuple[np.ndarray, np.ndarray]:
    uv, F = _grid(n)
    uv = 2.0 * uv - 1.0
    Vs, Fs = [], []
    for axis in range(3):
        for side in (-1.0, 1.0):
            V = np.zeros((len(uv), 3))
            V[:, axis] = side
            V[:, (axis + 1) % 3], V[:, (axis + 2) % 3] = uv[:, 0], uv[:, 1]
            Fs.append(F + sum(len(v) for v in Vs))
            Vs.append(V)
    return _weld(np.concatenate(Vs), np.concatenate(Fs))


def box(half: float = 30.0, n: int = 60) -> Mesh:
    """The closed cube |x|, |y|, |z| <= half, each face an n x n grid."""
    V, F = _box_points(n)
    V = V * half
    return Mesh(vertices=V, faces=_orient(V, F, lambda c: c), name="box")


def sphere(radius: float = 40.0, n: int = 40, center=(0.0, 0.0, 0.0)) -> Mesh:
    """A closed sphere: a cube grid pushed onto the sphere (poles at the face centres, +-y among them)."""
    V, F = _box_points(n)
    V = V / np.linalg.norm(V, axis=1, keepdims=True) * radius
    F = _orient(V, F, lambda c: c)
    return Mesh(vertices=V + np.asarray(center, dtype=np.float64), faces=F, name="sphere")


def bowl(radius: float = 60.0, n: int = 40, depth: float = 0.65) -> Mesh:
    """An open hemispherical bowl: the sphere below ``z = (depth - 1) * radius`` reversed, faces outward
    (away from the centre).  ``.replace(faces=bowl().faces[:, ::-1])`` faces into it, as many scans of open
    objects do."""
    s = sphere(radius=radius, n=n)
    keep = s.vertices[s.faces].mean(axis=1)[:, 2] < (depth - 1.0) * radius + 1e-9
    used = np.unique(s.faces[keep])
    index = np.full(s.n_vertices, -1)
    index[used] = np.arange(used.size)
    return Mesh(vertices=s.vertices[used], faces=index[s.faces[keep]], name="bowl")


def cylinder(radius: float = 20.0, length: float = 120.0, around: int = 256, along: int = 12) -> Mesh:
    """An open tube of the given radius around the x axis, |x| <= length/2, normals outward."""
    uv, F = _grid(along)
    t = np.linspace(0.0, 2.0 * np.pi, around, endpoint=False)
    x = np.linspace(-length / 2, length / 2, along + 1)
    X, T = np.meshgrid(x, t, indexing="ij")
    V = np.stack([X.ravel(), radius * np.cos(T.ravel()), radius * np.sin(T.ravel())], 1)
    idx = np.arange(V.shape[0]).reshape(along + 1, around)
    a, b = idx[:-1], idx[1:]
    c, d = np.roll(b, -1, axis=1), np.roll(a, -1, axis=1)
    F = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return Mesh(vertices=V, faces=_orient(V, F, lambda c: c * [0.0, 1.0, 1.0]), name="cylinder")


def bumps(size: float = 80.0, n: int = 80, seed: int = 0) -> Mesh:
    """A y-up height field of random Gaussian bumps and dents, with no symmetry."""
    rng = np.random.default_rng(seed)
    uv, F = _grid(n)
    x, z = (uv[:, 0] - 0.5) * size, (uv[:, 1] - 0.5) * size
    y = np.zeros_like(x)
    for _ in range(12):
        cx, cz = rng.uniform(-20, 20, 2)
        y += rng.uniform(-3, 3) * np.exp(-((x - cx) ** 2 + (z - cz) ** 2) / (2 * rng.uniform(3, 8) ** 2))
    V = np.stack([x, y, z], 1)
    return Mesh(vertices=V, faces=_orient(V, F, lambda c: np.array([0.0, 1.0, 0.0])), name="bumps")


def write_obj(path, mesh: Mesh) -> None:
    """A plain Wavefront OBJ of the mesh (for command-line tests)."""
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in mesh.vertices.tolist()]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in mesh.faces.tolist()]
    path.write_text("\n".join(lines) + "\n")


#: Where :func:`ball_and_domed` puts the dome: a unit direction from the ball's centre.
DOME_APEX = np.array([0.6, 0.64, 0.48]) / np.linalg.norm([0.6, 0.64, 0.48])


def ball_and_domed() -> tuple[Mesh, Mesh]:
    """Two objects that differ in one place only: a ball of radius 50, and the same ball with a dome on it."""
    ball = sphere(radius=50.0, n=24).replace(name="ball")
    angle = np.arccos(np.clip(ball.vertices @ DOME_APEX / 50.0, -1.0, 1.0))
    domed = Mesh(ball.vertices * (1.0 + 0.25 * np.exp(-((angle / 0.25) ** 2)))[:, None], ball.faces, name="domed")
    return ball, domed
