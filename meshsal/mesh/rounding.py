"""Embree's hits as another CPU may round them: a stand-in scene, to check that results do not depend on it.

Embree's SSE kernels divide with the CPU's approximate reciprocal (``rcpps``),
which Intel and AMD round with their own tables, so another CPU may give a
hit's distance and barycentrics other last bits and, near an edge of two
faces, the face across it.  :class:`OtherRounding` wraps an embreex scene
and gives its hits so; :func:`rounded_otherwise` makes every scene built in
its ``with`` block do it.  Inside a :class:`~meshsal.mesh.embree.Scene`
(``where="embree"``) the settling should absorb all of it; around the
settled hits (``where="settled"``) it shows what the results would be
without the settling.  ``scripts/other_rounding.py`` runs an experiment
both ways.
"""

from __future__ import annotations

import contextlib
import threading

import numpy as np

from meshsal.mesh import embree as embree_module
from meshsal.mesh.embree import Scene, _crossing, _faces, _inside

#: Where :func:`rounded_otherwise` puts the stand-in: around Embree's hits, or around the settled ones.
WHERE = ("embree", "settled")


class OtherRounding:
    """A scene whose hits round as another CPU's may.

    A ``share`` of the hits' ``tfar``, ``u`` and ``v`` move one unit in the
    last place up or down, at seeded random; with ``settled`` (the
    :class:`~meshsal.mesh.embree.Scene` whose corners and neighbours to use),
    every hit whose crossings with its face and with the face across an edge
    both lie within a ten-thousandth of that edge's length of it (away from
    the faces' other edges) is put on the other face, as float32 arithmetic
    and another rounding of the two distances may put it.

    Parameters
    ----------
    embree : object with ``run(origins, directions, **kwargs)``
        An embreex scene, or a :class:`~meshsal.mesh.embree.Scene`.
    share : float in [0, 1]
    rng : numpy.random.Generator
    settled : Scene, optional

    Attributes
    ----------
    moved, turned : int
        How many values moved a unit in the last place, and how many hits
        went to the face across an edge, so far.

    Examples
    --------
    >>> from meshsal.mesh import Mesh
    >>> from meshsal.mesh.embree import embree_scene
    >>> square = Mesh(vertices=[[0, 0, 0], [4, 0, 0], [0, 4, 0]], faces=[[0, 1, 2]])
    >>> scene = embree_scene(square)
    >>> other = OtherRounding(scene.embree, 1.0, np.random.default_rng(0))
    >>> o, d = np.array([[1, 1, 3]], np.float32), np.array([[0, 0, -1]], np.float32)
    >>> float(other.run(o, d, output=1)["tfar"][0]) != 3.0, float(scene.run(o, d, output=1)["tfar"][0])
    (True, 3.0)
    """

    def __init__(self, embree, share: float, rng: np.random.Generator, settled: Scene | None = None):
        self.embree, self.share, self.rng, self.settled = embree, share, rng, settled
        self.moved = self.turned = 0
        self._lock = threading.Lock()  # renderers share a scene across threads, and the generator is not safe

    def __getattr__(self, name):
        # The rest of the scene (is_committed, a Scene's corners and mesh) is the wrapped one's.
        if name == "embree":  # not yet set: no wrapped scene to ask
            raise AttributeError(name)
        return getattr(self.embree, name)

    def run(self, origins, directions, **kwargs):
        hit = self.embree.run(origins, directions, **kwargs)
        if isinstance(hit, dict):
            hits = np.flatnonzero(hit["primID"] >= 0)
            with self._lock:
                for key in ("tfar", "u", "v"):
                    some = hits[self.rng.random(hits.size) < self.share]
                    away = np.where(self.rng.random(some.size) < 0.5, -np.inf, np.inf).astype(np.float32)
                    hit[key][some] = np.nextafter(hit[key][some], away)
                    self.moved += some.size
            if self.settled is not None and hits.size:
                self._turn_edges(hit, hits, origins, directions)
        return hit

    def _turn_edges(self, hit, hits, origins, directions) -> None:
        def near_one_edge_only(inside):
            inside = np.sort(inside, axis=0)
            return (np.abs(inside[0]) < 1e-4) & (inside[1] > 1e-3)

        def inside_of(ids, o, d):
            faces = _faces(self.settled, ids)
            _, u, v, _ = _crossing(faces, o, d)
            return _inside(faces, u, v)

        o = origins if len(origins) == 1 else origins[hits]
        d = directions if len(directions) == 1 else directions[hits]
        f = hit["primID"][hits]
        inside = inside_of(f, o, d)
        g = self.settled.neighbors[f, np.argmin(inside, axis=0)]
        near = np.flatnonzero(near_one_edge_only(inside) & (g >= 0))
        o = o if len(o) == 1 else o[near]
        d = d if len(d) == 1 else d[near]
        turned = near[near_one_edge_only(inside_of(g[near], o, d))]
        hit["primID"][hits[turned]] = g[turned]
        with self._lock:
            self.turned += turned.size


@contextlib.contextmanager
def rounded_otherwise(share: float = 1.0, seed: int = 0, where: str = "embree"):
    """Every Embree scene built in the block gives its hits as another CPU may round them.

    It replaces :class:`meshsal.mesh.embree.Scene` for the block's duration,
    in every thread: a check to run on its own, not beside other work.

    Parameters
    ----------
    share : float in [0, 1]
        The share of each hit value moved a unit in the last place; hits near
        an edge go to the face across it too (see :class:`OtherRounding`).
    seed : int
    where : {"embree", "settled"}
        Around Embree's own hits, which the scene then settles, or around
        the settled hits: what results would be without the settling.

    Yields
    ------
    list of OtherRounding
        The stand-ins of the scenes built so far, for their counts.

    Examples
    --------
    >>> from meshsal.mesh import Mesh
    >>> from meshsal.mesh.embree import embree_scene
    >>> square = Mesh(vertices=[[0, 0, 0], [4, 0, 0], [0, 4, 0]], faces=[[0, 1, 2]])
    >>> o, d = np.array([[1, 1, 3]], np.float32), np.array([[0, 0, -1]], np.float32)
    >>> with rounded_otherwise() as stand_ins:
    ...     float(embree_scene(square).run(o, d, output=1)["tfar"][0])
    3.0
    >>> stand_ins[0].moved
    3
    """
    if where not in WHERE:
        raise ValueError(f"where must be one of {WHERE}, got {where!r}")
    rng, stand_ins, built = np.random.default_rng(seed), [], Scene

    def scene(embree, corners, mesh):
        settled = built(embree=embree, corners=corners, mesh=mesh)
        stand_ins.append(OtherRounding(embree if where == "embree" else settled, share, rng, settled=settled))
        # Around the settled hits the stand-in is the scene: inside another Scene they would be settled again.
        return built(embree=stand_ins[-1], corners=corners, mesh=mesh) if where == "embree" else stand_ins[-1]

    embree_module.Scene = scene
    try:
        yield stand_ins
    finally:
        embree_module.Scene = built
