"""One mesh being worked on: what the stages compute of it, each once, when first asked.

An experiment's instance, or a batch's mesh, goes through the point
methods, the touch check, the imprints and the codebooks.  They all need
the same things of it: its robust Embree scene, its vertex normals, its mesh
saliency, and, for the methods that look, its 72 rendered views with their
channels.  A :class:`Workpiece` holds the mesh and computes each of these on
first use, so a caller builds one per mesh and passes it on, and no stage
builds a second scene or renders twice.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from meshsal.attention.rig import ViewChannels, view_channels
from meshsal.mesh import Mesh, vertex_normals
from meshsal.points.attend import check_field
from meshsal.points.rules import PointOptions

__all__ = ["Workpiece"]


@dataclass(frozen=True, eq=False)
class Workpiece:
    """A mesh and what the stages compute of it, each on first use (see the module docstring).

    Attributes
    ----------
    mesh : Mesh
    view_size : int
        Side of the rendered views, pixels.
    threads : int or None
        Rendering and attention threads (None: the CPU count); changes nothing in the result.
    quiet : bool
        No progress bar while the views' channels are computed.

    Examples
    --------
    >>> import meshsal
    >>> piece = Workpiece.of(meshsal.objects.toys.make("cup"), view_size=64)
    >>> piece.scene is piece.scene, piece.vertex_saliency.shape == (piece.mesh.n_vertices,)
    (True, True)
    """

    mesh: Mesh
    view_size: int = PointOptions.size
    threads: int | None = None
    quiet: bool = True

    def __post_init__(self):
        if not isinstance(self.mesh, Mesh):
            raise ValueError(f"a Workpiece needs a meshsal.Mesh, got {type(self.mesh).__name__}")

    @classmethod
    def of(
        cls,
        mesh: Mesh,
        *,
        scene=None,
        vertex_saliency=None,
        seen: ViewChannels | None = None,
        view_size: int = PointOptions.size,
        threads: int | None = None,
        quiet: bool = True,
    ) -> Workpiece:
        """A workpiece of ``mesh`` that starts from what the caller already has.

        Parameters
        ----------
        mesh : Mesh, or a Workpiece (returned as it is when nothing else is given)
        scene : optional, the mesh's robust Embree scene (``meshsal.mesh.embree.embree_scene(mesh)``)
        vertex_saliency : (n_vertices,) float64, optional
        seen : ViewChannels, optional, the mesh's views and channels at ``view_size``
        view_size, threads, quiet : as the attributes
        """
        if isinstance(mesh, Workpiece):
            if scene is None and vertex_saliency is None and seen is None:
                return mesh
            mesh = mesh.mesh
        piece = cls(mesh, int(view_size), threads, quiet)
        if vertex_saliency is not None:
            vertex_saliency = check_field(mesh, vertex_saliency)
        # cached_property keeps its value in the instance's __dict__: what is given is what it returns.
        given = {"scene": scene, "vertex_saliency": vertex_saliency, "seen": seen}
        piece.__dict__.update({k: v for k, v in given.items() if v is not None})
        return piece

    @cached_property
    def scene(self):
        """The mesh's robust Embree scene (:func:`meshsal.mesh.embree.embree_scene`)."""
        from meshsal.mesh.embree import embree_scene

        return embree_scene(self.mesh)

    @cached_property
    def vertex_normals(self) -> np.ndarray:
        """(n_vertices, 3) float64 area-weighted unit vertex normals."""
        return vertex_normals(self.mesh.vertices, self.mesh.faces)

    @cached_property
    def vertex_saliency(self) -> np.ndarray:
        """(n_vertices,) float64, Lee et al.'s mesh saliency (:func:`meshsal.mesh.curvature.mesh_saliency`)."""
        from meshsal.mesh.curvature import mesh_saliency

        return check_field(self.mesh, mesh_saliency(self.mesh))

    @cached_property
    def seen(self) -> ViewChannels:
        """The rig's 72 views at ``view_size`` and their channels (:func:`meshsal.attention.rig.view_channels`).

        The renderer's slipped rays are traced again in :attr:`scene`, so the mesh has one robust scene.
        """
        from meshsal.views.tracer import tracer

        return view_channels(
            self.mesh,
            size=self.view_size,
            vertex_saliency=self.vertex_saliency,
            threads=self.threads,
            quiet=self.quiet,
            scene=tracer(self.mesh, robust=lambda: self.scene),
        )
