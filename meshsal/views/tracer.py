"""First hits of rays on a mesh: Embree's robust answers at the speed of its fast traversal.

Embree's robust mode is watertight: a ray through an edge or a vertex meets
one of the faces there.  Its fast mode traces about a fifth faster, but a
few rays in a million slip through such a crack and report a face behind
it.  On a closed, consistently oriented surface the slips show: a ray from
outside meets the surface first from outside, while a ray that slipped in is
inside the solid and meets the surface next from inside.  So a
:class:`Tracer` casts every ray through the fast scene and traces again,
robustly, the rays whose first hit faces away from them: in a small robust
scene of the faces their lines can meet, or in the whole mesh's robust
scene, built once, when many slipped at a time.  Surfaces that are not
closed and consistently oriented are traced robustly from the start.

Rays must start outside the solid, as a camera's do: a ray from inside
meets the surface first from inside, and one that slipped out could next
meet another part from outside unnoticed.

What it returns equals the robust scene's answers, but for ties: a ray
through an edge or a vertex may report another of the faces there (at the
same distance), barycentrics round differently, and a ray that only grazes
the surface at its silhouette, touching an edge or a vertex, may report a
miss.  One case stays out of reach: where a closed surface passes through
itself, a ray that slipped in can next meet another part from outside.
For such meshes pass a robust scene, ``tracer(mesh, embree_scene(mesh))``.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from concurrent.futures import Executor
from dataclasses import dataclass

import numpy as np

from meshsal.mesh import Mesh, closed_orientation
from meshsal.mesh.embree import embree_scene, is_robust

__all__ = ["Tracer", "tracer"]

# Each ray traced near its line costs a pass over the mesh (1.2 ms per 100k faces); past about
# this many in one call, building the whole robust scene once (30 ms of CPU) costs less.
_LOCAL_RAYS = 24


def _once(build: Callable[[], object]) -> Callable[[], object]:
    """``build()`` on the first call from any thread, its result on every call."""
    lock, built = threading.Lock(), []

    def get():
        with lock:
            if not built:
                built.append(build())
        return built[0]

    return get


@dataclass(frozen=True, eq=False)
class Tracer:
    """First hits of rays on one mesh, as a robust Embree scene gives them (see the module docstring).

    Build it with :func:`tracer`; call :meth:`first_hits` from any number of
    threads.

    Attributes
    ----------
    mesh : Mesh
    fast : Embree scene or None
        The non-robust scene every ray is cast through first; None when the
        robust scene answers every ray.
    facing : callable () -> int
        The mesh's :func:`~meshsal.mesh.closed_orientation`, waited for on first use.
    robust : callable () -> Embree scene
        The mesh's robust scene, built on first use.
    reach : callable () -> (m,) float64
        Each face's longest edge, measured on first use.
    local_rays : int
        Up to this many slipped rays of a call are traced in a small scene of
        the faces their lines can meet, more in the robust scene; 0 when the
        robust scene is held elsewhere, so using it costs no build.
    """

    mesh: Mesh
    fast: object | None
    facing: Callable[[], int]
    robust: Callable[[], object]
    reach: Callable[[], np.ndarray]
    local_rays: int = _LOCAL_RAYS

    def first_hits(self, origins: np.ndarray, directions: np.ndarray) -> dict:
        """The first hit of each ray.

        Parameters
        ----------
        origins : (k, 3) float32, outside the solid the mesh bounds (see the module docstring)
        directions : (k, 3) float32 unit vectors, or one (1, 3) row shared by all rays

        Returns
        -------
        dict
            ``primID`` (k,) int32, the face hit (-1 on a miss); ``u``, ``v``
            (k,) float32, the hit's barycentrics on the face's 2nd and 3rd
            corners; ``tfar`` (k,) float32, the distance to it (inf on a miss);
            ``Ng`` (k, 3) float32, the face's unnormalized geometric normal.
        """
        facing = self.facing() if self.fast is not None else 0
        hit = (self.fast if facing else self.robust()).run(origins, directions, dists=np.inf, output=1)
        if facing:
            self._retrace_slipped(facing, origins, directions, hit)
        return hit

    def _retrace_slipped(self, facing: int, origins: np.ndarray, directions: np.ndarray, hit: dict) -> None:
        if len(directions) == 1:
            along = hit["Ng"] @ directions[0]
        else:
            along = np.einsum("kd,kd->k", hit["Ng"], directions)
        # Edge-on faces (along == 0) are traced again too.
        slipped = np.flatnonzero((hit["primID"] >= 0) & (along * facing >= 0))
        if slipped.size == 0:
            return
        origins = np.take(origins, slipped, axis=0)
        if len(directions) > 1:
            directions = np.take(directions, slipped, axis=0)
        if slipped.size > self.local_rays:
            again = self.robust().run(origins, directions, dists=np.inf, output=1)
        else:
            again = _trace_near(self.mesh, self.reach(), origins, directions)
        for key, values in again.items():
            hit[key][slipped] = values


def _longest_edges(mesh: Mesh) -> np.ndarray:
    """The longest edge of each face, (m,) float64."""
    a, b, c = (np.take(mesh.vertices, corner, axis=0) for corner in mesh.faces.T)
    squared = [np.einsum("ij,ij->i", p - q, p - q) for p, q in ((a, b), (b, c), (c, a))]
    return np.sqrt(np.maximum(np.maximum(squared[0], squared[1]), squared[2]))


def _trace_near(mesh: Mesh, reach: np.ndarray, origins: np.ndarray, directions: np.ndarray) -> dict:
    """Robust first hits of a few rays, in a scene of only the faces their lines can meet.

    A face a line passes through has all its corners within its longest
    edge, ``reach``, of the crossing point, so of the line.  Face ids come
    back in the mesh's numbering.
    """
    V, F = mesh.vertices, mesh.faces
    # A margin for the float32 rounding of the scene's vertices and of the rays.
    reach = reach + 1e-5 * (np.abs(V).max() + np.abs(origins).max())
    near = np.zeros(len(F), bool)
    for o, d in zip(origins.astype(np.float64), np.broadcast_to(directions, origins.shape).astype(np.float64)):
        offset = V - o
        along = offset @ d
        distance = np.sqrt(np.maximum(np.einsum("nd,nd->n", offset, offset) - along * along, 0.0))
        farthest = np.maximum(
            np.maximum(np.take(distance, F[:, 0]), np.take(distance, F[:, 1])), np.take(distance, F[:, 2])
        )
        near |= farthest <= reach
    faces = np.flatnonzero(near)
    used, corners = np.unique(F[faces], return_inverse=True)
    local = Mesh(vertices=V[used], faces=corners.reshape(-1, 3))
    hit = embree_scene(local).run(origins, directions, dists=np.inf, output=1)
    seen = hit["primID"] >= 0
    hit["primID"][seen] = faces[hit["primID"][seen]]
    return hit


def tracer(mesh: Mesh, scene=None, executor: Executor | None = None, robust: Callable | None = None) -> Tracer:
    """A :class:`Tracer` of the mesh.

    Parameters
    ----------
    mesh : Mesh
    scene : optional
        ``meshsal.mesh.embree.embree_scene(mesh, robust=False)`` of this very mesh
        to reuse one across calls; a robust scene answers every ray itself.
        By default a fast scene is built (it costs about 15 ms per 100k faces).
    executor : optional
        Where the mesh's orientation is checked while the scene builds.
    robust : callable () -> Embree scene, optional
        Gives the mesh's robust scene (``embree_scene(mesh)``) held elsewhere,
        in which every slipped ray is traced again; by default the tracer
        builds its own when many slip at once.

    Raises
    ------
    ValueError
        If the mesh has no faces.

    Examples
    --------
    >>> tri = Mesh(vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0]], faces=[[0, 1, 2]])
    >>> hit = tracer(tri).first_hits(np.array([[0.2, 0.2, 1]], np.float32), np.array([[0, 0, -1]], np.float32))
    >>> int(hit["primID"][0]), round(float(hit["tfar"][0]), 5)       # float32 arithmetic: 1.0 within rounding
    (0, 1.0)
    """
    if mesh.n_faces == 0:
        raise ValueError(f"cannot trace rays on mesh {mesh.name!r}: it has no faces")
    reach = _once(lambda: _longest_edges(mesh))
    if scene is not None and is_robust(scene):
        return Tracer(mesh=mesh, fast=None, facing=lambda: 0, robust=lambda: scene, reach=reach)
    orientation = (
        executor.submit(closed_orientation, mesh.vertices, mesh.faces).result
        if executor is not None
        else _once(lambda: closed_orientation(mesh.vertices, mesh.faces))
    )
    # Built before the orientation is known: an open mesh wastes it, a closed one needs it at once.
    fast = embree_scene(mesh, robust=False) if scene is None else scene
    if robust is None:
        return Tracer(mesh=mesh, fast=fast, facing=orientation, robust=_once(lambda: embree_scene(mesh)), reach=reach)
    return Tracer(mesh=mesh, fast=fast, facing=orientation, robust=_once(robust), reach=reach, local_rays=0)
