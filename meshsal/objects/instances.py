"""Fresh instances of an object: turned, resized and repainted copies of one mesh.

An evaluation that trains on one copy of an object and tests on another
must not let the copies share anything but the object itself: pose, size
and paint vary between instances, as they would between two cups on a
table.  :func:`draw_instance` draws those variations from a generator;
:func:`make_instance` applies them to a mesh that
:func:`meshsal.mesh.transform.scale_to_principal` has brought to its nominal
size, centroid at the origin.

* pose: a rotation uniform over SO(3) (a uniform unit quaternion, ``scipy.spatial.transform.Rotation``);
* size: a scale factor uniform in ``1 ± scale_spread`` (5 % by default);
* paint: the toys of :mod:`meshsal.objects.toys` are repainted with a new paint
  seed; any other coloured mesh (vertex colours or a texture) has its hue
  turned about the grey axis and its brightness scaled; an uncoloured mesh
  stays uncoloured.

:func:`retessellate` gives an instance another tessellation of the same
surface (half the faces, or each face split in four): a test instance whose
vertices are not those training touched, as a scan of a real object's would not be.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from meshsal.mesh import Mesh, Similarity

__all__ = [
    "InstanceSpec",
    "TESSELLATIONS",
    "random_rotation",
    "draw_instance",
    "make_instance",
    "recolor",
    "retessellate",
]


#: Other tessellations of a surface (:func:`retessellate`).
TESSELLATIONS = ("decimated", "subdivided")


@dataclass(frozen=True, eq=False)
class InstanceSpec:
    """How one instance departs from the nominal object.

    Attributes
    ----------
    rotation : (3, 3) float64
        Proper rotation about the centroid.
    scale : float
        Size relative to the nominal one.
    paint_seed : int
        New paint seed (toys).
    hue_deg : float
        Hue turn about the grey axis (other coloured meshes).
    brightness : float
        Brightness factor (other coloured meshes).
    """

    rotation: np.ndarray
    scale: float
    paint_seed: int
    hue_deg: float
    brightness: float

    def key(self) -> list:
        """A JSON-ready description, for cache keys and reports."""
        return [
            np.round(self.rotation, 12).tolist(),
            round(self.scale, 12),
            self.paint_seed,
            round(self.hue_deg, 9),
            round(self.brightness, 12),
        ]


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A rotation matrix uniform over SO(3), (3, 3) float64.

    A unit quaternion from four standard normal draws is uniform on the
    3-sphere, hence its rotation is uniform over SO(3) (Shoemake 1992).

    Examples
    --------
    >>> R = random_rotation(np.random.default_rng(0))
    >>> bool(np.allclose(R @ R.T, np.eye(3))), bool(np.isclose(np.linalg.det(R), 1.0))
    (True, True)
    """
    w, x, y, z = rng.standard_normal(4)
    return Rotation.from_quat([x, y, z, w]).as_matrix()


def draw_instance(
    rng: np.random.Generator,
    scale_spread: float = 0.05,
    hue_deg: float = 30.0,
    brightness_spread: float = 0.15,
    rotate: bool = True,
) -> InstanceSpec:
    """Draw one instance's pose, size and paint.

    Parameters
    ----------
    rng : numpy.random.Generator
    scale_spread : float
        Scale uniform in ``[1 - scale_spread, 1 + scale_spread]``.
    hue_deg : float
        Hue turn uniform in ``[-hue_deg, hue_deg]``.
    brightness_spread : float
        Brightness factor uniform in ``[1 - brightness_spread, 1 + brightness_spread]``.
    rotate : bool
        False keeps the nominal pose (identity rotation).

    Examples
    --------
    >>> spec = draw_instance(np.random.default_rng(1))
    >>> 0.95 <= spec.scale <= 1.05, -30 <= spec.hue_deg <= 30
    (True, True)
    """
    if not 0 <= scale_spread < 1 or not 0 <= brightness_spread < 1 or hue_deg < 0:
        raise ValueError(
            f"spreads must be in [0, 1) and hue_deg >= 0, got scale_spread={scale_spread}, "
            f"brightness_spread={brightness_spread}, hue_deg={hue_deg}"
        )
    rotation = random_rotation(rng) if rotate else np.eye(3)
    scale = float(rng.uniform(1 - scale_spread, 1 + scale_spread))
    paint_seed = int(rng.integers(2**31 - 1))
    hue = float(rng.uniform(-hue_deg, hue_deg))
    brightness = float(rng.uniform(1 - brightness_spread, 1 + brightness_spread))
    return InstanceSpec(rotation, scale, paint_seed, hue, brightness)


def recolor(colors: np.ndarray, hue_deg: float, brightness: float) -> np.ndarray:
    """Turn RGB colours about the grey axis by ``hue_deg`` and scale them by ``brightness``.

    Parameters
    ----------
    colors : (..., 3) float in [0, 1] or uint8
    hue_deg, brightness : float

    Returns
    -------
    The same shape and dtype, clipped to the valid range.

    Examples
    --------
    >>> recolor(np.array([[0.5, 0.5, 0.5]]), 90.0, 1.0).round(6).tolist()   # grey has no hue
    [[0.5, 0.5, 0.5]]
    >>> recolor(np.array([[1.0, 0.0, 0.0]]), 120.0, 1.0).round(6).tolist()  # red -> green
    [[0.0, 1.0, 0.0]]
    """
    c = np.asarray(colors)
    t = np.deg2rad(hue_deg)
    cos, sin = np.cos(t), np.sin(t)
    # Rodrigues' rotation about (1, 1, 1) / sqrt(3).
    k = (1.0 - cos) / 3.0
    s = sin / np.sqrt(3.0)
    M = np.array([[cos + k, k - s, k + s], [k + s, cos + k, k - s], [k - s, k + s, cos + k]]) * brightness
    if c.dtype == np.uint8:
        out = (c.astype(np.float64) @ M.T).round()
        return np.clip(out, 0, 255).astype(np.uint8)
    return np.clip(c.astype(np.float64) @ M.T, 0.0, 1.0).astype(c.dtype)


def make_instance(mesh: Mesh, spec: InstanceSpec) -> Mesh:
    """Apply an instance's paint, size and pose to a nominal mesh (centroid at the origin).

    The returned mesh's ``transform`` composes the turn and the resize with
    the mesh's earlier steps, so ``transform.to_source`` still leads back to
    the file.

    Examples
    --------
    >>> m = Mesh(vertices=[[1.0, 0, 0], [0, 1, 0], [0, 0, 1]], faces=[[0, 1, 2]])
    >>> spec = InstanceSpec(np.eye(3), 2.0, 0, 0.0, 1.0)
    >>> make_instance(m, spec).vertices[0].tolist()
    [2.0, 0.0, 0.0]
    """
    from meshsal.objects import toys

    if mesh.name in toys.NAMES and mesh.vertex_colors is not None:
        mesh = toys.repaint(mesh, spec.paint_seed)
    else:
        if mesh.vertex_colors is not None:
            mesh = mesh.replace(vertex_colors=recolor(mesh.vertex_colors, spec.hue_deg, spec.brightness))
        if mesh.texture is not None:
            mesh = mesh.replace(texture=recolor(mesh.texture, spec.hue_deg, spec.brightness))
    step = Similarity(spec.scale, np.zeros(3), spec.rotation)
    return mesh.replace(vertices=step.apply(mesh.vertices), transform=mesh.transform.then(step))


def retessellate(mesh: Mesh, kind: str) -> Mesh:
    """The same surface with other vertices: ``"decimated"`` (half the faces) or ``"subdivided"`` (each face in four).

    Decimation collapses the shortest edges to their midpoints (libigl's
    ``decimate``); a kept vertex keeps the colour of the vertex it came from,
    and faces the collapses left without area are dropped
    (``meshsal.mesh.repair.repair_mesh``).
    Subdivision splits every face at its edges' midpoints (libigl's
    ``upsample``), which leaves the surface exactly where it was; colours and
    texture coordinates are interpolated.  A textured mesh cannot be
    decimated (its texture coordinates belong to faces that collapse).

    Parameters
    ----------
    mesh : Mesh
    kind : one of :data:`TESSELLATIONS`

    Returns
    -------
    Mesh, with the same name and transform

    Examples
    --------
    >>> tetra = Mesh(vertices=[[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]],
    ...              faces=[[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    >>> retessellate(tetra, "subdivided").n_faces
    16
    """
    import igl

    if kind not in TESSELLATIONS:
        raise ValueError(f"unknown tessellation {kind!r}; choose from {', '.join(TESSELLATIONS)}")
    V, F = mesh.vertices, np.asarray(mesh.faces, np.int32)
    if kind == "decimated":
        if mesh.uv is not None:
            raise ValueError(f"{mesh.name or 'mesh'}: a textured mesh cannot be decimated (use 'subdivided')")
        from meshsal.mesh.repair import repair_mesh

        U, G, _, born = igl.decimate(V, F, max(4, mesh.n_faces // 2))
        colors = None if mesh.vertex_colors is None else mesh.vertex_colors[np.asarray(born, np.int64)]
        return repair_mesh(mesh.replace(vertices=U, faces=G, vertex_colors=colors))[0]
    columns = [V] if mesh.vertex_colors is None else [V, mesh.vertex_colors.astype(np.float64)]
    both, G = igl.upsample(np.ascontiguousarray(np.hstack(columns)), F)
    colors = None if mesh.vertex_colors is None else both[:, 3:]
    uv = None
    if mesh.uv is not None:
        # libigl's upsample gives face (a, b, c) four children in a row: (a, ab, ca), (b, bc, ab), (ab, bc, ca), (bc, c, ca).
        a, b, c = mesh.uv[:, 0], mesh.uv[:, 1], mesh.uv[:, 2]
        ab, bc, ca = (a + b) / 2, (b + c) / 2, (c + a) / 2
        uv = np.stack([np.stack(t, axis=1) for t in ((a, ab, ca), (b, bc, ab), (ab, bc, ca), (bc, c, ca))], axis=1)
        uv = uv.reshape(-1, 3, 2)
    return mesh.replace(vertices=both[:, :3], faces=G, vertex_colors=colors, uv=uv)
