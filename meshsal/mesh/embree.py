"""The Embree ray-casting scene shared by the renderer, point projection and tactile imprints.

embreex copies a mesh into Embree one element at a time through Python
indexing: 50 ms of a 77 ms build for 100k faces.  Where the layout of its
scene object is the one checked below, :func:`embree_scene` instead hands
the vertex and index buffers to the Embree library embreex ships, through
ctypes, in one copy each (1 ms); anywhere else it falls back to embreex's
own path.  The scenes are the same either way.

Embree picks SSE2, AVX, AVX2 or AVX-512 kernels by CPU, and they round
differently: a hit's distance and barycentrics change in the last bits, and
with them renders, imprints and points.  Embree 4 takes its instruction set
only from the configuration string of the device a scene is created in
(``isa=sse2``, ``max_isa=avx2``...; it reads no environment variable or
file), and embreex creates every device without one.  So every scene here
is created in one device per process made with ``$VISUOTACTILE_EMBREE_CONFIG``
(``isa=sse2`` once :func:`meshsal.util.reproducible.pin_kernels` has run),
handed to embreex through ctypes.  With the variable unset or empty, Embree
chooses.

Even with one instruction set, Embree's SSE kernels divide by the CPU's
approximate reciprocal (``rcpps`` and a Newton step), which Intel and AMD
round with their own tables.  So every scene here is a :class:`Scene`, which
settles each hit's face, distance, barycentrics and normal with NumPy's
correctly rounded arithmetic: the same on every x86-64 CPU.
"""

from __future__ import annotations

import ctypes
import functools
import os
import threading
import warnings
import weakref
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from meshsal.mesh import Mesh
from meshsal.util.reproducible import EMBREE_VARIABLE

# Embree 4 constants (rtcore_geometry.h, rtcore_buffer.h, rtcore_common.h).
_GEOMETRY_TYPE_TRIANGLE = 0
_BUFFER_TYPE_INDEX, _BUFFER_TYPE_VERTEX = 0, 1
_FORMAT_UINT3, _FORMAT_FLOAT3 = 0x5003, 0x9003
_SCENE_FLAG_ROBUST = 1 << 2


@functools.cache
def _library():
    """The Embree library that embreex loaded, with the few signatures used here, or None."""
    try:
        import embreex
    except ImportError:
        return None
    shipped = sorted((Path(embreex.__file__).parent.parent / "embreex.libs").glob("libembree4*.so*"))
    if not shipped:
        return None
    try:
        lib = ctypes.CDLL(str(shipped[0]))  # the same file embreex loaded: the same library state
    except OSError:
        return None
    handle = ctypes.c_void_p
    signatures = {
        "rtcNewDevice": (handle, [ctypes.c_char_p]),
        "rtcGetSceneDevice": (handle, [handle]),
        "rtcReleaseDevice": (None, [handle]),
        "rtcGetDeviceError": (ctypes.c_int, [handle]),
        "rtcGetDeviceLastErrorMessage": (ctypes.c_char_p, [handle]),
        "rtcNewGeometry": (handle, [handle, ctypes.c_int]),
        "rtcSetNewGeometryBuffer": (
            handle,
            [handle, ctypes.c_int, ctypes.c_uint, ctypes.c_int, ctypes.c_size_t, ctypes.c_size_t],
        ),
        "rtcCommitGeometry": (None, [handle]),
        "rtcAttachGeometry": (ctypes.c_uint, [handle, handle]),
        "rtcReleaseGeometry": (None, [handle]),
        "rtcGetSceneFlags": (ctypes.c_int, [handle]),
    }
    for name, (restype, argtypes) in signatures.items():
        function = getattr(lib, name, None)
        if function is None:
            return None
        function.restype, function.argtypes = restype, argtypes
    return lib


def _scene_handle(scene) -> int | None:
    """The RTCScene inside an embreex ``EmbreeScene``, or None if its layout is not the expected one.

    embreex declares the object as the Python object header, then ``RTCScene
    scene_i``, then ``int is_committed`` (rtcore_scene.pxd).  Writing two
    values to the public ``is_committed`` and reading them back at its
    expected place proves the layout before the pointer next to it is used.
    """
    header = object.__basicsize__
    if type(scene).__basicsize__ < header + 16:
        return None
    field = id(scene) + header + 8
    saved = scene.is_committed
    try:
        seen = []
        for probe in (0x5A17, 0x1CE):
            scene.is_committed = probe
            seen.append(ctypes.c_int.from_address(field).value)
    finally:
        scene.is_committed = saved
    if seen != [0x5A17, 0x1CE]:
        return None
    return ctypes.c_void_p.from_address(id(scene) + header).value


def _attach_directly(scene, mesh: Mesh) -> bool:
    """Add the mesh's triangles to an empty, uncommitted embreex scene in one copy per buffer.

    Returns False, having attached nothing usable, where this cannot be done.
    """
    lib = _library()
    handle = _scene_handle(scene) if lib is not None else None
    if not handle:
        return False
    device = lib.rtcGetSceneDevice(handle)
    try:
        geometry = lib.rtcNewGeometry(device, _GEOMETRY_TYPE_TRIANGLE)
        if not geometry:
            return False
        # Vertices padded to 16 bytes, as embreex lays them out.
        vertices = np.zeros((mesh.n_vertices, 4), np.float32)
        vertices[:, :3] = mesh.vertices
        faces = np.ascontiguousarray(mesh.faces, dtype=np.uint32)
        for kind, fmt, array in (
            (_BUFFER_TYPE_VERTEX, _FORMAT_FLOAT3, vertices),
            (_BUFFER_TYPE_INDEX, _FORMAT_UINT3, faces),
        ):
            target = lib.rtcSetNewGeometryBuffer(geometry, kind, 0, fmt, array.strides[0], len(array))
            if not target:
                lib.rtcReleaseGeometry(geometry)
                return False
            ctypes.memmove(target, array.ctypes.data, array.nbytes)
        lib.rtcCommitGeometry(geometry)
        lib.rtcAttachGeometry(handle, geometry)
        lib.rtcReleaseGeometry(geometry)
        return lib.rtcGetDeviceError(device) == 0
    finally:
        lib.rtcReleaseDevice(device)


def _device_slot(device):
    """Where an embreex ``EmbreeDevice`` keeps its RTCDevice (a ctypes pointer), or None if that is not proven.

    embreex declares the object as the Python object header, then ``RTCDevice
    device`` (rtcore.pxd).  A scene created in the device reports the device
    it belongs to (``rtcGetSceneDevice``): equal to the pointer at that place,
    it proves the layout.
    """
    from embreex import rtcore_scene as rtcs

    lib = _library()
    header = object.__basicsize__
    if lib is None or type(device).__basicsize__ < header + 8:
        return None
    handle = _scene_handle(rtcs.EmbreeScene(device=device))
    if not handle:
        return None
    owner = lib.rtcGetSceneDevice(handle)
    try:
        slot = ctypes.c_void_p.from_address(id(device) + header)
        return slot if owner and slot.value == owner else None
    finally:
        lib.rtcReleaseDevice(owner)


_device_lock = threading.Lock()


@functools.cache
def _configured_device(config: str):
    """One embreex ``EmbreeDevice`` made with ``config``, or None where embreex's layout is not the one checked."""
    from embreex import rtcore as rtc

    device = rtc.EmbreeDevice()
    slot = _device_slot(device)
    if slot is None:
        warnings.warn(
            f"${EMBREE_VARIABLE}={config!r} is not applied: this embreex's device is not the one "
            f"meshsal.mesh.embree knows, so Embree picks its kernels by CPU",
            RuntimeWarning,
            stacklevel=3,
        )
        return None
    lib = _library()
    made = lib.rtcNewDevice(config.encode())
    if not made:
        message = (lib.rtcGetDeviceLastErrorMessage(None) or b"no message").decode(errors="replace")
        raise ValueError(f"Embree refuses the device configuration ${EMBREE_VARIABLE}={config!r}: {message}")
    replaced, slot.value = slot.value, made
    lib.rtcReleaseDevice(replaced)
    return device


def embree_device():
    """The embreex device every scene is created in: made with ``$VISUOTACTILE_EMBREE_CONFIG``, or None.

    None when the variable is unset or empty (embreex then makes a device
    per scene, and Embree picks its kernels by CPU).

    Raises
    ------
    ValueError
        If Embree refuses the configuration (e.g. ``isa=avx512`` on a CPU without it).
    """
    config = os.environ.get(EMBREE_VARIABLE, "").strip()
    if not config:
        return None
    with _device_lock:
        return _configured_device(config)


def is_robust(scene) -> bool:
    """Whether the scene is known to trace robustly: no ray slips between two triangles sharing an edge.

    False for a scene built with ``robust=False``, and for any scene whose
    flags cannot be read.
    """
    while hasattr(scene, "embree"):  # a Scene, or a stand-in around one (meshsal.mesh.rounding), holds embreex's
        scene = scene.embree
    lib = _library()
    handle = _scene_handle(scene) if lib is not None else None
    return bool(handle) and bool(lib.rtcGetSceneFlags(handle) & _SCENE_FLAG_ROBUST)


#: Within this fraction of an edge's length of an edge, Embree's float32 arithmetic may put a hit on either
#: face there, so the face across it is weighed too.
_NEAR_EDGE = 1e-3
#: A crossing this near a face (a fraction of the edge's length), or two distances this near (relative), are the
#: same: far above the error of float64's :func:`_crossing`, far below float32's.
_SAME = 1e-9
#: Each mesh's :attr:`Scene.corners` and :attr:`Scene.neighbors`, for as long as the mesh lives: its fast and
#: robust scenes share them.
_TABLES = {"corners": weakref.WeakKeyDictionary(), "neighbors": weakref.WeakKeyDictionary()}
_tables_lock = threading.Lock()


def _per_mesh(kind: str, mesh: Mesh, compute) -> np.ndarray:
    """``compute(mesh)``, once per mesh and ``kind``."""
    with _tables_lock:
        found = _TABLES[kind].get(mesh)
        if found is None:
            found = _TABLES[kind][mesh] = compute(mesh)
    return found


@dataclass(frozen=True, eq=False)
class Scene:
    """An Embree scene whose hits are the same on every x86-64 CPU.

    Embree's ``tfar``, ``u`` and ``v`` are quotients taken with the CPU's
    approximate reciprocal, and between two faces meeting at an edge it keeps
    the one it meets first unless the other is nearer by that quotient.  So
    :meth:`run` keeps only Embree's answer to which faces a ray meets, and
    settles the rest from the faces' float32 corners, the ray's origin and
    its direction in float64 (Cramer's rule, elementwise, rounded once to
    float32):

    - the distance and barycentrics, nearer the exact crossing than Embree's;
    - the face: within a thousandth of an edge's length of an edge Embree's
      face shares with one other face (by the corners' positions, so across
      texture seams too), the one of the two that holds its crossing with
      the ray nearer the ray's origin; at the same distance (the ray through
      the edge) the one facing the ray, then the lower index;
    - the geometric normal ``Ng``: the cross product of the face's edges
      from its first corner.

    What stays Embree's: a crossing near a corner, or on an edge of three or
    more faces, and faces at the same place that share no edge.

    Attributes
    ----------
    embree : embreex ``EmbreeScene``
    corners : (m, 15) float64
        A row per face: its first corner, its edges to the second and third
        corners, their cross product, and the cross product's length over each
        edge's squared length (edges opposite the first, second and third
        corner): 120 contiguous bytes a face, beside Embree's own hundred or so,
        so that a hit's face is gathered in one copy.
    mesh : Mesh
        The mesh the scene holds.
    """

    embree: object
    corners: np.ndarray
    mesh: Mesh

    @property
    def is_committed(self) -> int:
        return self.embree.is_committed

    @property
    def neighbors(self) -> np.ndarray:
        """(m, 3) int64: the other face across each face's edge opposite its first, second, third corner, or -1.

        Found at the first hit near an edge, once for all the mesh's scenes.
        """
        return _per_mesh("neighbors", self.mesh, _neighbors)

    def run(self, origins, directions, dists=None, query="INTERSECT", output=None):
        """embreex's ``EmbreeScene.run``, each hit settled as :class:`Scene` says.

        Parameters
        ----------
        origins : (k, 3) float32
        directions : (k, 3) float32, or (1, 3) shared by every ray
        dists : float or (k,) float32, optional
            How far each ray looks (``tfar`` on entry).
        query : str
        output : int, optional
            1 for the dict of hits described in :func:`embree_scene`; else
            what embreex gives (the face ids).
        """
        hit = self.embree.run(origins, directions, dists=dists, query=query, output=output)
        if isinstance(hit, dict):
            _settle(hit, origins, directions, self)
        return hit


def _corners(mesh: Mesh) -> np.ndarray:
    """The (m, 15) float64 table of :attr:`Scene.corners`, from the float32 vertices Embree holds."""
    V = np.asarray(mesh.vertices, np.float32).T.astype(np.float64)
    F = np.asarray(mesh.faces)
    table = np.empty((len(F), 15))
    columns = table.T
    a, e, f, n, spans = columns[0:3], columns[3:6], columns[6:9], columns[9:12], columns[12:15]
    for axis in range(3):
        np.take(V[axis], F[:, 0], out=a[axis])
        np.subtract(np.take(V[axis], F[:, 1]), a[axis], out=e[axis])
        np.subtract(np.take(V[axis], F[:, 2]), a[axis], out=f[axis])
    for axis in range(3):
        i, j = (axis + 1) % 3, (axis + 2) % 3
        np.subtract(e[i] * f[j], e[j] * f[i], out=n[axis])
    area = np.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
    with np.errstate(divide="ignore", invalid="ignore"):
        for row, side in zip(spans, (f - e, f, e)):  # the edges opposite the first, second, third corner
            np.divide(area, side[0] * side[0] + side[1] * side[1] + side[2] * side[2], out=row)
    return table


def _neighbors(mesh: Mesh) -> np.ndarray:
    """(m, 3) int64: across the edge opposite each corner, the one other face with that edge's two positions, or -1."""
    V = np.asarray(mesh.vertices, np.float32) + np.float32(0.0)  # -0.0 becomes 0.0: one position, one key
    F = np.asarray(mesh.faces, np.int64)
    # Vertices at the same float32 position are one: faces across a texture seam are neighbours too.
    order = np.lexsort(V.T[::-1])
    ranked = V[order]
    fresh = np.r_[True, np.any(ranked[1:] != ranked[:-1], axis=1)]
    place = np.empty(len(V), np.int64)
    place[order] = np.cumsum(fresh) - 1
    corners = place[F]
    n, m = int(place.max()) + 1, len(F)
    ends = [(corners[:, (j + 1) % 3], corners[:, (j + 2) % 3]) for j in range(3)]
    keys = np.concatenate([np.minimum(p, q) * n + np.maximum(p, q) for p, q in ends])
    order = np.argsort(keys)
    ranked = keys[order]
    starts = np.r_[True, ranked[1:] != ranked[:-1]]
    group = np.cumsum(starts) - 1
    size = np.bincount(group)[group]
    first = np.flatnonzero((size == 2) & starts)  # the first of each edge two faces have
    out = np.full(3 * m, -1, np.int64)
    out[order[first]] = order[first + 1] % m
    out[order[first + 1]] = order[first] % m
    return np.ascontiguousarray(out.reshape(3, m).T)  # a row per face, as the hits read them


def _crossing(faces: np.ndarray, origins: np.ndarray, directions: np.ndarray) -> tuple:
    """``(t, u, v, d . n)`` float64 solving ``o + t d = a + u e + v f`` for the (15, k) ``faces`` of :func:`_faces`.

    Cramer's rule with ``m = s x d``, ``s = o - a``: ``t = -(s . n) / (d . n)``,
    ``u = -(f . m) / (d . n)``, ``v = (e . m) / (d . n)``.  Elementwise
    arithmetic only (no dot products, whose summation order and fused
    multiply-adds vary by library), each operation correctly rounded.
    """
    ax, ay, az, ex, ey, ez, fx, fy, fz, nx, ny, nz = faces[:12]
    ox, oy, oz = origins.astype(np.float64).T
    dx, dy, dz = directions.astype(np.float64).T
    sx, sy, sz = ox - ax, oy - ay, oz - az
    mx = sy * dz
    mx -= sz * dy
    my = sz * dx
    my -= sx * dz
    mz = sx * dy
    mz -= sy * dx
    dn = dx * nx
    dn += dy * ny
    dn += dz * nz
    t, u, v = sx * nx, fx * mx, ex * mx
    t += sy * ny
    t += sz * nz
    u += fy * my
    u += fz * mz
    v += ey * my
    v += ez * mz
    with np.errstate(divide="ignore", invalid="ignore"):
        for quotient in (t, u, v):
            quotient /= dn
    np.negative(t, out=t)
    np.negative(u, out=u)
    return t, u, v, dn


def _inside(faces: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(3, k): how far inside each face's edge opposite its 1st, 2nd, 3rd corner the crossing lies, in edge lengths."""
    with np.errstate(invalid="ignore"):
        return np.stack([1.0 - u - v, u, v]) * faces[12:15]


def _faces(scene: Scene, ids: np.ndarray) -> np.ndarray:
    """(15, k) float64: the faces' rows of :attr:`Scene.corners`, gathered in one pass and seen by column."""
    return np.take(scene.corners, ids, axis=0).T


def _settle(hit: dict, origins: np.ndarray, directions: np.ndarray, scene: Scene) -> None:
    """Settle each hit's face, ``tfar``, ``u``, ``v`` and ``Ng`` in float64 arithmetic (see :class:`Scene`)."""
    every = hit["primID"] >= 0
    hits = slice(None) if every.all() else np.flatnonzero(every)
    if not isinstance(hits, slice):
        if hits.size == 0:
            return
        origins = origins if len(origins) == 1 else np.take(origins, hits, axis=0)
        directions = directions if len(directions) == 1 else np.take(directions, hits, axis=0)
    ids = hit["primID"][hits].astype(np.int64)
    faces = _faces(scene, ids)
    crossing = _crossing(faces, origins, directions)
    inside = _inside(faces, crossing[1], crossing[2])
    with np.errstate(invalid="ignore"):
        near = np.flatnonzero(inside.min(axis=0) <= _NEAR_EDGE)
    if near.size:
        inside = inside[:, near]
        moved = _weigh_the_face_across(
            scene, near, np.argmin(inside, axis=0), inside, ids, crossing, origins, directions
        )
        faces[:, moved] = _faces(scene, ids[moved])  # the faces the hits moved to, for their normals
    # Rounded to float32 before the scatter: NumPy scatters values of another type several times more slowly.
    for key, values in zip(("tfar", "u", "v"), crossing):
        if np.isfinite(values).all():
            hit[key][hits] = values.astype(np.float32)
        else:  # a face parallel to the ray in float64 too is degenerate: Embree's own value stays
            keep = np.isfinite(values)
            hit[key][np.flatnonzero(every)[keep]] = values[keep].astype(np.float32)
    hit["primID"][hits] = ids
    hit["Ng"][hits] = faces[9:12].T.astype(np.float32)


def _weigh_the_face_across(scene: Scene, near, edge, inside, ids, crossing, origins, directions) -> np.ndarray:
    """Give the ``near`` hits, whose faces' ``edge`` they lie near, the face of the two there that :class:`Scene`
    says (``ids`` and ``crossing``, ``(t, u, v, d . n)``, are changed in place); returns the hits moved."""
    f = ids[near]
    g = scene.neighbors[f, edge]
    known = np.flatnonzero(g >= 0)
    near, f, g, inside = near[known], f[known], g[known], inside[:, known]
    if near.size == 0:
        return near
    rays_o = origins if len(origins) == 1 else origins[near]
    rays_d = directions if len(directions) == 1 else directions[near]
    faces = _faces(scene, g)
    across = _crossing(faces, rays_o, rays_d)
    t_f, t_g = crossing[0][near], across[0]
    with np.errstate(invalid="ignore"):
        holds_f = inside.min(axis=0) >= -_SAME
        holds_g = (_inside(faces, across[1], across[2]).min(axis=0) >= -_SAME) & (t_g > 0)
        same = np.abs(t_g - t_f) <= _SAME * np.maximum(np.abs(t_f), np.abs(t_g))
    # The ray through the edge: the face it meets from the front (d . n < 0), then the lower index.
    front_f, front_g = crossing[3][near] < 0, across[3] < 0
    rather = (front_g & ~front_f) | ((front_g == front_f) & (g < f))
    move = np.flatnonzero(holds_g & (~holds_f | np.where(same, rather, t_g < t_f)))
    rows = near[move]
    ids[rows] = g[move]
    for ours, theirs in zip(crossing, across):
        ours[rows] = theirs[move]
    return rows


def embree_scene(mesh: Mesh, robust: bool = True):
    """A :class:`Scene` of the mesh's triangles, built and ready for concurrent queries.

    ``scene.run(origins, directions, output=1)`` takes (k, 3) float32 arrays
    and returns a dict with ``primID`` (-1 on a miss), ``u``, ``v`` (the hit's
    barycentrics on the triangle's 2nd and 3rd corners), ``tfar`` and ``Ng``,
    the same on every x86-64 CPU.
    Embree releases the GIL while tracing, so threads may share one scene.
    Every scene is created in :func:`embree_device`, whose instruction set
    ``$VISUOTACTILE_EMBREE_CONFIG`` chooses.

    A robust scene (the default) is watertight: a ray through an edge or a
    vertex meets one of the faces there.  ``robust=False`` traces about a
    fifth faster, but a few rays in a million slip through such cracks.

    Examples
    --------
    >>> tri = Mesh(vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0]], faces=[[0, 1, 2]])
    >>> hit = embree_scene(tri).run(np.array([[0.2, 0.2, 1]], np.float32),
    ...                             np.array([[0, 0, -1]], np.float32), output=1)
    >>> int(hit["primID"][0]), round(float(hit["tfar"][0]), 5)       # float32 arithmetic: 1.0 within rounding
    (0, 1.0)
    """
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    device = embree_device()
    scene = rtcs.EmbreeScene(device=device, robust=robust)
    if mesh.n_faces == 0 or not _attach_directly(scene, mesh):
        scene = rtcs.EmbreeScene(device=device, robust=robust)
        TriangleMesh(
            scene,
            np.ascontiguousarray(mesh.vertices, dtype=np.float32),
            np.ascontiguousarray(mesh.faces, dtype=np.int32),
        )
    # The first query commits (builds) the scene: do it before threads share it.
    scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), output=0)
    return Scene(embree=scene, corners=_per_mesh("corners", mesh, _corners), mesh=mesh)
